"""VRS probe: a sine sweep ``Z(t) = Z0 + A sin(ω0 t²)`` whose descent speed grows slowly, to find the
vehicle's real VRS onset (paper §IV, NOTES §3).

The guard *observes* the cone (it logs where the vehicle enters the region but does not act), and
enforces hard limits: a descent-speed cap, the altitude floor, and the fluctuation detector
(angular-rate and vertical-acceleration standard deviation over a short window). The first limit
hit ends the probe with the abort ladder — the expected end (outcome ``probe_stopped``).

    flighttest fly probe --connect udpout://127.0.0.1:14580 --vehicle x500 --yes
"""

from pathlib import Path

from flighttest.missions_config import MissionConfig
from flighttest.planner.export import probe_trajectory
from flighttest.planner.probe import plan_probe
from flighttest.profiles import VehicleProfile
from flighttest.trajectory import Trajectory

CONFIG = Path(__file__).with_suffix(".toml")


def plan(profile: VehicleProfile, cfg: MissionConfig) -> Trajectory:
    p, fl = cfg.plan, cfg.flight
    pp = plan_probe(
        amplitude_m=float(p.get("amplitude_m", 2.0)),
        omega0_rps2=float(p.get("omega0_rps2", 0.05)),
        ramp_s=float(p.get("ramp_s", 3.0)),
        max_descent_mps=float(cfg.guard.max_descent_mps or 3.0),
        duration_s=float(p.get("duration_s", 40.0)),
        start_alt_m=fl.start_height_m,
        floor_alt_m=fl.min_alt_m,
    )
    return probe_trajectory(pp, profile.name, profile.mass_kg)


if __name__ == "__main__":
    import sys

    from flighttest.cli.fly import mission_main

    sys.exit(mission_main("probe", sys.modules[__name__]))
