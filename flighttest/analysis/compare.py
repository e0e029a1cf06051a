"""Descents side by side: the main descent of each flight and its speed-up over the first flight's.

A speed-up compares like with like only: where a flight's main descent starts more than
``SAME_DESCENT_TOL_M`` higher or lower than the first flight's, or descends more or less than that
much further (the planned heights where both flights have a plan, else the flown ones), the row says
so (``descent_differs``) and gets no speed-up unless asked (``allow_unequal``).
"""

from __future__ import annotations

import math

import pandas as pd

from flighttest.analysis.descent_time import (
    BASIS_PLANNED,
    BASIS_SEGMENT,
    MAIN_DESCENT_KEYS,
    TIMED_EVENT,
    is_abort_phase,
)
from flighttest.planner.optimum import EFFICIENCY_KEYS

# two main descents "start at the same height and descend as far" within this (the descent-time rule's
# end band is ±0.2 m, so two flights of one plan can end 0.4 m apart in the worst case; settling at the
# start holds the start height to about 0.1 m)
SAME_DESCENT_TOL_M = 0.5

COMPARE_KEYS = (
    "mission",
    "trajectory",
    "start_s",
    "duration_s",
    "height_m",
    "mean_rate_mps",
    "max_rate_mps",
    "horizontal_excursion_m",
    "time_inside_s",
    "time_near_s",
    "min_margin_mps",
    "time_vrs_s",
    "fluct_index_max",
    "time_inside_worst_s",
    "min_margin_worst_mps",
)


def abort_time_s(events: list[dict] | None) -> float | None:
    """When the flight's abort began (its first ``abort`` event), None when it never aborted."""
    t = next((e.get("t_s") for e in events or () if e.get("event") == "abort"), None)
    return float(t) if isinstance(t, int | float) and math.isfinite(t) else None


def _main_candidates(d: pd.DataFrame, events: list[dict] | None) -> pd.DataFrame:
    """The descents that may be a flight's main one: none flown by the abort ladder (an abort phase,
    or starting after the abort: PX4's own Land after an abort is not the test)."""
    keep = pd.Series(True, index=d.index)
    if "phase" in d:
        keep &= ~d["phase"].map(is_abort_phase).astype(bool)
    t_abort = abort_time_s(events)
    if t_abort is not None and "start_s" in d:
        keep &= pd.to_numeric(d["start_s"], errors="coerce") < t_abort
    return d[keep]


def primary_descent(d: pd.DataFrame, events: list[dict] | None = None) -> pd.Series | None:
    """The descent a flight was about: the flight's own (``main``: a flighttest flight's, timed from its
    events, ``flighttest.analysis.pipeline``), else the one flown in the 'stream' phase, else the highest;
    never one the abort ladder flew (:func:`_main_candidates`: ``events`` tell when the abort began). None
    when there is no other (:func:`no_main_descent_why` says why)."""
    if not len(d):
        return None
    if "main" in d and d["main"].astype(bool).any():
        return d[d["main"].astype(bool)].iloc[0]
    d = _main_candidates(d, events)
    if not len(d):
        return None
    ok = d[~d["glitch"].astype(bool)] if "glitch" in d else d
    ok = ok if len(ok) else d
    streamed = ok[ok["phase"].astype(str) == "stream"] if "phase" in ok else ok.iloc[0:0]
    pick = streamed if len(streamed) else ok
    return pick.loc[pick["height_m"].idxmax()]


def no_main_descent_why(d: pd.DataFrame, events: list[dict] | None = None) -> str | None:
    """Why :func:`primary_descent` found no main descent (None when it found one)."""
    if primary_descent(d, events) is not None:
        return None
    if not len(d):
        return "no descent in the log"
    t_abort = abort_time_s(events)
    when = f" at {t_abort:.1f} s" if t_abort is not None else ""
    return f"no main descent: the log's {len(d)} descent(s) came after the abort{when} (the abort ladder's)"


def flown_descent(events: list[dict]) -> pd.Series | None:
    """The descent as flighttest flew it, from a log folder's events: from the first setpoint of the
    planned descent (``stream_start``) until the vehicle was at the end point's height with its
    vertical speed settled (``flighttest.analysis.descent_time``; ``horizontal_error_m`` beside it).
    The analysis times every folder again with that rule (its ``descent_timed`` event, added by
    ``flighttest.analysis.pipeline``): older folders' ``descent_reached`` waited for the horizontal
    error to close too. Without it, the folder's own ``descent_reached``. None for other logs and for
    descents not reached (aborted, never settled)."""
    start = next((e["t_s"] for e in events if e.get("event") == "stream_start" and "t_s" in e), None)
    if not isinstance(start, int | float):
        return None
    timed = next((e for e in events if e.get("event") == TIMED_EVENT), None)
    ev = timed or next((e for e in events if e.get("event") == "descent_reached"), None)
    dur = ev.get("descent_time_s") if ev else None
    if not isinstance(dur, int | float) or not math.isfinite(dur):
        return None
    horiz = ev.get("horizontal_error_m")
    return pd.Series({"start_s": float(start), "end_s": float(start) + float(dur), "duration_s": float(dur),
                      "horizontal_error_m": float(horiz) if isinstance(horiz, int | float) else None,
                      "timed_by": "analysis" if timed else "flight"})  # fmt: skip


def flight_outcome(meta: dict | None) -> str | None:
    """How a flighttest flight ended (``summary.json`` ``outcome``: completed, aborted, probe_stopped,
    ...); None for logs of other tools and for flights whose process never wrote its summary."""
    return _summary_text(meta, "outcome")


def flight_abort_reason(meta: dict | None) -> str | None:
    """Why a flighttest flight aborted or stopped (``summary.json`` ``abort_reason``), None otherwise."""
    return _summary_text(meta, "abort_reason")


def _summary_text(meta: dict | None, key: str) -> str | None:
    summary = meta.get("summary") if isinstance(meta, dict) else None
    value = summary.get(key) if isinstance(summary, dict) else None
    return value if isinstance(value, str) and value else None


def main_record(row: pd.Series, planned=None, note: str | None = None) -> dict:
    """The main descent's record (``descent_time.MAIN_DESCENT_KEYS``) from a segmentation row: logs of
    other programs, and flighttest flights whose trajectory returns to its start (the probe)."""

    def num(key):
        v = row.get(key)
        return round(float(v), 3) if isinstance(v, int | float) and math.isfinite(v) else None

    rec = dict.fromkeys(MAIN_DESCENT_KEYS)
    rec.update(basis=BASIS_SEGMENT, start_s=num("start_s"), end_s=num("end_s"), duration_s=num("duration_s"),
               start_height_m=num("start_alt_m"), height_m=num("height_m"), mean_rate_mps=num("mean_rate_mps"),
               max_rate_mps=num("max_rate_mps"), reached=bool(row.get("settled", False)), note=note)  # fmt: skip
    if planned is not None:
        rec.update(planned_descent_s=planned.descent_time_s, planned_height_m=round(planned.height_m, 3),
                   planned_max_rate_mps=round(planned.max_rate_mps, 3))  # fmt: skip
    return rec


# the main descent's figures a compare row takes from the analysis's record (``main``)
MAIN_FIGURES = ("start_s", "duration_s", "start_height_m", "height_m", "mean_rate_mps", "max_rate_mps")


def descent_wind_keys(d: pd.Series) -> dict:
    """The wind a descent was judged with (its ``wind_n/e/d_mps``, ``wind_sd_mps``, ``wind_source``
    columns, :mod:`flighttest.analysis.pipeline`) as ``wind_ned_mps`` [n, e, d], ``wind_speed_mps``
    (horizontal), ``wind_sd_mps`` and ``wind_source``; the keys with None where the descent has none."""
    ned = [d.get(k) for k in ("wind_n_mps", "wind_e_mps", "wind_d_mps")]
    ok = all(isinstance(x, int | float) and math.isfinite(x) for x in ned)
    sd = d.get("wind_sd_mps")
    src = d.get("wind_source")
    return {"wind_ned_mps": [float(x) for x in ned] if ok else None,
            "wind_speed_mps": math.hypot(ned[0], ned[1]) if ok else None,
            "wind_sd_mps": float(sd) if isinstance(sd, int | float) and math.isfinite(sd) else None,
            "wind_source": src if isinstance(src, str) else None}  # fmt: skip


def compare_row(
    log: str,
    descents: pd.DataFrame,
    events: list[dict] | None = None,
    meta: dict | None = None,
    params: dict | None = None,
    main: dict | None = None,
) -> dict:
    """One row of ``flighttest compare``: the log, how many descents, its main descent's figures and the
    wind it was judged with (:func:`descent_wind_keys`; ``main_descent_note`` says why there is none:
    only the abort ladder's descents) and, for flighttest's own flights (``events`` with a
    ``stream_start``), ``descent_time_s`` and ``horizontal_error_m`` (see ``flown_descent``; None when
    not reached or for a probe).

    Given the log's ``meta`` the row gets ``outcome`` and ``abort_reason`` (:func:`flight_outcome`);
    given its parameters, ``params``: the ones that shape these tests (``flighttest.analysis.params.relevant``);
    given the analysis's main-descent record (``Analysis.main``), its figures (``MAIN_FIGURES``), the
    plan's ``planned_descent_s`` and ``planned_height_m`` and ``main_basis``. Without them the row keeps
    its older shape (the campaign's ``compare.csv``)."""
    row: dict = {"log": log, "mission": None, "descents": len(descents)}
    if meta is not None:
        row["outcome"] = flight_outcome(meta)
        row["abort_reason"] = flight_abort_reason(meta)
    p = primary_descent(descents, events)
    if p is not None:
        row.update({k: p.get(k) for k in COMPARE_KEYS})
        row.update(descent_wind_keys(p))
        row["start_height_m"] = p.get("start_alt_m")
    elif len(descents):  # no main descent: the flight's mission and trajectory still say what it was
        row.update({k: descents.iloc[0].get(k) for k in ("mission", "trajectory")})
    if main is not None:  # the analysis's record of it: the same figures as analyse --json and fly --json
        if p is not None:
            row.update({k: main.get(k) for k in MAIN_FIGURES})
        # where it started and what was planned, even for a descent the abort cut before it was one
        row.update(start_height_m=main.get("start_height_m"), planned_descent_s=main.get("planned_descent_s"),
                   planned_height_m=main.get("planned_height_m"), main_basis=main.get("basis"))  # fmt: skip
        row.update({k: main.get(k) for k in EFFICIENCY_KEYS})  # hover to hover against the planner's optimum
    row["main_descent_note"] = no_main_descent_why(descents, events)
    if events is not None and any(e.get("event") == "stream_start" for e in events):  # flighttest's own flight
        flown = flown_descent(events)
        row["descent_time_s"] = None if flown is None else flown["duration_s"]
        row["horizontal_error_m"] = None if flown is None else flown["horizontal_error_m"]
    if params is not None:
        from flighttest.analysis.params import relevant

        row["params"] = relevant(params)
    return row


def add_param_differences(rows: list[dict]) -> list[dict]:
    """``param_differences`` of each row: {name: this flight's value (None: its log lacks it)} for the
    relevant parameters not the same in every flight compared (``flighttest.analysis.params.differences``;
    a log without parameters takes no part). Rows without ``params`` count as logs without parameters."""
    from flighttest.analysis.params import differences

    diff = differences([row.get("params") or {} for row in rows])
    for i, row in enumerate(rows):
        row["param_differences"] = {name: values[i] for name, values in diff.items()}
    return rows


def _num(row: dict, key: str) -> float | None:
    v = row.get(key)
    return float(v) if isinstance(v, int | float) and math.isfinite(v) else None


def descent_differs(row: dict, first: dict, tol_m: float = SAME_DESCENT_TOL_M) -> str | None:
    """How ``row``'s main descent differs from ``first``'s in start height or height (module docstring),
    None when they are alike or a figure is missing."""
    planned = all(r.get("main_basis") == BASIS_PLANNED and _num(r, "planned_height_m") is not None
                  for r in (row, first))  # fmt: skip
    hkey = "planned_height_m" if planned else "height_m"
    out = []
    for key, what in (("start_height_m", "starts at"), (hkey, "plans to descend" if planned else "descends")):
        a, b = _num(row, key), _num(first, key)
        if a is not None and b is not None and abs(a - b) > tol_m:
            out.append(f"{what} {a:.2f} m against {b:.2f} m")
    return " and ".join(out) or None


def add_speedup(rows: list[dict], key: str = "duration_s", allow_unequal: bool = False) -> list[dict]:
    """``speedup_vs_first`` = the first row's descent duration (``key``; a flighttest log's: its
    ``descent_time_s``, None when it has none) / this row's (None where undefined), and
    ``descent_differs`` (:func:`descent_differs` against the first row): where it is set, no speed-up
    unless ``allow_unequal``."""

    for row in rows:
        ratio = _ratio(rows[0], row, key)
        row["descent_differs"] = descent_differs(row, rows[0]) if row is not rows[0] else None
        refused = row["descent_differs"] is not None and not allow_unequal
        row["speedup_vs_first"] = ratio if not refused else None
    return rows


def _ratio(first: dict, row: dict, key: str) -> float | None:
    """The first row's descent duration over this row's, None where either is missing (a flighttest log
    without a descent time, not reached or a probe, has none to compare)."""
    base, dur = (r.get("descent_time_s") if "descent_time_s" in r else r.get(key) for r in (first, row))
    ok = isinstance(base, int | float) and isinstance(dur, int | float) and math.isfinite(base) and math.isfinite(dur)
    return base / dur if ok and base > 0 and dur > 0 else None


def refused_speedups(rows: list[dict], names: list[str] | None = None, key: str = "duration_s") -> str | None:
    """The one line saying which speed-ups :func:`add_speedup` refused and why (None when none was)."""
    names = names or [str(row.get("log")) for row in rows]
    bad = [(n, row["descent_differs"]) for n, row in zip(names, rows) if row.get("descent_differs")
           and row.get("speedup_vs_first") is None and _ratio(rows[0], row, key) is not None]  # fmt: skip
    if not bad:
        return None
    what = "; ".join(f"{n} {why}" for n, why in bad)
    return f"no speed-up across unequal descents: {what} (the first log's); --allow-unequal gives it anyway"
