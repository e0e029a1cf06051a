"""``flighttest demo``: the main job end to end against the built-in fake vehicle.

It grows with every capability; today it shows the vehicle and its velocity-space chart.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.table import Table

from flighttest.console import console, print_json
from flighttest.profiles import load_profile


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the main job end to end against the built-in fake vehicle")
    p.add_argument("--vehicle", default="x500", help="profile name or .toml path (default x500)")
    p.add_argument("-o", "--output", type=Path, default=Path("logs/demo"), help="folder for the results")
    p.add_argument("--json", action="store_true", help="machine-readable summary")
    p.set_defaults(func=cmd_demo)


def cmd_demo(args: argparse.Namespace) -> int:
    from flighttest.chart import write_chart

    profile = load_profile(args.vehicle)
    args.output.mkdir(parents=True, exist_ok=True)
    chart = write_chart(profile, args.output / f"chart_{profile.name}.png")
    summary = {"vehicle": profile.summary(), "chart": str(chart)}
    if args.json:
        print_json(summary)
        return 0
    t = Table(title=f"flighttest demo — vehicle '{profile.name}'", show_header=False)
    t.add_column("quantity")
    t.add_column("value", justify="right")
    for key in ("mass_kg", "rotor_diameter_m", "v_h_mps", "w_allow_mps", "w_allow_n", "cone_deg", "margin_mps"):
        t.add_row(key, f"{summary['vehicle'][key]:g}")
    console.print(t)
    console.print(f"velocity-space chart: {chart}")
    return 0
