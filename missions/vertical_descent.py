"""Vertical descent: the baseline, straight down at the vehicle's safe vertical speed.

Cruise at ``w_allow − margin − extra_margin`` (inside the guard's own bound, so it stays silent), accelerating and
braking within the vehicle's limits and, for a profile with an ``[autopilot]`` table, within the autopilot's
(``flighttest.planner.vertical``), the acceleration changing at most at ``jerk_max_mps3``. Edit
``vertical_descent.toml`` or copy this file.

    python missions/vertical_descent.py --connect udpout://127.0.0.1:14580 --vehicle x500 --yes
    flighttest fly vertical --connect udpout://127.0.0.1:14580 --vehicle x500 --yes
"""

from pathlib import Path

from flighttest.flying.missions_config import MissionConfig
from flighttest.flying.plan_config import VerticalPlanConfig
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import Trajectory
from flighttest.planner.export import vertical_trajectory
from flighttest.planner.vertical import plan_vertical

CONFIG = Path(__file__).with_suffix(".toml")


def plan(profile: VehicleProfile, cfg: MissionConfig) -> Trajectory:
    p = VerticalPlanConfig.from_table(cfg.plan)
    vp = plan_vertical(
        profile,
        height_m=p.descent_m,
        # the guard's own bound minus a tracking margin, so the guard stays silent
        margin_mps=profile.vrs.margin_mps + p.extra_margin_mps,
        accel_fraction=p.accel_fraction,
        jerk_mps3=p.jerk_max_mps3,
    )
    return vertical_trajectory(vp, profile.name, profile.mass_kg)


if __name__ == "__main__":
    import sys

    from flighttest.cli.fly import mission_main

    sys.exit(mission_main("vertical", sys.modules[__name__]))
