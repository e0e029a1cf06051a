"""The blade-frame test the guard uses: known states and properties (CONVENTIONS §1-2)."""

import inspect
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sitl_fakes.disturbance
import sitl_fakes.physics
from flighttest.flying import guard
from flighttest.model import frames
from flighttest.model.frames import GuardRegion

REGION = GuardRegion(w_allow_mps=0.8, v_h_mps=6.0, cone_deg=20.0, margin_mps=0.0)
LEVEL = (1.0, 0.0, 0.0, 0.0)


def glide(speed, angle_deg):
    """NED velocity of a level vehicle descending along a glide path of ``angle_deg`` below horizontal."""
    a = math.radians(angle_deg)
    return speed * math.cos(a), 0.0, speed * math.sin(a)


def test_rotation_matches_matrix():
    q = frames.quat_from_euler(0.3, -0.2, 1.1)
    r = frames.quat_to_rotmat(q)
    v = np.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(frames.ned_to_body(*v, *q), r.T @ v, atol=1e-12)
    np.testing.assert_allclose(frames.body_to_ned(*v, *q), r @ v, atol=1e-12)
    np.testing.assert_allclose(np.array(frames.quat_to_euler(q)), [0.3, -0.2, 1.1], atol=1e-12)


C45 = math.sqrt(0.5)
YAW_90 = (C45, 0.0, 0.0, C45)  # nose east
ROLL_90 = (C45, C45, 0.0, 0.0)  # right wing down


# every helper that rotates a vector: (callable, the names its vector's three components go by, how
# many parameters come before them, whether a wind follows the quaternion)
ROTATION_HELPERS = [
    (frames.ned_to_body, ("vn", "ve", "vd"), 0, False),
    (frames.body_to_ned, ("bx", "by", "bz"), 0, False),
    (frames.blade_velocity_mps, ("vn", "ve", "vd"), 0, True),
    (GuardRegion.check, ("vn", "ve", "vd"), 1, True),  # after self
    (sitl_fakes.physics.rotate_body_to_ned, ("bx", "by", "bz"), 0, False),
    (sitl_fakes.physics.rotate_ned_to_body, ("vn", "ve", "vd"), 0, False),
    (sitl_fakes.disturbance.blade_velocity_mps, ("vn", "ve", "vd"), 0, True),
    (sitl_fakes.disturbance.Disturbance.step, ("vn", "ve", "vd"), 2, True),  # after self, dt_s
]


@pytest.mark.parametrize(
    ("helper", "vector", "skip", "wind"),
    ROTATION_HELPERS,
    ids=[f"{h.__module__}.{h.__qualname__}" for h, *_ in ROTATION_HELPERS],
)
def test_every_rotation_helper_takes_the_vector_then_the_quaternion_then_the_wind(helper, vector, skip, wind):
    names = list(inspect.signature(helper).parameters)[skip:]
    expected = [*vector, "qw", "qx", "qy", "qz", *(("wn", "we", "wd") if wind else ())]
    assert names == expected, f"{helper.__module__}.{helper.__qualname__}{inspect.signature(helper)}"


def test_the_planned_attitude_helper_keeps_the_order_and_refuses_the_old_one():
    # the commanded acceleration stands where the quaternion does, the wind after it
    names = list(inspect.signature(guard.predicted_blade_velocity_mps).parameters)
    assert names == ["vn", "ve", "vd", "an_cmd", "ae_cmd", "ad_cmd", "wn", "we", "wd", "horizon_s"]
    # ten positional arguments were (v, wind, a_cmd, horizon): now refused, not silently swapped
    with pytest.raises(TypeError):
        guard.predicted_blade_velocity_mps(0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    # rising air (updraft 1 m/s) under a level disk, no acceleration: 1 m/s through the disk; with
    # the wind taken for the acceleration it would read 0
    w, u = guard.predicted_blade_velocity_mps(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, horizon_s=0.0)
    assert (w, u) == pytest.approx((1.0, 0.0))


ROTATE_CASES = [
    # (quaternion, body vector, the same vector in NED), worked by hand: yaw 90° turns body x (nose)
    # to east and body y (right) to south; roll 90° turns body y to down and body z to west
    (YAW_90, (1.0, 2.0, 3.0), (-2.0, 1.0, 3.0)),
    (ROLL_90, (1.0, 2.0, 3.0), (1.0, -3.0, 2.0)),
]


@pytest.mark.parametrize(("q", "body", "ned"), ROTATE_CASES)
@pytest.mark.parametrize(
    ("to_ned", "to_body"),
    [
        (frames.body_to_ned, frames.ned_to_body),
        (sitl_fakes.physics.rotate_body_to_ned, sitl_fakes.physics.rotate_ned_to_body),
    ],
    ids=["flighttest", "fake"],
)
def test_rotations_with_a_known_answer(to_ned, to_body, q, body, ned):
    """Seven floats either way round: only a known answer tells a swapped order (or a conjugated
    quaternion) from the right one."""
    np.testing.assert_allclose(to_ned(*body, *q), ned, atol=1e-12)
    np.testing.assert_allclose(to_body(*ned, *q), body, atol=1e-12)


@pytest.mark.parametrize("blade", [frames.blade_velocity_mps, sitl_fakes.disturbance.blade_velocity_mps])
def test_blade_velocity_with_a_known_answer(blade):
    # rolled 90° (right wing down, body z pointing west), flying east at 2 m/s with a 0.5 m/s east
    # wind: 1.5 m/s through the air along −z_body, as in a climb, so the air flows down through the
    # disk (w = −1.5) and none of it across
    w, u = blade(0.0, 2.0, 0.0, *ROLL_90, 0.0, 0.5, 0.0)
    assert float(w) == pytest.approx(-1.5) and float(u) == pytest.approx(0.0, abs=1e-12)


def test_px4_convention_pitch():
    # PX4: positive pitch is nose up. Nose down 10°: body +x points forward and down, so a straight
    # descent has a positive body-x component; nose up, a negative one. Body z stays near the descent.
    q = frames.quat_from_euler(0.0, math.radians(-10), 0.0)
    bx, _, bz = frames.ned_to_body(0.0, 0.0, 1.0, *q)
    assert bx == pytest.approx(math.sin(math.radians(10)))
    q = frames.quat_from_euler(0.0, math.radians(10), 0.0)
    bx, _, bz = frames.ned_to_body(0.0, 0.0, 1.0, *q)
    assert bx == pytest.approx(-math.sin(math.radians(10))) and bz == pytest.approx(math.cos(math.radians(10)))
    # positive roll (right wing down): body +y points right and down
    q = frames.quat_from_euler(math.radians(30), 0.0, 0.0)
    _, by, _ = frames.ned_to_body(0.0, 0.0, 1.0, *q)
    assert by == pytest.approx(math.sin(math.radians(30)))


def test_hover_is_allowed():
    allowed, w, u, m = REGION.check(0.0, 0.0, 0.0, *LEVEL)
    assert allowed and w == 0 and u == 0 and m == pytest.approx(0.8)


def test_glide_15_deg_allowed_30_deg_forbidden():
    assert REGION.check(*glide(5.0, 15.0), *LEVEL)[0]
    allowed, w, u, m = REGION.check(*glide(5.0, 30.0), *LEVEL)
    assert not allowed and m < 0
    assert w == pytest.approx(2.5) and u == pytest.approx(5 * math.cos(math.radians(30)))


def test_straight_descent_above_w_allow_forbidden_below_allowed():
    assert not REGION.check(0.0, 0.0, 1.0, *LEVEL)[0]
    assert REGION.check(0.0, 0.0, 0.7, *LEVEL)[0]


def test_climb_always_allowed():
    for vn in (0.0, 3.0, -10.0):
        assert REGION.check(vn, 0.0, -2.0, *LEVEL)[0]
    strict = GuardRegion(0.0, 6.0, 20.0, margin_mps=0.3)
    assert strict.check(0.0, 0.0, -0.01, *LEVEL)[0]


def test_upside_down_descent_allowed():
    flipped = frames.quat_from_euler(math.pi, 0.0, 0.0)
    allowed, w, _, _ = REGION.check(0.0, 0.0, 3.0, *flipped)
    assert allowed and w == pytest.approx(-3.0)


def test_wind_makes_it_air_relative():
    # hovering in a 3 m/s downdraft: the air rises through the disk at 3 m/s
    allowed, w, _, _ = REGION.check(0.0, 0.0, 0.0, *LEVEL, 0.0, 0.0, -3.0)
    assert not allowed and w == pytest.approx(3.0)
    # descending at 3 m/s with a 3 m/s headwind along the path: u = 3, w = 3 → inside the cone
    assert not REGION.check(0.0, 0.0, 3.0, *LEVEL, -3.0, 0.0, 0.0)[0]
    # with 10 m/s of air-relative horizontal speed the 3 m/s descent is outside it
    assert REGION.check(0.0, 0.0, 3.0, *LEVEL, -10.0, 0.0, 0.0)[0]


def test_vectorised_equals_scalar():
    rng = np.random.default_rng(1)
    n = 500
    v = rng.normal(0, 3, (3, n))
    q = rng.normal(0, 1, (4, n))
    q /= np.linalg.norm(q, axis=0)
    wind = rng.normal(0, 1, (3, n))
    allowed, w, u, m = REGION.check(*v, *q, *wind)
    for i in range(0, n, 37):
        a1, w1, u1, m1 = REGION.check(*v[:, i].tolist(), *q[:, i].tolist(), *wind[:, i].tolist())
        assert a1 == allowed[i] and w1 == pytest.approx(w[i]) and m1 == pytest.approx(m[i])


def test_validate_quaternion():
    mask = frames.validate_quaternion(np.array([1.0, 2.0, np.nan]), np.zeros(3), np.zeros(3), np.zeros(3))
    assert mask.tolist() == [True, False, False]


unit = st.floats(-1, 1, allow_nan=False)
speed = st.floats(-20, 20, allow_nan=False)


def _quat(a, b, c, d):
    n = math.sqrt(a * a + b * b + c * c + d * d)
    return (1.0, 0.0, 0.0, 0.0) if n < 1e-3 else (a / n, b / n, c / n, d / n)


@settings(max_examples=300, deadline=None)
@given(speed, speed, speed, unit, unit, unit, unit, st.floats(-math.pi, math.pi))
def test_yaw_of_world_does_not_change_verdict(vn, ve, vd, a, b, c, d, psi):
    """Rotating velocity and attitude together about NED z leaves w, u and the verdict unchanged."""
    q = _quat(a, b, c, d)
    allowed, w, u, m = REGION.check(vn, ve, vd, *q)
    rz = (math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2))
    q2 = tuple(frames.quat_multiply(rz, q))
    vn2 = math.cos(psi) * vn - math.sin(psi) * ve
    ve2 = math.sin(psi) * vn + math.cos(psi) * ve
    allowed2, w2, u2, m2 = REGION.check(vn2, ve2, vd, *q2)
    assert w2 == pytest.approx(w, abs=1e-9) and u2 == pytest.approx(u, abs=1e-9)
    assert m2 == pytest.approx(m, abs=1e-9)


@settings(max_examples=300, deadline=None)
@given(speed, speed, speed, unit, unit, unit, unit, st.floats(-math.pi, math.pi))
def test_body_yaw_does_not_change_w_or_u(vn, ve, vd, a, b, c, d, psi):
    """Spinning the vehicle about its own z (the rotor axis) changes neither w nor u."""
    q = _quat(a, b, c, d)
    _, w, u, _ = REGION.check(vn, ve, vd, *q)
    q2 = tuple(frames.quat_multiply(q, (math.cos(psi / 2), 0.0, 0.0, math.sin(psi / 2))))
    _, w2, u2, _ = REGION.check(vn, ve, vd, *q2)
    assert w2 == pytest.approx(w, abs=1e-9) and u2 == pytest.approx(u, abs=1e-9)


@settings(max_examples=300, deadline=None)
@given(speed, speed, speed, unit, unit, unit, unit)
def test_margin_sign_agrees_with_verdict_and_is_continuous(vn, ve, vd, a, b, c, d):
    q = _quat(a, b, c, d)
    allowed, w, u, m = REGION.check(vn, ve, vd, *q)
    assert allowed == (m >= 0)
    assert math.isfinite(m)
    # Lipschitz continuity: a 1 mm/s change of velocity moves the margin by at most ~(1+tan20)·1 mm/s
    _, _, _, m2 = REGION.check(vn + 1e-3, ve, vd, *q)
    assert abs(m2 - m) <= 1e-3 * (1 + math.tan(math.radians(20))) + 1e-9


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 20.0), st.floats(0.0, 20.0))
def test_verdict_monotone_in_descent_rate(u, w):
    """More sink at the same in-plane speed never turns a forbidden state into an allowed one."""
    if REGION.margin(w, u) < 0:
        assert REGION.margin(w + 0.5, u) < 0
