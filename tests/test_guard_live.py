"""The live guard's staleness (any state stream counts) and its prediction on a well-flown helix."""

from __future__ import annotations

import math

import numpy as np

from flighttest.flying import guard as g
from flighttest.model.aero import G_MPS2
from flighttest.model.frames import quat_from_euler
from flighttest.model.profiles import load_profile

X500 = load_profile("x500")


def _limits(**kw) -> g.GuardLimits:
    return g.GuardLimits(region=X500.guard_region(), telemetry_period_s=0.02, **kw)


def _hover(t: float) -> g.GuardSample:
    return g.GuardSample(t, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 5.0)


def test_any_state_stream_keeps_the_guard_fresh_but_velocity_must_not_stop_for_long():
    guard = g.Guard(_limits(stale_periods=3.0))  # 60 ms
    assert guard.on_tick(100.0) is None  # nothing seen yet: not stale (the link check is preflight's)
    guard.on_sample(_hover(100.0))
    assert guard.on_tick(100.05) is None
    # position-velocity late, attitude still arriving: not a dead link
    for t in (100.04, 100.08, 100.10):
        guard.note_state_sample(t)
    assert guard.on_tick(100.11) is None
    # nothing at all for more than 3 periods: stale, acts
    d = guard.on_tick(100.17)
    assert d.verdict == g.STALE and d.aborts and d.reason == "no telemetry for 70 ms (> 60 ms)"
    # attitude alone for more than twice the allowance: the region cannot be judged, stale too
    guard = g.Guard(_limits(stale_periods=3.0))
    guard.on_sample(_hover(0.0))
    for k in range(1, 8):
        guard.note_state_sample(0.02 * k)
    d = guard.on_tick(0.141)
    assert d.verdict == g.STALE and d.reason.startswith("no position-velocity telemetry for 141 ms (> 120 ms)")
    # an older sample arriving late never moves the clock back
    guard = g.Guard(_limits())
    guard.note_state_sample(5.0)
    guard.note_state_sample(4.0)
    assert guard.last_sample_t == 5.0


def test_a_larger_allowance_tolerates_a_busy_machine():
    guard = g.Guard(_limits(stale_periods=15.0))  # 300 ms
    guard.on_sample(_hover(0.0))
    assert guard.on_tick(0.25) is None
    assert guard.on_tick(0.31).verdict == g.STALE


def test_prediction_is_silent_on_a_well_tracked_helix():
    """A steady descending turn at the edge of what the plan allows: speed u along the circle, sink
    v_d, the disk tilted exactly as the centripetal acceleration needs. Measured and predicted state
    stay outside the region, sample after sample, all the way round."""
    guard = g.Guard(_limits(horizon_s=0.2, debounce_samples=3))
    radius, speed, sink = 2.5, 3.0, 0.8
    omega = speed / radius
    a_c = speed * omega  # centripetal, m/s²
    tilt = math.atan2(a_c, G_MPS2)
    verdicts = []
    for k in range(int(2 * math.pi / omega / 0.02)):
        t = k * 0.02
        th = omega * t
        vn, ve = -speed * math.sin(th), speed * math.cos(th)
        an, ae = -a_c * math.cos(th), -a_c * math.sin(th)  # towards the centre
        # thrust (−z_body) along (a − g): tilt towards the centre, nose along the path
        heading = th + math.pi / 2
        q = quat_from_euler(np.array([-tilt]), np.array([0.0]), np.array([heading]))[0]
        d = guard.on_sample(g.GuardSample(t, vn, ve, sink, *q, 5.0, 0, 0, 0, an, ae, 0.0))
        verdicts.append(d.verdict)
        assert d.margin_mps > 0.1 and d.predicted_margin_mps > 0.1, (t, d)
    assert set(verdicts) == {g.OK}


def test_prediction_still_catches_a_straight_down_acceleration_into_the_region():
    guard = g.Guard(_limits(horizon_s=0.2, debounce_samples=3))
    actions = []
    vd = 0.2
    for k in range(40):
        d = guard.on_sample(g.GuardSample(0.02 * k, 0.0, 0.0, vd, 1.0, 0.0, 0.0, 0.0, 5.0, 0, 0, 0, 0, 0, 3.0))
        actions.append(d.action)
        if d.aborts:
            break
        vd += 3.0 * 0.02
    assert actions[-1] == g.ABORT
    # it acted before the measured state entered the region
    assert d.margin_mps > 0 and d.verdict == g.PREDICTED
