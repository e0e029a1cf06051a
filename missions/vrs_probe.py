"""VRS probe: a sine sweep ``Z(t) = Z0 + A sin(ω0 t²)`` whose descent speed grows slowly, to find the
vehicle's real VRS onset (paper §IV, CONVENTIONS §3).

The sweep ramps in, then each cycle descends a little faster, up to a top speed beyond the onset it
looks for (``max_descent_ratio`` × the profile's ``w_allow`` unless ``max_descent_mps`` or
``--max-descent-speed`` says otherwise). The guard *observes* the cone (it logs where the vehicle
enters the region but does not act), and enforces hard limits: a descent-speed cap, the altitude
floor, and the fluctuation detector (angular-rate and vertical-acceleration std over a short window
against the hover measured just before the sweep). The first limit hit ends the probe with the
abort ladder (arrest the sink, hold, land) — the expected end (outcome ``probe_stopped``).
Then ``flighttest identify LOG --vehicle NAME`` finds the onset in the log.

    flighttest fly probe --connect udpout://127.0.0.1:14580 --vehicle x500 --yes
"""

from pathlib import Path

from flighttest.errors import FlighttestError
from flighttest.flying.missions_config import MissionConfig
from flighttest.flying.plan_config import ProbePlanConfig
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import Trajectory
from flighttest.planner.export import probe_trajectory
from flighttest.planner.problems import probe_plan

CONFIG = Path(__file__).with_suffix(".toml")


def top_speed_mps(profile: VehicleProfile, cfg: MissionConfig) -> float:
    """The sweep's top descent speed: explicit, else a multiple of the vehicle's ``w_allow``."""
    return ProbePlanConfig.from_table(cfg.plan).top_speed_mps(profile.w_allow_mps)


def plan(profile: VehicleProfile, cfg: MissionConfig) -> Trajectory:
    p, fl = ProbePlanConfig.from_table(cfg.plan), cfg.flight
    top = p.top_speed_mps(profile.w_allow_mps)
    cap = cfg.guard.max_descent_mps
    if cap is not None and cap <= top:
        raise FlighttestError(
            f"probe: the guard's descent cap {cap:g} m/s must exceed the sweep's top speed {top:.2f} m/s "
            "(raise [guard] max_descent_mps or lower the top speed)"
        )
    # within the vehicle's accelerations and, where the profile names them, its autopilot's limits
    pp = probe_plan(
        profile,
        amplitude_m=p.amplitude_m,
        omega0_rps2=p.omega0_rps2,
        ramp_s=p.ramp_s,
        max_descent_mps=top,
        duration_s=p.duration_s,
        start_alt_m=fl.start_height_m,
        floor_alt_m=fl.min_alt_m,
        accel_fraction=p.accel_fraction,
    )
    return probe_trajectory(pp, profile.name, profile.mass_kg)


if __name__ == "__main__":
    import sys

    from flighttest.cli.fly import mission_main

    sys.exit(mission_main("probe", sys.modules[__name__]))
