"""``flighttest vehicle list|show``: the vehicle profiles and their VRS numbers."""

from __future__ import annotations

import argparse
import sys

from rich import box
from rich.table import Table

from flighttest.console import console, print_json
from flighttest.model.profiles import load_profile, scan_profiles

NAME_FITS_80 = 24


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("vehicle", help="list and show vehicle profiles (v_h, w_allow, cone)")
    vsub = p.add_subparsers(dest="vehicle_command", metavar="ACTION", required=True)
    pl = vsub.add_parser(
        "list", help="all shipped and user profiles",
        description="Every profile that loads. A file that does not (malformed, not UTF-8, a bad field) is named "
        "on stderr, one line each, and skipped: the others are still listed and the exit code stays 0; "
        "`vehicle show FILE` or any command using that vehicle refuses it with exit code 2.",
    )
    pl.add_argument("--json", action="store_true", help="machine-readable output")
    pl.set_defaults(func=cmd_list)
    ps = vsub.add_parser("show", help="one profile in full")
    ps.add_argument("name", help="profile name or path to a .toml file")
    ps.add_argument("--json", action="store_true", help="machine-readable output")
    ps.set_defaults(func=cmd_show)


def cmd_list(args: argparse.Namespace) -> int:
    profiles, problems = scan_profiles()
    for line in problems:  # one damaged file in a user folder must not hide the good ones
        print(f"flighttest: warning: skipped {line}", file=sys.stderr)
    if args.json:
        print_json([p.summary() for p in profiles])
        return 0
    # headers on two lines (the quantity, then its unit): at 80 columns nothing is cut for names up to
    # NAME_FITS_80 characters (the shipped ones reach 15)
    t = Table(title="Vehicle profiles", box=box.SIMPLE_HEAD, title_justify="left")
    for col in ("name", "mass\nkg", "rotor Ø\nm", "v_h\nm/s", "w_allow\nm/s", "w_allow\n/ v_h", "cone\n°"):
        t.add_column(col, justify="left" if col == "name" else "right", no_wrap=True)
    for p in profiles:
        s = p.summary()
        t.add_row(
            p.name,
            f"{p.mass_kg:g}",
            f"{p.rotor_diameter_m:g}",
            f"{s['v_h_mps']:.2f}",
            f"{s['w_allow_mps']:.3f}",
            f"{s['w_allow_n']:.3f}",
            f"{p.vrs.cone_deg:g}",
        )
    console.print(t)
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    p = load_profile(args.name)
    s = p.summary()
    if args.json:
        print_json(s)
        return 0
    t = Table(title=f"Vehicle '{p.name}'", show_header=False)
    t.add_column("field", no_wrap=True)
    t.add_column("value", overflow="fold")  # a long path folds onto the next line, never cut
    for key, value in s.items():
        t.add_row(key, _shown(value))
    console.print(t)
    return 0


def _shown(value: object) -> str:
    """A summary value in the table: floats to 4 digits, a table (``autopilot``) as its given keys."""
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, dict):
        return ", ".join(f"{k} {_shown(v)}" for k, v in value.items() if v is not None)
    return str(value)
