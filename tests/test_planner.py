"""Planner: Table II cases, the cone on re-simulated solutions, helix, vertical baseline, probe, CLI."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from flighttest.errors import FlighttestError
from flighttest.model.profiles import load_profile
from flighttest.model.trajectory import Trajectory
from flighttest.planner.cases import TABLE_II, detected_classes
from flighttest.planner.cone import VelocityConstraint, planar_blade_velocity
from flighttest.planner.helix import problem_for_vehicle, solve_helix
from flighttest.planner.planar import PlanarProblem, classify, solve_planar
from flighttest.planner.probe import plan_probe
from flighttest.planner.vertical import plan_vertical

# Between-node tolerance: the mesh refinement drives the 1 kHz re-simulated violation below 1 mm/s.
RESIM_TOL_MPS = 2e-3


@pytest.mark.parametrize("number", sorted(TABLE_II))
def test_table_ii_case_converges_with_the_papers_manoeuvre(number):
    case = TABLE_II[number]
    sol = solve_planar(case.problem)
    assert sol.success, sol.attempts
    assert detected_classes(sol.manoeuvre()) == case.paper_class
    # Never worse than GPOPS-II's local optimum (small slack for the paper's 2-digit rounding).
    assert sol.t_f_s <= case.paper_t_f_s + 0.03
    assert sol.t_f_s > 0.5 * case.paper_t_f_s
    # The cone holds on the 1 kHz re-simulation with the interpolated controls, not only at nodes.
    assert sol.check["worst_margin_mps"] >= -RESIM_TOL_MPS
    assert sol.check["end_position_error_m"] < 0.02
    x = sol.result.x
    assert np.abs(x[:, 0]).max() <= case.problem.y_bound_m + 1e-6
    if case.problem.phi_bound_rad is not None:
        assert np.abs(x[:, 4]).max() <= case.problem.phi_bound_rad + 1e-6
    if case.problem.y_final == "fixed":
        assert abs(x[-1, 0]) < 1e-6


def test_flips_need_more_than_one_rad_per_second():
    """With the Table I bound ω ≤ 1 rad/s the flip case cannot come near the paper's 2.27 s."""
    slow = solve_planar(PlanarProblem(phi_bound_rad=None, omega_max_rps=1.0, y_final="fixed", n_intervals=40))
    assert slow.success
    assert slow.t_f_s > 2.27 + 0.5


def test_real_flight_planar_plan_keeps_thrust_positive_and_guard_margin():
    x500 = load_profile("x500")
    con = VelocityConstraint(w_allow_mps=x500.w_allow_mps, margin_mps=x500.vrs.margin_mps)
    p = PlanarProblem(f_min_mps2=0.0, f_max_mps2=15.0, phi_bound_rad=math.radians(45), omega_max_rps=3.0,
                      y_bound_m=5.0, constraint=con, n_intervals=60, n_coarse=30)  # fmt: skip
    sol = solve_planar(p)
    assert sol.success
    assert sol.result.u[:, 0].min() >= -1e-6
    # The guard region (w_allow > 0) permits a faster descent than the pure cone with the same bounds.
    cone = solve_planar(p.__class__(**{**p.__dict__, "constraint": VelocityConstraint(margin_mps=0.1)}))
    assert sol.t_f_s < cone.t_f_s
    # Guard's own check on the re-simulated solution.
    assert sol.check["worst_margin_mps"] >= -RESIM_TOL_MPS


def test_classifier_reads_the_path_not_the_case():
    t = np.linspace(0, 1, 101)
    x = np.zeros((101, 5))
    x[:, 0] = 3 * np.sin(2 * np.pi * t)  # out, back and out the other side: 2 reversals
    assert classify(t, x, 5.0)["label"] == "zig-zag"
    x[:, 0] = 8 * t
    assert classify(t, x, 5.0)["label"] == "oblique"
    x[:, 4] = 2 * np.pi * t
    assert classify(t, x, 5.0)["label"] == "oblique+flips"


def test_blade_velocity_matches_notes_formula_and_guard():
    u, w = planar_blade_velocity(np.array([1.0]), np.array([2.0]), np.array([0.3]))
    assert u[0] == pytest.approx(math.cos(0.3) + 2 * math.sin(0.3))
    assert w[0] == pytest.approx(-math.sin(0.3) + 2 * math.cos(0.3))
    con = VelocityConstraint()
    assert con.margin(0.35, 1.0) == pytest.approx(math.tan(math.radians(20)) - 0.35)
    assert con.margin(-1.0, 0.0) >= 0  # climbing through the disk is always allowed


def test_helix_stays_in_radius_and_returns_to_its_xy(tmp_path):
    from flighttest.planner.export import helix_trajectory

    x500 = load_profile("x500")
    p = problem_for_vehicle(x500, height_m=5.0, radius_m=2.0, n_intervals=36, n_coarse=20)
    sol = solve_helix(p)
    assert sol.success, sol.attempts
    c = sol.check
    assert c["max_radius_m"] <= 2.0 + 0.02
    assert c["end_position_error_m"] < 0.05
    assert c["worst_margin_mps"] >= -0.01
    assert c["turns"] > 0.5  # it circles: a helix, not a straight drop
    # Tilt, rates, thrust and the cone hold on the 1 kHz re-simulation, not only at the nodes.
    assert c["limits_ok"], c
    assert c["max_tilt_deg"] <= x500.max_tilt_deg + c["tolerances"]["tilt_deg"]
    assert c["max_rate_dps"] <= max(x500.max_rate_dps) * (1 + 1e-6)
    assert c["min_thrust_mps2"] >= -1e-6
    assert sol.result.u[:, 0].min() >= -1e-6
    traj = helix_trajectory(sol, "x500", x500.mass_kg)
    traj.validate(x500)
    assert abs(traj.column("n_m")[-1]) < 0.05 and abs(traj.column("e_m")[-1]) < 0.05
    assert traj.column("d_m")[-1] == pytest.approx(5.0, abs=0.05)
    # Much faster than the vertical baseline at w_allow.
    assert sol.t_f_s < 0.7 * plan_vertical(x500, 5.0).t_f_s


def test_helix_tightens_the_tilt_it_would_break_between_nodes():
    """Riding the tilt limit, the path between nodes bulges past it; the solver tightens the bound
    until the re-simulation holds it (the first fine solve alone breaks it)."""
    mambo = load_profile("mambo")
    p = problem_for_vehicle(mambo, height_m=3.0, radius_m=1.5, n_intervals=24, n_coarse=16)
    sol = solve_helix(p)
    assert sol.success, sol.attempts
    fine = [a for a in sol.attempts if "backoff" in a]
    assert len(fine) >= 2 and fine[-1]["backoff"]["tilt_rad"] > 0
    assert sol.check["limits_ok"], sol.check
    assert sol.check["max_tilt_deg"] <= mambo.max_tilt_deg + sol.check["tolerances"]["tilt_deg"]


def test_helix_margin_options_derate_the_problem():
    x500 = load_profile("x500")
    base = problem_for_vehicle(x500)
    p = problem_for_vehicle(x500, extra_margin_mps=0.2, tilt_margin_deg=10.0, rate_margin_dps=20.0)
    assert p.constraint.margin_mps == pytest.approx(base.constraint.margin_mps + 0.2)
    assert math.degrees(p.tilt_max_rad) == pytest.approx(x500.max_tilt_deg - 10.0)
    assert math.degrees(p.rate_max_rps[0]) == pytest.approx(x500.max_rate_dps[0] - 20.0)
    with pytest.raises(FlighttestError, match="margin"):
        problem_for_vehicle(x500, tilt_margin_deg=-1.0)
    with pytest.raises(FlighttestError, match="no tilt"):
        problem_for_vehicle(x500, tilt_margin_deg=50.0)


@pytest.mark.parametrize("planner", ["planar", "helix"])
def test_compiled_resimulation_matches_the_numpy_reference(planner):
    """The planners re-simulate with CasADi's compiled RK4; it must agree with the plain numpy one."""
    from flighttest.planner import helix, planar
    from flighttest.planner.ocp import rk4_resimulate, rk4_resimulate_compiled

    rng = np.random.default_rng(1)
    t_nodes = np.linspace(0.0, 2.3456, 13)
    if planner == "planar":
        mod, x0 = planar, np.array([0.1, 0.2, 0.0, 0.3, 0.2])
        u = np.column_stack([rng.uniform(5, 15, 13), rng.uniform(-1, 1, 13)])
    else:
        mod, x0 = helix, np.array([0, 0, 0, 0.5, 0, 0.2, 1.0, 0, 0, 0])
        u = np.column_stack([rng.uniform(5, 15, 13), rng.uniform(-1, 1, (13, 3))])
    t_ref, x_ref, u_ref = rk4_resimulate(mod._dynamics_np, t_nodes, x0, u, 500.0)
    t_c, x_c, u_c = rk4_resimulate_compiled(mod.dynamics, t_nodes, x0, u, 500.0)
    assert len(t_c) == len(t_ref) == 1174  # crosses a chunk boundary (1000 steps)
    np.testing.assert_allclose(x_c, x_ref, atol=1e-9)
    np.testing.assert_allclose(u_c, u_ref)


@pytest.mark.parametrize("vehicle", ["x500", "mambo"])
def test_vertical_never_exceeds_w_allow(vehicle):
    prof = load_profile(vehicle)
    plan = plan_vertical(prof, 5.0)
    assert plan.vd_mps.max() <= prof.w_allow_mps - prof.vrs.margin_mps + 1e-12
    assert plan.d_m[-1] == pytest.approx(5.0)
    assert plan.vd_mps[0] == 0.0 and plan.vd_mps[-1] == 0.0
    assert np.all(np.diff(plan.d_m) >= -1e-12)
    # Position is the integral of velocity (trapezoid on the output clock).
    integral = np.concatenate([[0], np.cumsum(0.5 * (plan.vd_mps[1:] + plan.vd_mps[:-1]) * np.diff(plan.t_s))])
    np.testing.assert_allclose(integral, plan.d_m, atol=2e-3)
    # Cruise dominates: the time is close to height / cruise plus the speed-up/slow-down.
    assert plan.t_f_s == pytest.approx(
        5.0 / plan.cruise_mps + plan.cruise_mps / (2 * plan.a_down_mps2) + plan.cruise_mps / (2 * plan.a_up_mps2)
    )


def test_vertical_triangular_when_short():
    prof = load_profile("x500")
    plan = plan_vertical(prof, 0.01)
    assert plan.cruise_mps < prof.w_allow_mps - prof.vrs.margin_mps
    assert plan.d_m[-1] == pytest.approx(0.01)


def test_probe_one_sided_capped_and_reports_first_speeds():
    plan = plan_probe(amplitude_m=2.0, omega0_rps2=0.05, ramp_s=3.0, max_descent_mps=1.5, duration_s=60.0,
                      start_alt_m=10.0, floor_alt_m=2.0)  # fmt: skip
    assert plan.d_m.min() >= -1e-9 and plan.d_m.max() <= 2.0 + 1e-9  # never above the start, never below floor
    assert plan.vd_mps.max() <= 1.5
    assert plan.vd_mps.min() < -0.5  # it comes back up
    assert plan.d_m[-1] == 0.0 and plan.vd_mps[-1] == 0.0
    assert plan.cycles >= 2
    speeds = [r["speed_mps"] for r in plan.speed_first_reached]
    times = [r["t_s"] for r in plan.speed_first_reached]
    assert speeds[0] == pytest.approx(0.1) and times == sorted(times)
    for row in plan.speed_first_reached:
        i = int(np.searchsorted(plan.t_s, row["t_s"]))
        assert plan.vd_mps[i] >= row["speed_mps"] - 1e-9
        assert plan.vd_mps[:i].max(initial=0) < row["speed_mps"]
    with pytest.raises(FlighttestError, match="altitude floor"):
        plan_probe(amplitude_m=9.0, start_alt_m=10.0, floor_alt_m=2.0)


def _cli(tmp_path, *args):
    return subprocess.run([sys.executable, "-m", "flighttest", "plan", *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)  # fmt: skip


def test_cli_planar_case_json_writes_a_loadable_trajectory(tmp_path):
    r = _cli(tmp_path, "planar", "--case", "4", "--json", "-o", "out/c4", "--plot", "c4.png")
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    assert data["status"] == "optimal"
    assert data["t_f_s"] == pytest.approx(3.35, abs=0.05)
    assert data["solve_s"] > 0
    assert data["manoeuvre"] == "oblique"
    assert data["path"].endswith("c4.csv")
    traj = Trajectory.load(tmp_path / data["path"])
    assert traj.kind == "planar" and traj.meta["table_case"] == 4 and traj.meta["paper_t_f_s"] == 3.39
    assert traj.duration_s == pytest.approx(data["t_f_s"])
    assert (tmp_path / "c4.png").stat().st_size > 10_000


def test_cli_vertical_and_probe(tmp_path):
    r = _cli(tmp_path, "vertical", "--vehicle", "mambo", "--json")
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    traj = Trajectory.load(tmp_path / data["path"], profile=load_profile("mambo"))
    assert traj.column("vd_mps").max() <= data["w_allow_mps"]
    r = _cli(tmp_path, "probe", "--json", "-o", "p", "--max-descent-speed", "2")
    assert r.returncode == 0, r.stderr
    data = json.loads(r.stdout)
    meta = json.loads((tmp_path / "p.json").read_text())
    assert meta["speed_first_reached"] == data["speed_first_reached"]
    assert meta["kind"] == "probe"


def test_cli_solver_failure_writes_nothing_and_exits_1(tmp_path):
    r = _cli(tmp_path, "planar", "--y-bound", "0.001", "--phi-bound", "0.5", "--json", "-o", "bad")
    assert r.returncode == 1
    data = json.loads(r.stdout)
    assert data["status"] != "optimal" and data["path"] is None
    assert "best_point" in data
    assert not (tmp_path / "bad.csv").exists()


@pytest.mark.parametrize(
    "args",
    [
        ["planar", "--case", "1", "--height", "-3"],
        ["planar", "--phi-bound", "lots"],
        ["helix", "--radius", "0"],
        ["helix", "--vehicle", "nosuchvehicle"],
        ["probe", "--amplitude", "20"],
        ["vertical", "--w-allow", "nan"],
    ],
)
def test_cli_bad_input_is_one_line_exit_2(tmp_path, args):
    r = _cli(tmp_path, *args)
    assert r.returncode == 2
    assert r.stderr.startswith("flighttest: error:") and "Traceback" not in r.stderr
