"""The guard's decisions and the abort ladder, pure (no vehicle)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from flighttest.flying import guard as g
from flighttest.model.frames import GuardRegion, quat_from_euler, quat_to_rotmat
from flighttest.model.profiles import load_profile

REGION = GuardRegion(w_allow_mps=0.8, v_h_mps=6.0, cone_deg=20.0, margin_mps=0.1)
LEVEL = (1.0, 0.0, 0.0, 0.0)


def limits(**kw) -> g.GuardLimits:
    base = dict(region=REGION, telemetry_period_s=0.02, horizon_s=0.2, debounce_samples=3,
                clear_violation_mps=0.05)  # fmt: skip
    base.update(kw)
    return g.GuardLimits(**base)


def sample(t=0.0, v=(0.0, 0.0, 0.0), q=LEVEL, alt=10.0, wind=(0.0, 0.0, 0.0), acc=(0.0, 0.0, 0.0)):
    return g.GuardSample(t, *v, *q, alt, *wind, *acc)


def test_hover_is_ok_and_logs_its_inputs():
    d = g.Guard(limits()).on_sample(sample(v=(0.0, 0.0, 0.1)))
    assert (d.verdict, d.action) == (g.OK, g.NONE)
    assert d.w_mps == pytest.approx(0.1)
    assert d.u_mps == pytest.approx(0.0)
    assert d.margin_mps == pytest.approx(0.8 - 0.1 - 0.1)
    assert d.sample.vd_mps == 0.1


def test_clear_violation_acts_on_the_first_sample():
    d = g.Guard(limits(debounce_samples=10)).on_sample(sample(v=(0.0, 0.0, 1.6)))
    assert d.verdict == g.VIOLATION and d.aborts
    assert d.margin_mps == pytest.approx(0.7 - 1.6)


def test_marginal_violation_is_debounced_and_a_good_sample_resets_it():
    gd = g.Guard(limits(debounce_samples=3))
    marginal = sample(v=(0.0, 0.0, 0.72))  # margin −0.02, inside the 0.05 band
    assert [gd.on_sample(marginal).action for _ in range(2)] == [g.NONE, g.NONE]
    assert gd.on_sample(sample(v=(0, 0, 0.2))).verdict == g.OK
    actions = [gd.on_sample(marginal) for _ in range(3)]
    assert [a.action for a in actions] == [g.NONE, g.NONE, g.ABORT]
    assert actions[-1].verdict == g.MARGINAL


def test_prediction_from_the_measured_trend():
    # allowed now (w = 0.5 < 0.7) but w has risen 0.1 m/s every 20 ms: 0.2 s ahead w ≈ 1.5 — a
    # predicted violation, debounced; the commanded acceleration plays no part
    gd = g.Guard(limits(debounce_samples=2))
    ds = [gd.on_sample(sample(t=0.02 * k, v=(0, 0, 0.1 + 0.1 * k))) for k in range(5)]
    *_, d1, d2 = ds
    assert d1.verdict == g.PREDICTED and d1.action == g.NONE
    assert d1.margin_mps > 0 > d1.predicted_margin_mps
    assert d2.action == g.ABORT
    # the same state reached by braking (w falling) is fine, whatever the command says
    gb = g.Guard(limits())
    assert [gb.on_sample(sample(t=0.02 * k, v=(0, 0, 0.9 - 0.1 * k), acc=(0, 0, 3.0))).verdict
            for k in range(3, 5)] == [g.OK, g.OK]  # fmt: skip


def test_prediction_needs_a_trend_window_of_samples():
    # one sample (or a burst within half the window): no slope to extrapolate, prediction = measurement
    d = g.Guard(limits()).on_sample(sample(v=(0, 0, 0.5), acc=(0.0, 0.0, 30.0)))
    assert d.predicted_margin_mps == pytest.approx(d.margin_mps)


def test_px4_helix_plunge_is_predicted_before_it_is_measured():
    # PX4 SITL, helix-5m-guard-abort-1 (guard.csv around the abort): w rose 0.29 → 0.60 → 0.85 m/s in
    # 40 ms with u ≈ 0.1, tilt lagging the plan. The old command-based predictor showed +0.21 m/s of
    # margin on the sample before the violation; the trend sees it coming.
    gd = g.Guard(limits(region=GuardRegion(w_allow_mps=0.848, v_h_mps=6.28, margin_mps=0.1), horizon_s=0.1))
    decisions = [gd.on_sample(sample(t=t, v=(0.0, 0.0, w))) for t, w in ((0.0, 0.05), (0.02, 0.15), (0.04, 0.29),
                                                                          (0.06, 0.45), (0.08, 0.60))]  # fmt: skip
    assert decisions[-1].margin_mps > 0 > decisions[-1].predicted_margin_mps


def test_predicted_blade_velocity_matches_the_region_test_for_level_hover_command():
    # zero commanded acceleration ⇒ level disk ⇒ same w, u as GuardRegion.check with a level quaternion
    rng = np.random.default_rng(1)
    for vn, ve, vd in rng.normal(0, 3, (20, 3)):
        w, u = g.predicted_blade_velocity_mps(vn, ve, vd, 0, 0, 0, horizon_s=0.2)
        _, w_ref, u_ref, _ = REGION.check(vn, ve, vd, *LEVEL)
        assert w == pytest.approx(w_ref, abs=1e-9) and u == pytest.approx(u_ref, abs=1e-9)


def test_predicted_tilt_follows_commanded_acceleration():
    # commanded 2 m/s² north at constant height: disk tilted forward by atan(2/g); flying north at
    # 3 m/s puts air through the disk from below-front: w = −3·sin(tilt) (< 0: not descending)
    w, u = g.predicted_blade_velocity_mps(3.0, 0, 0, 2.0, 0, 0, horizon_s=0.0)
    tilt = math.atan2(2.0, 9.80665)
    assert w == pytest.approx(-3.0 * math.sin(tilt))
    assert u == pytest.approx(3.0 * math.cos(tilt))


def test_forward_descent_inside_the_cone_bound_is_allowed():
    # 2 m/s forward and 0.7 m/s down, level: u = 2, tan20·2 = 0.73 → bound 0.8−0.1 → allowed
    d = g.Guard(limits()).on_sample(sample(v=(2.0, 0.0, 0.6)))
    assert d.verdict == g.OK
    # steep: 1 m/s down with 1 m/s forward, level → w=1 > max(0.8, 0.36)−0.1 → violation
    assert g.Guard(limits()).on_sample(sample(v=(1.0, 0.0, 1.0))).verdict == g.VIOLATION


def test_updraft_counts_as_descending_through_the_disk():
    # hovering still over ground in a 1.5 m/s updraft (wind d = −1.5): air flows up through the disk
    d = g.Guard(limits()).on_sample(sample(v=(0, 0, 0), wind=(0.0, 0.0, -1.5)))
    assert d.w_mps == pytest.approx(1.5) and d.verdict == g.VIOLATION


def test_tilted_attitude_changes_w():
    # 1 m/s straight down with the vehicle rolled 60°: w = cos60 = 0.5, u = sin60·1
    q = quat_from_euler(math.radians(60), 0.0, 0.0)
    d = g.Guard(limits(horizon_s=0.0)).on_sample(sample(v=(0, 0, 1.0), q=tuple(q)))
    assert d.predicted_margin_mps == pytest.approx(d.margin_mps)
    assert d.w_mps == pytest.approx(0.5)
    assert d.u_mps == pytest.approx(math.sin(math.radians(60)))
    assert d.verdict == g.OK


@pytest.mark.parametrize("field", ["vn_mps", "qw", "alt_m", "wn_mps"])
def test_non_finite_input_aborts(field):
    kw = dict(t_s=0.0, vn_mps=0, ve_mps=0, vd_mps=0, qw=1, qx=0, qy=0, qz=0, alt_m=5)
    kw[field] = math.nan
    d = g.Guard(limits()).on_sample(g.GuardSample(**kw))
    assert d.verdict == g.NON_FINITE and d.aborts


def test_non_unit_quaternion_aborts():
    d = g.Guard(limits()).on_sample(sample(q=(0.5, 0.0, 0.0, 0.0)))
    assert d.verdict == g.NON_FINITE and d.aborts


def test_stale_after_three_periods_and_not_before_the_first_sample():
    gd = g.Guard(limits(telemetry_period_s=0.02, stale_periods=3))
    assert gd.on_tick(100.0) is None
    gd.on_sample(sample(t=1.0))
    assert gd.on_tick(1.059) is None
    d = gd.on_tick(1.061)
    assert d.verdict == g.STALE and d.aborts and "61 ms" in d.reason


def test_floor_and_speed_cap_hold_in_observe_mode():
    gd = g.Guard(limits(observe_region=True, min_alt_m=2.0, max_descent_mps=3.0))
    d = gd.on_sample(sample(v=(0, 0, 2.0)))
    assert d.verdict == g.VIOLATION and d.action == g.OBSERVE
    assert gd.on_sample(sample(v=(0, 0, 3.2))).verdict == g.SPEED_CAP
    assert gd.on_sample(sample(v=(0, 0, 3.2))).aborts
    d = gd.on_sample(sample(v=(0, 0, 0.1), alt=1.9))
    assert d.verdict == g.FLOOR and d.aborts


def test_floor_not_judged_where_it_is_off_but_the_rest_is():
    # on the ground and in takeoff/landing the runner turns the floor off: below it is the point there
    gd = g.Guard(limits(min_alt_m=2.0, max_descent_mps=3.0))
    gd.floor_active = False
    assert gd.on_sample(sample(v=(0, 0, 0.1), alt=0.5)).verdict == g.OK
    assert gd.on_sample(sample(v=(0, 0, 3.2), alt=0.5)).verdict == g.SPEED_CAP
    gd.floor_active = True
    assert gd.on_sample(sample(v=(0, 0, 0.1), alt=0.5)).verdict == g.FLOOR


def test_ladder_finish_ends_it_with_nothing_more_commanded():
    lad = g.AbortLadder()
    assert lad.trigger(10.0, "guard") == g.CMD_RECOVER
    lad.finish(10.5, "pilot in control (POSCTL)")
    assert lad.done and lad.rung == g.Rung.DONE and lad.history[-1] == (10.5, "DONE", "pilot in control (POSCTL)")
    assert lad.step(g.LadderObservation(t_s=11.0, vd_mps=2.0, region_ok=False)) is None


def test_disarmed_guard_logs_but_does_not_act():
    gd = g.Guard(limits())
    gd.armed = False
    d = gd.on_sample(sample(v=(0, 0, 3.0)))
    assert d.verdict == g.VIOLATION and d.action == g.NONE


def test_fluctuation_detector_sees_shaking_not_steady_turns():
    gd = g.Guard(limits(max_rate_std_dps=10.0, max_accel_std_mps2=1.0, fluct_window_s=0.5))
    fired = [gd.on_rates(i * 0.02, 0.0, 0.0, math.radians(60)) for i in range(100)]  # steady yaw
    assert not any(fired) and gd.rate_std_dps == pytest.approx(0.0, abs=1e-6)
    shaking = [gd.on_rates(2 + i * 0.02, math.radians(30) * math.sin(i * 1.3), 0, 0) for i in range(50)]
    first = next(d for d in shaking if d is not None)
    assert first.verdict == g.FLUCTUATION and first.aborts and "angular-rate" in first.reason
    gd2 = g.Guard(limits(max_accel_std_mps2=1.0))
    hits = [gd2.on_vertical_accel(i * 0.02, -9.8 + 3.0 * (-1) ** i) for i in range(50)]
    assert any(h is not None and h.aborts for h in hits)
    assert all(gd2.on_vertical_accel(10 + i * 0.02, -9.8) is None for i in range(100))


@given(
    vn=st.floats(-10, 10), ve=st.floats(-10, 10), vd=st.floats(-10, 10),
    roll=st.floats(-1.0, 1.0), pitch=st.floats(-1.0, 1.0), yaw=st.floats(-3.1, 3.1),
)  # fmt: skip
def test_guard_agrees_with_the_region_test(vn, ve, vd, roll, pitch, yaw):
    # with the acceleration that attitude gives at constant height, a zero horizon predicts "now"
    q = tuple(float(x) for x in quat_from_euler(roll, pitch, yaw))
    zn, ze, zd = quat_to_rotmat(q)[:, 2]
    thrust = 9.80665 / zd
    acc = (-thrust * zn, -thrust * ze, 0.0)
    d = g.Guard(limits(debounce_samples=1, horizon_s=0.0)).on_sample(sample(v=(vn, ve, vd), q=q, acc=acc))
    assert d.predicted_margin_mps == pytest.approx(d.margin_mps, abs=1e-6)
    allowed, w, u, m = REGION.check(vn, ve, vd, *q)
    assert d.margin_mps == pytest.approx(float(m), abs=1e-9)
    assert d.aborts == (not bool(allowed))


def test_profile_region_vertical_at_twice_w_allow_is_a_clear_violation():
    prof = load_profile("x500")
    gd = g.Guard(limits(region=prof.guard_region()))
    d = gd.on_sample(sample(v=(0, 0, 2 * prof.w_allow_mps)))
    assert d.verdict == g.VIOLATION and d.aborts


# -- ladder ------------------------------------------------------------------------------------------


def ob(t, **kw):
    return g.LadderObservation(t_s=t, **kw)


def test_ladder_recover_hold_land_done():
    lad = g.AbortLadder(g.LadderTiming(arrested_for_s=0.3, hold_dwell_s=1.0))
    assert lad.trigger(0.0, "in guard region") == g.CMD_RECOVER
    assert lad.trigger(0.1, "stale") is None and lad.reason == "in guard region"
    assert lad.step(ob(0.1, vd_mps=1.0, mode="OFFBOARD")) is None
    assert lad.step(ob(0.2, vd_mps=0.1, mode="OFFBOARD")) is None
    assert lad.step(ob(0.55, vd_mps=0.1, mode="OFFBOARD")) == g.CMD_HOLD
    assert lad.step(ob(0.6, mode="OFFBOARD")) is None
    assert lad.step(ob(0.7, mode="HOLD")) is None
    assert lad.step(ob(1.8, mode="HOLD")) == g.CMD_LAND
    assert lad.step(ob(2.0, mode="LAND")) is None
    assert lad.step(ob(9.0, mode="LAND", landed=True)) is None and lad.done
    assert [h[1] for h in lad.history] == ["RECOVER", "HOLD", "LAND", "DONE"]


def test_ladder_recovery_times_out_into_hold_when_telemetry_is_stale():
    lad = g.AbortLadder(g.LadderTiming(recover_max_s=1.5))
    lad.trigger(0.0, "stale")
    assert lad.step(ob(1.0, vd_mps=0.0, telemetry_fresh=False)) is None
    assert lad.step(ob(1.5, vd_mps=0.0, telemetry_fresh=False)) == g.CMD_HOLD


def test_ladder_no_land_ends_in_hold_and_unconfirmed_hold_escalates():
    lad = g.AbortLadder(g.LadderTiming(land=False))
    lad.trigger(0.0, "sigint", first=g.Rung.HOLD)
    assert lad.step(ob(0.5, mode="HOLD")) is None and lad.done
    lad2 = g.AbortLadder(g.LadderTiming(hold_confirm_s=2.0))
    assert lad2.trigger(0.0, "left offboard", first=g.Rung.HOLD) == g.CMD_HOLD
    # (a mode that is neither Hold nor a pilot's: a pilot's mode ends the ladder, test_ladder_land_watch)
    assert lad2.step(ob(2.1, mode="OFFBOARD")) == g.CMD_LAND
    assert lad2.step(ob(2.2, mode="OFFBOARD")) is None
    assert lad2.step(ob(5.3, mode="OFFBOARD")) == g.CMD_LAND  # re-sent
    assert lad2.reason == "left offboard"


def test_ladder_escalate_and_autopilot_landing_is_followed():
    lad = g.AbortLadder()
    lad.trigger(0.0, "x")
    assert lad.escalate(0.1, "second ctrl-c") == g.CMD_HOLD
    assert lad.step(ob(0.2, mode="LAND")) is None and lad.rung == g.Rung.LAND
    assert lad.escalate(0.3, "again") is None and lad.rung == g.Rung.LAND
