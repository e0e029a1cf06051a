"""Drag calibration: level out-and-back legs at a few speeds, north–south and east–west.

The IMU feels the air's drag across the thrust axis; flown at known speeds in both directions, it
identifies the airframe's drag (``flighttest identify LOG --drag``), which flighttest needs to estimate the
wind in flight (``flighttest.model.wind_estimate``). Fly it once per airframe, in steady air or steady
wind (the wind cancels between the legs), with room around the start (``reach_m`` of the plan).

    flighttest fly drag --connect udpin://0.0.0.0:14540 --vehicle x500 --yes
    flighttest identify logs/<folder> --vehicle x500 --drag --write-profile
"""

from pathlib import Path

from flighttest.flying.missions_config import MissionConfig
from flighttest.flying.plan_config import DragPlanConfig
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import Trajectory
from flighttest.planner.calibration import CalibrationPlan, calibration_trajectory

CONFIG = Path(__file__).with_suffix(".toml")


def plan(profile: VehicleProfile, cfg: MissionConfig) -> Trajectory:
    p = DragPlanConfig.from_table(cfg.plan)
    cal = CalibrationPlan(p.speeds_mps, p.cruise_s, p.accel_mps2, p.pause_s)
    return calibration_trajectory(cal, profile.name, cfg.flight.geofence_radius_m)


if __name__ == "__main__":
    import sys

    from flighttest.cli.fly import mission_main

    sys.exit(mission_main("drag", sys.modules[__name__]))
