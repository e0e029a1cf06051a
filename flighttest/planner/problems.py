"""Problems from plain options: one function per kind of plan, for ``flighttest plan`` and scripts alike.

Each takes a vehicle profile and typed values (None: the default the docstring names) and returns
what the planner solves (``planar_problem``, ``helix_problem``) or the closed-form plan itself
(``vertical_plan``, ``probe_plan``). Defaults that live in the flying layer (a mission's ``[plan]``
table, its start height and floor) are the caller's to resolve: the planner does not read mission
configs.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from flighttest.errors import FlighttestError
from flighttest.model.profiles import VehicleProfile
from flighttest.planner.autopilot_limits import capped, plan_limits
from flighttest.planner.cases import table_case
from flighttest.planner.cone import VelocityConstraint
from flighttest.planner.helix import HelixProblem, problem_for_vehicle
from flighttest.planner.planar import PlanarProblem
from flighttest.planner.probe import ProbePlan, plan_probe
from flighttest.planner.vertical import VerticalPlan, plan_vertical

CONSTRAINT_KINDS = ("cone", "guard")


def vehicle_constraint(profile: VehicleProfile, kind: str = "cone", margin_mps: float | None = None,
                       w_allow_mps: float | None = None) -> VelocityConstraint:  # fmt: skip
    """The constraint at the profile's cone angle: the pure ``cone`` (``w_allow = 0``, the paper's)
    or the ``guard``'s region (``w_allow_mps``, default the profile's); ``margin_mps`` default the
    profile's guard margin."""
    if kind not in CONSTRAINT_KINDS:
        raise FlighttestError(f"constraint must be one of {', '.join(CONSTRAINT_KINDS)} (got {kind!r})")
    w_allow = (profile.w_allow_mps if w_allow_mps is None else w_allow_mps) if kind == "guard" else 0.0
    margin = profile.vrs.margin_mps if margin_mps is None else margin_mps
    return VelocityConstraint(cone_deg=profile.vrs.cone_deg, w_allow_mps=w_allow, margin_mps=margin)


def default_coarse_intervals(n_intervals: int) -> int:
    """The multi-start's coarse mesh for a fine mesh of ``n_intervals``: half, at least 10."""
    return max(10, n_intervals // 2)


def planar_problem(
    profile: VehicleProfile,
    case: int | None = None,
    *,
    constraint_kind: str = "cone",
    margin_mps: float | None = None,
    height_m: float | None = None,
    y_bound_m: float | None = None,
    y_final: str | None = None,
    phi_bound_deg: float | None = None,
    flips: bool = False,
    omega_max_rps: float | None = None,
    f_min_mps2: float | None = None,
    f_max_mps2: float | None = None,
    v_bound_mps: float | None = None,
    wind_y_mps: float = 0.0,
    wind_z_mps: float = 0.0,
    n_intervals: int = 80,
    n_coarse: int | None = None,
) -> PlanarProblem:
    """A planar descent: Table II ``case``'s bounds (thrust may go negative; margin default 0, the
    paper's) or, without a case, the vehicle's (collective thrust from the rotors' minimum to 90 % of
    their maximum, tilt, roll rate, speed). Every option given replaces its bound: ``flips`` drops the
    roll bound (flips allowed), ``n_coarse`` defaults to ``default_coarse_intervals``. The Z bound
    grows to the height when needed."""
    if flips and phi_bound_deg is not None:
        raise FlighttestError("planar problem: a roll bound and flips (no roll bound) exclude each other")
    if case is not None:
        base = table_case(case).problem
        if margin_mps is None:
            margin_mps = 0.0
    else:
        n, m = profile.n_rotors, profile.mass_kg
        base = PlanarProblem(
            f_min_mps2=n * profile.min_thrust_per_rotor_n / m,
            f_max_mps2=0.9 * n * profile.max_thrust_per_rotor_n / m,
            phi_bound_rad=math.radians(profile.max_tilt_deg),
            omega_max_rps=math.radians(profile.max_rate_dps[0]),
            v_bound_mps=profile.max_speed_mps,
        )
    overrides: dict[str, Any] = {
        "constraint": vehicle_constraint(profile, constraint_kind, margin_mps),
        "n_intervals": n_intervals,
        "n_coarse": default_coarse_intervals(n_intervals) if n_coarse is None else n_coarse,
        "wind_y_mps": wind_y_mps,
        "wind_z_mps": wind_z_mps,
    }
    for name, value in (("height_m", height_m), ("y_bound_m", y_bound_m), ("y_final", y_final),
                        ("omega_max_rps", omega_max_rps), ("f_min_mps2", f_min_mps2), ("f_max_mps2", f_max_mps2),
                        ("v_bound_mps", v_bound_mps)):  # fmt: skip
        if value is not None:
            overrides[name] = value
    if flips:
        overrides["phi_bound_rad"] = None
    elif phi_bound_deg is not None:
        overrides["phi_bound_rad"] = math.radians(phi_bound_deg)
    p = replace(base, **overrides)
    return replace(p, z_bound_m=max(p.z_bound_m, p.height_m))


def helix_problem(
    profile: VehicleProfile,
    *,
    height_m: float = 5.0,
    radius_m: float = 2.0,
    constraint_kind: str = "cone",
    margin_mps: float | None = None,
    thrust_fraction: float = 0.9,
    tilt_max_deg: float | None = None,
    rate_max_dps: float | None = None,
    wind_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0),
    end_ne_m: tuple[float, float] = (0.0, 0.0),
    n_intervals: int = 60,
    n_coarse: int | None = None,
) -> HelixProblem:
    """A 3D descent for the vehicle (``helix.problem_for_vehicle``) against ``vehicle_constraint``;
    ``n_coarse`` defaults to ``default_coarse_intervals``."""
    return problem_for_vehicle(
        profile,
        height_m=height_m,
        radius_m=radius_m,
        constraint=vehicle_constraint(profile, constraint_kind, margin_mps),
        thrust_fraction=thrust_fraction,
        tilt_max_deg=tilt_max_deg,
        rate_max_dps=rate_max_dps,
        wind_ned_mps=wind_ned_mps,
        end_ne_m=end_ne_m,
        n_intervals=n_intervals,
        n_coarse=default_coarse_intervals(n_intervals) if n_coarse is None else n_coarse,
    )


def vertical_plan(profile: VehicleProfile, height_m: float, *, w_allow_mps: float | None = None,
                  margin_mps: float | None = None, extra_margin_mps: float = 0.0,
                  accel_fraction: float = 0.8, jerk_mps3: float | None = None) -> VerticalPlan:  # fmt: skip
    """The vertical baseline (``vertical.plan_vertical``) cruising ``extra_margin_mps`` inside the
    guard's bound on top of its margin (``margin_mps``, default the profile's): room for the
    autopilot's tracking error."""
    margin = (profile.vrs.margin_mps if margin_mps is None else margin_mps) + extra_margin_mps
    return plan_vertical(profile, height_m, w_allow_mps, margin, accel_fraction, jerk_mps3=jerk_mps3)


def vertical_constraint(profile: VehicleProfile, plan: VerticalPlan) -> VelocityConstraint:
    """The guard's region a vertical plan was made against (its ``w_allow`` and margin)."""
    return vehicle_constraint(profile, "guard", plan.problem["margin_mps"], plan.problem["w_allow_mps"])


def probe_plan(profile: VehicleProfile, *, amplitude_m: float, omega0_rps2: float, ramp_s: float,
               max_descent_mps: float, duration_s: float, start_alt_m: float, floor_alt_m: float,
               speed_step_mps: float = 0.1, accel_fraction: float = 1.0) -> ProbePlan:  # fmt: skip
    """The probe reference (``probe.plan_probe``) within ``accel_fraction`` of the vehicle's up and
    down accelerations, and within its autopilot's vertical acceleration, descent and climb speeds where
    the profile names them (``autopilot_limits.plan_limits``: GUIDED flies a faster sweep late)."""
    limits = plan_limits(profile)
    a_down = capped(accel_fraction * profile.max_accel_down_mps2, limits.accel_z_max_mps2)
    a_up = capped(accel_fraction * profile.max_accel_up_mps2, limits.accel_z_max_mps2)
    # every cycle climbs back to the start as fast as it went down: the cap holds for both
    top = capped(capped(max_descent_mps, limits.descent_max_mps), limits.climb_max_mps)
    return plan_probe(amplitude_m, omega0_rps2, ramp_s, top, duration_s, start_alt_m, floor_alt_m, speed_step_mps,
                      max_accel_down_mps2=a_down, max_accel_up_mps2=a_up)  # fmt: skip
