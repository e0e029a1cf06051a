"""flighttest campaign: the field day, end to end, in one folder.

  probe     fly the sine-sweep VRS probe (stopped by the fluctuation detector)
  identify  find the VRS onset in its log; store it as w_allow in DIR/vehicles/NAME.toml
  plan      plan the vertical baseline and the helix with that boundary (DIR/plans/)
  vertical  fly the vertical baseline with the live guard
  helix     fly the helix with the live guard
  report    descent times side by side, exposure, figures: DIR/report/summary.md

Before each step it says what comes next and asks to go on (--yes: it does not ask; each flight also
asks its own GO after the preflight checks). Run the same command again to resume after a stop, an
abort or Ctrl-C: steps already done are not flown again. --only STEP runs one step again from the
files of the earlier ones (e.g. --only plan after editing DIR/config/helix_descent.toml, then
--only helix); --from STEP runs it and everything after.

  flighttest campaign --sim --yes -o logs/campaign                 # ground rehearsal on the fake
  flighttest campaign --sim --yes -o logs/build-up --build-up 3    # each descent up to 3 times, narrower each time
  flighttest campaign --vehicle x500 --connect udpin://0.0.0.0:14540 -o logs/2026-12-01-field
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import sys
from typing import TYPE_CHECKING

from rich.table import Table

from flighttest.campaign.state import FLIGHT_STEPS, STEPS, CampaignOutcome
from flighttest.console import console, err_console, print_json
from flighttest.errors import FlighttestError
from flighttest.inputs import Range, shown

if TYPE_CHECKING:
    from pathlib import Path

    from rich.console import Console

    from flighttest.campaign.run import Campaign, SimOptions


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("campaign", help="the whole field day: probe, identify, plan, fly vertical and helix, report",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    link = p.add_mutually_exclusive_group(required=True)
    link.add_argument("--connect", metavar="URL",
                      help="the vehicle: serial:///dev/ttyAMA0:921600 (a companion on TELEM2), udpin://0.0.0.0:14540 "
                      "(PX4 SITL), udpout://127.0.0.1:14580 (flighttest sim), …")  # fmt: skip
    link.add_argument("--sim", action="store_true", help="fly the built-in fake vehicle (started and stopped here)")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="the campaign's folder")
    p.add_argument("--vehicle", metavar="NAME", help="vehicle profile name or .toml path (with --sim default x500)")
    _add_common(p)
    steps = p.add_mutually_exclusive_group()
    steps.add_argument("--only", choices=STEPS, metavar="STEP", help=f"run just this step ({', '.join(STEPS)})")
    steps.add_argument("--from", dest="start", choices=STEPS, metavar="STEP", help="run this step and all after it")
    p.set_defaults(func=cmd_campaign)

    d = sub.add_parser("demo", help="= campaign --sim --yes -o logs/demo-<time>: the whole job on the fake",
                       description="The whole campaign against the built-in fake vehicle, without prompts "
                       "(flighttest campaign --sim --yes).")  # fmt: skip
    d.add_argument("-o", "--output", metavar="DIR", help="the campaign's folder (default logs/demo-<time>)")
    d.add_argument("--vehicle", metavar="NAME", default="x500", help="vehicle profile (default x500)")
    _add_common(d)
    d.set_defaults(func=cmd_demo)


def _add_common(p: argparse.ArgumentParser) -> None:
    from flighttest.campaign.rehearsal import sim_param_help

    p.add_argument("--yes", action="store_true", help="do not ask before each step and each flight")
    p.add_argument("--stale-periods", type=float, metavar="N",
                   help="stale-telemetry allowance in telemetry periods (default: the mission configs' "
                   "stale_after_s, 0.25 s); "
                   "raise it only when rehearsing on a heavily loaded machine")  # fmt: skip
    p.add_argument("--build-up", type=BUILD_UP, default=1, metavar="N",
                   help="fly the vertical baseline and the helix up to N times each, every flight's margin narrowed "
                   "by what the earlier ones proved; stops at the floor, on any word from the guard, or when the "
                   "time stops improving, and keeps the fastest clean flight (default 1: one flight each; "
                   "[build_up] in the mission configs)")  # fmt: skip
    p.add_argument("--json", action="store_true", help="print the campaign summary as JSON (progress on stderr)")
    g = p.add_argument_group("the fake vehicle (--sim)")
    g.add_argument("--truth-onset", type=float, metavar="MPS",
                   help="the fake's true VRS onset descent rate (default: Onera's for its profile)")  # fmt: skip
    g.add_argument("--sim-wind", type=float, nargs=3, metavar=("N", "E", "D"), help="the fake's wind, m/s NED")
    g.add_argument("--sim-seed", type=int, metavar="N", help="seed of the fake's fluctuations and gusts")
    g.add_argument("--sim-param", action="append", default=[], metavar="NAME=VALUE", help=sim_param_help())
    g.add_argument("--sim-autopilot", choices=("px4", "ardupilot"), default="px4",
                   help="the fake's personality: PX4 (default) or ArduCopter (GUIDED, BRAKE, its parameters, "
                   "its EKF's 42 s start-up; fly it with --vehicle arducopter_sitl)")  # fmt: skip


def cmd_demo(args: argparse.Namespace) -> int:
    from flighttest.flying.log_writer import default_log_root

    args.sim, args.connect, args.only, args.start, args.yes = True, None, None, None, True
    args.output = args.output or str(default_log_root() / f"demo-{dt.datetime.now():%Y%m%d-%H%M%S}")
    return cmd_campaign(args)


# the stale-telemetry allowance: 1 period is the field's tightest; beyond 50 (1 s at 50 Hz) the
# guard would fly on for a second without knowing where the vehicle is
STALE_PERIODS = Range(1.0, 50.0, "telemetry periods")
SEED = Range(0, 2**32 - 1, integer=True)  # what the fake's random generator takes
BUILD_UP = Range(1, 20, integer=True)  # flights per descent; 20 is a long day already


def _validate(args: argparse.Namespace) -> SimOptions | None:
    """Every input checked before the fake starts or anything connects; returns the fake's options
    (None with --connect)."""
    from flighttest import inputs as ip
    from flighttest.campaign.rehearsal import SIM_DEFAULT_PARAMS, SIM_DEFAULT_PARAMS_ARDUPILOT
    from flighttest.campaign.run import SimOptions
    from flighttest.flying.link import check_connection, check_url

    if args.connect is not None:  # an empty URL is a link asked for, and refused by check_url
        check_url(args.connect)
        if not args.vehicle:
            raise FlighttestError("--vehicle is required with --connect (the profile of the aircraft you fly)")
        if (args.truth_onset is not None or args.sim_wind or args.sim_seed is not None or args.sim_param
                or args.sim_autopilot != "px4"):  # fmt: skip
            raise FlighttestError("--truth-onset, --sim-wind, --sim-seed, --sim-param and --sim-autopilot need --sim")
    if args.stale_periods is not None:
        STALE_PERIODS.check(args.stale_periods, "--stale-periods")
    if args.truth_onset is not None:
        ip.W_ALLOW_POSITIVE_MPS.check(args.truth_onset, "--truth-onset")
    for axis, w in zip("NED", args.sim_wind or ()):
        ip.WIND_MPS.check(w, f"--sim-wind {axis}")
    if args.sim_seed is not None:
        SEED.check(args.sim_seed, "--sim-seed")
    ardupilot = args.sim_autopilot == "ardupilot"
    params: dict[str, float] = dict(SIM_DEFAULT_PARAMS_ARDUPILOT if ardupilot else SIM_DEFAULT_PARAMS)
    for item in args.sim_param:
        name, value = _sim_param(item, ardupilot)
        params[name] = value
    if args.connect is not None:
        check_connection(args.connect)  # last: a host name may take a moment to resolve
        return None
    wind = tuple(args.sim_wind) if args.sim_wind else None
    return SimOptions(truth_onset_mps=args.truth_onset, wind_ned_mps=wind, seed=args.sim_seed, params=params,
                      autopilot=args.sim_autopilot)  # fmt: skip


def _output_dir(text: str | Path) -> Path:
    """``-o DIR`` as a folder the campaign can live in, checked before anything is written (an empty
    name would be the current folder; a file, or a folder under a file, cannot hold a campaign)."""
    from flighttest.inputs import check_output_folder

    return check_output_folder(text, "-o")


def _sim_param(item: str, ardupilot: bool = False) -> tuple[str, float]:
    """``NAME=NUMBER`` for a parameter the fake has (its start would fail on any other, after the
    campaign had begun), integer parameters as integers."""
    from sitl_fakes import ardupilot as ap
    from sitl_fakes import px4

    name, sep, value = item.partition("=")
    name, value = name.strip(), value.strip()
    if ardupilot:
        known = {k: p.type in ap.INT_TYPES for k, p in ap.default_params().items()}
        where = "sitl_fakes/ardupilot.py"
    else:
        known = {k: p.type == px4.PARAM_INT32 for k, p in px4.default_params().items()}
        where = "sitl_fakes/px4.py"
    if not sep or not name:
        raise FlighttestError(f"--sim-param must be NAME=NUMBER (got {shown(item)})")
    if name not in known:
        raise FlighttestError(f"--sim-param {shown(name)}: not a parameter of the fake (see {where})")
    try:
        number = int(value, 10) if known[name] else float(value)
    except ValueError:
        kind = "a whole number" if known[name] else "a number"
        raise FlighttestError(f"--sim-param {name}: must be {kind} (got {shown(value)})") from None
    # the bound first: a whole number of 400 digits has no float for isfinite (OverflowError)
    if not (abs(number) <= 1e6 and math.isfinite(number)):  # no PX4 parameter the fake has goes beyond
        raise FlighttestError(f"--sim-param {name}: must be a finite number of at most 1e6 (got {shown(value)})")
    return name, number


class CampaignFailed(FlighttestError):
    """An unexpected error inside a step: one line (the step is marked failed in campaign.json)."""

    exit_code = 1


def cmd_campaign(args: argparse.Namespace) -> int:
    """The campaign; with ``--json`` stdout is JSON whatever happens: the summary, or — once a step has
    begun — the summary so far with the failure (``error``, ``outcome``, ``failed_step``), or a refusal
    before anything started (``{"error", "outcome", "out_dir"}``)."""
    from flighttest.cli.fly import json_failure

    campaign: Campaign | None = None  # once open: a stop after its record is written prints the summary so far
    try:
        campaign = _open(args)
        return _run(args, campaign)
    except FlighttestError as exc:
        outcome = CampaignOutcome.REFUSED if exc.exit_code == 2 else CampaignOutcome.FAILED
        if _json_stop(args, campaign, str(exc), outcome):
            exc.json_printed = True  # type: ignore[attr-defined]
        json_failure(exc, args.json, out_dir=str(args.output))
        raise
    except KeyboardInterrupt:
        error = "interrupted by the operator"
        if args.json and not _json_stop(args, campaign, error, CampaignOutcome.INTERRUPTED):
            print_json({"error": error, "outcome": CampaignOutcome.INTERRUPTED, "out_dir": str(args.output)})
        raise
    except Exception as exc:  # a bug or a library's surprise: one line, the details in campaign.json
        err = CampaignFailed(f"campaign stopped by an unexpected error: {type(exc).__name__}: {exc}")
        if _json_stop(args, campaign, str(err), CampaignOutcome.FAILED):
            err.json_printed = True  # type: ignore[attr-defined]
        json_failure(err, args.json, out_dir=str(args.output))
        raise err from exc


def _json_stop(args: argparse.Namespace, campaign: Campaign | None, error: str, outcome: CampaignOutcome) -> bool:
    """With ``--json`` once steps have begun: print the summary so far with the failure; False when
    there is nothing to summarise yet (the caller prints the refusal)."""
    if not args.json or campaign is None or not campaign.started:
        return False
    try:
        doc = campaign.summary_so_far()
    except Exception as exc:  # the summary must never hide the failure it reports
        doc = {"out_dir": str(args.output), "summary_error": f"{type(exc).__name__}: {exc}"}
    doc.update(error=error, outcome=outcome, failed_step=campaign.current_step)
    print_json(doc)
    return True


def _open(args: argparse.Namespace) -> Campaign:
    """The campaign the arguments ask for, every input checked before anything is written or connects
    (arguments and link first, then the profile, the folder and its record: one error line for the first)."""
    from flighttest.campaign.run import Campaign, CampaignRequest
    from flighttest.model.profiles import load_profile

    sim = _validate(args)
    vehicle = args.vehicle or "x500"
    profile = load_profile(vehicle)
    request = CampaignRequest(out_dir=_output_dir(args.output), vehicle=vehicle, connect=args.connect, sim=sim,
                              only=args.only, start=args.start, yes=args.yes, stale_periods=args.stale_periods,
                              build_up=args.build_up, show_panel=_out(args).is_terminal and not args.json)  # fmt: skip
    campaign = Campaign.open(request, profile)
    # refused before anything is written: a campaign that cannot start leaves no folder behind
    if campaign.steps and not args.yes and not sys.stdin.isatty():
        raise FlighttestError("no terminal to confirm each step: pass --yes to run the campaign unattended")
    return campaign


def _out(args: argparse.Namespace) -> Console:
    """Progress goes to stderr under --json: stdout holds the JSON only."""
    return err_console if args.json else console


def _run(args: argparse.Namespace, campaign: Campaign) -> int:
    from flighttest.campaign.run import CampaignHooks
    from flighttest.cli.fly import confirm_go

    out = _out(args)
    hooks = CampaignHooks(say=out.print, heading=out.rule, step_heading=lambda text: out.rule(text, align="left"),
                          busy=out.status, ask_step=None if args.yes else _ask, confirm_flight=confirm_go)  # fmt: skip
    result = campaign.run(hooks)
    if result.stopped_before:
        _json_stop(args, campaign, f"stopped before '{result.stopped_before}' by the operator", CampaignOutcome.STOPPED)
        return 1
    return _final(campaign, args.json, out)


def _ask(step: str) -> bool:
    from rich.prompt import Confirm

    return Confirm.ask(f"[bold]go on with '{step}'?[/]", default=step not in FLIGHT_STEPS)


def _final(campaign: Campaign, as_json: bool, out: Console) -> int:
    from flighttest.campaign.run import clock_text
    from flighttest.campaign.summary import headlines, table_rows

    state = campaign.state
    if not state.done("report"):
        if as_json:  # the summary so far: its keys, what campaign.json knows, and each step's status
            print_json(campaign.summary_so_far())
        else:
            out.print("steps: " + ", ".join(f"{s} {state.steps[s].status}" for s in STEPS))
            out.print("no report yet: run the campaign again (without --only) to finish")
        return 0
    summary = campaign.summary()
    if as_json:
        print_json(summary)
        return 0
    t = Table(title=f"campaign summary — {summary['vehicle']} — paste into the test report", title_justify="left")
    t.add_column("")
    t.add_column("vertical baseline", justify="right")
    t.add_column("helix", justify="right")
    for row in table_rows(summary):
        t.add_row(*row)
    out.print(t)
    for line in headlines(summary):
        out.print(line)
    took = ", ".join(f"{s} {clock_text(v)}" for s, v in summary["steps_elapsed_s"].items() if v is not None)
    out.print(f"[dim]step times: {took}[/]")
    out.print(f"report: [bold]{state.dir.report / 'summary.md'}[/]")
    return 0
