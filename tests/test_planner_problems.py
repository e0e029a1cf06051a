"""Problems from plain options (flighttest.planner.problems): what `flighttest plan KIND` builds, no solve."""

from __future__ import annotations

import math

import pytest

from flighttest.errors import FlighttestError
from flighttest.model.profiles import load_profile
from flighttest.planner.cases import TABLE_II
from flighttest.planner.cone import VelocityConstraint
from flighttest.planner.helix import problem_for_vehicle
from flighttest.planner.problems import (
    helix_problem,
    planar_problem,
    probe_plan,
    vehicle_constraint,
    vertical_constraint,
    vertical_plan,
)
from flighttest.planner.vertical import plan_vertical


@pytest.fixture(scope="module")
def x500():
    return load_profile("x500")


def test_constraint_kinds(x500):
    cone = vehicle_constraint(x500)
    assert cone == VelocityConstraint(cone_deg=x500.vrs.cone_deg, w_allow_mps=0.0, margin_mps=x500.vrs.margin_mps)
    guard = vehicle_constraint(x500, "guard", margin_mps=0.0)
    assert guard.name == "guard" and guard.w_allow_mps == x500.w_allow_mps and guard.margin_mps == 0.0
    with pytest.raises(FlighttestError, match="cone, guard"):
        vehicle_constraint(x500, "cylinder")


def test_a_table_ii_case_keeps_the_papers_bounds_and_zero_margin(x500):
    p = planar_problem(x500, 5)
    case = TABLE_II[5].problem
    assert p.phi_bound_rad is None and p.f_min_mps2 == case.f_min_mps2 < 0 and p.omega_max_rps == case.omega_max_rps
    assert p.constraint.margin_mps == 0.0 and p.constraint.w_allow_mps == 0.0
    assert (p.n_intervals, p.n_coarse) == (80, 40)
    # options replace bounds; the Z bound grows to a taller descent
    q = planar_problem(x500, 5, height_m=20.0, phi_bound_deg=30.0, constraint_kind="guard", n_intervals=30)
    assert q.height_m == 20.0 and q.z_bound_m == 20.0 and q.phi_bound_rad == pytest.approx(math.radians(30))
    assert q.constraint.w_allow_mps == x500.w_allow_mps and q.n_coarse == 15


def test_a_vehicle_planar_problem_has_the_vehicles_bounds(x500):
    p = planar_problem(x500, flips=True, wind_y_mps=0.5, n_intervals=16)
    n_thrust = x500.n_rotors / x500.mass_kg
    assert p.f_min_mps2 == pytest.approx(n_thrust * x500.min_thrust_per_rotor_n) and p.f_min_mps2 >= 0
    assert p.f_max_mps2 == pytest.approx(0.9 * n_thrust * x500.max_thrust_per_rotor_n)
    assert p.phi_bound_rad is None and p.wind_y_mps == 0.5 and p.n_coarse == 10
    assert p.constraint.margin_mps == x500.vrs.margin_mps
    assert planar_problem(x500).phi_bound_rad == pytest.approx(math.radians(x500.max_tilt_deg))
    with pytest.raises(FlighttestError, match="exclude"):
        planar_problem(x500, flips=True, phi_bound_deg=30.0)


def test_helix_problem_is_problem_for_vehicle_with_the_chosen_constraint(x500):
    p = helix_problem(x500, height_m=3.0, constraint_kind="guard", margin_mps=0.1, n_intervals=24)
    con = VelocityConstraint(cone_deg=x500.vrs.cone_deg, w_allow_mps=x500.w_allow_mps, margin_mps=0.1)
    assert p == problem_for_vehicle(x500, height_m=3.0, constraint=con, n_intervals=24, n_coarse=12)


def test_closed_form_plans(x500):
    plan = vertical_plan(x500, 3.0, extra_margin_mps=0.35, accel_fraction=0.15)
    ref = plan_vertical(x500, 3.0, margin_mps=x500.vrs.margin_mps + 0.35, accel_fraction=0.15)
    assert plan.t_f_s == ref.t_f_s and plan.problem == ref.problem
    con = vertical_constraint(x500, plan)
    assert con.w_allow_mps == x500.w_allow_mps and con.margin_mps == pytest.approx(x500.vrs.margin_mps + 0.35)
    probe = probe_plan(x500, amplitude_m=2.0, omega0_rps2=0.05, ramp_s=3.0, max_descent_mps=1.5, duration_s=60.0,
                       start_alt_m=10.0, floor_alt_m=2.0, accel_fraction=0.5)  # fmt: skip
    assert probe.problem["max_accel_up_mps2"] == pytest.approx(0.5 * x500.max_accel_up_mps2)
    assert probe.vd_mps.max() <= 1.5
