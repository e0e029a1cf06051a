"""``flighttest params save|apply|restore``: a vehicle's parameters to a file and back, as QGroundControl does."""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from pathlib import Path

from rich import box
from rich.table import Table

from flighttest.console import console, print_json
from flighttest.errors import FlighttestError

EPILOG = """\
a flight-test day:
  flighttest params save --connect URL -o before.params      everything the vehicle holds now
  flighttest params apply test-day.params --connect URL      shows each change, asks, keeps a backup
  ... fly ...
  flighttest params restore before.params --connect URL      back to what it was

Files are QGroundControl's parameter files (Mission Planner's NAME,value lines load too). Parameters are
never changed on an armed vehicle. Exit code 2 and one error line for a bad file or a name the vehicle
does not have (nothing is applied), 1 when the vehicle did not take a value.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("params", help="save a vehicle's parameters to a file, apply a file, restore the saved",
                       description=__doc__, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    psub = p.add_subparsers(dest="params_command", metavar="ACTION", required=True)
    ps = psub.add_parser("save", help="every parameter of the vehicle into a QGroundControl parameter file")
    ps.add_argument("-o", "--output", type=Path, metavar="FILE",
                    help="the file to write (default vehicle-<date>-<time>.params)")  # fmt: skip
    _link_args(ps)
    ps.set_defaults(func=cmd_save)
    for name, what in (("apply", "set the parameters of a file that differ on the vehicle (shows them, asks first)"),
                       ("restore", "set the vehicle back to a file `params save` (or apply's backup) wrote")):
        pa = psub.add_parser(name, help=what, description=what)
        pa.add_argument("file", type=Path, metavar="FILE", help="QGroundControl parameter file")
        pa.add_argument("--yes", action="store_true", help="no question: apply the changes shown")
        pa.add_argument("--backup", type=Path, metavar="FILE",
                        help="where the vehicle's values of the parameters about to change are saved first "
                             + ("(default params-before-<date>-<time>.params; restore it afterwards)"
                                if name == "apply" else "(default: none)"))  # fmt: skip
        _link_args(pa)
        pa.set_defaults(func=cmd_apply, action_name=name)


def _link_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--connect", required=True, metavar="URL",
                   help="vehicle link: udpin://0.0.0.0:14540, udpout://HOST:PORT, tcpout://HOST:PORT, serial://DEV:BAUD")
    p.add_argument("--sysid", type=int, metavar="N", help="system id of the autopilot when several answer")
    p.add_argument("--json", action="store_true", help="machine-readable output")


def _stamp() -> str:
    return time.strftime("%Y%m%d-%H%M%S")


def _check_output(path: Path) -> Path:
    from flighttest.inputs import check_output_path

    return check_output_path(path, "parameter file")


def cmd_save(args: argparse.Namespace) -> int:
    from flighttest.flying.link import check_url
    from flighttest.flying.vehicle_params import save

    check_url(args.connect)
    out = _check_output(args.output or Path(f"vehicle-{_stamp()}.params"))
    res = asyncio.run(save(args.connect, out, args.sysid))
    if args.json:
        print_json(res.record())
    else:
        console.print(f"{res.count} parameters of system {res.sysid} ({res.autopilot or 'autopilot unknown'}) "
                      f"saved to {out}", markup=False, highlight=False)  # fmt: skip
    return 0


def change_table(todo, title: str) -> Table:
    from flighttest.analysis.params import format_value

    t = Table(title=title, box=box.SIMPLE_HEAD, title_justify="left")
    for col in ("parameter", "on the vehicle", "the file's"):
        t.add_column(col, justify="left" if col == "parameter" else "right", no_wrap=True)
    for c in todo:
        t.add_row(c.name, format_value(c.now), format_value(c.new))
    return t


def cmd_apply(args: argparse.Namespace) -> int:
    from flighttest.flying.link import check_url
    from flighttest.flying.params_file import read_params
    from flighttest.flying.vehicle_params import apply

    check_url(args.connect)
    read_params(args.file)  # a bad file: its one error line before anything connects
    backup = args.backup
    if backup is None and args.action_name == "apply":
        backup = Path(f"params-before-{_stamp()}.params")
    if backup is not None:
        backup = _check_output(backup)
    if not args.yes and not sys.stdin.isatty():
        raise FlighttestError("no terminal to ask: pass --yes to apply the changes without the question")

    def show(todo, own) -> None:
        if args.json:
            return
        if own:
            names = ", ".join(own[:6]) + (f" and {len(own) - 6} more" if len(own) > 6 else "")
            console.print(f"left alone: {len(own)} the autopilot keeps itself ({names})", markup=False)
        if not todo:
            console.print(f"{args.file}: the vehicle holds every value already; nothing to change", markup=False)
        else:
            console.print(change_table(todo, f"{len(todo)} parameter(s) to change ({args.file})"))

    def confirm(todo) -> bool:
        from rich.prompt import Confirm

        return Confirm.ask(f"[bold]set these {len(todo)} parameter(s) on the vehicle?[/]", default=False)

    res = asyncio.run(apply(args.connect, args.file, action=args.action_name, backup=backup, sysid=args.sysid,
                            confirm=None if args.yes else confirm, show=show))  # fmt: skip
    if args.json:
        print_json(res.record())
    elif res.declined:
        console.print("declined: nothing changed")
    elif res.changes:
        console.print(f"set {len(res.applied)} of {len(res.changes)}", markup=False)
        if res.backup:
            console.print(f"the values before: {res.backup} (flighttest params restore {res.backup} --connect "
                          f"{args.connect})", markup=False, highlight=False)  # fmt: skip
    for f in res.failed:
        print(f"flighttest: error: {f['name']} not set: {f['why']}", file=sys.stderr)
    return 1 if res.failed else 0
