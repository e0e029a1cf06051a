"""Plans that fit within the autopilot's setpoint shaping (issue 15): a profile's ``[autopilot]`` table, and
the vertical, probe and helix plans kept within AUTOPILOT_LIMIT_FRACTION of its limits, so ArduCopter's
GUIDED (WP_ACC_Z 1.0, WP_ACC 2.5, WP_SPD_DN 1.5, WP_SPD_UP 2.5 by default) flies them as planned and
the preflight's checks of those parameters pass. Profiles without the table plan as before."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import tomli_w

from flighttest.errors import FlighttestError
from flighttest.flying import autopilot as flying_autopilot
from flighttest.flying.mission_scripts import load_mission_module, mission_config_path
from flighttest.flying.missions_config import load_mission_config
from flighttest.flying.plan_config import VerticalPlanConfig
from flighttest.flying.preflight import FAIL, ardupilot_param_checks, trajectory_stats
from flighttest.model.aero import G_MPS2
from flighttest.model.profiles import (
    AUTOPILOT_NAMES,
    AutopilotLimits,
    load_profile,
    profile_to_dict,
    write_w_allow,
)
from flighttest.model.trajectory import Trajectory
from flighttest.planner import helix
from flighttest.planner.autopilot_limits import AUTOPILOT_LIMIT_FRACTION, NO_LIMITS, plan_limits
from flighttest.planner.export import probe_trajectory, vertical_trajectory
from flighttest.planner.probe import plan_probe
from flighttest.planner.problems import helix_problem, probe_plan, vertical_plan
from flighttest.planner.tracking import TrackingMargin, helix_problem_for_flight
from flighttest.planner.vertical import plan_vertical

# ArduCopter's defaults (../shared/ardupilot_sitl): what arducopter_sitl.toml's [autopilot] table holds
ARDUCOPTER = {"WP_ACC_Z": 1.0, "WP_ACC": 2.5, "WP_SPD_DN": 1.5, "WP_SPD_UP": 2.5, "PSC_JERK_NE": 5.0, "PSC_JERK_D": 5.0}
FRACTION = AUTOPILOT_LIMIT_FRACTION
# x500's 5 m helix as `flighttest plan helix --vehicle x500 --height 5` solves it, measured before the
# autopilot limits existed: a profile without the table must plan exactly as before
X500_HELIX_5M_T_F_S = 3.5590


@pytest.fixture(scope="module")
def ac():
    return load_profile("arducopter_sitl")


@pytest.fixture(scope="module")
def x500():
    return load_profile("x500")


def _write(tmp_path, base, autopilot) -> str:
    d = profile_to_dict(base)
    d.pop("autopilot", None)
    if autopilot is not None:
        d["autopilot"] = autopilot
    path = tmp_path / "vehicle.toml"
    path.write_text(tomli_w.dumps(d))
    return str(path)


# -- the profile's table -------------------------------------------------------------------------------


def test_arducopter_sitl_carries_arducopters_defaults_px4s_profiles_px4s(ac):
    assert ac.autopilot == AutopilotLimits(name="ArduPilot", accel_z_max_mps2=ARDUCOPTER["WP_ACC_Z"],
                                           accel_h_max_mps2=ARDUCOPTER["WP_ACC"],
                                           descent_max_mps=ARDUCOPTER["WP_SPD_DN"],
                                           climb_max_mps=ARDUCOPTER["WP_SPD_UP"],
                                           jerk_h_max_mps3=ARDUCOPTER["PSC_JERK_NE"],
                                           jerk_z_max_mps3=ARDUCOPTER["PSC_JERK_D"])  # fmt: skip
    text = Path(ac.path).read_text(encoding="utf-8")
    assert all(name in text for name in ARDUCOPTER)  # the comment cites the parameters
    for name in ("x500", "sih_quadx"):  # PX4's: the vertical speeds its offboard control clips to, by default
        assert load_profile(name).autopilot == AutopilotLimits(name="PX4", descent_max_mps=1.5, climb_max_mps=3.0)
    for name in ("mambo", "tunnel_rig"):
        p = load_profile(name)
        assert p.autopilot is None and p.summary()["autopilot"] is None and "autopilot" not in profile_to_dict(p)


def test_autopilot_names_are_the_flying_layers():
    assert set(AUTOPILOT_NAMES) == {flying_autopilot.PX4, flying_autopilot.ARDUPILOT}


def test_summary_and_round_trip(ac, x500, tmp_path):
    s = ac.summary()
    assert s["autopilot"] == {"name": "ArduPilot", "accel_z_max_mps2": 1.0, "accel_h_max_mps2": 2.5,
                              "descent_max_mps": 1.5, "climb_max_mps": 2.5, "jerk_h_max_mps3": 5.0,
                              "jerk_z_max_mps3": 5.0}  # fmt: skip
    json.dumps(s, allow_nan=False)
    assert load_profile(_write(tmp_path, ac, profile_to_dict(ac)["autopilot"])).autopilot == ac.autopilot
    # only a name and one limit: the others do not apply, and are left out when written back
    partial = load_profile(_write(tmp_path, x500, {"name": "PX4", "descent_max_mps": 1.5}))
    assert partial.autopilot == AutopilotLimits(name="PX4", descent_max_mps=1.5)
    assert profile_to_dict(partial)["autopilot"] == {"name": "PX4", "descent_max_mps": 1.5}
    # a measured w_allow written into the user's copy keeps the table
    target = tmp_path / "user" / "arducopter_sitl.toml"
    write_w_allow(ac, 0.7, "test", target=target)
    assert load_profile(str(target)).autopilot == ac.autopilot


@pytest.mark.parametrize(
    ("table", "field", "words"),
    [
        (1.0, "autopilot", "must be a table"),
        ({"accel_z_max_mps2": 1.0}, "autopilot.name", "is missing"),
        ({"name": "Ardupilot"}, "autopilot.name", "must be one of PX4, ArduPilot"),
        ({"name": 4}, "autopilot.name", "must be a string"),
        ({"name": "ArduPilot", "wp_acc": 1.0}, "autopilot.wp_acc", "is not a known field"),
        ({"name": "ArduPilot", "accel_z_max_mps2": 0.0}, "autopilot.accel_z_max_mps2", "must be a number > 0"),
        ({"name": "ArduPilot", "accel_h_max_mps2": -2.5}, "autopilot.accel_h_max_mps2", "must be a number > 0"),
        ({"name": "ArduPilot", "descent_max_mps": math.inf}, "autopilot.descent_max_mps", "must be a number"),
        ({"name": "ArduPilot", "climb_max_mps": "2.5"}, "autopilot.climb_max_mps", "must be a number"),
        ({"name": "ArduPilot", "climb_max_mps": True}, "autopilot.climb_max_mps", "must be a number"),
        ({"name": "ArduPilot", "accel_z_max_mps2": 1e3}, "autopilot.accel_z_max_mps2", "≤ 100"),
    ],
)
def test_a_bad_table_is_one_line_naming_the_field(x500, tmp_path, table, field, words):
    path = _write(tmp_path, x500, table)
    with pytest.raises(FlighttestError) as exc:
        load_profile(path)
    msg = str(exc.value)
    assert path in msg and f"'{field}'" in msg and words in msg and "\n" not in msg


def test_plan_limits_derate_the_table(ac, x500):
    lim = plan_limits(ac)
    assert (lim.accel_z_max_mps2, lim.accel_h_max_mps2, lim.descent_max_mps, lim.climb_max_mps) == pytest.approx(
        (FRACTION * 1.0, FRACTION * 2.5, FRACTION * 1.5, FRACTION * 2.5))  # fmt: skip
    assert plan_limits(x500) is NO_LIMITS
    assert plan_limits(replace(x500, autopilot=AutopilotLimits(name="PX4"))) == NO_LIMITS
    with pytest.raises(FlighttestError, match="fraction"):
        plan_limits(ac, 1.5)


# -- the preflight of the missions' plans -----------------------------------------------------------------


def _guided_failures(profile, mission: str, traj: Trajectory) -> list[str]:
    """The preflight's GUIDED-limit checks of what the mission would stream, at ArduCopter's defaults."""
    cfg = load_mission_config(mission_config_path(mission))
    stats = trajectory_stats(traj.resample(cfg.flight.rate_hz), profile.guard_region(), 0.5 * profile.max_accel_up_mps2)
    checks = ardupilot_param_checks(ARDUCOPTER, stats, profile.w_allow_mps, 245, cfg.abort.recovery_climb_mps)
    return [c.name for c in checks if c.name in ARDUCOPTER and c.status == FAIL]


@pytest.mark.parametrize("mission", ["vertical", "probe"])
def test_closed_form_mission_plans_pass_arducopters_defaults(ac, mission):
    cfg = load_mission_config(mission_config_path(mission))
    module = load_mission_module(mission)
    assert _guided_failures(ac, mission, module.plan(ac, cfg)) == []
    # the same vehicle without the table asks for more than WP_ACC_Z: the preflight would refuse it
    assert "WP_ACC_Z" in _guided_failures(ac, mission, module.plan(replace(ac, autopilot=None), cfg))


# -- the vertical baseline ---------------------------------------------------------------------------------


def test_vertical_caps_its_accelerations_and_descent(ac):
    plan = vertical_plan(ac, 3.0, extra_margin_mps=0.35, accel_fraction=0.15)  # what `fly vertical` plans
    assert plan.a_down_mps2 == pytest.approx(FRACTION * 1.0) and plan.a_up_mps2 == pytest.approx(FRACTION * 1.0)
    assert np.abs(plan.ad_mps2).max() <= FRACTION * 1.0 + 1e-12
    assert plan.problem["autopilot_accel_z_max_mps2"] == pytest.approx(FRACTION * 1.0)
    # a boundary far above WP_SPD_DN: the cruise is the autopilot's descent limit, not the guard's
    fast = replace(ac, vrs=replace(ac.vrs, w_allow_mps=3.0))
    plan = plan_vertical(fast, 5.0)
    assert plan.cruise_mps == pytest.approx(FRACTION * 1.5) and plan.vd_mps.max() <= FRACTION * 1.5 + 1e-12
    assert np.abs(plan.ad_mps2).max() <= FRACTION * 1.0 + 1e-12
    # below the limits nothing changes: the vehicle's own fraction applies
    gentle = plan_vertical(ac, 3.0, accel_fraction=0.05)
    assert gentle.a_down_mps2 == pytest.approx(0.05 * ac.max_accel_down_mps2)
    assert gentle.a_down_mps2 < FRACTION * 1.0


def test_vertical_ramps_its_acceleration_at_the_autopilots_jerk(ac):
    # GUIDED ramps acceleration at PSC_JERK_D: a plan whose acceleration steps is flown late, and GUIDED's
    # catch-up ran its desired descent to 0.55 m/s on a 0.3 m/s plan on ArduCopter SITL (bench/RESULTS.md)
    for height_m in (3.0, 0.2):  # cruising, and too short to reach the cruise
        plan = vertical_plan(ac, height_m, extra_margin_mps=0.35, accel_fraction=0.15)
        t, d, v, a = plan.t_s, plan.d_m, plan.vd_mps, plan.ad_mps2
        assert plan.problem["jerk_z_mps3"] == pytest.approx(FRACTION * 5.0)
        assert np.abs(np.diff(a[:-1]) / np.diff(t[:-1])).max() <= FRACTION * 5.0 + 1e-6
        assert a[0] == 0.0 and np.abs(a).max() <= FRACTION * 1.0 + 1e-12
        # the samples are one motion: speed is the integral of acceleration, height of speed
        assert np.allclose(np.diff(v), np.diff(t) * 0.5 * (a[1:] + a[:-1]), atol=1e-6)
        assert np.allclose(np.diff(d), np.diff(t) * 0.5 * (v[1:] + v[:-1]), atol=1e-5)
        assert d[-1] == height_m and v[-1] == 0.0 and v.max() == pytest.approx(plan.cruise_mps)
    # without a jerk in the table the profile is the closed-form bang-cruise-bang
    steps = vertical_plan(replace(ac, autopilot=replace(ac.autopilot, jerk_z_max_mps3=None)), 3.0,
                          extra_margin_mps=0.35, accel_fraction=0.15)  # fmt: skip
    assert steps.problem["jerk_z_mps3"] is None and steps.ad_mps2[0] == pytest.approx(FRACTION * 1.0)


def test_the_missions_jerk_bounds_the_vertical_on_any_autopilot(x500, ac):
    """PX4 shapes nothing in offboard: the vertical's own jerk keeps its entry into cruise gradual, where a step
    read 0.1·a above the cruise in the guard's prediction and aborted PX4 SITL's vertical (bench/RESULTS.md)."""
    jerk = VerticalPlanConfig().jerk_max_mps3
    for profile, expected in ((x500, jerk), (ac, min(jerk, FRACTION * 5.0))):
        plan = vertical_plan(profile, 5.0, extra_margin_mps=0.1, accel_fraction=0.25, jerk_mps3=jerk)
        t, a = plan.t_s, plan.ad_mps2
        assert plan.problem["jerk_z_mps3"] == pytest.approx(expected)
        assert np.abs(np.diff(a[:-1]) / np.diff(t[:-1])).max() <= expected + 1e-6
        assert a[0] == 0.0 and plan.vd_mps.max() == pytest.approx(plan.cruise_mps)
    # and it costs at most the ramps' a/J (less where the ramp never reaches a)
    step = vertical_plan(x500, 5.0, extra_margin_mps=0.1, accel_fraction=0.25)
    ramped = vertical_plan(x500, 5.0, extra_margin_mps=0.1, accel_fraction=0.25, jerk_mps3=jerk)
    assert 0.0 < ramped.t_f_s - step.t_f_s <= 0.5 * (step.a_down_mps2 + step.a_up_mps2) / jerk + 1e-9
    with pytest.raises(FlighttestError, match="jerk must be a positive number"):
        plan_vertical(x500, 5.0, jerk_mps3=0.0)


def test_vertical_unchanged_without_the_table(x500):
    plan = plan_vertical(x500, 5.0)
    assert plan.a_down_mps2 == 0.8 * x500.max_accel_down_mps2 and plan.a_up_mps2 == 0.8 * x500.max_accel_up_mps2
    assert plan.cruise_mps == x500.w_allow_mps - x500.vrs.margin_mps
    assert plan.problem["autopilot_accel_z_max_mps2"] is None


# -- the probe ---------------------------------------------------------------------------------------------


def test_probe_keeps_the_autopilots_vertical_limits(ac):
    plan = probe_plan(ac, amplitude_m=3.0, omega0_rps2=0.015, ramp_s=3.0, max_descent_mps=2.5, duration_s=60.0,
                      start_alt_m=8.0, floor_alt_m=2.0, accel_fraction=0.5)  # fmt: skip
    assert plan.problem["max_descent_mps"] == pytest.approx(FRACTION * 1.5)  # asked 2.5, WP_SPD_DN 1.5
    assert plan.vd_mps.max() <= FRACTION * 1.5 + 1e-9 and np.abs(plan.ad_mps2).max() <= FRACTION * 1.0 + 1e-9
    assert plan.problem["max_accel_down_mps2"] == plan.problem["max_accel_up_mps2"] == pytest.approx(FRACTION)


def test_probe_mission_unchanged_without_the_table(x500):
    cfg = load_mission_config(mission_config_path("probe"))
    traj = load_mission_module("probe").plan(x500, cfg)
    p = cfg.plan
    ref = plan_probe(amplitude_m=p["amplitude_m"], omega0_rps2=p["omega0_rps2"], ramp_s=p["ramp_s"],
                     max_descent_mps=p["max_descent_ratio"] * x500.w_allow_mps, duration_s=p["duration_s"],
                     start_alt_m=cfg.flight.start_height_m, floor_alt_m=cfg.flight.min_alt_m,
                     max_accel_down_mps2=p["accel_fraction"] * x500.max_accel_down_mps2,
                     max_accel_up_mps2=p["accel_fraction"] * x500.max_accel_up_mps2)  # fmt: skip
    expected = probe_trajectory(ref, x500.name, x500.mass_kg)
    for col in ("t_s", "d_m", "vd_mps", "ad_mps2"):
        np.testing.assert_array_equal(traj.column(col), expected.column(col))


# -- the helix ---------------------------------------------------------------------------------------------


def test_helix_problem_takes_the_bounds_from_the_profile(ac, x500):
    p = helix_problem(ac, height_m=5.0)
    assert (p.accel_z_max_mps2, p.accel_h_max_mps2, p.descent_max_mps, p.climb_max_mps) == pytest.approx(
        (FRACTION * 1.0, FRACTION * 2.5, FRACTION * 1.5, FRACTION * 2.5))  # fmt: skip
    spec = helix._spec(p, 10)
    assert spec.x_ub[5] == pytest.approx(FRACTION * 1.5) and spec.x_lb[5] == pytest.approx(-FRACTION * 2.5)
    assert len(spec.path_lb) == len(spec.path_ub) == 6  # cone, radius, tilt, speed, a_D, a_H
    assert helix._Backoff(p, 10).path_lb().shape == (21, 6)
    q = helix_problem(x500, height_m=5.0)
    assert (q.accel_z_max_mps2, q.accel_h_max_mps2, q.descent_max_mps, q.climb_max_mps) == (None,) * 4
    assert len(helix._spec(q, 10).path_lb) == 4
    # the flight's tracking margin keeps the lower of its own descent bound and the autopilot's
    flight = helix_problem_for_flight(ac, 5.0, 3.0, TrackingMargin())
    assert flight.descent_max_mps == TrackingMargin().descent_max_mps < FRACTION * 1.5
    fast = helix_problem_for_flight(ac, 5.0, 3.0, TrackingMargin(descent_max_mps=2.0))
    assert fast.descent_max_mps == pytest.approx(FRACTION * 1.5) and fast.accel_z_max_mps2 == pytest.approx(FRACTION)
    with pytest.raises(FlighttestError, match="vertical acceleration bound"):
        replace(p, accel_z_max_mps2=-1.0).validate()


def test_a_table_without_limits_is_the_same_nlp(x500):
    """A profile whose table gives no limit plans the NLP of a profile without one (same rows, same values)."""
    p = helix_problem(x500, height_m=5.0)
    q = helix_problem(replace(x500, autopilot=AutopilotLimits(name="PX4")), height_m=5.0)
    assert p == q
    rng = np.random.default_rng(1)
    spec = helix._spec(p, 10)
    for _ in range(5):
        x, u = rng.normal(size=10), rng.normal(size=4)
        rows_p, rows_q = (np.asarray(s.path(x, u)).ravel() for s in (spec, helix._spec(q, 10)))
        np.testing.assert_array_equal(rows_p, rows_q)


def test_x500_helix_as_before(x500):
    sol = helix.solve_helix(helix_problem(x500, height_m=5.0))
    assert sol.success and sol.check["limits_ok"]
    assert sol.t_f_s == pytest.approx(X500_HELIX_5M_T_F_S, abs=1e-3)
    assert sol.check["max_accel_z_mps2"] > 2.0  # the optimum it always was, far beyond ArduCopter's default


def test_plan_helix_cli_on_arducopter_sitl_keeps_within_the_limits(ac, tmp_path):
    """``flighttest plan helix --vehicle arducopter_sitl --height 5``: the planned an/ae/ad, descent and
    climb within the problem's bounds (between nodes up to the check's tolerance), below ArduCopter's defaults."""
    out = tmp_path / "helix"
    proc = subprocess.run([sys.executable, "-m", "flighttest", "plan", "helix", "--vehicle", "arducopter_sitl",
                           "--height", "5", "--json", "-o", str(out)], capture_output=True, text=True,
                          timeout=240)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["status"] == "optimal" and report["check"]["limits_ok"], report["check"]
    bounds = report["problem"]
    assert bounds["accel_z_max_mps2"] == pytest.approx(FRACTION * 1.0)
    assert bounds["accel_h_max_mps2"] == pytest.approx(FRACTION * 2.5)
    traj = Trajectory.load(f"{out}.csv", ac)
    an, ae, ad, vd = (traj.column(c) for c in ("an_mps2", "ae_mps2", "ad_mps2", "vd_mps"))
    tol = helix.ACCEL_TOL_MPS2
    assert np.abs(ad).max() <= bounds["accel_z_max_mps2"] + tol < ARDUCOPTER["WP_ACC_Z"]
    assert np.hypot(an, ae).max() <= bounds["accel_h_max_mps2"] + tol < ARDUCOPTER["WP_ACC"]
    assert vd.max() <= bounds["descent_max_mps"] + 0.01 and -vd.min() <= bounds["climb_max_mps"] + 0.01
    # the preflight would let it fly on ArduCopter's defaults
    assert _guided_failures(ac, "helix", traj) == []


def test_plan_vertical_cli_on_arducopter_sitl(ac, tmp_path):
    out = tmp_path / "vertical"
    proc = subprocess.run([sys.executable, "-m", "flighttest", "plan", "vertical", "--vehicle", "arducopter_sitl",
                           "--json", "-o", str(out)], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["a_down_mps2"] == report["a_up_mps2"] == pytest.approx(FRACTION * 1.0)
    traj = Trajectory.load(f"{out}.csv", ac)
    assert np.abs(traj.column("ad_mps2")).max() <= FRACTION * 1.0 + 1e-9
    assert _guided_failures(ac, "vertical", traj) == []
    expected = vertical_trajectory(vertical_plan(ac, 3.0, extra_margin_mps=0.35, accel_fraction=0.15,
                                                 jerk_mps3=VerticalPlanConfig().jerk_max_mps3),
                                   ac.name, ac.mass_kg)  # fmt: skip
    assert traj.duration_s == pytest.approx(expected.duration_s)


def test_the_autopilots_jerk_bounds_the_helix_tilt_rate_and_thrust_rate(ac, x500):
    # ArduCopter ramps accelerations at PSC_JERK_NE / PSC_JERK_D: a plan that tilts faster than jerk / g, or
    # changes thrust faster than jerk, is flown late and overshoots (its SITL's first helix, bench/RESULTS.md)
    p = helix.problem_for_vehicle(ac)
    tilt_rate = FRACTION * ARDUCOPTER["PSC_JERK_NE"] / G_MPS2
    assert p.rate_max_rps[0] == pytest.approx(tilt_rate) and p.rate_max_rps[1] == pytest.approx(tilt_rate)
    assert p.thrust_rate_max_mps3 == pytest.approx(FRACTION * ARDUCOPTER["PSC_JERK_D"])
    q = helix.problem_for_vehicle(x500)
    assert q.thrust_rate_max_mps3 is None and q.rate_max_rps[0] == pytest.approx(math.radians(x500.max_rate_dps[0]))


def test_the_vehicles_own_limits_replace_the_profiles_only_where_they_differ():
    # issue 22: the preflight plans within what the vehicle holds (flighttest.flying.live_limits)
    from flighttest.flying.live_limits import ardupilot_limits, with_live_limits

    prof = load_profile("arducopter_sitl")
    assert with_live_limits(prof, ardupilot_limits(ARDUCOPTER)) == (prof, [])  # the defaults: nothing to plan again
    raised, diffs = with_live_limits(prof, ardupilot_limits({**ARDUCOPTER, "WP_ACC_Z": 2.0}))
    assert raised.autopilot.accel_z_max_mps2 == 2.0 and diffs == ["WP_ACC_Z 2 (the profile's 1)"]
    assert raised.autopilot.accel_h_max_mps2 == prof.autopilot.accel_h_max_mps2
    # older firmware: cm/s², cm/s; a limit reported as 0 (off) is not a limit of 0
    old = ardupilot_limits({"WPNAV_ACCEL_Z": 150, "WPNAV_SPEED_DN": 120.0, "PSC_JERK_Z": 0.0})
    assert old["accel_z_max_mps2"].value == 1.5 and old["descent_max_mps"].value == pytest.approx(1.2)
    assert "jerk_z_max_mps3" not in old and old["accel_z_max_mps2"].describe() == "WPNAV_ACCEL_Z 150 (1.5 m/s²)"


def test_px4s_speed_limits_change_no_flown_plan_and_guided_limits_replace_px4s():
    from flighttest.flying.live_limits import ardupilot_limits, plans_bound, px4_limits, with_live_limits

    x500 = load_profile("x500")
    live = px4_limits({"MPC_Z_VEL_MAX_DN": 3.0, "MPC_Z_VEL_MAX_UP": 3.0, "MPC_XY_P": 0.95})
    raised, diffs = with_live_limits(x500, live, "PX4")
    assert raised.autopilot.descent_max_mps == 3.0 and diffs == ["MPC_Z_VEL_MAX_DN 3 (the profile's 1.5)"]
    assert with_live_limits(x500, px4_limits({"MPC_Z_VEL_MAX_DN": 1.5}), "PX4") == (x500, [])
    assert not plans_bound(x500, raised)  # PX4 clips: only the optimum is made again
    # ArduCopter's limits shape every plan: any change of them plans again
    ac = load_profile("arducopter_sitl")
    for change in ({"WP_SPD_DN": 3.0}, {"WP_ACC_Z": 2.0}):
        assert plans_bound(ac, with_live_limits(ac, ardupilot_limits({**ARDUCOPTER, **change}))[0]), change
    # an x500 profile on ArduPilot firmware: GUIDED's limits, not PX4's table with them mixed in
    on_ap, _ = with_live_limits(x500, ardupilot_limits(ARDUCOPTER))
    assert on_ap.autopilot == ac.autopilot


def test_a_lower_tilt_limit_of_the_vehicle_replaces_the_profiles_and_plans_again_on_either_autopilot():
    # issue 22: ANGLE_MAX and MPC_TILTMAX_AIR are limits the position control imposes, as WP_ACC_Z is
    from flighttest.flying.live_limits import ardupilot_limits, plans_bound, px4_limits, with_live_limits

    ac = load_profile("arducopter_sitl")  # 30°, ATC_ANGLE_MAX's default
    assert with_live_limits(ac, ardupilot_limits({**ARDUCOPTER, "ATC_ANGLE_MAX": 30.0, "PSC_ANGLE_MAX": 0.0})) == (
        ac, [])  # fmt: skip
    lower, diffs = with_live_limits(ac, ardupilot_limits({**ARDUCOPTER, "ATC_ANGLE_MAX": 20.0}))
    assert lower.max_tilt_deg == 20.0 and diffs == ["ATC_ANGLE_MAX 20 (the profile's 30)"]
    assert lower.autopilot == ac.autopilot and plans_bound(ac, lower)
    # a higher one is not the airframe's: the profile's stands (its SITL's helix at 25° was stopped at the flare)
    assert with_live_limits(ac, ardupilot_limits({**ARDUCOPTER, "ATC_ANGLE_MAX": 40.0})) == (ac, [])
    # PSC_ANGLE_MAX, where set, is the position controller's own, within the attitude controller's; older
    # firmware: ANGLE_MAX in cdeg
    assert ardupilot_limits({"PSC_ANGLE_MAX": 25.0, "ATC_ANGLE_MAX": 40.0})["max_tilt_deg"].param == "PSC_ANGLE_MAX"
    assert ardupilot_limits({"PSC_ANGLE_MAX": 45.0, "ATC_ANGLE_MAX": 40.0})["max_tilt_deg"].value == 40.0
    old = ardupilot_limits({"ANGLE_MAX": 4500})["max_tilt_deg"]
    assert old.value == 45.0 and old.describe() == "ANGLE_MAX 4500 (45 °)"
    # PX4 clips offboard tilt to MPC_TILTMAX_AIR: unlike its speeds, a change plans again
    x500 = load_profile("x500")
    lower, diffs = with_live_limits(x500, px4_limits({"MPC_TILTMAX_AIR": 35.0, "MPC_Z_VEL_MAX_DN": 1.5}), "PX4")
    assert lower.max_tilt_deg == 35.0 and diffs == ["MPC_TILTMAX_AIR 35 (the profile's 45)"]
    assert plans_bound(x500, lower)
