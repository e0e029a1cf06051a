"""The plan a flighttest flight flew, on its log's clock, and how far the vehicle was from it.

A log folder holds ``trajectory.csv`` (the plan, relative to its start) and the ``stream_start`` event
(``origin_ned``: where that start was in the autopilot's local frame, and when). The plan on the log
is ``origin + row`` at ``stream_start + t_s``: what the vehicle was asked to fly, before the feed-forward
the runner adds (``setpoints.csv`` holds what was sent). The tracking error is the flown position (the
estimator's own, the frame the plan was flown in) minus the plan at the same instant, over the plan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from flighttest.analysis.descent_time import PlannedDescent, planned_descent

PLAN_COLUMNS = ["t_s", "n_m", "e_m", "d_m", "vn_mps", "ve_mps", "vd_mps"]
TRACKING_COLUMNS = ["t_s", "north_m", "east_m", "down_m", "horizontal_m", "vertical_m", "total_m"]


def read_plan(folder: Path) -> pd.DataFrame | None:
    """``trajectory.csv`` of a log folder (``PLAN_COLUMNS``, relative to the start), None when absent or broken."""
    path = Path(folder) / "trajectory.csv"
    if not path.is_file():
        return None
    try:
        df = pd.read_csv(path, usecols=PLAN_COLUMNS).apply(pd.to_numeric, errors="coerce")
    except (OSError, ValueError, KeyError):
        return None
    if not len(df) or not np.isfinite(df.to_numpy(float)).all() or not (np.diff(df["t_s"]) > 0).all():
        return None
    return df


def _stream_start(events: list[dict]) -> dict | None:
    return next((e for e in events or () if e.get("event") == "stream_start" and isinstance(e.get("t_s"), int | float)),
                None)  # fmt: skip


def plan_on_log(log) -> pd.DataFrame | None:
    """The plan on the log's clock and in its local frame (``PLAN_COLUMNS``), None for logs without one
    (other programs' logs, folders without ``trajectory.csv`` or a ``stream_start`` with its origin)."""
    if log.path is None or not Path(log.path).is_dir():
        return None
    start = _stream_start(log.events)
    origin = start.get("origin_ned") if start else None
    if not (isinstance(origin, list | tuple) and len(origin) == 3
            and all(isinstance(x, int | float) and math.isfinite(x) for x in origin)):  # fmt: skip
        return None
    plan = read_plan(Path(log.path))
    if plan is None:
        return None
    out = plan.copy()
    out["t_s"] = plan["t_s"] - float(plan["t_s"].iloc[0]) + float(start["t_s"])
    for col, o in zip(("n_m", "e_m", "d_m"), origin):
        out[col] = plan[col] + float(o)
    return out


def planned(log) -> PlannedDescent | None:
    """The flight's plan timed by the descent-time rule (``descent_time.planned_descent``)."""
    plan = read_plan(Path(log.path)) if log.path is not None and Path(log.path).is_dir() else None
    if plan is None:
        return None
    return planned_descent(plan["t_s"], plan["n_m"], plan["e_m"], plan["d_m"], plan["vd_mps"])


def tracking_error(state: pd.DataFrame, plan: pd.DataFrame, until_s: float | None = None) -> pd.DataFrame:
    """Flown minus planned position at each state sample from the plan's start until ``until_s`` (the end
    of the descent's phases: the plan's end point is held after its last row), else over the plan's span
    (``TRACKING_COLUMNS``)."""
    t = state["t_s"].to_numpy(float)
    tp = plan["t_s"].to_numpy(float)
    end = tp[-1] if until_s is None or not math.isfinite(until_s) else until_s
    sel = (t >= tp[0]) & (t <= end)
    d = state["d_est_m"] if "d_est_m" in state else state["d_m"]  # the frame the plan was flown in
    err = {}
    for name, flown, col in (("north_m", state["n_m"], "n_m"), ("east_m", state["e_m"], "e_m"), ("down_m", d, "d_m")):
        err[name] = flown.to_numpy(float)[sel] - np.interp(t[sel], tp, plan[col].to_numpy(float))
    out = pd.DataFrame({"t_s": t[sel], **err})
    out["horizontal_m"] = np.hypot(out["north_m"], out["east_m"])
    out["vertical_m"] = out["down_m"].abs()
    out["total_m"] = np.hypot(out["horizontal_m"], out["down_m"])
    return out[TRACKING_COLUMNS]


@dataclass(frozen=True)
class TrackingSummary:
    """The tracking error over the plan, in numbers (``Analysis.summary()["tracking_error"]``)."""

    max_m: float
    rms_m: float
    max_horizontal_m: float
    max_vertical_m: float
    at_max_s: float

    def record(self) -> dict[str, float | None]:
        def r(x):
            return round(float(x), 3) if math.isfinite(x) else None

        return {"max_m": r(self.max_m), "rms_m": r(self.rms_m), "max_horizontal_m": r(self.max_horizontal_m),
                "max_vertical_m": r(self.max_vertical_m), "at_max_s": r(self.at_max_s)}  # fmt: skip


def summarise(err: pd.DataFrame) -> TrackingSummary | None:
    total = err["total_m"].to_numpy(float)
    ok = np.isfinite(total)
    if not ok.any():
        return None
    k = int(np.nanargmax(total))
    return TrackingSummary(float(total[k]), float(np.sqrt(np.mean(total[ok] ** 2))),
                           float(np.nanmax(err["horizontal_m"])), float(np.nanmax(err["vertical_m"])),
                           float(err["t_s"].iloc[k]))  # fmt: skip
