"""Helix descent: the 3D minimum-time descent that stays out of the guard region (paper §IV).

Plans the helix with the vehicle's bounds (or loads a planned file given as ``plan.trajectory`` in
``helix_descent.toml``) and flies it. Planning takes a few seconds of IPOPT.

    flighttest fly helix --connect udpout://127.0.0.1:14580 --vehicle x500 --yes
"""

from pathlib import Path

from flighttest.missions_config import MissionConfig
from flighttest.planner.cone import VelocityConstraint
from flighttest.planner.export import helix_trajectory
from flighttest.planner.helix import problem_for_vehicle, solve_helix
from flighttest.profiles import VehicleProfile
from flighttest.trajectory import Trajectory

CONFIG = Path(__file__).with_suffix(".toml")


def plan(profile: VehicleProfile, cfg: MissionConfig) -> Trajectory:
    p = cfg.plan
    if p.get("trajectory"):
        return Trajectory.load(CONFIG.parent / str(p["trajectory"]), profile)
    # plan against the guard's own region (w_allow and margin), with some extra margin for tracking
    constraint = VelocityConstraint(
        cone_deg=profile.vrs.cone_deg,
        w_allow_mps=profile.w_allow_mps,
        margin_mps=profile.vrs.margin_mps + float(p.get("extra_margin_mps", 0.4)),
    )
    problem = problem_for_vehicle(
        profile,
        height_m=float(p.get("descent_m", 3.0)),
        radius_m=float(p.get("radius_m", 1.5)),
        constraint=constraint,
        thrust_fraction=float(p.get("thrust_fraction", 0.7)),
        tilt_max_deg=float(p.get("tilt_max_deg", 25.0)),
        rate_max_dps=float(p.get("rate_max_dps", 90.0)),
        n_intervals=int(p.get("n_intervals", 60)),
        n_coarse=int(p.get("n_coarse", 30)),
    )
    sol = solve_helix(problem)
    if not sol.result.success:
        from flighttest.errors import FlighttestError

        raise FlighttestError(f"helix planner did not converge ({sol.result.status})")
    return helix_trajectory(sol, profile.name, profile.mass_kg)


if __name__ == "__main__":
    import sys

    from flighttest.cli.fly import mission_main

    sys.exit(mission_main("helix", sys.modules[__name__]))
