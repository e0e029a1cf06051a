"""``flighttest sim``: run the fake PX4 quadcopter (``sitl_fakes``) for rehearsals and tests."""

from __future__ import annotations

import argparse

DESCRIPTION = """\
Run the fake PX4 quadcopter: MAVLink 2 over UDP, real-time rigid-body physics, a PX4-like controller
and a VRS/WBS disturbance whose truth (onset, cone, severity, seed) you set here, independently of
what flighttest believes. Its first output line is `connect: udpout://127.0.0.1:P`. See
sitl_fakes/README.md for the truth-log columns.
"""


def register(sub: argparse._SubParsersAction) -> None:
    from sitl_fakes.app import add_arguments

    p = sub.add_parser(
        "sim",
        help="run the fake PX4 quadcopter with VRS/WBS physics",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_arguments(p)
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from sitl_fakes.app import run

    return run(args)
