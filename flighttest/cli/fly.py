"""``flighttest fly probe|helix|vertical|TRAJECTORY_FILE --connect URL --vehicle NAME``.

The three named missions are mission scripts, each with its TOML config beside it (the user's
copies first, else the shipped ones: see the end of ``--help``); a trajectory file is flown as
planned. Prints the preflight table, asks go/no-go (``--yes`` skips it; without a terminal and
without ``--yes`` it refuses to arm), flies with the live guard, and prints the flight's log folder
at the end (``--json``: the summary).
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

from flighttest.console import console, err_console, print_json
from flighttest.errors import FlighttestError
from flighttest.flying.mission_scripts import MISSIONS, load_mission_module, search_dirs


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
        p.add_argument("target", metavar="probe|helix|vertical|TRAJECTORY_FILE",
                       help="a named mission (see below) or a trajectory file (NAME.csv + NAME.json)")  # fmt: skip
    p.add_argument("--connect", required=True, metavar="URL",
                   help="vehicle link: udpin://0.0.0.0:14540, udpout://HOST:PORT, tcpout://HOST:PORT, serial://DEV:BAUD")
    p.add_argument("--vehicle", required=True, metavar="NAME", help="vehicle profile name or .toml path")
    p.add_argument("--config", type=Path, metavar="TOML", help="mission config (default: the mission's own TOML)")
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
                   help="wind in m/s NED for the guard when the vehicle reports none (default 0 0 0)")
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
    from flighttest.flying.missions_config import DESCENT_KEYS, load_mission_config

    heights, descents = [], []
    for mission in MISSIONS:
        try:
            cfg = load_mission_config(mission_config_path(mission))
        except (FlighttestError, OSError):
            heights.append(f"{mission}: its config does not load")
            continue
        heights.append(f"{mission} {cfg.flight.start_height_m:g} m")
        depth = cfg.plan.get(DESCENT_KEYS[mission])
        what = " (sweep depth)" if mission == "probe" else ""
        descents.append(f"{mission} {depth:g} m{what}" if depth is not None else f"{mission}: its script's default")
    return {"height": "by default " + ", ".join(heights), "descent": "by default " + ", ".join(descents)}


def with_descent(cfg, descent_m: float | None, target: str):
    """The config with ``--descent`` applied (``missions_config.DESCENT_KEYS``), refused for a trajectory
    file (and a helix config flying a planned file): their descent is in the file."""
    from flighttest.flying.missions_config import DESCENT_KEYS

    if descent_m is None:
        return cfg
    if cfg.mission not in DESCENT_KEYS:
        raise FlighttestError(
            f"--descent does not apply to a trajectory file ({target}): its descent is in the file "
            "(plan another with `flighttest plan ... --height M`, or fly a named mission)"
        )
    if cfg.plan.get("trajectory"):
        raise FlighttestError(f"--descent does not apply: {cfg.path or 'the config'} flies the planned file "
                              f"{cfg.plan['trajectory']!r}, whose descent is in the file")  # fmt: skip
    return dataclasses.replace(cfg, plan={**cfg.plan, DESCENT_KEYS[cfg.mission]: float(descent_m)})


def check_room(cfg) -> None:
    """The mission's descent fits between its start height and the altitude floor (one line, exit 2,
    before anything connects)."""
    from flighttest.flying.missions_config import DESCENT_KEYS

    fl = cfg.flight
    if fl.start_height_m <= fl.min_alt_m:
        raise FlighttestError(f"start height {fl.start_height_m:g} m must exceed the altitude floor {fl.min_alt_m:g} m")
    key = DESCENT_KEYS.get(cfg.mission)
    depth = cfg.plan.get(key) if key and not cfg.plan.get("trajectory") else None
    room = fl.start_height_m - fl.min_alt_m
    if depth is not None and depth > room + 1e-9:
        raise FlighttestError(
            f"the {cfg.mission} mission's descent of {depth:g} m from {fl.start_height_m:g} m goes below the "
            f"altitude floor {fl.min_alt_m:g} m: at most {room:g} m (set --descent, --height or --min-alt)"
        )


def _check_numbers(args: argparse.Namespace) -> None:
    """Every number of the command line within its physical range (``flighttest.inputs``), before
    any file is read or anything connects."""
    from flighttest import inputs as ip

    checks = (("--height", args.height, ip.START_HEIGHT_M), ("--descent", args.descent, ip.HEIGHT_M),
              ("--min-alt", args.min_alt, ip.ALTITUDE_FLOOR_M),
              ("--geofence-radius", args.geofence_radius, ip.DISTANCE_M),
              ("--max-descent-speed", args.max_descent_speed, ip.SPEED_MPS),
              ("--sysid", args.sysid, ip.SYSID))  # fmt: skip
    for name, value, rng in checks:
        if value is not None:
            rng.check(value, name)
    for axis, w in zip("NED", args.wind_ned or ()):
        ip.WIND_MPS.check(w, f"--wind-ned {axis}")


def log_root(text: str | None) -> Path:
    """The root folder of flight logs (``--log-dir``, else ``$FLIGHTTEST_LOG_DIR``, else ``logs``), checked
    before anything connects: a folder there must be possible. Nothing is created here."""
    import os

    if text is None:
        env = os.environ.get("FLIGHTTEST_LOG_DIR")
        name, text = "$FLIGHTTEST_LOG_DIR", (env if env is not None else "logs")
    else:
        name = "--log-dir"
    from flighttest.inputs import check_output_folder

    return check_output_folder(text, name)


def build_request(args: argparse.Namespace, mission: str | None = None, module: ModuleType | None = None):
    """Profile, config (file + command-line overrides), trajectory → ``FlyRequest``."""
    from flighttest.flying.link import check_connection, check_url
    from flighttest.flying.missions_config import MissionConfig, load_mission_config
    from flighttest.flying.runner import FlyRequest, check_duration
    from flighttest.model.profiles import load_profile
    from flighttest.model.trajectory import Trajectory

    check_url(args.connect)
    _check_numbers(args)
    root = log_root(args.log_dir)
    profile = load_profile(args.vehicle)
    target = mission or args.target
    if module is None and target in MISSIONS:
        module = load_mission_module(target)
    if module is not None:
        cfg = load_mission_config(args.config or module.CONFIG)
    elif args.config is not None:
        cfg = load_mission_config(args.config)
    else:
        cfg = MissionConfig("file")
    overrides = {}
    if args.height is not None:
        overrides["start_height_m"] = args.height
    if args.min_alt is not None:
        overrides["min_alt_m"] = args.min_alt
    if args.geofence_radius is not None:
        overrides["geofence_radius_m"] = args.geofence_radius
    if args.no_land:
        overrides["land"] = False
    if overrides:
        cfg = cfg.with_flight(**overrides)
    if args.max_descent_speed is not None:
        if cfg.mission != "probe":
            raise FlighttestError("--max-descent-speed applies to the probe mission only")
        cfg = dataclasses.replace(cfg, plan={**cfg.plan, "max_descent_mps": args.max_descent_speed})
    cfg = with_descent(cfg, args.descent, str(target))
    check_room(cfg)
    if module is not None:
        try:
            traj = module.plan(profile, cfg)
        except FlighttestError:
            raise
        except Exception as exc:  # the plan follows from the profile and the config alone: they are at fault
            where = cfg.path or "its config"
            raise FlighttestError(f"cannot plan the {cfg.mission} mission from {where}: {exc}") from None
        name, traj_path = cfg.mission, ""
    else:
        traj = Trajectory.load(args.target, profile)
        name, traj_path = Path(args.target).stem, str(args.target)
    check_duration(traj, f"trajectory {traj_path}" if traj_path else f"the {name} mission's trajectory")
    check_connection(args.connect)  # last: it may wait a moment for a host name to resolve
    return FlyRequest(
        connect=args.connect, profile=profile, config=cfg, trajectory=traj, mission_name=name,
        trajectory_path=traj_path, sysid=args.sysid, yes=args.yes, dry_run=args.dry_run,
        wind_ned_mps=tuple(args.wind_ned) if args.wind_ned else None,
        log_root=root, show_panel=console.is_terminal and not args.json,
        confirm=confirm_go, print_fn=(err_console.print if args.json else console.print),
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
    else:
        colour = {Outcome.COMPLETED: "green", Outcome.DRY_RUN: "green", Outcome.PROBE_STOPPED: "yellow"}.get(
            out.outcome, "red")
        line = f"[{colour}]{out.outcome}[/]"
        if out.abort_reason:
            line += f": {out.abort_reason}"
        if out.descent_time_s is not None:
            off = out.extra.get("horizontal_error_m")
            side = f", {off:.2f} m off sideways" if off is not None else ""
            line += f"  (descent {out.descent_time_s:.2f} s{side})"
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
