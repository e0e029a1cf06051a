"""Descents side by side: the main descent of each flight and its speed-up over the first flight's."""

from __future__ import annotations

import math

import pandas as pd

from flighttest.analysis.descent_time import TIMED_EVENT, is_abort_phase

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
    """The descent a flight was about: the one flown in the 'stream' phase, else the highest; never one
    the abort ladder flew (:func:`_main_candidates`: ``events`` tell when the abort began). None when
    there is no other (:func:`no_main_descent_why` says why)."""
    if not len(d):
        return None
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
    summary = meta.get("summary") if isinstance(meta, dict) else None
    outcome = summary.get("outcome") if isinstance(summary, dict) else None
    return outcome if isinstance(outcome, str) and outcome else None


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
) -> dict:
    """One row of ``flighttest compare``: the log, how many descents, its main descent's figures and the
    wind it was judged with (:func:`descent_wind_keys`; ``main_descent_note`` says why there is none:
    only the abort ladder's descents) and, for
    flighttest's own logs, ``descent_time_s`` and ``horizontal_error_m`` (see ``flown_descent``).

    Given the log's ``meta`` the row gets ``outcome`` (:func:`flight_outcome`); given its parameters,
    ``params``: the ones that shape these tests (``flighttest.analysis.params.relevant``). Without
    them the row keeps its older shape (the campaign's ``compare.csv``)."""
    row: dict = {"log": log, "mission": None, "descents": len(descents)}
    if meta is not None:
        row["outcome"] = flight_outcome(meta)
    p = primary_descent(descents, events)
    if p is not None:
        row.update({k: p.get(k) for k in COMPARE_KEYS})
        row.update(descent_wind_keys(p))
    elif len(descents):  # no main descent: the flight's mission and trajectory still say what it was
        row.update({k: descents.iloc[0].get(k) for k in ("mission", "trajectory")})
    row["main_descent_note"] = no_main_descent_why(descents, events)
    if events is not None:
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


def add_speedup(rows: list[dict], key: str = "duration_s") -> list[dict]:
    """``speedup_vs_first`` = the first row's descent duration (``key``) / this row's (None where undefined)."""
    base = rows[0].get(key) if rows else None
    for row in rows:
        dur = row.get(key)
        ok = base and dur and math.isfinite(base) and math.isfinite(dur) and dur > 0
        row["speedup_vs_first"] = base / dur if ok else None
    return rows
