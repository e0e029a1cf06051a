"""Long helical descents: the planner solves 2–30 m, checks the dense solution, not open-loop drift.

Issue 11: ``plan helix --height 20 --radius 2`` exited 2 after 64 s, its refinement rounds having
read the open-loop drift of a 10 s re-simulation as constraint overshoot and relaxed the radius
bound by hundreds of metres. An independent solver finds 9.99 s for that problem.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from flighttest.model.profiles import load_profile
from flighttest.planner import helix
from flighttest.planner.export import helix_trajectory
from flighttest.planner.ocp import rk4_piecewise, rk4_resimulate

INDEPENDENT_T_F_S = 9.99  # 20 m, radius 2 m, x500 (issue 11)
# The dense re-sampling may pass the radius bound by this much (the check's own tolerance, 1 mm,
# plus the trajectory file's 100 Hz linear interpolation).
RADIUS_TOL_M = 2e-3


def _cli_problem(height_m: float, radius_m: float) -> helix.HelixProblem:
    """What ``flighttest plan helix --vehicle x500 --height H --radius R`` solves (60 / 30 intervals)."""
    return helix.problem_for_vehicle(load_profile("x500"), height_m=height_m, radius_m=radius_m,
                                     n_intervals=60, n_coarse=30)  # fmt: skip


def _assert_flyable(sol: helix.HelixSolution, p: helix.HelixProblem) -> None:
    x500 = load_profile("x500")
    c = sol.check
    assert c["limits_ok"], c
    assert c["node_gap_ok"], c
    # Radius on a dense re-sampling: the 1 kHz path between the nodes and the file that is flown.
    dense = helix.dense_path(sol.result, 1000.0)
    assert np.hypot(dense.x[:, 0], dense.x[:, 1]).max() <= p.radius_m + RADIUS_TOL_M
    traj = helix_trajectory(sol, "x500", x500.mass_kg)
    traj.validate(x500)
    assert np.hypot(traj.column("n_m"), traj.column("e_m")).max() <= p.radius_m + RADIUS_TOL_M
    # Hover to hover at the end point, no drift: the file ends where the plan does.
    assert abs(traj.column("d_m")[-1] - p.height_m) < 0.01
    assert math.hypot(traj.column("n_m")[-1], traj.column("e_m")[-1]) < 0.01
    assert math.hypot(traj.column("vn_mps")[-1], traj.column("ve_mps")[-1], traj.column("vd_mps")[-1]) < 0.01


def test_20_m_helix_within_5_percent_of_the_independent_optimum():
    p = _cli_problem(20.0, 2.0)
    sol = helix.solve_helix(p)
    assert sol.success, sol.attempts
    assert abs(sol.t_f_s - INDEPENDENT_T_F_S) <= 0.05 * INDEPENDENT_T_F_S, sol.t_f_s
    _assert_flyable(sol, p)
    assert sol.check["turns"] > 3  # a long helix on the radius bound, not a plunge
    # Tightening was local and small: never a relaxed bound (the bug moved it by hundreds of metres).
    for a in sol.attempts:
        if "backoff" in a:
            assert 0 <= a["backoff"]["radius_m"] <= helix.MAX_RADIUS_BACKOFF_FRACTION * p.radius_m
            assert 0 <= a["backoff"]["tilt_rad"] <= math.radians(helix.MAX_TILT_BACKOFF_DEG)
    # The mesh grew with the duration (more than the 60 asked for a 2.5 s descent).
    assert sol.check["n_intervals"] > 60
    assert sol.solve_s < 60.0  # 6-9 s on the 2-core machine; it was 64 s and a failure


def test_2_m_helix_short_descent():
    p = _cli_problem(2.0, 2.0)
    sol = helix.solve_helix(p)
    assert sol.success, sol.attempts
    assert 1.8 < sol.t_f_s < 2.6, sol.t_f_s  # 2.25 s
    _assert_flyable(sol, p)
    assert sol.check["n_intervals"] == 60


def test_dense_path_is_the_integration_from_every_node():
    """Nodes that lie on the dynamics' own trajectory: the dense path is that trajectory, gaps ~0;
    nodes off it: the path still ends on every node, each interval's miss reported as its gap."""
    rng = np.random.default_rng(3)
    t_nodes = np.linspace(0.0, 2.0, 21)
    u = np.column_stack([rng.uniform(8, 12, 21), rng.uniform(-0.5, 0.5, (21, 3))])
    x0 = np.array([0, 0, 0, 0.3, 0, 0.2, 1.0, 0, 0, 0])
    t_ref, x_ref, _ = rk4_resimulate(helix._dynamics_np, t_nodes, x0, u, 1000.0)
    x_nodes = x_ref[:: len(t_ref) // 20]
    d = rk4_piecewise(helix.dynamics, t_nodes, x_nodes, u, 1000.0)
    assert np.abs(d.gaps).max() < 1e-9
    np.testing.assert_allclose(d.x, x_ref, atol=1e-9)
    np.testing.assert_allclose(d.t, t_ref, atol=1e-12)
    off = x_nodes.copy()
    off[5, 0] += 0.01  # one node 1 cm off the trajectory
    d = rk4_piecewise(helix.dynamics, t_nodes, off, u, 1000.0)
    assert np.abs(d.gaps[4, 0]) == pytest.approx(0.01, abs=1e-9)
    m = (len(d.t) - 1) // 20
    np.testing.assert_allclose(d.x[::m], off, atol=1e-12)  # continuous: every node is on the path


def test_backoff_is_local_and_capped():
    p = _cli_problem(20.0, 2.0)
    b = helix._Backoff(p, 10)
    over = np.full(10, -1.0)
    over[4] = 1.0  # interval 4 broke the radius bound by 1 m: far more than a between-node bulge
    for _ in range(5):
        b.raise_where("radius_m", over, np.full(10, 1.0))
    cap = helix.MAX_RADIUS_BACKOFF_FRACTION * p.radius_m
    assert b.radius_m.max() == pytest.approx(cap)
    assert not b.raise_where("radius_m", over, np.full(10, 1.0))  # at the cap: nothing moves
    lb = b.path_lb()
    # Tightened (lower bound of R² − N² − E² raised) on intervals 3–5 only, never relaxed.
    assert lb[:, 1].min() == 0.0
    assert lb[:, 1].max() == pytest.approx(p.radius_m**2 - (p.radius_m - cap) ** 2)
    assert np.flatnonzero(lb[:11, 1]).tolist() == [3, 4, 5, 6]
    # The cone is never tightened at the hover nodes (its slack is exactly 0 there).
    over_c = np.zeros(10)
    over_c[[0, 9]] = 1.0
    b.raise_where("cone_mps", over_c, np.full(10, 0.001))
    assert b.cone_mps[0] == 0.0 and b.cone_mps[10] == 0.0 and b.cone_mps.max() > 0


def test_steady_helix_rides_the_cone_and_the_tilt():
    p = _cli_problem(20.0, 2.0)
    c = helix.steady_helix(p)
    assert c.radius_m < p.radius_m and c.bank_rad < p.tilt_max_rad
    assert math.tan(c.bank_rad) == pytest.approx(c.speed_h_mps**2 / (c.radius_m * helix.G_MPS2), rel=1e-3)
    w = c.descent_mps * math.cos(c.bank_rad)
    u = math.hypot(c.speed_h_mps, c.descent_mps * math.sin(c.bank_rad))
    margin = p.constraint.margin(np.array([w]), np.array([u]))[0]
    assert 0 <= margin <= p.constraint.smoothing_mps + 1e-9  # on the cone, inside it by the smoothing
    t_f, _ = helix.steady_helix_duration(p)
    assert INDEPENDENT_T_F_S < t_f < 1.2 * INDEPENDENT_T_F_S  # a warm start near the optimum
