"""What one flighttest flight proved about its margins: the evidence a build-up narrows the next one by.

From a flight's log folder (docs/CONTRACTS.md "Flight log folders"):

- **the guard's least margin over the descent** (``guard.csv`` ``margin_mps`` from ``stream_start`` to
  ``stream_end``): how close the estimated state came to the guard's bound, the wind's uncertainty
  included, and whether the guard said anything but ``ok`` there; beside it the plan's own least margin
  (``preflight.json``): what the flight used is the difference. The guard also acts on its prediction (a
  horizon ahead along the vehicle's trend) beyond its clear-violation band, so how close it came to acting is
  the least of the two (``min_acting_margin_mps``): PX4 SITL's vertical kept 0.126 m/s measured and 0.057 m/s
  predicted, and the next one, planned on the 0.126, aborted on its prediction (bench/RESULTS.md);
- **the tracking error**: the estimated velocity against the plan's, over the descent (95th percentile
  of the difference's magnitude), from ``flighttest.analysis.plan_track``;
- **the estimate's error**: the estimator's climb rate against the barometer's, in 2 s windows over the
  whole time in the air, twice its RMS (the barometer's own noise taken out; :func:`estimate_error`).
  Holding its estimated height, a vehicle whose velocity estimate is off really moves, and the barometer
  sees it; in the descent the two disagree by the estimate's error. One snapshot (the hover before the
  descent, as first tried) caught 0.13 m/s of an error that reached 0.27 m/s in the descent that followed
  on the fake's PX4 (bench/RESULTS.md, "The build-up"). A log without a barometer has none: the budget then
  keeps its default.

Only flighttest folders carry the plan and the guard's log; for anything else this raises.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from flighttest.errors import FlighttestError
from flighttest.flying.missions_config import GuardConfig

WINDOW_S = 2.0  # the estimate judged against the barometer over windows this long (ArduCopter's 2 Hz of it too)
MIN_BARO_SAMPLES = 4  # per window
MIN_WINDOWS = 5  # fewer: not measured
AIRBORNE_M = 1.0  # the estimate judged while the vehicle is this far above where it started
QUIET_VERDICTS = ("ok",)  # guard.csv verdicts that mean the guard had nothing to say


@dataclass(frozen=True)
class MarginEvidence:
    """What a flight proved (m/s throughout; None where the log cannot say)."""

    log_dir: str
    outcome: str | None
    min_margin_mps: float | None  # the guard's least margin over the descent (negative: inside its bound)
    plan_min_margin_mps: float | None  # the plan's own least margin to the guard's bound (the preflight's)
    guard_flags: int  # guard.csv rows over the descent whose verdict was not ok
    guard_aborts: int  # guard.csv rows anywhere in the flight whose action was abort
    tracking_mps: float | None  # 95th percentile of |v estimated − v planned| over the descent
    estimate_mps: float | None  # 2 × RMS of the climb rate, estimator − barometer, in the air
    estimate_source: str  # which barometer, or why not measured
    hover_to_hover_s: float | None
    flown_over_optimum: float | None
    # the least of min_margin_mps and the guard's predicted margin beyond its clear-violation band (where it acts)
    min_acting_margin_mps: float | None = None

    @property
    def guard_silent(self) -> bool:
        return self.guard_flags == 0 and self.guard_aborts == 0

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "guard_silent": self.guard_silent}


def _events(folder: Path) -> list[dict[str, Any]]:
    path = folder / "events.jsonl"
    out = []
    if path.is_file():
        for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
            try:
                e = json.loads(line)
            except ValueError:
                continue  # a line cut by a killed process: the rest still counts
            if isinstance(e, dict):
                out.append(e)
    return out


def _event_t(events: list[dict[str, Any]], name: str) -> float | None:
    for e in events:
        if e.get("event") == name and isinstance(e.get("t_s"), int | float) and math.isfinite(e["t_s"]):
            return float(e["t_s"])
    return None


def guard_over(guard: pd.DataFrame, t0_s: float, t1_s: float) -> tuple[float | None, int]:
    """The guard's least margin and how many of its verdicts were not ok, for rows in ``[t0_s, t1_s]``."""
    rows = guard[(guard["t_s"] >= t0_s) & (guard["t_s"] <= t1_s)]
    margins = pd.to_numeric(rows["margin_mps"], errors="coerce").to_numpy(float)
    margins = margins[np.isfinite(margins)]
    flags = int((~rows["verdict"].astype(str).isin(QUIET_VERDICTS)).sum())
    return (float(margins.min()) if margins.size else None), flags


def acting_over(guard: pd.DataFrame, t0_s: float, t1_s: float, clear_violation_mps: float) -> float | None:
    """How close the guard came to acting over ``[t0_s, t1_s]``: the least of its margin and of its predicted
    margin plus the clear-violation band (a prediction acts only beyond it: ``flighttest.flying.guard``)."""
    rows = guard[(guard["t_s"] >= t0_s) & (guard["t_s"] <= t1_s)]
    m = pd.to_numeric(rows["margin_mps"], errors="coerce").to_numpy(float)
    if "predicted_margin_mps" in rows:
        p = pd.to_numeric(rows["predicted_margin_mps"], errors="coerce").to_numpy(float) + clear_violation_mps
        m = np.concatenate([m, p])
    m = m[np.isfinite(m)]
    return float(m.min()) if m.size else None


def _clear_violation(meta: dict[str, Any]) -> float:
    """The guard's clear-violation band the flight flew with (the log's ``meta.json``), else the default."""
    try:
        v = meta["config"]["guard"]["clear_violation_mps"]
    except (KeyError, TypeError):
        v = None
    ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v >= 0
    return float(v) if ok else GuardConfig().clear_violation_mps


def estimate_error(t_s: np.ndarray, vd_mps: np.ndarray, baro_t_s: np.ndarray, baro_alt_m: np.ndarray,
                   t0_s: float, t1_s: float, window_s: float = WINDOW_S) -> float | None:  # fmt: skip
    """Twice the RMS disagreement between the estimator's climb rate and the barometer's over ``[t0_s, t1_s]``:
    in windows of ``window_s`` (half overlapping), the least-squares rate of the barometer's height less the
    height the estimator's own velocity climbs, at the barometer's samples (the same weighting of the same
    true velocity: a least-squares slope weighs a window's middle, a mean weighs it evenly, and through a
    helix's speed changes the two differ by up to 0.2 m/s), the barometer's own noise (each fit's standard
    error) taken out in quadrature. None with fewer than ``MIN_WINDOWS`` windows of at least
    ``MIN_BARO_SAMPLES`` barometer samples."""
    ok = np.isfinite(t_s) & np.isfinite(vd_mps)
    t, vd = t_s[ok], vd_mps[ok]
    if t.size < 2:
        return None
    climbed_m = np.concatenate([[0.0], np.cumsum(-0.5 * (vd[1:] + vd[:-1]) * np.diff(t))])
    d2, se2 = [], []
    for a in np.arange(t0_s, t1_s - window_s + 1e-9, window_s / 2.0):
        b = (baro_t_s >= a) & (baro_t_s < a + window_s) & np.isfinite(baro_alt_m)
        e = (t >= a) & (t < a + window_s)
        if b.sum() < MIN_BARO_SAMPLES or e.sum() < 2:
            continue
        x = baro_t_s[b] - baro_t_s[b].mean()
        sxx = float((x * x).sum())
        if sxx <= 0:
            continue
        y = baro_alt_m[b] - np.interp(baro_t_s[b], t, climbed_m)
        y = y - y.mean()
        slope = float((x * y).sum() / sxx)
        resid = y - slope * x
        se2.append(float((resid * resid).sum()) / max(int(b.sum()) - 2, 1) / sxx)
        d2.append(slope**2)
    if len(d2) < MIN_WINDOWS:
        return None
    return 2.0 * math.sqrt(max(0.0, float(np.mean(d2)) - float(np.mean(se2))))


def airborne_window(t_s: np.ndarray, d_m: np.ndarray) -> tuple[float, float] | None:
    """From the first to the last sample more than ``AIRBORNE_M`` above where the estimate was in the log's
    first second."""
    ok = np.isfinite(t_s) & np.isfinite(d_m)
    if ok.sum() < 2:
        return None
    t, d = t_s[ok], d_m[ok]
    up = -(d - np.median(d[t <= t[0] + 1.0]))  # the log's first second: on the ground
    air = np.flatnonzero(up > AIRBORNE_M)
    return (float(t[air[0]]), float(t[air[-1]])) if air.size else None


def _tracking(log) -> float | None:
    """Over the plan until the stream's end, both on the log's own clock (zero at its first state sample), not
    flighttest's: on ArduCopter SITL the first state came 41.6 s after flighttest started (its EKF's start-up),
    and the descent on flighttest's clock missed every sample (bench/RESULTS.md, "The feed-forward lead")."""
    from flighttest.analysis.plan_track import plan_on_log

    plan = plan_on_log(log)
    if plan is None:
        return None
    end = _event_t(log.events, "stream_end")
    st = log.state
    t1 = float(plan["t_s"].iloc[-1]) if end is None else min(end, float(plan["t_s"].iloc[-1]))
    m = (st["t_s"] >= float(plan["t_s"].iloc[0])) & (st["t_s"] <= t1)
    if m.sum() < 2:
        return None
    t = st.loc[m, "t_s"].to_numpy(float)
    err = np.zeros(len(t))
    for col in ("vn_mps", "ve_mps", "vd_mps"):
        err += (st.loc[m, col].to_numpy(float) - np.interp(t, plan["t_s"], plan[col])) ** 2
    err = np.sqrt(err)
    err = err[np.isfinite(err)]
    return float(np.percentile(err, 95)) if err.size else None


def _plan_margin(folder: Path) -> float | None:
    """The preflight's least margin of the plan to the guard's bound (``preflight.json``), None without it."""
    try:
        v = json.loads((folder / "preflight.json").read_text(encoding="utf-8"))["trajectory"]["guard_margin_min_mps"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return float(v) if isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) else None


def flight_evidence(log_dir: Path | str) -> MarginEvidence:
    """The evidence of one flighttest flight folder (raises FlighttestError for anything else)."""
    from flighttest.analysis.loaders import load_log

    folder = Path(log_dir)
    guard_path = folder / "guard.csv"
    if not guard_path.is_file():
        raise FlighttestError(f"{folder}: no guard.csv: not a flighttest flight folder")
    events = _events(folder)
    t0, t1 = _event_t(events, "stream_start"), _event_t(events, "stream_end")
    wanted = {"t_s", "verdict", "margin_mps", "predicted_margin_mps", "action"}
    guard = pd.read_csv(guard_path, usecols=lambda c: c in wanted)
    guard["t_s"] = pd.to_numeric(guard["t_s"], errors="coerce")
    aborts = int((guard["action"].astype(str) == "abort").sum())
    summary: dict[str, Any] = {}
    with_summary = folder / "summary.json"
    if with_summary.is_file():
        try:
            summary = json.loads(with_summary.read_text(encoding="utf-8"))
        except ValueError:
            summary = {}
    base = {"log_dir": str(folder), "outcome": summary.get("outcome"), "guard_aborts": aborts,
            "plan_min_margin_mps": _plan_margin(folder),
            "hover_to_hover_s": summary.get("hover_to_hover_s"),
            "flown_over_optimum": summary.get("flown_over_optimum")}  # fmt: skip
    if t0 is None:
        return MarginEvidence(**base, min_margin_mps=None, guard_flags=0, tracking_mps=None, estimate_mps=None,
                              estimate_source="no descent was flown")  # fmt: skip
    t1 = t1 if t1 is not None else float(guard["t_s"].max())
    least, flags = guard_over(guard, t0, t1)
    log = load_log(folder)
    acting = acting_over(guard, t0, t1, _clear_violation(log.meta))
    tracking = _tracking(log)
    estimate, source = None, "no barometer in the log"
    st = log.state
    t, vd = st["t_s"].to_numpy(float), st["vd_mps"].to_numpy(float)
    air = airborne_window(t, st["d_m"].to_numpy(float))
    for h in (h for h in log.heights if h.kind == "baro") if air else ():
        value = estimate_error(t, vd, h.t_s, h.alt_m, *air)
        if value is None:
            if estimate is None:
                source = f"{h.name}: too little of it in the air"
            continue
        if estimate is None or value > estimate:  # two barometers: the worse disagreement
            estimate, source = value, f"2 × the RMS of the estimator's climb rate less {h.name}'s, in the air"
    return MarginEvidence(**base, min_margin_mps=least, guard_flags=flags, tracking_mps=tracking,
                          estimate_mps=estimate, estimate_source=source, min_acting_margin_mps=acting)  # fmt: skip


def no_evidence(outcome: str | None) -> MarginEvidence:
    """A flight that left no log folder (nothing answered): it proved nothing."""
    return MarginEvidence(log_dir="", outcome=outcome, min_margin_mps=None, plan_min_margin_mps=None,
                          guard_flags=0, guard_aborts=0,
                          tracking_mps=None, estimate_mps=None, estimate_source="no log",
                          hover_to_hover_s=None, flown_over_optimum=None)  # fmt: skip
