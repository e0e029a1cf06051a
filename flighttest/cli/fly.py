"""flighttest fly probe|helix|vertical|drag|TRAJECTORY_FILE --connect URL --vehicle NAME

The named missions are mission scripts, each with its TOML config beside it (the user's copies
first, else the shipped ones: see the end of --help); probe, helix and vertical plan as
`flighttest plan` does by default. A trajectory file (`flighttest plan ... -o NAME`) is flown as planned, from --height.
Prints the preflight table, asks go/no-go (--yes skips it; without a terminal and without --yes it
refuses to arm), flies with the live guard, and prints the flight's log folder at the end (--json:
the summary).
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

from flighttest.console import console, err_console, print_json
from flighttest.errors import FlighttestError
from flighttest.flying.mission_scripts import MISSIONS, search_dirs


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("fly", help="fly a mission or trajectory file in offboard with the live VRS guard",
                       description=__doc__, epilog=missions_epilog(),
                       formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    add_fly_arguments(p)
    p.set_defaults(func=cmd_fly)


def missions_epilog() -> str:
    scripts = ", ".join(f"{m}: {s}.py" for m, s in MISSIONS.items())
    dirs = "\n".join(f"  {d}" for d in search_dirs())
    return (f"named missions ({scripts}) are taken from the first of these folders that has them\n"
            f"(to edit one, copy its script and TOML into the first):\n{dirs}")  # fmt: skip


def add_fly_arguments(p: argparse.ArgumentParser, target: bool = True) -> None:
    if target:
        p.add_argument("target", metavar="probe|helix|vertical|drag|TRAJECTORY_FILE",
                       help="a named mission (see below) or a trajectory file (NAME.csv + NAME.json)")  # fmt: skip
    p.add_argument("--connect", required=True, metavar="URL",
                   help="vehicle link: udpin://0.0.0.0:14540, udpout://HOST:PORT, tcpout://HOST:PORT, serial://DEV:BAUD")
    p.add_argument("--vehicle", required=True, metavar="NAME", help="vehicle profile name or .toml path")
    p.add_argument("--config", type=Path, metavar="TOML",
                   help="mission config (default: a named mission's own TOML; a trajectory file: the defaults "
                        "of flighttest.flying.missions_config)")  # fmt: skip
    defaults = mission_defaults()
    p.add_argument("--height", type=float, metavar="H",
                   help=f"start height above home in m (overrides the config; {defaults['height']})")
    p.add_argument("--descent", type=float, metavar="M",
                   help=f"how far down from the start height in m (overrides the config; {defaults['descent']}); "
                        "at most the start height minus the altitude floor; not for a trajectory file, whose "
                        "descent is in the file")  # fmt: skip
    p.add_argument("--min-alt", type=float, metavar="M", help="altitude floor in m (overrides the config)")
    p.add_argument("--geofence-radius", type=float, metavar="R", help="horizontal room around the start in m")
    p.add_argument("--max-descent-speed", type=float, metavar="MPS",
                   help="probe only: top descent speed of the sweep in m/s (default: the config's "
                        "max_descent_mps, else max_descent_ratio × the profile's w_allow)")  # fmt: skip
    p.add_argument("--wind-ned", type=float, nargs=3, metavar=("N", "E", "D"),
                   help="the wind measured on the ground, m/s NED (the velocity of the air): a prior the guard "
                        "fuses with the autopilot's own estimate, if it reports one")  # fmt: skip
    p.add_argument("--wind-sd", type=float, metavar="MPS",
                   help="how far off --wind-ned may be at the vehicle's height, 1 σ in m/s (default 1.0: shear and "
                        "gusts); the guard judges the worst air within 2.45 σ")  # fmt: skip
    p.add_argument("--sysid", type=int, metavar="N", help="system id of the autopilot to fly when several answer")
    p.add_argument("--yes", action="store_true", help="skip the go/no-go prompt")
    p.add_argument("--dry-run", action="store_true", help="connect, plan and check; do not arm")
    p.add_argument("--no-land", action="store_true", help="end in Hold at the end point instead of landing")
    p.add_argument("--log-dir", metavar="DIR",
                   help="root folder of flight logs (default $FLIGHTTEST_LOG_DIR, else logs/)")  # fmt: skip
    p.add_argument("--json", action="store_true", help="print the flight summary as JSON")


def mission_defaults() -> dict[str, str]:
    """The named missions' start heights and descents as their TOMLs set them, for ``--help``
    (``height``: "probe 8 m, helix 7 m, vertical 5 m"; a config that does not load says so)."""
    from flighttest.flying.mission_scripts import mission_config_path
    from flighttest.flying.missions_config import DESCENT_KEYS, FlightConfig, load_mission_config

    heights, descents = [], []
    for mission in MISSIONS:
        try:
            cfg = load_mission_config(mission_config_path(mission))
        except (FlighttestError, OSError):
            heights.append(f"{mission}: its config does not load")
            continue
        heights.append(f"{mission} {cfg.flight.start_height_m:g} m")
        if mission not in DESCENT_KEYS:  # the drag calibration flies level
            continue
        depth = cfg.plan.get(DESCENT_KEYS[mission])
        what = " (sweep depth)" if mission == "probe" else ""
        descents.append(f"{mission} {depth:g} m{what}" if depth is not None else f"{mission}: its script's default")
    heights.append(f"a trajectory file {FlightConfig().start_height_m:g} m")
    return {"height": "by default " + ", ".join(heights), "descent": "by default " + ", ".join(descents)}


# the options' names in messages (the library names its keywords: flighttest.flying.mission)
OPTION_NAMES = {"height_m": "--height", "descent_m": "--descent", "min_alt_m": "--min-alt",
                "geofence_radius_m": "--geofence-radius", "max_descent_mps": "--max-descent-speed",
                "sysid": "--sysid", "wind_ned_mps": "--wind-ned", "wind_sd_mps": "--wind-sd",
                "log_dir": "--log-dir"}  # fmt: skip


def build_request(args: argparse.Namespace, mission: str | None = None, module: ModuleType | None = None):
    """The command line → ``flighttest.flying.mission.prepare_flight`` → ``FlyRequest``."""
    from flighttest.flying.mission import prepare_flight

    return prepare_flight(
        mission or args.target, connect=args.connect, vehicle=args.vehicle, config=args.config,
        height_m=args.height, descent_m=args.descent, min_alt_m=args.min_alt,
        geofence_radius_m=args.geofence_radius, max_descent_mps=args.max_descent_speed, land=not args.no_land,
        wind_ned_mps=tuple(args.wind_ned) if args.wind_ned else None, wind_sd_mps=args.wind_sd,
        sysid=args.sysid, log_dir=args.log_dir, yes=args.yes, dry_run=args.dry_run, confirm=confirm_go,
        print_fn=(err_console.print if args.json else console.print),
        show_panel=console.is_terminal and not args.json, module=module, names=OPTION_NAMES,
    )  # fmt: skip


def confirm_go(pre) -> bool:
    from rich.prompt import Confirm

    warn = [c for c in pre.checks if c.status == "warn"]
    if warn:
        console.print(f"[yellow]{len(warn)} warning(s): {', '.join(c.name for c in warn)}[/]")
    return Confirm.ask("[bold]GO: arm and fly?[/]", default=False)


def run_request(req, as_json: bool) -> int:
    from flighttest.flying.outcome import Outcome
    from flighttest.flying.runner import fly

    out = asyncio.run(fly(req))
    summary = out.summary()
    if as_json:
        print_json({**summary, "error": out.abort_reason} if out.outcome == Outcome.REFUSED else summary)
    elif out.outcome != Outcome.REFUSED:  # a refusal is the one error line below, on stderr
        colour = {Outcome.COMPLETED: "green", Outcome.DRY_RUN: "green", Outcome.PROBE_STOPPED: "yellow"}.get(
            out.outcome, "red")
        line = f"[{colour}]{out.outcome}[/]"
        if out.abort_reason:
            line += f": {out.abort_reason}"
        if out.descent_time_s is not None:
            off = out.extra.get("horizontal_error_m")
            side = f", {off:.2f} m off sideways" if off is not None else ""
            line += f"  (descent {out.descent_time_s:.2f} s{side})"
        h2h, ratio = out.extra.get("hover_to_hover_s"), out.extra.get("flown_over_optimum")
        if h2h is not None:
            line += f"  hover to hover {h2h:.2f} s" + (f", {ratio:.2f}× the optimum" if ratio is not None else "")
        console.print(line)
        if out.log_dir:
            console.print(f"log: {out.log_dir}")
    if out.outcome == Outcome.REFUSED:
        exc = FlighttestError(out.abort_reason or "refused")
        exc.json_printed = as_json  # type: ignore[attr-defined]  (stdout already holds the summary)
        raise exc
    if out.exit_code and not as_json:
        print(f"flighttest: aborted: {out.abort_reason}", file=sys.stderr)
    return out.exit_code


def json_failure(exc: FlighttestError, as_json: bool, **extra: Any) -> None:
    """With ``--json`` stdout is JSON in every outcome: a refusal prints ``{"error", "outcome", ...}``
    (once; ``json_printed`` tells the CLI's own handler it is done), the error line still goes to stderr."""
    if as_json and not getattr(exc, "json_printed", False):
        print_json({"error": str(exc), "outcome": "refused" if exc.exit_code == 2 else "failed", **extra})
        exc.json_printed = True  # type: ignore[attr-defined]


def cmd_fly(args: argparse.Namespace) -> int:
    try:
        return run_request(build_request(args), args.json)
    except FlighttestError as exc:
        json_failure(exc, args.json)
        raise


def mission_main(mission: str, module: ModuleType, argv: list[str] | None = None) -> int:
    """Entry point of the mission scripts (``python vertical_descent.py``): the options of ``flighttest fly``."""
    from flighttest.inputs import ArgumentParser

    p = ArgumentParser(prog=f"{MISSIONS[mission]}.py", description=module.__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    add_fly_arguments(p, target=False)
    as_json = "--json" in (sys.argv[1:] if argv is None else argv)
    try:
        args = p.parse_args(argv)
        args.target = mission
        return run_request(build_request(args, mission, module), args.json)
    except FlighttestError as exc:
        json_failure(exc, as_json)
        print(f"flighttest: error: {exc}", file=sys.stderr)
        return exc.exit_code
