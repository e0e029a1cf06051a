"""``flighttest sim``: run the fake PX4 quadcopter (``sitl_fakes``) for rehearsals and tests."""

from __future__ import annotations

import argparse

from flighttest import inputs as ip

DESCRIPTION = """\
Run the fake quadcopter: MAVLink 2 over UDP, real-time rigid-body physics, a PX4-like controller (or,
--autopilot ardupilot, ArduCopter's) and a VRS/WBS disturbance whose truth (onset, cone, severity, seed)
you set here, independently of what flighttest believes. Its first output line is
`connect: udpout://127.0.0.1:P`, the --connect URL for flighttest fly and campaign; Ctrl-C stops it.
See sitl_fakes/README.md for the truth-log columns.
"""

# The fake's numbers within what its real-time loop and physics can run: a physics rate of 1e308 Hz
# would make each step too small to advance the clock (a hang), a gust of 1e308 m/s overflows.
_RANGES = {
    "truth_onset": ("--truth-onset", ip.W_ALLOW_POSITIVE_MPS),
    "truth_cone_deg": ("--truth-cone-deg", ip.TILT_DEG),
    "truth_severity": ("--truth-severity", ip.Range(0.0, 10.0)),
    "truth_rate_hz": ("--truth-rate-hz", ip.Range(0.0, 2000.0, "Hz")),
    "seed": ("--seed", ip.Range(0, 2**32 - 1, integer=True)),
    "gust_mps": ("--gust-mps", ip.Range(0.0, ip.MAX_WIND_MPS, "m/s")),
    "gust_tau_s": ("--gust-tau-s", ip.Range(0.01, 3600.0, "s")),
    "physics_hz": ("--physics-hz", ip.Range(50.0, 2000.0, "Hz")),
    "telemetry_hz": ("--telemetry-hz", ip.Range(1.0, 500.0, "Hz")),
    "crash_speed_mps": ("--crash-speed-mps", ip.Range(0.0, ip.MAX_SPEED_MPS, "m/s", lo_open=True)),
    "gps_delay_s": ("--gps-delay-s", ip.Range(0.0, 3600.0, "s")),
    "duration_s": ("--duration-s", ip.Range(0.0, 7 * 24 * 3600.0, "s")),
}

# a drag coefficient per body axis: 1000 N per m/s (or per (m/s)²) would stop any airframe flighttest flies
TRUTH_DRAG_COEF = ip.Range(0.0, 1000.0)


def register(sub: argparse._SubParsersAction) -> None:
    from sitl_fakes.app import add_arguments

    p = sub.add_parser(
        "sim",
        help="run the fake quadcopter (PX4 or ArduCopter) with VRS/WBS physics",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_arguments(p)
    p.set_defaults(func=_run)


def check_args(args: argparse.Namespace) -> None:
    """Every number in its range and the truth log writable, before the fake binds its port."""
    for key, (flag, rng) in _RANGES.items():
        value = getattr(args, key, None)
        if value is not None:
            rng.check(value, flag)
    if args.truth_log is not None:
        ip.check_output_path(args.truth_log, "--truth-log")
    if getattr(args, "truth_drag", None) is not None:
        for i, part in enumerate(str(args.truth_drag).split(",")):
            try:
                value = float(part)
            except ValueError:
                continue  # sitl_fakes words a non-number itself
            TRUTH_DRAG_COEF.check(value, f"--truth-drag value {i + 1}")
    for i, text in enumerate(args.wind_ned):
        for part in str(text).split(","):
            if part.strip():
                try:
                    value = float(part)
                except ValueError:
                    continue  # sitl_fakes words a non-number itself
                ip.WIND_MPS.check(value, f"--wind-ned value {i + 1}")


def _run(args: argparse.Namespace) -> int:
    from sitl_fakes.app import run

    check_args(args)
    return run(args)
