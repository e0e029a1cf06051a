"""Issue 22, item 1: the honest efficiency figure — hover to hover against the planner's optimum.

The hover-to-hover rule on samples (no link needed), the optimum against the plans that fly, its cache, and
the arithmetic of ``flown_over_optimum``. The flights' own figures are asserted in ``test_runner_virtual``
(virtual time) and ``test_campaign`` (the fake).
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from flighttest.analysis import descent_time as dtime
from flighttest.errors import FlighttestError
from flighttest.flying.mission_scripts import load_mission_module, mission_config_path
from flighttest.flying.missions_config import load_mission_config
from flighttest.model.profiles import load_profile
from flighttest.model.trajectory import Trajectory
from flighttest.planner import optimum as opt
from flighttest.planner.autopilot_limits import NO_LIMITS, plan_limits
from flighttest.planner.vertical import plan_vertical

RATE_HZ = 50.0


def _track(t_s: np.ndarray, n_m: np.ndarray, d_m: np.ndarray) -> dict:
    vd = np.gradient(d_m, t_s)
    vn = np.gradient(n_m, t_s)
    return {"t_s": t_s, "n_m": n_m, "e_m": np.zeros_like(t_s), "d_m": d_m, "vd_mps": vd, "vn_mps": vn,
            "ve_mps": np.zeros_like(t_s)}  # fmt: skip


def _timed(tr: dict, rule: dtime.DescentRule) -> float | None:
    r = dtime.descent_reached(tr["t_s"], tr["n_m"], tr["e_m"], tr["d_m"], tr["vd_mps"], 0.0, (0.0, 0.0, 5.0),
                              rule=rule, vn_mps=tr["vn_mps"], ve_mps=tr["ve_mps"])  # fmt: skip
    return None if r is None else r.descent_time_s


def test_hover_to_hover_waits_for_the_end_point_sideways():
    # at the end height at 3 s, 1 m off sideways, drifting home at 0.25 m/s: within 0.5 m at 5 s
    t = np.arange(0.0, 10.0, 1 / RATE_HZ)
    d = np.minimum(t / 3.0, 1.0) * 5.0
    n = np.where(t < 3.0, 1.0, np.maximum(1.0 - 0.25 * (t - 3.0), 0.0))
    tr = _track(t, n, d)
    assert _timed(tr, dtime.DescentRule()) == pytest.approx(3.0, abs=0.05)
    assert _timed(tr, dtime.HOVER_RULE) == pytest.approx(5.0, abs=0.05)


def test_passing_through_the_end_point_is_not_a_hover():
    # at the end height from 3 s, crossing the end point sideways at 1 m/s, then stopping 2 m beyond it
    t = np.arange(0.0, 10.0, 1 / RATE_HZ)
    d = np.minimum(t / 3.0, 1.0) * 5.0
    n = np.clip(t - 4.0, -1.0, 2.0)
    tr = _track(t, n, d)
    assert _timed(tr, dtime.DescentRule()) == pytest.approx(3.0, abs=0.05)
    assert _timed(tr, dtime.HOVER_RULE) is None


def test_a_hover_rule_needs_both_its_horizontal_terms():
    with pytest.raises(FlighttestError, match="go together"):
        dtime.DescentRule(horizontal_tol_m=0.5)
    with pytest.raises(FlighttestError, match="settled_vh_mps"):
        dtime.DescentRule(horizontal_tol_m=0.5, settled_vh_mps=float("nan"))
    assert "sideways" in dtime.HOVER_RULE.describe() and "sideways" not in dtime.DescentRule().describe()


@pytest.mark.parametrize("vehicle", ["x500", "sih_quadx", "arducopter_sitl"])
def test_the_vertical_optimum_is_faster_than_the_plan_that_flies(vehicle):
    profile = load_profile(vehicle)
    cfg = load_mission_config(mission_config_path("vertical"))
    traj = load_mission_module("vertical").plan(profile, cfg)
    df = traj.df
    flown_plan = dtime.planned_descent(df["t_s"], df["n_m"], df["e_m"], df["d_m"], df["vd_mps"], dtime.HOVER_RULE)
    best = opt.optimum_for(traj, profile)
    assert best is not None and best.kind == "vertical" and best.optimum_s is not None
    # the margins cost time: the flown plan cruises 0.45 m/s inside the bound, the optimum on it
    assert best.optimum_s < 0.8 * flown_plan.descent_time_s
    # the optimum rides the bound: cruise at w_allow, no faster
    assert best.optimum_s > best.height_m / profile.w_allow_mps
    if plan_limits(profile) is not NO_LIMITS:  # the autopilot's full limits, not the 90 % the flown plans keep
        derated = plan_vertical(profile, best.height_m, margin_mps=0.0, accel_fraction=1.0)
        assert best.optimum_s < derated.t_f_s - 0.1


def test_the_helix_optimum_uses_the_autopilots_full_limits_and_is_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("FLIGHTTEST_CACHE", str(tmp_path / "cache"))
    profile = load_profile("arducopter_sitl")
    cfg = load_mission_config(mission_config_path("helix"))
    traj = load_mission_module("helix").plan(profile, cfg)
    assert opt.OPTIMUM_KEY not in traj.meta
    q = opt.question(traj.meta)
    assert q["kind"] == "helix" and q["height_m"] == 5.0 and q["radius_m"] == 3.0
    best = opt.with_optimum(traj, profile).meta[opt.OPTIMUM_KEY]
    planned = dtime.planned_descent(traj.df["t_s"], traj.df["n_m"], traj.df["e_m"], traj.df["d_m"],
                                    traj.df["vd_mps"], dtime.HOVER_RULE, traj.df["vn_mps"],
                                    traj.df["ve_mps"])  # fmt: skip
    assert 0 < best["optimum_s"] < planned.descent_time_s
    cached = list((tmp_path / "cache" / "plans").glob("optimum-arducopter_sitl-*.json"))
    assert len(cached) == 1 and json.loads(cached[0].read_text())["optimum_s"] == best["optimum_s"]

    # a second plan of the same question solves nothing: the cache answers
    def no_solve(*_a, **_k):
        raise AssertionError("solved again")

    monkeypatch.setattr(opt, "solve", no_solve)
    again = Trajectory(traj.df, {k: v for k, v in traj.meta.items() if k != opt.OPTIMUM_KEY})
    assert opt.optimum_for(again, profile).optimum_s == best["optimum_s"]


def test_the_px4_helix_optimum_descends_no_faster_than_px4_lets_it():
    # PX4's offboard control clips its vertical velocity setpoint to MPC_Z_VEL_MAX_DN (1.5 m/s by default):
    # without it the optimum of sih_quadx's helix took 2.90 s hover to hover, descending at up to 2.5 m/s, which
    # PX4 flies no faster than 1.5 (the flown helix, 5.4 s, read 1.85× an optimum it could not fly)
    profile = load_profile("sih_quadx")
    assert profile.autopilot.name == "PX4" and profile.autopilot.descent_max_mps == 1.5
    assert plan_limits(profile) is NO_LIMITS  # the flown plans: their configs keep below it, the preflight checks
    default = opt.helix_optimum(profile, 5.0, 3.0).optimum_s
    raised = opt.helix_optimum(replace(profile, autopilot=replace(profile.autopilot, descent_max_mps=3.0)),
                               5.0, 3.0).optimum_s  # fmt: skip
    assert 3.6 < default < 4.4 and raised < 3.2


def test_a_plan_turned_for_another_wind_direction_asks_the_same_question():
    from flighttest.flying.wind import rotate_plan

    profile = load_profile("x500")
    cfg = load_mission_config(mission_config_path("vertical"))
    traj = load_mission_module("vertical").plan(profile, cfg)
    assert opt.question(rotate_plan(traj, 1.0).meta) == opt.question(traj.meta)
    probe = load_mission_module("probe").plan(profile, load_mission_config(mission_config_path("probe")))
    assert opt.question(probe.meta) is None and opt.optimum_for(probe, profile) is None


def test_flown_over_optimum_is_the_ratio_or_nothing():
    assert opt.efficiency(6.0, 4.0) == {"hover_to_hover_s": 6.0, "optimum_s": 4.0, "flown_over_optimum": 1.5}
    assert opt.efficiency(None, 4.0)["flown_over_optimum"] is None
    assert opt.efficiency(6.0, None)["flown_over_optimum"] is None
    assert opt.efficiency(float("nan"), 4.0) == {"hover_to_hover_s": None, "optimum_s": 4.0,
                                                 "flown_over_optimum": None}  # fmt: skip


def test_a_folders_optimum_is_its_summarys_first_then_its_plans():
    held = opt.Optimum("helix", 3.5, 5.0, (0.0, 0.0, 0.0), 3.0).to_dict()
    assert opt.logged_optimum_s({"summary": {"optimum_s": 4.2}, "trajectory_meta": {"optimum": held}}) == 4.2
    assert opt.logged_optimum_s({"summary": {"optimum_s": None}, "trajectory_meta": {"optimum": held}}) == 3.5
    # an edited or older folder's values are no yardstick
    assert opt.logged_optimum_s({"summary": {"optimum_s": "4"}, "trajectory_meta": {"optimum": {"x": 1}}}) is None
    assert opt.logged_optimum_s({"summary": {"optimum_s": -1.0}}) is None
    assert opt.logged_optimum_s(None) is None


def test_analyses_line_names_hover_to_hover_and_the_ratio():
    from flighttest.analysis import legend

    rec = {**dict.fromkeys(dtime.MAIN_DESCENT_KEYS), "basis": dtime.BASIS_PLANNED, "descent_time_s": 5.0,
           "horizontal_error_m": 0.3, **opt.efficiency(5.5, 2.9)}  # fmt: skip
    assert "; hover to hover 5.50 s, 1.90× the optimum" in legend.main_text(rec)
    rec.update(opt.efficiency(None, 2.9))
    assert "hover to hover" not in legend.main_text(rec)


def test_an_optimum_stopped_by_the_clock_is_not_kept(tmp_path, monkeypatch):
    # a busy machine's IPOPT wall-time stop is no answer for the next flight (as the wind plans' cache)
    from flighttest.planner.wind_plans import WALL_TIME_STATUS

    monkeypatch.setenv("FLIGHTTEST_CACHE", str(tmp_path / "cache"))
    profile = load_profile("x500")
    traj = load_mission_module("vertical").plan(profile, load_mission_config(mission_config_path("vertical")))
    stopped = opt.Optimum("vertical", None, 3.0, (0.0, 0.0, 0.0), why=f"did not converge ({WALL_TIME_STATUS})")
    monkeypatch.setattr(opt, "solve", lambda *_: stopped)
    assert opt.optimum_for(traj, profile) == stopped
    assert not list((tmp_path / "cache").rglob("optimum-*.json"))
    monkeypatch.undo()
    monkeypatch.setenv("FLIGHTTEST_CACHE", str(tmp_path / "cache"))
    assert opt.optimum_for(traj, profile).optimum_s > 0  # solved again, and kept
    assert len(list((tmp_path / "cache").rglob("optimum-*.json"))) == 1
