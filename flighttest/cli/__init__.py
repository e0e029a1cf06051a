"""The ``flighttest`` command: one sub-command module per capability, each with ``register()``."""

from __future__ import annotations

import argparse
import sys

from flighttest import __version__
from flighttest.errors import FlighttestError

DESCRIPTION = """\
flighttest: fast-descent flight tests that avoid the vortex ring state (VRS) and the windmill-brake
state (WBS) on quadcopters (Talaeizadeh et al., arXiv:1909.09069; docs/PAPER.md). Plan minimum-time
descents, fly them in PX4 offboard (or ArduCopter GUIDED) with a live blade-frame VRS guard, probe the
VRS onset with a sine sweep, and analyse the logs.
"""

EPILOG = """\
start here:
  flighttest campaign --sim --yes -o logs/campaign
                                          the whole field day end to end against the built-in fake vehicle
  flighttest campaign --vehicle NAME --connect URL -o DIR
                                          ... and on the real aircraft (asks before each step)
  flighttest vehicle list                 shipped and user vehicle profiles
  flighttest region chart --vehicle x500 -o chart.png
every command that reports numbers takes --json; bad input exits with code 2 and one error line.
"""


def build_parser() -> argparse.ArgumentParser:
    from flighttest.cli import analysis, campaign, fly, params, plan, region, sim, vehicle
    from flighttest.inputs import ArgumentParser

    # flighttest.inputs.ArgumentParser (one-line errors, negative numbers in any notation); the
    # sub-commands' parsers are of the same class
    parser = ArgumentParser(
        prog="flighttest",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"flighttest {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in (campaign, vehicle, region, plan, sim, fly, params, analysis):
        module.register(sub)
    return parser


def _wants_json(argv: list[str]) -> bool:
    """``--json`` among the options (before a ``--``), known before parsing: a refused command line
    must answer in JSON too."""
    words = argv[: argv.index("--")] if "--" in argv else argv
    return "--json" in words


def _tolerant_stdout() -> None:
    """A file name's bytes that are not UTF-8 (Python keeps them as surrogates) are written back as the bytes
    they were, as Python does under the C locale: under a UTF-8 locale such as en_US.UTF-8 stdout is strict,
    and printing such a log's name ended the command in a UnicodeEncodeError."""
    out = sys.stdout
    if getattr(out, "errors", None) == "strict" and hasattr(out, "reconfigure"):
        out.reconfigure(errors="surrogateescape")


def main(argv: list[str] | None = None) -> int:
    from flighttest import console

    argv = list(sys.argv[1:] if argv is None else argv)
    _tolerant_stdout()
    as_json = _wants_json(argv)
    console.json_printed = False
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if not getattr(args, "func", None):
            parser.print_help()
            return 2
        as_json = bool(getattr(args, "json", as_json))
        return int(args.func(args) or 0)
    except FlighttestError as exc:
        # with --json stdout is JSON in every outcome: {"error"} unless the command printed its own
        # failure object already
        if as_json and not console.json_printed and not getattr(exc, "json_printed", False):
            console.print_json({"error": str(exc)})
        print(f"flighttest: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("flighttest: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
