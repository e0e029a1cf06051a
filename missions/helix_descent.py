"""Helix descent: the 3D minimum-time descent that stays out of the guard region (paper §IV).

Plans the helix for the vehicle (or loads a planned file given as ``plan.trajectory`` in
``helix_descent.toml``) and flies it. The plan keeps a *tracking margin* (``[plan]`` in the TOML,
``flighttest.planner.tracking``): inside the guard's bound by ``guard_margin_mps``, tilt, body
rates and thrust below the vehicle's limits, descent below PX4's ``MPC_Z_VEL_MAX_DN``, so the
autopilot's feedback has room and the guard stays silent on a well-flown helix. A profile with an
``[autopilot]`` table (``arducopter_sitl``: ArduCopter's GUIDED limits) also keeps the helix's
acceleration, descent and climb within those limits. Planning takes a few seconds of IPOPT, once: the plans
are kept in the plan cache (``flighttest.planner.plan_cache``).

    flighttest fly helix --connect udpout://127.0.0.1:14580 --vehicle x500 --yes
"""

from pathlib import Path

from flighttest.errors import FlighttestError
from flighttest.flying.missions_config import MissionConfig
from flighttest.flying.plan_config import HelixPlanConfig
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import Trajectory
from flighttest.planner.export import helix_trajectory
from flighttest.planner.helix import solve_helix
from flighttest.planner.plan_cache import cached_plan
from flighttest.planner.tracking import TrackingMargin, helix_problem_for_flight
from flighttest.planner.wind_plans import SOLVE_MAX_S, helix_plans_for_winds, wind_speeds

CONFIG = Path(__file__).with_suffix(".toml")


def plan(profile: VehicleProfile, cfg: MissionConfig) -> Trajectory:
    p = cfg.plan
    hp = HelixPlanConfig.from_table(p)
    if hp.trajectory:
        return Trajectory.load(Path(cfg.path or CONFIG).parent / hp.trajectory, profile)

    def solve() -> Trajectory:
        problem = helix_problem_for_flight(
            profile,
            height_m=hp.descent_m,
            radius_m=hp.radius_m,
            margin=TrackingMargin.from_plan(p),
            n_intervals=hp.n_intervals,
            n_coarse=hp.n_coarse,
            wind_radius_mps=hp.calm_wind_radius_mps,
        )
        sol = solve_helix(problem)
        if not sol.success:
            raise FlighttestError(f"helix planner did not converge ({sol.result.status})")
        return helix_trajectory(sol, profile.name, profile.mass_kg, extra={"tracking_margin": dict(p)})

    # seconds of IPOPT before every flight otherwise (7.7 s for arducopter_sitl: bench/RESULTS.md, "The plan cache")
    return cached_plan("helix-calm", profile, {"plan": dict(p)}, solve)


def plans_for_wind(profile: VehicleProfile, cfg: MissionConfig, progress=lambda _: None) -> list[Trajectory]:
    """Helices for winds up to ``max_wind_mps`` (along +east; the start hover turns the one it chooses)."""
    p = cfg.plan
    hp = HelixPlanConfig.from_table(p)
    if hp.trajectory:
        return []

    def solve(speed_mps: float, radius_mps: float) -> Trajectory:
        problem = helix_problem_for_flight(profile, height_m=hp.descent_m, radius_m=hp.radius_m,
                                           margin=TrackingMargin.from_plan(p), n_intervals=hp.n_intervals,
                                           n_coarse=hp.n_coarse, wind_ned_mps=(0.0, speed_mps, 0.0),
                                           wind_radius_mps=radius_mps)  # fmt: skip
        sol = solve_helix(problem, max_solve_s=SOLVE_MAX_S)
        if not sol.success:
            raise FlighttestError(f"the planner did not converge ({sol.result.status})")
        return helix_trajectory(sol, profile.name, profile.mass_kg, extra={"tracking_margin": dict(p)})

    speeds = wind_speeds(cfg.flight.max_wind_mps, hp.wind_step_mps)
    return helix_plans_for_winds(profile, dict(p), speeds, hp.wind_radius_mps, solve, progress)


if __name__ == "__main__":
    import sys

    from flighttest.cli.fly import mission_main

    sys.exit(mission_main("helix", sys.modules[__name__]))
