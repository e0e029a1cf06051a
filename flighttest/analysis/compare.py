"""Descents side by side: the main descent of each flight and its speed-up over the first flight's."""

from __future__ import annotations

import math

import pandas as pd

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
)


def primary_descent(d: pd.DataFrame) -> pd.Series | None:
    """The descent a flight was about: the one flown in the 'stream' phase, else the highest."""
    if not len(d):
        return None
    ok = d[~d["glitch"]] if "glitch" in d else d
    ok = ok if len(ok) else d
    streamed = ok[ok["phase"].astype(str) == "stream"] if "phase" in ok else ok.iloc[0:0]
    pick = streamed if len(streamed) else ok
    return pick.loc[pick["height_m"].idxmax()]


def flown_descent(events: list[dict]) -> pd.Series | None:
    """The descent as flighttest flew it, from a log folder's events: from the first setpoint of the
    planned descent (``stream_start``) until the vehicle was at rest within 0.2 m of the end point
    (``descent_reached``) — the paper's t_f, rest to rest. None for other logs or unfinished descents."""
    start = next((e["t_s"] for e in events if e.get("event") == "stream_start" and "t_s" in e), None)
    dur = next((e["descent_time_s"] for e in events if e.get("event") == "descent_reached"), None)
    if not isinstance(start, int | float) or not isinstance(dur, int | float) or not math.isfinite(dur):
        return None
    return pd.Series({"start_s": float(start), "end_s": float(start) + float(dur), "duration_s": float(dur)})


def flight_outcome(meta: dict | None) -> str | None:
    """How a flighttest flight ended (``summary.json`` ``outcome``: completed, aborted, probe_stopped,
    ...); None for logs of other tools and for flights whose process never wrote its summary."""
    summary = meta.get("summary") if isinstance(meta, dict) else None
    outcome = summary.get("outcome") if isinstance(summary, dict) else None
    return outcome if isinstance(outcome, str) and outcome else None


def compare_row(
    log: str,
    descents: pd.DataFrame,
    events: list[dict] | None = None,
    meta: dict | None = None,
    params: dict | None = None,
) -> dict:
    """One row of ``flighttest compare``: the log, how many descents, its main descent's figures and,
    for flighttest's own logs, ``descent_time_s`` (rest to rest, see ``flown_descent``).

    Given the log's ``meta`` the row gets ``outcome`` (:func:`flight_outcome`); given its parameters,
    ``params``: the ones that shape these tests (``flighttest.analysis.params.relevant``). Without
    them the row keeps its older shape (the campaign's ``compare.csv``)."""
    row: dict = {"log": log, "mission": None, "descents": len(descents)}
    if meta is not None:
        row["outcome"] = flight_outcome(meta)
    p = primary_descent(descents)
    if p is not None:
        row.update({k: p[k] for k in COMPARE_KEYS})
    if events is not None:
        flown = flown_descent(events)
        row["descent_time_s"] = None if flown is None else flown["duration_s"]
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
