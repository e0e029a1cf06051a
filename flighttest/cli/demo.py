"""flighttest demo: a whole test campaign, end to end, against the built-in fake vehicle.

It does what a flight-test team does on the field, with the fake PX4 quadcopter of sitl_fakes
standing in for the aircraft (its true VRS onset set independently of what flighttest believes):

1. the vehicle and its velocity-space chart;
2. the sine-sweep VRS probe, stopped by the fluctuation detector, and the identified onset
   stored as the profile's w_allow (in a demo-local profile folder, never your own);
3. the vertical baseline at the measured w_allow and the optimised helix, both with the
   live guard;
4. the analysis: descent times side by side with the speed-up, VRS exposure, and a report with
   plots.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import datetime as dt
import os
import sys
from pathlib import Path
from typing import Any

import tomli_w
from rich.table import Table

from flighttest.console import console, print_json
from flighttest.errors import FlighttestError
from flighttest.profiles import load_profile, write_w_allow
from flighttest.tomlfile import read_toml


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="a whole campaign end to end against the built-in fake vehicle (probe, identify, fly, analyse)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--vehicle", default="x500", help="profile name (default x500)")
    p.add_argument("--truth-onset", type=float, default=None, metavar="MPS",
                   help="the fake's true VRS onset descent rate in m/s (default: its Onera value)")  # fmt: skip
    p.add_argument("--skip-probe", action="store_true", help="fly only the vertical baseline and the helix")
    p.add_argument("--log-dir", type=Path, default=None, metavar="DIR", help="root of flight logs (default logs/)")
    p.add_argument("--stale-periods", type=float, default=None, metavar="N",
                   help="stale-telemetry allowance in telemetry periods (default: the missions' own, 3); "
                   "raise it when rehearsing on a heavily loaded machine")  # fmt: skip
    p.add_argument("--json", action="store_true", help="machine-readable summary (progress goes to stderr)")
    p.set_defaults(func=cmd_demo)


def _mission_config(mission: str, out_dir: Path, stale_periods: float | None) -> Path:
    """A copy of the mission's own TOML for this demo. The vertical baseline descends the same height
    from the same start as the helix, so the two times compare like for like (the paper: 5 m, 8.3 s
    vertical vs 2.5 s helix); ``--stale-periods`` relaxes the stale-telemetry guard on a busy machine."""
    from flighttest.cli.fly import MISSIONS, MISSIONS_DIR

    cfg = read_toml(MISSIONS_DIR / f"{MISSIONS[mission]}.toml", "mission config")
    if mission == "vertical":
        helix = read_toml(MISSIONS_DIR / "helix_descent.toml", "mission config")
        cfg["flight"]["start_height_m"] = helix["flight"]["start_height_m"]
        cfg["plan"]["descent_m"] = helix["plan"]["descent_m"]
    if stale_periods is not None:
        cfg.setdefault("guard", {})["stale_periods"] = stale_periods
    path = out_dir / f"{MISSIONS[mission]}.toml"
    path.write_text(tomli_w.dumps(cfg))
    return path


def _fly(mission: str, url: str, vehicle: str, log_root: Path, config: Path, panel: bool) -> Any:
    """Fly one named mission exactly as ``flighttest fly MISSION --yes`` would."""
    from flighttest.cli.fly import add_fly_arguments, build_request
    from flighttest.mission import fly

    p = argparse.ArgumentParser()
    add_fly_arguments(p)
    argv = [mission, "--connect", url, "--vehicle", vehicle, "--yes", "--log-dir", str(log_root)]
    args = p.parse_args([*argv, "--config", str(config)])
    req = build_request(args)
    req.show_panel = panel and console.is_terminal
    return asyncio.run(fly(req))


def cmd_demo(args: argparse.Namespace) -> int:
    from flighttest.analysis.identify import identify_onset
    from flighttest.analysis.loaders import load_log
    from flighttest.chart import write_chart
    from flighttest.cli import main as cli_main
    from flighttest.flightlog import default_log_root
    from sitl_fakes.launcher import FakeVehicle

    profile = load_profile(args.vehicle)
    if args.stale_periods is not None and not (args.stale_periods >= 1 and args.stale_periods < 1e6):
        raise FlighttestError(f"--stale-periods must be a number ≥ 1 (got {args.stale_periods})")
    log_root = args.log_dir or default_log_root()
    out_dir = log_root / f"demo-{dt.datetime.now():%Y%m%d-%H%M%S}"
    out_dir.mkdir(parents=True, exist_ok=True)
    # Identified boundaries go to a demo-local profile folder, so the demo never edits your profiles.
    os.environ["FLIGHTTEST_VEHICLES"] = str(out_dir / "vehicles")
    summary: dict[str, Any] = {"vehicle": profile.summary(), "out_dir": str(out_dir), "flights": []}
    summary["chart"] = str(write_chart(profile, out_dir / f"chart_{profile.name}.png"))
    if not args.json:
        console.rule(f"[bold]flighttest demo — {profile.name}")
        console.print(f"v_h = {profile.v_h_mps:.2f} m/s, Onera w_allow = {profile.w_allow_mps:.3f} m/s; "
                      f"chart: {summary['chart']}")  # fmt: skip

    fake_opts: dict[str, Any] = {"param": {"MPC_Z_VEL_MAX_DN": 3.0}}
    if args.truth_onset is not None:
        fake_opts["truth_onset"] = args.truth_onset
    ok = True
    with FakeVehicle(vehicle=profile.name, truth_log=out_dir / "fake_truth.csv", **fake_opts) as fake:
        if not args.json:
            console.print(f"fake vehicle: {fake.url} (truth log {out_dir / 'fake_truth.csv'})")
        missions = ["vertical", "helix"] if args.skip_probe else ["probe", "vertical", "helix"]
        for mission in missions:
            if not args.json:
                console.rule(f"[bold]{mission}")
            config = _mission_config(mission, out_dir, args.stale_periods)
            with contextlib.redirect_stdout(sys.stderr) if args.json else contextlib.nullcontext():
                out = _fly(mission, fake.url, profile.name, log_root, config, panel=not args.json)
            flight = out.summary()
            flight["mission"] = mission
            summary["flights"].append(flight)
            if out.exit_code != 0:
                ok = False
                if not args.json:
                    console.print(f"[red]{mission}: {out.outcome}: {out.abort_reason}[/]  log: {out.log_dir}")
                break
            if not args.json:
                line = f"{mission}: [green]{out.outcome}[/]"
                if out.descent_time_s is not None:
                    line += f", descent {out.descent_time_s:.2f} s"
                console.print(f"{line}  log: {out.log_dir}")
            if mission == "probe":
                onset = identify_onset(load_log(out.log_dir), profile)
                path = write_w_allow(profile, onset.w_onset_mps, f"demo probe {Path(out.log_dir).name}")
                profile = load_profile(profile.name)
                summary["identified_w_allow_mps"] = onset.w_onset_mps
                summary["identified_profile"] = str(path)
                if not args.json:
                    console.print(f"identified VRS onset: {onset.w_onset_mps:.3f} m/s "
                                  f"(± {onset.uncertainty_mps:.3f}); stored in {path}")  # fmt: skip
    if ok:
        logs = [f["log_dir"] for f in summary["flights"]]
        report_dir = out_dir / "report"
        # with --json, the nested commands' tables go to stderr so stdout stays one JSON document
        with contextlib.redirect_stdout(sys.stderr) if args.json else contextlib.nullcontext():
            console.rule("[bold]analysis")
            cli_main(["compare", *[d for d, f in zip(logs, summary["flights"]) if f["mission"] != "probe"],
                      "--vehicle", profile.name])  # fmt: skip
            cli_main(["report", *logs, "-o", str(report_dir), "--vehicle", profile.name])
        summary["report"] = str(report_dir)
        times = {f["mission"]: f.get("descent_time_s") for f in summary["flights"]}
        if times.get("vertical") and times.get("helix"):
            summary["speedup_helix_vs_vertical"] = times["vertical"] / times["helix"]
    if args.json:
        print_json(summary)
    else:
        t = Table(title="demo summary", show_header=True)
        for col in ("mission", "outcome", "descent s", "log"):
            t.add_column(col)
        for f in summary["flights"]:
            d = f.get("descent_time_s")
            t.add_row(f["mission"], f["outcome"], f"{d:.2f}" if d is not None else "–", str(f["log_dir"]))
        console.print(t)
        if "speedup_helix_vs_vertical" in summary:
            ratio = summary["speedup_helix_vs_vertical"]
            console.print(f"over the same height the helix descends {ratio:.2f}× as fast as the vertical baseline")
    if not ok:
        raise FlighttestError("demo stopped: a flight did not complete (see its log above)")
    return 0
