"""Preflight decisions (pure): what passes, what warns, what stops a mission before arming."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from flighttest.flying import preflight as pf
from flighttest.flying.link import TelemetryState
from flighttest.model.profiles import load_profile
from flighttest.model.trajectory import FORMAT, Trajectory
from flighttest.planner.export import vertical_trajectory
from flighttest.planner.vertical import plan_vertical
from virtual_flight import leaning_descent

X500 = load_profile("x500")
REGION = X500.guard_region()


def _vertical(height_m=3.0, w_allow=None, margin=0.25):
    plan = plan_vertical(X500, height_m=height_m, w_allow_mps=w_allow, margin_mps=margin, accel_fraction=0.5)
    return vertical_trajectory(plan, "x500", X500.mass_kg)


def _by_name(checks) -> dict[str, pf.Check]:
    return {c.name: c for c in checks}


def test_trajectory_stats_of_a_vertical_descent():
    traj = _vertical(3.0)
    st = pf.trajectory_stats(traj, REGION, arrest_accel_mps2=3.0)
    assert st.depth_max_m == pytest.approx(3.0)
    assert st.radius_max_m == pytest.approx(0.0)
    cruise = X500.w_allow_mps - 0.25
    assert st.descent_max_mps == pytest.approx(cruise) and st.speed_max_mps == pytest.approx(cruise)
    assert st.duration_s == pytest.approx(traj.duration_s)
    # level, no wind: w = v_D, so the margin is the guard's bound minus the cruise speed
    assert st.guard_margin_min_mps == pytest.approx(0.25 - X500.vrs.margin_mps, abs=1e-6)
    # arresting a sink of v at 3 m/s² costs v²/6 of height below where it starts
    assert st.arrest_floor_m == pytest.approx(-3.0, abs=cruise**2 / 6 + 1e-6)
    assert st.arrest_floor_m < -3.0 + 1e-9


@pytest.mark.parametrize(("start", "floor", "status"), [(5.0, 1.0, pf.PASS), (4.0, 1.0, pf.PASS), (3.5, 1.0, pf.FAIL)])
def test_height_check(start, floor, status):
    st = pf.trajectory_stats(_vertical(3.0), REGION, 3.0)
    checks = _by_name(pf.trajectory_checks(st, X500, start, floor, geofence_radius_m=10.0))
    assert checks["height"].status == status
    assert checks["height"].value == f"start {start:.2f} m, lowest point {start - 3.0:.2f} m"


def test_arresting_the_sink_needs_room_below_the_lowest_point():
    st = pf.trajectory_stats(_vertical(3.0), REGION, arrest_accel_mps2=0.5)  # a weak brake
    checks = _by_name(pf.trajectory_checks(st, X500, 4.0, 1.0, 10.0))
    assert checks["height"].status == pf.PASS
    assert checks["height to arrest the sink"].status == pf.FAIL


def test_horizontal_room_counts_the_recovery_escape():
    st = pf.trajectory_stats(_vertical(3.0), REGION, 3.0)
    def room(radius_m: float) -> str:
        checks = pf.trajectory_checks(st, X500, 5.0, 1.0, radius_m, recovery_room_m=1.0)
        return _by_name(checks)["horizontal room"].status

    assert (room(1.5), room(0.5)) == (pf.PASS, pf.FAIL)


def test_a_plan_inside_the_guard_region_warns_and_says_what_happens():
    st = pf.trajectory_stats(_vertical(3.0, w_allow=2 * X500.w_allow_mps, margin=0.0), REGION, 3.0)
    assert st.guard_margin_min_mps < -0.5
    c = _by_name(pf.trajectory_checks(st, X500, 5.0, 1.0, 10.0))["plan vs guard region"]
    assert c.status == pf.WARN and "the guard will abort" in c.value
    c = _by_name(pf.trajectory_checks(st, X500, 5.0, 1.0, 10.0, observe_region=True))["plan vs guard region"]
    assert c.status == pf.WARN and "observed only" in c.value


def _healthy_state() -> TelemetryState:
    st = TelemetryState(n_m=0.0, e_m=0.0, d_m=0.0, vn_mps=0.0, ve_mps=0.0, vd_mps=0.0, q=(1.0, 0.0, 0.0, 0.0),
                        battery_percent=0.9, battery_v=16.4, landed_state="ON_GROUND",
                        health={"is_local_position_ok": True, "is_home_position_ok": True,
                                "is_armable": True})  # fmt: skip
    for stream in ("posvel", "attitude"):
        for i in range(51):
            st.count(stream, 100.0 + i * 0.02)
    return st


def _recount(st, stream: str, rate_hz: float, last_s: float = 101.0) -> None:
    """The stream's arrivals replaced by ``rate_hz`` from 98 s until ``last_s``."""
    for d in (st.counts, st.first_t, st.recent):
        d.pop(stream, None)
    for t in np.arange(98.0, last_s + 1e-9, 1.0 / rate_hz):
        st.count(stream, float(t))


def test_a_streams_rate_is_its_last_seconds():
    # ArduCopter SITL sent 39 Hz on average from the connection, 50 Hz once it took the rate asked of it
    st = _healthy_state()
    _recount(st, "posvel", 5.0, last_s=100.0)
    for t in np.arange(100.02, 101.0 + 1e-9, 0.02):
        st.count("posvel", float(t))
    assert st.rate_hz("posvel", 101.0) == pytest.approx(50.0, abs=1.0)
    assert st.rate_hz("posvel", 103.0) == 0.0  # nothing for two seconds: no rate


def test_vehicle_checks_pass_a_healthy_vehicle_on_the_ground():
    checks = pf.vehicle_checks(_healthy_state(), now_s=101.0, telemetry_hz=50.0, min_battery_percent=30.0)
    assert [c.status for c in checks] == [pf.PASS] * 5
    assert _by_name(checks)["battery"].value == "90 %, 16.40 V"  # MAVSDK reports a fraction


@pytest.mark.parametrize(
    ("change", "failing"),
    [
        (lambda st: setattr(st, "connected", False), "link and telemetry rate"),
        (lambda st: _recount(st, "posvel", 20.0), "link and telemetry rate"),  # 20 Hz < 0.8 × 50 Hz
        (lambda st: _recount(st, "attitude", 50.0, last_s=99.5), "link and telemetry rate"),  # stopped 1.5 s ago
        (lambda st: st.health.update(is_armable=False), "health"),
        (lambda st: setattr(st, "health", {}), ("health", "estimator")),
        (lambda st: setattr(st, "vn_mps", math.nan), "estimator"),
        (lambda st: st.health.update(is_home_position_ok=False), ("health", "estimator")),
        (lambda st: setattr(st, "battery_percent", 0.2), "battery"),
        (lambda st: setattr(st, "armed", True), "on the ground, disarmed"),
        (lambda st: setattr(st, "landed_state", "IN_AIR"), "on the ground, disarmed"),
    ],
)
def test_vehicle_checks_fail_with_the_reason(change, failing):
    st = _healthy_state()
    change(st)
    result = pf.PreflightResult(pf.vehicle_checks(st, 101.0, 50.0, 30.0))
    assert not result.ok
    names = failing if isinstance(failing, tuple) else (failing,)
    assert tuple(c.name for c in result.failures) == names
    assert result.first_failure().startswith(f"{names[0]}: ")


def test_an_unreported_battery_warns_but_does_not_stop():
    st = _healthy_state()
    st.battery_percent = math.nan
    c = _by_name(pf.vehicle_checks(st, 101.0, 50.0, 30.0))["battery"]
    assert c.status == pf.WARN


PX4_DEFAULTS = {"COM_OF_LOSS_T": 1.0, "COM_OBL_RC_ACT": 0, "COM_RC_OVERRIDE": 1, "MPC_Z_VEL_MAX_DN": 1.5,
                "MPC_LAND_SPEED": 0.7, "MPC_Z_V_AUTO_DN": 1.5, "MPC_LAND_ALT1": 10.0, "MPC_LAND_ALT2": 5.0}


def test_param_checks_on_px4_defaults():
    checks = _by_name(pf.param_checks(PX4_DEFAULTS, descent_max_mps=1.3, w_allow_mps=0.85))
    assert checks["COM_OF_LOSS_T"].status == pf.PASS
    assert checks["COM_OBL_RC_ACT"].status == pf.PASS and checks["COM_OBL_RC_ACT"].value == "0 = Position"
    # PX4's default lets sticks take over only in position modes, not offboard: worth a warning
    assert checks["COM_RC_OVERRIDE"].status == pf.WARN
    assert checks["MPC_Z_VEL_MAX_DN"].status == pf.PASS
    # the ladder's Land from 4 m descends at MPC_LAND_SPEED (below MPC_LAND_ALT2 5 m): below w_allow
    assert checks["PX4 Land after an abort"].status == pf.PASS


def test_px4_land_from_above_land_alt2_is_faster_than_w_allow_and_says_what_to_set():
    # PX4 SITL's Land from 7.3 m ran at 1.0 m/s at 6 m (../shared/px4_sih): between MPC_LAND_ALT2 and ALT1
    # it interpolates towards MPC_Z_V_AUTO_DN
    assert pf.px4_land_speed_mps(PX4_DEFAULTS, 7.0) == pytest.approx(0.7 + 2.0 / 5.0 * 0.8)
    assert pf.px4_land_speed_mps(PX4_DEFAULTS, 12.0) == 1.5 and pf.px4_land_speed_mps(PX4_DEFAULTS, 3.0) == 0.7
    c = _by_name(pf.param_checks(PX4_DEFAULTS, descent_max_mps=1.3, w_allow_mps=0.85, height_max_m=7.0))
    land = c["PX4 Land after an abort"]
    assert land.status == pf.WARN and land.value.startswith("1.02 m/s from 7.0 m")
    assert "raise MPC_LAND_ALT1/ALT2 above 7.0 m" in land.requirement
    raised = {**PX4_DEFAULTS, "MPC_LAND_ALT1": 9.0, "MPC_LAND_ALT2": 8.0}
    assert _by_name(pf.param_checks(raised, 1.3, 0.85, 7.0))["PX4 Land after an abort"].status == pf.PASS


def test_the_estimates_height_on_the_ground_is_checked_and_said():
    assert pf.ground_height_check(0.1).status == pf.PASS
    c = pf.ground_height_check(0.9)
    assert c.status == pf.WARN and "+0.90 m" in c.value
    assert pf.ground_height_check(-4.0).status == pf.FAIL and pf.ground_height_check(math.nan).status == pf.FAIL


def test_free_disk_for_the_log_is_checked(tmp_path):
    assert pf.disk_check(tmp_path, 60.0, 50.0).status == pf.PASS  # 6 MB
    assert pf.disk_check(tmp_path, 1e9, 50.0).status == pf.FAIL  # 100 TB
    assert pf.disk_check(tmp_path / "gone", 60.0, 50.0).status == pf.FAIL


@pytest.mark.parametrize(
    ("name", "value", "status"),
    [
        ("COM_OF_LOSS_T", 5.0, pf.FAIL),
        ("COM_OF_LOSS_T", 0.0, pf.FAIL),
        ("COM_OBL_RC_ACT", 4, pf.PASS),  # Land
        ("COM_OBL_RC_ACT", 7, pf.FAIL),  # Disarm: drops the vehicle
        ("COM_OBL_RC_ACT", 6, pf.FAIL),  # Terminate
        ("COM_OBL_RC_ACT", 42, pf.FAIL),  # unknown
        ("COM_RC_OVERRIDE", 3, pf.PASS),
        ("MPC_Z_VEL_MAX_DN", 1.0, pf.FAIL),  # PX4 would clip the planned 1.3 m/s descent
        ("MPC_Z_VEL_MAX_DN", None, pf.WARN),
        ("COM_OF_LOSS_T", None, pf.WARN),
    ],
)
def test_param_checks_decide_each_parameter(name, value, status):
    params = {**PX4_DEFAULTS, name: value}
    assert _by_name(pf.param_checks(params, 1.3, 0.85))[name].status == status


def test_preflight_result_summary():
    res = pf.PreflightResult([pf.Check("a", pf.PASS, "1", "r"), pf.Check("b", pf.WARN, "2", "r"),
                              pf.Check("c", pf.FAIL, "3", "≥ 4")])  # fmt: skip
    assert not res.ok and res.first_failure() == "c: 3 (needs ≥ 4)"
    d = res.to_dict()
    assert d["ok"] is False and [c["status"] for c in d["checks"]] == ["pass", "warn", "fail"]
    assert pf.PreflightResult([pf.Check("a", pf.WARN, "", "")]).ok


def test_the_plan_is_judged_with_the_disk_the_drag_tilts():
    # forward at 3 m/s, sinking 0.8 m/s, level in the file (no acceleration): the thrust also takes the drag,
    # so the disk leans into the motion and the air meets it less from below (sih_quadx's helix warned
    # −0.34 m/s from its drag-free file attitude where the planner's drag-aware check keeps it clear)
    t = np.arange(0.0, 2.0, 0.02)
    one, zero = np.ones_like(t), np.zeros_like(t)
    meta = {"kind": "planar", "vehicle": "x500", "problem": {}, "status": "ok", "format": FORMAT}
    traj = Trajectory.from_arrays(meta, t_s=t, n_m=3.0 * t, e_m=zero, d_m=0.8 * t, vn_mps=3.0 * one, ve_mps=zero,
                                  vd_mps=0.8 * one, an_mps2=zero, ae_mps2=zero, ad_mps2=zero, yaw_deg=zero,
                                  qw=one, qx=zero, qy=zero, qz=zero)  # fmt: skip
    level = pf.trajectory_stats(traj, REGION, 3.0)
    assert level.guard_margin_min_mps == pytest.approx(float(REGION.margin(0.8, 3.0)), abs=1e-9)
    k = 0.5
    z = np.array([-k * 3.0, 0.0, 9.80665 - k * 0.8])  # body z ∥ g − a − k·v_air
    z /= np.linalg.norm(z)
    v = np.array([3.0, 0.0, 0.8])
    w = float(v @ z)
    u = math.sqrt(float(v @ v) - w * w)
    tilted = pf.trajectory_stats(traj, REGION, 3.0, drag_per_s=k)
    assert tilted.guard_margin_min_mps == pytest.approx(float(REGION.margin(w, u)), abs=1e-6)
    assert tilted.guard_margin_min_mps > level.guard_margin_min_mps
    # into a 3 m/s headwind the air comes faster: the drag and the air both change
    windy = pf.trajectory_stats(traj, REGION, 3.0, drag_per_s=k, wind_ned_mps=(-3.0, 0.0, 0.0))
    z = np.array([-k * 6.0, 0.0, 9.80665 - k * 0.8])
    z /= np.linalg.norm(z)
    va = np.array([6.0, 0.0, 0.8])
    w = float(va @ z)
    assert windy.guard_margin_min_mps == pytest.approx(float(REGION.margin(w, math.sqrt(float(va @ va) - w * w))),
                                                       abs=1e-6)  # fmt: skip


def test_the_plans_tilt_is_judged_against_the_vehicles_limit():
    # issue 22: ATC_ANGLE_MAX / MPC_TILTMAX_AIR clip the tilt; a plan that leans further is flown late. A level
    # descent, then one that accelerates at 3 m/s² horizontally (17.9° of tilt)
    level = pf.trajectory_stats(_vertical(3.0), REGION, 3.0)
    assert level.tilt_max_deg == pytest.approx(0.0, abs=1e-9)
    lean = leaning_descent()
    st = pf.trajectory_stats(lean, REGION, 3.0)
    assert st.tilt_max_deg == pytest.approx(math.degrees(math.atan2(3.0, 9.80665 - 0.5)), abs=0.01)
    assert _by_name(pf.trajectory_checks(st, X500, 5.0, 1.0, 10.0))["tilt"].status == pf.PASS
    low = dataclasses.replace(X500, max_tilt_deg=15.0)
    c = _by_name(pf.trajectory_checks(st, low, 5.0, 1.0, 10.0))["tilt"]
    assert c.status == pf.FAIL and c.value == "max 17.9°" and "≤ 15°" in c.requirement
