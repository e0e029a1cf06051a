"""``flighttest analyse|compare|report|identify``: what the logs say after a flight."""

from __future__ import annotations

import argparse
import dataclasses
import errno
import math
import os
import stat
import sys
from pathlib import Path

import pandas as pd
from rich.measure import Measurement
from rich.table import Table
from rich.text import Text

from flighttest.analysis import legend
from flighttest.analysis.compare import add_param_differences, add_speedup, compare_row, refused_speedups
from flighttest.analysis.identify import IdentifyConfig
from flighttest.console import console, print_json
from flighttest.errors import FlighttestError
from flighttest.flying.wind import WIND_COVERAGE_SIGMAS
from flighttest.inputs import FINITE, Range, atomic_write, check_output_path, check_path_text

JOBS = Range(1, 256, integer=True)  # worker processes (flighttest.analysis.batch.MAX_JOBS)
VELOCITY_SD = Range(0.0, 2.0, "m/s")  # an estimate worse than 2 m/s has no onset to give to a quarter of itself

SEG_OPTIONS = {  # option → SegmentConfig field
    "rate_threshold": "rate_threshold_mps",
    "min_height": "min_height_m",
    "start_tol": "start_tol_m",
    "end_tol": "end_tol_m",
    "settle_hold": "settle_hold_s",
}


def _add_segment_options(p: argparse.ArgumentParser) -> None:
    # finite here; each one's physical range (segment.SEGMENT_RANGES) is checked by _seg_config, so the
    # error names both the option and the threshold it sets
    g = p.add_argument_group("descent segmentation (flighttest.analysis.segment)")
    g.add_argument("--rate-threshold", type=FINITE, metavar="MPS", help="a descent falls faster than this (0.15)")
    g.add_argument("--min-height", type=FINITE, metavar="M", help="smaller drops are not descents (0.5)")
    g.add_argument("--start-tol", type=FINITE, metavar="M", help="starts this far below the start height (0.05)")
    g.add_argument("--end-tol", type=FINITE, metavar="M", help="ends within this of the end height (0.10)")
    g.add_argument("--settle-hold", type=FINITE, metavar="S", help="... for at least this long (0.5)")


VEHICLE_HELP = ("judge every log with this profile as it is today (default: each flighttest flight with the "
                "vehicle it flew with, from its meta.json)")  # fmt: skip


def _add_profile_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--vehicle", metavar="NAME", help=VEHICLE_HELP)
    p.add_argument("--profile-now", action="store_true",
                   help="judge each flight with its vehicle's profile as it is today (after identify "
                        "--write-profile, say), not with the w_allow it flew with")  # fmt: skip


def register(sub: argparse._SubParsersAction) -> None:
    pa = sub.add_parser(
        "analyse",
        help="descents, timing, VRS exposure and fluctuation of flight logs",
        description="Analyse flighttest log folders, MAVLink .tlog, ArduPilot .bin and PX4 .ulg files (told by "
        "their content, whatever their name). "
        "VRS exposure is air-relative: with the wind flighttest flew with (a folder's guard.csv), else the "
        "autopilot's estimate in the log, else flighttest's own estimate from the log's IMU, attitude and "
        "velocity with the vehicle's drag model; each log names its wind_source. "
        "A folder that is not itself a flight log is walked for logs of every format, analysed on every "
        "core, and its per-descent table written as Parquet.",
    )
    pa.add_argument("logs", nargs="+", metavar="LOG|DIR")  # text: Path("") would be the current folder
    _add_profile_options(pa)
    pa.add_argument(
        "--json",
        action="store_true",
        help='per log, its descents and what was missing, as JSON (a log that failed: {"log", "error"})',
    )
    pa.add_argument("--csv", metavar="FILE", help="write the per-descent table as CSV")
    pa.add_argument(
        "--parquet",
        metavar="FILE",
        help="where to write the per-descent Parquet table (default DIR/flighttest-descents.parquet "
        "when a folder is walked)",
    )
    pa.add_argument("--jobs", type=JOBS, metavar="N", help="worker processes (default: every core)")
    pa.add_argument("--wide", action="store_true", help="every column, however narrow the terminal")
    _add_segment_options(pa)
    pa.set_defaults(func=cmd_analyse)

    pc = sub.add_parser("compare", help="descent times side by side, speed-up ratio and VRS exposure")
    pc.add_argument("logs", nargs="+", metavar="LOG")
    _add_profile_options(pc)
    pc.add_argument("--json", action="store_true", help='machine-readable output (a log that failed: {"log", "error"})')
    pc.add_argument("--allow-unequal", action="store_true",
                    help="give the speed-up even where the main descents start at different heights or "
                         "descend different heights (without it: refused, exit code 2)")  # fmt: skip
    pc.add_argument("--wide", action="store_true", help="one row per flight, however narrow the terminal")
    _add_segment_options(pc)
    pc.set_defaults(func=cmd_compare)

    pr = sub.add_parser("report", help="PNG plots and a Markdown summary of flight logs")
    pr.add_argument("logs", nargs="+", metavar="LOG")
    pr.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for report.md and PNGs")
    _add_profile_options(pr)
    _add_segment_options(pr)
    pr.set_defaults(func=cmd_report)

    pi = sub.add_parser(
        "identify",
        help="VRS onset from a probe flight; optionally store it as the profile's w_allow",
        description="Find the descent speed (blade-frame, air-relative) at which fluctuation first rises "
        "above the flight's hover baseline, with its uncertainty, normalised by v_h. The air is the log's wind "
        "(what flighttest flew with, the autopilot's estimate, or flighttest's own from the IMU's drag), named in "
        "the result; a probe flown in more wind than that correction can vouch for is refused.",
    )
    pi.add_argument("log", metavar="LOG")  # text: Path("") would be the current folder
    pi.add_argument("--vehicle", required=True, metavar="NAME", help="vehicle profile name or .toml path")
    pi.add_argument(
        "--threshold",
        type=float,
        default=2.0,
        metavar="RATIO",
        help="fluctuation rise that counts as the onset, × hover (default 2)",
    )
    pi.add_argument(
        "--velocity-sd",
        type=VELOCITY_SD,
        default=None,
        metavar="MPS",
        help="the velocity estimate's vertical error, 1 σ, which moves the onset read from one pass through it "
        f"alike (default {IdentifyConfig().velocity_sd_mps:g}, PX4 EKF2's with GNSS; lower it for RTK or motion "
        "capture)",
    )
    pi.add_argument(
        "--write-profile",
        action="store_true",
        help="store the onset as w_allow (with --drag: the drag model) in your copy of the profile: the first "
        "folder of $FLIGHTTEST_VEHICLES, else ~/.config/flighttest/vehicles/ (a shipped profile stays as shipped)",
    )
    pi.add_argument("--drag", action="store_true",
                    help="identify the airframe's drag from a calibration flight (`flighttest fly drag`) instead: "
                         "linear and quadratic per body axis with its uncertainty, which flighttest's wind estimate "
                         "needs")  # fmt: skip
    pi.add_argument("--json", action="store_true", help="machine-readable output")
    pi.set_defaults(func=cmd_identify)


def _seg_config(args: argparse.Namespace):
    from flighttest.analysis.segment import SEGMENT_RANGES, SegmentConfig

    given = {f: getattr(args, o) for o, f in SEG_OPTIONS.items() if getattr(args, o, None) is not None}
    for option, field in SEG_OPTIONS.items():
        if field in given:
            SEGMENT_RANGES[field].check(given[field], f"--{option.replace('_', '-')} ({field})")
    return SegmentConfig(**given)


def _log_paths(paths: list[str]) -> list[Path]:
    """The command line's logs, each checked before any is read: a path that is empty (it would be
    the current folder), too long, missing, a FIFO (reading it blocks for ever) or a device is one
    error line for the whole command; a log whose content is damaged is found when it is read."""
    from flighttest.analysis.loaders import check_log_path

    return [check_log_path(p) for p in paths]


_FILE_SUFFIXES = (".md", ".png", ".pdf", ".svg", ".html", ".txt", ".json", ".csv")


def _check_output_folder(path: str, what: str) -> Path:
    """An output *folder* (report -o) checked before any log is read: not empty, not a file, not
    under a file, writable, not named like a file (report.md goes inside it). Created when written."""
    folder = Path(check_path_text(path, what))
    if folder.suffix.lower() in _FILE_SUFFIXES:
        raise FlighttestError(f"{what} {path}: names a file; give the folder for report.md and the PNGs")
    try:
        st = os.stat(folder)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        if exc.errno == errno.ENOTDIR:
            st = None  # a file on the way: check_output_path below says which
        else:
            raise FlighttestError(f"{what} {path}: {exc.strerror or exc}") from None
    if st is not None and not stat.S_ISDIR(st.st_mode):
        raise FlighttestError(f"{what} {path}: is a file, not a folder")
    try:  # the folders on the way: a file among them, one not writable
        check_output_path(folder / "report.md", what)
    except FlighttestError as exc:
        raise FlighttestError(str(exc).replace(str(folder / "report.md"), path, 1)) from None
    return folder


def _expand(paths: list[Path]) -> tuple[list[Path], list[Path]]:
    """(logs, walked folders) from the command line."""
    from flighttest.analysis.batch import find_logs
    from flighttest.analysis.loaders.folder import is_log_folder

    logs: list[Path] = []
    walked: list[Path] = []
    for p in _log_paths(paths):
        if p.is_dir() and not is_log_folder(p):
            found, skipped = find_logs(p)
            for line in skipped:  # a note, not an error: the other logs of the folder are analysed
                print(f"flighttest: note: {line}", file=sys.stderr)
            if not found:
                raise FlighttestError(
                    f"{p}: no flight logs found (.tlog, .bin, .ulg, by name or content, or flighttest log folders)"
                )
            logs += found
            walked.append(p)
        else:
            logs.append(p)
    return logs, walked


def _run(paths: list[Path], vehicle: str | None, seg, jobs: int | None = None, profile_now: bool = False):
    from flighttest.analysis.batch import analyse_many

    if vehicle:
        from flighttest.model.profiles import load_profile

        load_profile(vehicle)  # a bad profile is one error, not one per log
    results = analyse_many(paths, vehicle, seg, jobs, profile_now)
    errors = [err for _, _, err in results if err]
    for err in errors:
        print(f"flighttest: error: {err}", file=sys.stderr)
    return [r for _, r, _ in results if r is not None], errors, results


def _in_input_order(results: list, entries: list[dict]) -> list[dict]:
    """``entries`` (one per log analysed, in order) with ``{"log", "error"}`` where a log failed, so
    ``--json`` stays one document with one entry per log whatever failed (docs/CONTRACTS.md)."""
    done = iter(entries)
    return [next(done) if r is not None else {"log": path, "error": err} for path, r, err in results]


def _num(v, fmt: str = "{:.2f}") -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return fmt.format(v)


# -- tables that fit the terminal ------------------------------------------------------------------
# rich squeezes a table wider than the terminal by cutting headers and values to "sta…", "2.…":
# unreadable. Every table here is measured first and, when it does not fit, printed with fewer
# columns or stacked (one column per descent / flight) — with full headers and values always.


def _natural_width(table: Table) -> int:
    """The width ``table`` needs to show every header and value unwrapped and uncut."""
    return Measurement.get(console, console.options.update_width(100_000), table).maximum


def _fits(table: Table, width: int | None = None) -> bool:
    return _natural_width(table) <= (width or console.width)


def _print_table(table: Table) -> None:
    """Print at the table's own width even when that is wider than the terminal (``--wide``):
    lines longer than the terminal wrap there, but nothing is cut."""
    need = _natural_width(table)
    if need > console.width:
        table.width = need
        console.print(table, crop=False)
    else:
        console.print(table)


def _row_table(title: str | None, headers: list[str], rows: list[list[str]], left: tuple[str, ...] = ()) -> Table:
    # every header and cell as Text: log names and missions come from the logs, and a "[/x]" in them
    # would be taken for rich markup (a MarkupError, or text silently styled away)
    t = Table(title=Text(title) if title else None, title_justify="left")
    for h in headers:
        t.add_column(Text(h), justify="left" if h in left else "right", no_wrap=True)
    for r in rows:
        t.add_row(*(Text(c) for c in r))
    return t


def _stacked_tables(
    title: str | None, labels: list[str], columns: list[tuple[str, list[str]]], width: int | None = None
) -> list:
    """One row per label and one column per item (``columns``: (header, values)), split into as many
    tables as it takes for each to fit ``width`` (at least one item per table). The title goes on a
    line of its own: a narrow table would wrap it."""
    width = width or console.width
    out: list = [Text(title)] if title else []
    if not columns:
        return [*out, _stacked(None, labels, [])]
    i = 0
    while i < len(columns):
        n = 1
        while i + n < len(columns) and _fits(_stacked(None, labels, columns[i : i + n + 1]), width):
            n += 1
        out.append(_stacked(None, labels, columns[i : i + n]))
        i += n
    return out


def _stacked(title: str | None, labels: list[str], columns: list[tuple[str, list[str]]]) -> Table:
    t = Table(title=Text(title) if title else None, title_justify="left")
    t.add_column("", no_wrap=True)
    for header, _ in columns:
        t.add_column(Text(header), justify="right", no_wrap=True)
    for k, label in enumerate(labels):
        t.add_row(Text(label), *(Text(values[k]) for _, values in columns))
    return t


DESCENT_COLUMNS = {  # header: (descents column, format)
    "#": ("descent", "{}"),
    "start s": ("start_s", "{:.2f}"),
    "duration s": ("duration_s", "{:.2f}"),
    "height m": ("height_m", "{:.2f}"),
    "mean m/s": ("mean_rate_mps", "{:.2f}"),
    "max m/s": ("max_rate_mps", "{:.2f}"),
    "horiz. m": ("horizontal_excursion_m", "{:.2f}"),
    "inside s": ("time_inside_s", "{:.2f}"),
    "near s": ("time_near_s", "{:.2f}"),
    "min margin m/s": ("min_margin_mps", "{:.2f}"),
    "fluct. max": ("fluct_index_max", "{:.1f}"),
    "phase": ("phase", "{}"),
}
# what a narrow terminal keeps: when, how long, how far, how fast, how long inside the guard region
DESCENT_ESSENTIALS = ("#", "start s", "duration s", "height m", "max m/s", "inside s", "phase")


def _descent_cells(d: pd.DataFrame) -> list[list[str]]:
    rows = []
    for r in d.to_dict("records"):
        cells = []
        for header, (key, fmt) in DESCENT_COLUMNS.items():
            v = r.get(key)
            if header == "phase":
                cells.append(v if isinstance(v, str) and v else "–")
            elif header == "#":
                cells.append(f"{v}{legend.MAIN_MARK}" if r.get("main") is True else str(v))
            else:
                cells.append(_num(v, fmt))
        rows.append(cells)
    return rows


def descent_tables(title: str, d: pd.DataFrame, wide: bool = False, width: int | None = None) -> list:
    """The per-descent table of one log as renderables that fit ``width`` (the terminal's by default):
    every column when they fit (or ``wide``), else the essential columns and a line naming the others,
    else one column per descent, stacked into as many tables as it takes."""
    width = width or console.width
    headers = list(DESCENT_COLUMNS)
    rows = _descent_cells(d)
    full = _row_table(None, headers, rows, left=("phase",))
    if wide or _fits(full, width):
        return [Text(title), full]  # the title on its own line: as the table's, it would wrap at the table's width
    keep = [headers.index(h) for h in DESCENT_ESSENTIALS]
    narrow = _row_table(None, list(DESCENT_ESSENTIALS), [[r[i] for i in keep] for r in rows], left=("phase",))
    if _fits(narrow, width):
        return [Text(title), narrow, Text("  --wide, --json and --csv show every column")]
    return _stacked_tables(title, headers[1:], [(f"#{r[0]}", r[1:]) for r in rows], width)


def _print_all(renderables: list) -> None:
    for item in renderables:
        if isinstance(item, Table):
            _print_table(item)
        else:
            console.print(item)


def cmd_analyse(args: argparse.Namespace) -> int:
    from flighttest.analysis.batch import PARQUET_NAME, descent_table, write_parquet

    seg = _seg_config(args)
    # outputs before any log is read: a path that cannot be written is refused, not found out at the end
    csv = check_output_path(args.csv, "--csv", (".csv",)) if args.csv is not None else None
    parquet = check_output_path(args.parquet, "--parquet", (".parquet",)) if args.parquet is not None else None
    logs, walked = _expand(args.logs)
    if parquet is None and walked:
        try:  # the default beside the walked folder: where it cannot be written, analyse without it
            parquet = check_output_path(walked[0] / PARQUET_NAME, "the Parquet table", (".parquet",))
        except FlighttestError as exc:
            print(f"flighttest: warning: not writing {exc}", file=sys.stderr)
    results, errors, outcome = _run(logs, args.vehicle, seg, args.jobs, args.profile_now)
    tables = [r["descents"] for r in results]
    if args.json:
        print_json(_in_input_order(outcome, [r["summary"] for r in results]))
    else:
        shown: list[str] = []
        for r in results:
            s = r["summary"]
            title = f"{s['log']} ({s['source']}, {s['duration_s']:.1f} s, vehicle {s['vehicle'] or '–'})"
            renderables = descent_tables(title, r["descents"], wide=args.wide)
            _print_all(renderables)
            shown += [h for h in _headers_of(renderables) if h not in shown]
            _print_flight(s)
            _print_sources(s)
            for g in s["glitches"]:
                console.print(Text(_glitch_line(g)))
            # markup off: notes quote the log's own bytes, and "[/x]" in them would be taken for rich markup
            for k, v in s["missing"].items():
                console.print(f"  missing {k}: {v}", markup=False)
            for n in s["notes"]:
                console.print(f"  note: {n}", markup=False)
    if not args.json and results:
        console.print(_legend_table(shown))
    if csv is not None:
        df = descent_table(tables) if any(len(t) for t in tables) else pd.DataFrame()
        try:
            with atomic_write(csv) as tmp:
                df.to_csv(tmp, index=False)
        except OSError as exc:
            raise FlighttestError(f"{csv}: cannot write CSV ({exc.strerror or exc})") from None
    if parquet is not None:
        out = write_parquet(tables, parquet)
        if not args.json:
            n = sum(len(t) for t in tables)
            console.print(f"wrote {out} ({n} descents from {len(results)} logs)", markup=False)
    return 2 if errors else 0


def _glitch_line(g: dict) -> str:
    """One estimator glitch in words: an altitude jump, or a span where the height sources disagreed."""
    when = f"at {_num(g.get('start_s'))} s for {_num(g.get('duration_s'))} s"
    if g.get("kind") == "disagreement":
        said = g.get("sources") if isinstance(g.get("sources"), dict) else {}
        detail = ", ".join(f"{k} {_num(v, '{:.1f}')} m" for k, v in said.items())
        return (
            f"  estimator glitch {when}: {g.get('source') or 'a height source'} disagreed with the others by "
            f"{_num(g.get('max_jump_m'), '{:.1f}')} m" + (f" ({detail})" if detail else "") + " (not a descent)"
        )
    what = f" ({g['source']})" if g.get("source") else ""
    return f"  estimator glitch{what} {when}: altitude jumped {_num(g.get('max_jump_m'), '{:.1f}')} m (not a descent)"


def wind_line(s: dict) -> str | None:
    """The wind the log was judged with, in words (keys of ``Analysis.summary``), None without one."""
    if not s.get("wind_source"):
        return None
    w, sd = s.get("wind_ned_mps"), s.get("wind_sd_mps")
    if not w or w[0] is None:
        return f"  wind: unknown ({s['wind_source']})"
    spread = f" ± {sd:.2f}" if isinstance(sd, int | float) else " (uncertainty unknown)"
    return (f"  wind: {math.hypot(w[0], w[1]):.2f} m/s{spread} (N {w[0]:+.2f}, E {w[1]:+.2f}, D {w[2]:+.2f}) "
            f"from {s['wind_source']}: exposure is air-relative")  # fmt: skip


def airborne_line(s: dict) -> str | None:
    """The exposure over all the time airborne (the guard region is entered outside descents too)."""
    e = s.get("airborne_exposure")
    if not e or not isinstance(e.get("time_inside_s"), int | float) or not math.isfinite(e["time_inside_s"]):
        return None
    worst = e.get("time_inside_worst_s")
    at_worst = (f" ({_num(worst)} s at the worst air within {WIND_COVERAGE_SIGMAS:g} σ of the wind)"
                if isinstance(worst, int | float) and math.isfinite(worst) else "")  # fmt: skip
    return (f"  airborne {_num(e.get('airborne_s'), '{:.1f}')} s: inside the guard region {_num(e['time_inside_s'])} s"
            f"{at_worst}, min margin {_num(e.get('min_margin_mps'))} m/s")  # fmt: skip


def _legend_table(headers: list[str]) -> Table:
    """What each of ``headers`` means (``flighttest.analysis.legend``), the meanings wrapped beside them."""
    t = Table.grid(padding=(0, 1))
    t.add_column(no_wrap=True, justify="right")
    t.add_column(ratio=1)
    for h in headers:
        if h in legend.COLUMNS:
            t.add_row(Text(h), Text(legend.COLUMNS[h]))
    return t


def _headers_of(renderables: list) -> list[str]:
    """The column headers (and, stacked, the row labels) of the tables among ``renderables``."""
    out: list[str] = []
    for item in renderables:
        if isinstance(item, Table):
            out += [str(c.header) for c in item.columns if str(c.header)]
            if item.columns and not str(item.columns[0].header):  # stacked: the labels are the first column
                out += [str(cell) for cell in item.columns[0].cells]
    return out


def _print_flight(s: dict) -> None:
    """How the flight ended, its main descent and which profile judged it (``analyse`` summary keys)."""
    if s.get("outcome"):
        why = f" ({s['abort_reason']})" if s.get("abort_reason") else ""
        console.print(Text(f"  outcome: {s['outcome']}{why}"))
    console.print(Text(f"  main descent: {legend.main_text(s.get('main_descent'), s.get('main_descent_note'))}"))
    t = s.get("tracking_error")
    if t:
        console.print(Text(f"  off the plan: at most {_num(t.get('max_m'))} m (rms {_num(t.get('rms_m'))} m; "
                           f"sideways {_num(t.get('max_horizontal_m'))}, vertically {_num(t.get('max_vertical_m'))})"))
    console.print(Text(f"  judged with: {legend.judged_text(s.get('judged_with'))}"))


def _print_sources(s: dict) -> None:
    """Where the log's height, attitude, wind and parameters came from (keys the summary may carry)."""
    if s.get("height_source"):
        console.print(f"  height from: {s['height_source']}")
    if "attitude_source" in s:
        console.print(f"  attitude from: {s['attitude_source'] or 'none in the log'}")
    for line in (wind_line(s), airborne_line(s)):
        if line:
            console.print(line, markup=False)
    if "params" in s:
        params = s.get("params") or {}
        src = f" (from {s['params_source']})" if s.get("params_source") else ""
        console.print(
            f"  parameters{src}: {len(params)} that shape these tests (--json, report)"
            if params
            else f"  parameters{src}: none that shape these tests in the log"
        )


COMPARE_COLUMNS = {  # header: (key, format)
    "outcome": ("outcome", "{}"),
    "start m": ("start_height_m", "{:.2f}"),
    "height m": ("height_m", "{:.2f}"),
    "descent s": ("descent_time_s", "{:.2f}"),  # logs of other programs: duration_s (_compare_cell)
    "planned s": ("planned_descent_s", "{:.2f}"),
    "hover→hover s": ("hover_to_hover_s", "{:.2f}"),
    "÷ optimum": ("flown_over_optimum", "{:.2f}"),
    "horiz. err m": ("horizontal_error_m", "{:.2f}"),
    "speed-up ×": ("speedup_vs_first", "{:.2f}"),
    "mean m/s": ("mean_rate_mps", "{:.2f}"),
    "max m/s": ("max_rate_mps", "{:.2f}"),
    "inside s": ("time_inside_s", "{:.2f}"),
    "inside worst s": ("time_inside_worst_s", "{:.2f}"),
    "near s": ("time_near_s", "{:.2f}"),
    "min margin m/s": ("min_margin_mps", "{:.2f}"),
    "wind m/s": ("wind_speed_mps", "{:.2f}"),
    "fluct. max": ("fluct_index_max", "{:.1f}"),
}


def _flight_headers(names: list[str], kinds: list[str], labels: list[str], cells: list[list[str]], width: int):
    """Column headers for one column per flight: "name\\nkind" when those fit, else "1", "2", ...
    with a legend (long folder names would not fit two flights into 80 columns)."""
    full = [f"{n}\n{k}" for n, k in zip(names, kinds)]
    if _fits(_stacked(None, labels, list(zip(full, cells))), width):
        return full, []
    legend = [Text(f"  {i}: {n} ({k})") for i, (n, k) in enumerate(zip(names, kinds), start=1)]
    return [str(i) for i in range(1, len(names) + 1)], legend


def _compare_cell(row: dict, key: str, fmt: str) -> str:
    if key == "descent_time_s" and key not in row:  # a log of another program: its main descent's duration
        key = "duration_s"
    return _num(row.get(key), fmt)


def compare_tables(rows: list[dict], wide: bool = False, width: int | None = None) -> list:
    """``flighttest compare`` as renderables that fit ``width``: one row per flight when that fits
    (or ``wide``), else one column per flight (numbered, with a legend, when the names are long),
    then the parameters that differ between the flights."""
    width = width or console.width
    names = [Path(row["log"]).name for row in rows]
    kinds = [str(row.get("trajectory") or row.get("mission") or "–") for row in rows]
    title = "descent times side by side (the main descent of each flight)"
    values = [[_compare_cell(row, key, fmt) for key, fmt in COMPARE_COLUMNS.values()] for row in rows]
    flat = _row_table(
        title, ["log", "mission", *COMPARE_COLUMNS], [[n, k, *v] for n, k, v in zip(names, kinds, values)],
        left=("log", "mission", "outcome"),
    )  # fmt: skip
    out: list = []
    labels = list(COMPARE_COLUMNS)
    headers, legend = [f"{n}\n{k}" for n, k in zip(names, kinds)], []
    if wide or _fits(flat, width):
        out.append(flat)
    else:
        per_flight = [list(col) for col in zip(*values)] if values else []
        cells = [[v[k] for v in per_flight] for k in range(len(rows))]
        headers, legend = _flight_headers(names, kinds, labels, cells, width)
        out += [Text(title), *legend, *_stacked_tables(None, labels, list(zip(headers, cells)), width)]
    out += param_difference_tables(rows, headers, wide, width)
    return out


def param_difference_tables(rows: list[dict], headers: list[str], wide: bool = False, width: int | None = None):
    """The relevant parameters not the same in every flight (rows' ``param_differences``), one row
    per parameter and one column per flight (``headers``)."""
    from flighttest.analysis.params import format_value

    width = width or console.width
    diff_names = list(rows[0].get("param_differences") or {}) if rows else []
    with_params = sum(bool(row.get("params")) for row in rows)
    if len(rows) < 2:
        return []
    if with_params < 2:
        return [Text(f"parameters: {with_params} of {len(rows)} logs carry them, nothing to compare")]
    if not diff_names:
        return [Text(f"parameters: the {with_params} logs that carry them were set up alike")]
    title = f"parameters that differ between the flights ({len(diff_names)})"
    columns = [(h, [format_value(row["param_differences"][n]) for n in diff_names]) for h, row in zip(headers, rows)]
    if wide:
        return [_stacked(title, diff_names, columns)]
    return [*_stacked_tables(title, diff_names, columns, width), Text("  –: that log does not have the parameter")]


def cmd_compare(args: argparse.Namespace) -> int:
    seg = _seg_config(args)
    results, errors, outcome = _run(_log_paths(args.logs), args.vehicle, seg, profile_now=args.profile_now)
    rows = []
    for r in results:
        s = r["summary"]
        rows.append(compare_row(s["log"], r["descents"], r["events"], r.get("meta") or {}, s.get("params") or {},
                                s.get("main_descent")))  # fmt: skip
    # flighttest's own logs know when each descent started and came to rest: compare those; others by segment
    basis = "descent_time_s" if rows and all(row.get("descent_time_s") for row in rows) else "duration_s"
    for row, r in zip(rows, results):
        row["judged_with"] = r["summary"].get("judged_with")
    for row in add_speedup(rows, key=basis, allow_unequal=args.allow_unequal):
        row["speedup_basis"] = basis
    add_param_differences(rows)
    refused = refused_speedups(rows, [Path(row["log"]).name for row in rows], basis)
    if args.json:
        print_json(_in_input_order(outcome, rows))  # speed-ups are against the first log analysed
    else:
        _print_all(compare_tables(rows, wide=args.wide))
        for row in rows:
            name = Path(row["log"]).name
            if row.get("main_descent_note"):
                console.print(f"{name}: {row['main_descent_note']}", markup=False)
            elif row.get("descent_differs") and not refused:
                console.print(f"{name}: {row['descent_differs']} (the first log's main descent)", markup=False)
        judged = {legend.judged_text(row.get("judged_with")) for row in rows}
        if len(judged) == 1:
            console.print(Text(f"judged with: {judged.pop()}"))
        else:
            for row in rows:
                judged_text = legend.judged_text(row.get("judged_with"))
                console.print(Text(f"{Path(row['log']).name}: judged with {judged_text}"))
        console.print(_legend_table(list(COMPARE_COLUMNS)))
        if basis != "descent_time_s":
            console.print("speed-up: of the main descents' durations (not every log has a descent time)")
    if refused:
        print(f"flighttest: error: {refused}", file=sys.stderr)
    return 2 if errors or refused else 0


def _is_probe(a) -> bool:
    kind = f"{a.log.mission_name or ''} {a.descents['trajectory'].iloc[0] if len(a.descents) else ''}"
    return "probe" in kind.lower()


def cmd_report(args: argparse.Namespace) -> int:
    from flighttest.analysis.batch import quiet_numerics
    from flighttest.analysis.identify import identify_onset
    from flighttest.analysis.loaders import load_log
    from flighttest.analysis.pipeline import analyse
    from flighttest.analysis.report import write_report

    seg = _seg_config(args)
    output = _check_output_folder(args.output, "report -o")
    paths = _log_paths(args.logs)
    if args.vehicle:
        from flighttest.model.profiles import load_profile

        load_profile(args.vehicle)  # a bad profile is one error, not one per log
    analyses, onsets, failed = [], {}, 0
    for path in paths:
        try:
            with quiet_numerics():
                a = analyse(load_log(path), args.vehicle, seg, profile_now=args.profile_now)
        except FlighttestError as exc:
            print(f"flighttest: error: {exc}", file=sys.stderr)
            failed += 1
            continue
        except Exception as exc:  # one log's failure is one line, and the others are still reported
            print(f"flighttest: error: {path}: analysis failed ({_detail(exc)})", file=sys.stderr)
            failed += 1
            continue
        if a.profile is not None and _is_probe(a):
            try:
                with quiet_numerics():
                    onsets[str(a.log.path)] = identify_onset(a.log, a.profile)
            except FlighttestError as exc:
                a.notes.append(f"onset not identified: {exc}")
            except Exception as exc:
                a.notes.append(f"onset not identified: identification failed ({_detail(exc)})")
        analyses.append(a)
    if analyses:
        try:
            with quiet_numerics():
                out = write_report(analyses, output, onsets)
        except FlighttestError:
            raise
        except OSError as exc:
            raise FlighttestError(f"report -o {output}: cannot write ({exc.strerror or exc})") from None
        except Exception as exc:
            raise FlighttestError(f"report -o {output}: writing the report failed ({_detail(exc)})") from None
        console.print(f"wrote {out}", markup=False)
    return 2 if failed else 0


def _detail(exc: BaseException) -> str:
    """An unexpected exception as a short single-line detail for an error line."""
    return " ".join(f"{type(exc).__name__}: {exc}".split())[:200]


MAX_THRESHOLD_RATIO = 10.0  # beyond this no real onset would count, and "no onset up to X" would be invented


def cmd_identify(args: argparse.Namespace) -> int:
    """The onset, or (exit 0) the lower bound of a quiet probe with the prior kept, or one line saying
    why this log gives no onset to trust (exit 2, nothing stored): ``flighttest.analysis.identify``."""
    from flighttest.analysis.identify import IdentifyConfig, NoOnset, identify_onset, no_onset_line
    from flighttest.analysis.loaders import load_log
    from flighttest.model.profiles import load_profile, w_allow_target, write_w_allow

    if not (math.isfinite(args.threshold) and 1.0 < args.threshold <= MAX_THRESHOLD_RATIO):
        raise FlighttestError(f"--threshold must be a number > 1 and at most {MAX_THRESHOLD_RATIO:g} "
                              f"(got {args.threshold})")  # fmt: skip
    cfg = IdentifyConfig(threshold_ratio=args.threshold)
    if args.velocity_sd is not None:
        cfg = dataclasses.replace(cfg, velocity_sd_mps=args.velocity_sd)
    from flighttest.analysis.batch import quiet_numerics

    profile = load_profile(args.vehicle)
    (args.log,) = _log_paths([args.log])
    if args.write_profile:  # where the result would go, before the log is read: a result that cannot be stored
        w_allow_target(profile)
    if args.drag:
        return _identify_drag(args, profile)
    prior = profile.w_allow_mps
    try:
        with quiet_numerics():
            log = load_log(args.log)
            onset = identify_onset(log, profile, cfg)
    except NoOnset as none:
        line = no_onset_line(none.lower_bound_mps, prior)
        if args.json:
            print_json({"log": str(args.log), "vehicle": profile.name, **none.summary(), "prior_w_allow_mps": prior,
                        "previous_w_allow_mps": prior, "profile_written": None, "message": line})  # fmt: skip
            return 0
        console.print(line)
        console.print(f"[dim]{none} — {none.samples} samples; {none.evidence}[/]")
        if none.wind is not None:
            console.print(f"the sweep was {none.wind.note('the lower bound')}", markup=False)
        if args.write_profile:
            console.print("nothing stored: there is no onset to store (the profile keeps its prior)")
        return 0
    out = {
        "log": str(args.log),
        "vehicle": profile.name,
        **onset.summary(),
        "prior_w_allow_mps": prior,
        "previous_w_allow_mps": prior,
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
        f"(v_h {onset.v_h_mps:.2f} m/s; hinge fit, fluctuation rises {onset.rise_ratio:.1f}× over hover, "
        f"{onset.observed_rise_ratio:.1f}× in the fastest samples; "
        f"{onset.samples} descending samples up to {onset.max_speed_mps:.2f} m/s)"
    )
    console.print(f"[dim]{onset.probe_evidence}[/]")
    if onset.wind is not None:
        console.print(f"the probe was {onset.wind.note()}", markup=False)
    console.print(f"profile w_allow now: {profile.w_allow_mps:.3f} m/s ({profile.w_allow_source})")
    if out["profile_written"]:
        console.print(f"stored w_allow = {onset.w_onset_mps:.3f} m/s in {out['profile_written']}")
    else:
        console.print("not stored (add --write-profile to make plans and the guard use it)")
    return 0


def _identify_drag(args: argparse.Namespace, profile) -> int:
    """``identify --drag``: the drag model of a calibration flight, or one line saying why not (exit 2)."""
    from flighttest.analysis.batch import quiet_numerics
    from flighttest.analysis.drag import identify_drag
    from flighttest.analysis.loaders import load_log
    from flighttest.model.profiles import write_drag

    with quiet_numerics():
        result = identify_drag(load_log(args.log), profile, str(args.log))
    out = {"log": str(args.log), "vehicle": profile.name, **result.summary(), "profile_written": None,
           "previous_drag": profile.drag.to_table() if profile.drag is not None else None}  # fmt: skip
    if args.write_profile:
        out["profile_written"] = str(write_drag(profile, result.model))
    if args.json:
        print_json(out)
        return 0
    m = result.model
    console.print(
        f"drag of {profile.name} from {args.log}: linear [bold]{m.linear_n_per_mps[0]:.3f}, {m.linear_n_per_mps[1]:.3f}"
        f"[/] N/(m/s), quadratic [bold]{m.quadratic_n_per_mps2[0]:.4f}, {m.quadratic_n_per_mps2[1]:.4f}[/] N/(m/s)² "
        f"(body x, y), ±{m.rel_sd:.0%}; {result.samples} samples up to {result.airspeed_max_mps:.1f} m/s of air; "
        f"the wind during the calibration ({result.wind_ned_mps[0]:.2f}, {result.wind_ned_mps[1]:.2f}) m/s NED"
    )
    if out["profile_written"]:
        console.print(f"stored in {out['profile_written']}")
    else:
        console.print("not stored (add --write-profile for flighttest's wind estimate to use it)")
    return 0
