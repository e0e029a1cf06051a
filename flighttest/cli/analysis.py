"""``flighttest analyse|compare|report|identify``: what the logs say after a flight."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import pandas as pd
from rich.table import Table

from flighttest.analysis.compare import add_speedup, compare_row
from flighttest.console import console, print_json
from flighttest.errors import FlighttestError

SEG_OPTIONS = {  # option → SegmentConfig field
    "rate_threshold": "rate_threshold_mps",
    "min_height": "min_height_m",
    "start_tol": "start_tol_m",
    "end_tol": "end_tol_m",
    "settle_hold": "settle_hold_s",
}


def _add_segment_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("descent segmentation (flighttest.analysis.segment)")
    g.add_argument("--rate-threshold", type=float, metavar="MPS", help="a descent falls faster than this (0.15)")
    g.add_argument("--min-height", type=float, metavar="M", help="smaller drops are not descents (0.5)")
    g.add_argument("--start-tol", type=float, metavar="M", help="starts this far below the start height (0.05)")
    g.add_argument("--end-tol", type=float, metavar="M", help="ends within this of the end height (0.10)")
    g.add_argument("--settle-hold", type=float, metavar="S", help="... for at least this long (0.5)")


def register(sub: argparse._SubParsersAction) -> None:
    pa = sub.add_parser(
        "analyse",
        help="descents, timing, VRS exposure and fluctuation of flight logs",
        description="Analyse flighttest log folders, MAVLink .tlog, ArduPilot .bin and PX4 .ulg files. "
        "A folder that is not itself a flight log is walked for logs of every format, analysed on every "
        "core, and its per-descent table written as Parquet.",
    )
    pa.add_argument("logs", nargs="+", type=Path, metavar="LOG|DIR")
    pa.add_argument("--vehicle", metavar="NAME", help="vehicle profile (default: the one in the log's meta.json)")
    pa.add_argument("--json", action="store_true", help="per log, its descents and what was missing, as JSON")
    pa.add_argument("--csv", type=Path, metavar="FILE", help="write the per-descent table as CSV")
    pa.add_argument(
        "--parquet",
        type=Path,
        metavar="FILE",
        help="where to write the per-descent Parquet table (default DIR/flighttest-descents.parquet "
        "when a folder is walked)",
    )
    pa.add_argument("--jobs", type=int, metavar="N", help="worker processes (default: every core)")
    _add_segment_options(pa)
    pa.set_defaults(func=cmd_analyse)

    pc = sub.add_parser("compare", help="descent times side by side, speed-up ratio and VRS exposure")
    pc.add_argument("logs", nargs="+", type=Path, metavar="LOG")
    pc.add_argument("--vehicle", metavar="NAME", help="vehicle profile (default: from each log)")
    pc.add_argument("--json", action="store_true", help="machine-readable output")
    _add_segment_options(pc)
    pc.set_defaults(func=cmd_compare)

    pr = sub.add_parser("report", help="PNG plots and a Markdown summary of flight logs")
    pr.add_argument("logs", nargs="+", type=Path, metavar="LOG")
    pr.add_argument("-o", "--output", type=Path, required=True, metavar="DIR", help="folder for report.md and PNGs")
    pr.add_argument("--vehicle", metavar="NAME", help="vehicle profile (default: from each log)")
    _add_segment_options(pr)
    pr.set_defaults(func=cmd_report)

    pi = sub.add_parser(
        "identify",
        help="VRS onset from a probe flight; optionally store it as the profile's w_allow",
        description="Find the descent speed (blade-frame, air-relative) at which fluctuation first rises "
        "above the flight's hover baseline, with its uncertainty, normalised by v_h.",
    )
    pi.add_argument("log", type=Path, metavar="LOG")
    pi.add_argument("--vehicle", required=True, metavar="NAME", help="vehicle profile name or .toml path")
    pi.add_argument(
        "--threshold",
        type=float,
        default=2.0,
        metavar="RATIO",
        help="fluctuation rise that counts as the onset, × hover (default 2)",
    )
    pi.add_argument(
        "--write-profile",
        action="store_true",
        help="store the onset as w_allow (with provenance) in the user's copy of the profile",
    )
    pi.add_argument("--json", action="store_true", help="machine-readable output")
    pi.set_defaults(func=cmd_identify)


def _seg_config(args: argparse.Namespace):
    from flighttest.analysis.segment import SegmentConfig

    given = {f: getattr(args, o) for o, f in SEG_OPTIONS.items() if getattr(args, o, None) is not None}
    return SegmentConfig(**given)


def _expand(paths: list[Path]) -> tuple[list[Path], list[Path]]:
    """(logs, walked folders) from the command line."""
    from flighttest.analysis.batch import find_logs
    from flighttest.analysis.loaders.folder import is_log_folder

    logs: list[Path] = []
    walked: list[Path] = []
    for p in paths:
        if p.is_dir() and not is_log_folder(p):
            found = find_logs(p)
            if not found:
                raise FlighttestError(f"{p}: no flight logs found (.tlog, .bin, .ulg or flighttest log folders)")
            logs += found
            walked.append(p)
        else:
            logs.append(p)
    return logs, walked


def _run(paths: list[Path], vehicle: str | None, seg, jobs: int | None = None):
    from flighttest.analysis.batch import analyse_many

    if jobs is not None and jobs < 1:
        raise FlighttestError(f"--jobs must be ≥ 1 (got {jobs})")
    if vehicle:
        from flighttest.profiles import load_profile

        load_profile(vehicle)  # a bad profile is one error, not one per log
    results = analyse_many(paths, vehicle, seg, jobs)
    errors = [err for _, _, err in results if err]
    for err in errors:
        print(f"flighttest: error: {err}", file=sys.stderr)
    return [r for _, r, _ in results if r is not None], errors


def _num(v, fmt: str = "{:.2f}") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return fmt.format(v)


def _descent_table(title: str, d: pd.DataFrame) -> Table:
    t = Table(title=title, title_justify="left")
    for col in (
        "#",
        "start s",
        "duration s",
        "height m",
        "mean m/s",
        "max m/s",
        "horiz. m",
        "inside s",
        "near s",
        "min margin m/s",
        "fluct. max",
        "phase",
    ):
        t.add_column(col, justify="right" if col != "phase" else "left")
    for r in d.itertuples():
        t.add_row(
            str(r.descent),
            _num(r.start_s),
            _num(r.duration_s),
            _num(r.height_m),
            _num(r.mean_rate_mps),
            _num(r.max_rate_mps),
            _num(r.horizontal_excursion_m),
            _num(r.time_inside_s),
            _num(r.time_near_s),
            _num(r.min_margin_mps),
            _num(r.fluct_index_max, "{:.1f}"),
            str(r.phase or "–") if isinstance(r.phase, str) else "–",
        )
    return t


def cmd_analyse(args: argparse.Namespace) -> int:
    from flighttest.analysis.batch import PARQUET_NAME, write_parquet

    seg = _seg_config(args)
    logs, walked = _expand(args.logs)
    results, errors = _run(logs, args.vehicle, seg, args.jobs)
    tables = [r["descents"] for r in results]
    if args.json:
        print_json([r["summary"] for r in results])
    else:
        for r in results:
            s = r["summary"]
            console.print(
                _descent_table(
                    f"{s['log']} ({s['source']}, {s['duration_s']:.1f} s, vehicle {s['vehicle'] or '–'})", r["descents"]
                )
            )
            for g in s["glitches"]:
                console.print(
                    f"  estimator glitch at {g['start_s']:.2f} s: altitude jumped {g['max_jump_m']:.1f} m "
                    f"for {g['duration_s']:.2f} s (not a descent)"
                )
            for k, v in s["missing"].items():
                console.print(f"  missing {k}: {v}")
            for n in s["notes"]:
                console.print(f"  note: {n}")
    if args.csv:
        df = (
            pd.concat([t for t in tables if len(t)], ignore_index=True)
            if any(len(t) for t in tables)
            else pd.DataFrame()
        )
        try:
            df.to_csv(args.csv, index=False)
        except OSError as exc:
            raise FlighttestError(f"{args.csv}: cannot write CSV ({exc.strerror})") from None
    parquet = args.parquet or (walked[0] / PARQUET_NAME if walked else None)
    if parquet is not None:
        out = write_parquet(tables, parquet)
        if not args.json:
            console.print(f"wrote {out} ({sum(len(t) for t in tables)} descents from {len(results)} logs)")
    return 2 if errors else 0


def cmd_compare(args: argparse.Namespace) -> int:
    results, errors = _run(args.logs, args.vehicle, _seg_config(args))
    rows = [compare_row(r["summary"]["log"], r["descents"], r["events"]) for r in results]
    # flighttest's own logs know when each descent started and came to rest: compare those; others by segment
    basis = "descent_time_s" if rows and all(row.get("descent_time_s") for row in rows) else "duration_s"
    for row in add_speedup(rows, key=basis):
        row["speedup_basis"] = basis
    if args.json:
        print_json(rows)
    else:
        columns = {  # header: (key, format)
            "height m": ("height_m", "{:.2f}"),
            "duration s": ("duration_s", "{:.2f}"),
            "rest-to-rest s": ("descent_time_s", "{:.2f}"),
            "speed-up ×": ("speedup_vs_first", "{:.2f}"),
            "mean m/s": ("mean_rate_mps", "{:.2f}"),
            "max m/s": ("max_rate_mps", "{:.2f}"),
            "inside s": ("time_inside_s", "{:.2f}"),
            "near s": ("time_near_s", "{:.2f}"),
            "min margin m/s": ("min_margin_mps", "{:.2f}"),
            "fluct. max": ("fluct_index_max", "{:.1f}"),
        }
        names = [Path(row["log"]).name for row in rows]
        kinds = [str(row.get("trajectory") or row.get("mission") or "–") for row in rows]
        title = "descent times side by side (the main descent of each flight)"
        t = Table(title=title, title_justify="left")
        if console.width < 140 and len(rows) <= 6:  # a narrow terminal: one column per flight
            t.add_column("")
            for name, kind in zip(names, kinds):
                t.add_column(f"{name}\n{kind}", justify="right")
            for header, (key, fmt) in columns.items():
                t.add_row(header, *(_num(row.get(key), fmt) for row in rows))
        else:
            for col in ("log", "mission", *columns):
                t.add_column(col, justify="left" if col in ("log", "mission") else "right")
            for name, kind, row in zip(names, kinds, rows):
                t.add_row(name, kind, *(_num(row.get(key), fmt) for key, fmt in columns.values()))
        console.print(t)
        console.print(
            "duration: the main descent found in the log; rest-to-rest: flighttest's own logs, from the first "
            "setpoint of the descent to rest at its end point; speed-up × = the first log's "
            f"{'rest-to-rest time' if basis == 'descent_time_s' else 'duration'} / this one's"
        )
    return 2 if errors else 0


def _is_probe(a) -> bool:
    kind = f"{a.log.mission_name or ''} {a.descents['trajectory'].iloc[0] if len(a.descents) else ''}"
    return "probe" in kind.lower()


def cmd_report(args: argparse.Namespace) -> int:
    from flighttest.analysis.identify import identify_onset
    from flighttest.analysis.loaders import load_log
    from flighttest.analysis.pipeline import analyse
    from flighttest.analysis.report import write_report

    seg = _seg_config(args)
    analyses, onsets, failed = [], {}, 0
    for path in args.logs:
        try:
            a = analyse(load_log(path), args.vehicle, seg)
        except FlighttestError as exc:
            print(f"flighttest: error: {exc}", file=sys.stderr)
            failed += 1
            continue
        if a.profile is not None and _is_probe(a):
            try:
                onsets[str(a.log.path)] = identify_onset(a.log, a.profile)
            except FlighttestError as exc:
                a.notes.append(f"onset not identified: {exc}")
        analyses.append(a)
    if analyses:
        out = write_report(analyses, args.output, onsets)
        console.print(f"wrote {out}")
    return 2 if failed else 0


def cmd_identify(args: argparse.Namespace) -> int:
    from flighttest.analysis.identify import IdentifyConfig, identify_onset
    from flighttest.analysis.loaders import load_log
    from flighttest.profiles import load_profile, write_w_allow

    if not (math.isfinite(args.threshold) and args.threshold > 1.0):
        raise FlighttestError(f"--threshold must be a number > 1 (got {args.threshold})")
    profile = load_profile(args.vehicle)
    log = load_log(args.log)
    onset = identify_onset(log, profile, IdentifyConfig(threshold_ratio=args.threshold))
    out = {
        "log": str(args.log),
        "vehicle": profile.name,
        **onset.summary(),
        "previous_w_allow_mps": profile.w_allow_mps,
        "profile_written": None,
    }
    if args.write_profile:
        source = onset.provenance(args.log, "flighttest identify")
        out["profile_written"] = str(write_w_allow(profile, onset.w_onset_mps, source))
    if args.json:
        print_json(out)
        return 0
    console.print(
        f"VRS onset of {profile.name} from {args.log}: [bold]{onset.w_onset_mps:.3f} ± "
        f"{onset.uncertainty_mps:.3f} m/s[/] = {onset.w_onset_n:.4f} ± {onset.uncertainty_n:.4f} v_h "
        f"(v_h {onset.v_h_mps:.2f} m/s; hinge fit, fluctuation rises {onset.rise_ratio:.1f}× over hover; "
        f"{onset.samples} descending samples up to {onset.max_speed_mps:.2f} m/s)"
    )
    console.print(f"profile w_allow now: {profile.w_allow_mps:.3f} m/s ({profile.w_allow_source})")
    if out["profile_written"]:
        console.print(f"stored w_allow = {onset.w_onset_mps:.3f} m/s in {out['profile_written']}")
    else:
        console.print("not stored (add --write-profile to make plans and the guard use it)")
    return 0
