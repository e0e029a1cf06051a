"""Find the descents in a flight, time them, and flag estimator glitches.

A **descent** is a stretch where the height falls faster than ``rate_threshold_mps`` (runs closer
than ``merge_gap_s`` joined) by at least ``min_height_m``. Its **start height** is the median height
over ``settle_window_s`` before the stretch, its **end height** the median over ``settle_window_s``
starting half a window after it (the tail is still creeping at the threshold). It **starts** when
the height first falls ``start_tol_m`` below the start height and **ends** when the height comes
within ``end_tol_m`` of the end height and stays there for ``settle_hold_s`` (so an overshoot or a
bounce counts as part of the descent). Crossing times are interpolated between samples, and the
rate (the central difference of the height over ``smooth_s``) and the start/end heights (medians over
time of the interpolated height) are defined in time rather than in samples, so one flight logged at
different rates (PX4's 125 Hz ``.ulg``, our jittery 50 Hz ``.tlog``) gives the same descents. All
thresholds live in :class:`SegmentConfig`. A descent's mean and max rates both come from the height
it was timed on: the mean is its height over its duration, the max the fastest fall of the same
height over ``smooth_s``, never below the mean (an estimator's velocity can read 0.4 m/s while its
height falls at 0.16, and a max below the mean says nothing true).

A window known to hold one descent (a flighttest flight's main descent, timed from its events by
:mod:`flighttest.analysis.descent_time`) is passed as ``exclude``: no descent found here starts, ends or
merges across it, so the one descent there is not cut into pieces at its slow spots, nor joined to the
landing that follows it.

An **estimator glitch** is a sample whose altitude jumps away from its neighbours (more than
``glitch_jump_m`` off the running median over ``glitch_window_s``, or moving faster than
``glitch_speed_mps`` between samples): an altitude "jumping through the ground". Glitch samples are
flagged (``state.glitch``), bridged by interpolation for the segmentation, and reported as glitches
of kind ``"jump"``, never as descents. Samples the height arbitration already bridged
(:mod:`flighttest.analysis.heights`, its ``"disagreement"`` glitches, passed as ``bridged``) are
flagged the same way but not re-interpolated: their height is already the other sources'.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from flighttest.analysis.descent_time import RATE_WINDOW_S
from flighttest.inputs import MAX_DURATION_S, MAX_HEIGHT_M, MAX_HORIZONTAL_M, MAX_SPEED_MPS, Range


@dataclass(frozen=True)
class SegmentConfig:
    rate_threshold_mps: float = 0.15  # a descent falls at least this fast (smoothed)
    min_height_m: float = 0.5  # smaller drops are station-keeping, not descents
    merge_gap_s: float = 1.0  # pauses shorter than this do not split a descent
    smooth_s: float = RATE_WINDOW_S  # centred moving average on rates, against sensor noise
    settle_window_s: float = 1.0  # start/end heights: medians over this long outside the descent
    start_tol_m: float = 0.05  # the descent starts once this far below the start height
    end_tol_m: float = 0.10  # ... and ends once within this of the end height
    settle_hold_s: float = 0.5  # ... for at least this long
    glitch_jump_m: float = 2.0  # altitude this far off its running median is a glitch
    glitch_window_s: float = 2.0  # running-median window for the glitch test
    glitch_speed_mps: float = 25.0  # altitude moving faster than this between samples is a glitch

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            SEGMENT_RANGES[name].check(value, f"segmentation threshold {name}")


# Every threshold is positive and physically bounded: an unbounded one overflowed into a sample count
# (``settle_hold_s = 1e308`` → OverflowError). Heights, speeds and durations as flighttest.inputs
# bounds them; a glitch speed may go to ten times any multicopter's (that turns the speed test off).
SEGMENT_RANGES: dict[str, Range] = {
    "rate_threshold_mps": Range(0.0, MAX_SPEED_MPS, "m/s", lo_open=True),
    "min_height_m": Range(0.0, MAX_HEIGHT_M, "m", lo_open=True),
    "merge_gap_s": Range(0.0, MAX_DURATION_S, "s", lo_open=True),
    "smooth_s": Range(0.0, MAX_DURATION_S, "s", lo_open=True),
    "settle_window_s": Range(0.0, MAX_DURATION_S, "s", lo_open=True),
    "start_tol_m": Range(0.0, MAX_HEIGHT_M, "m", lo_open=True),
    "end_tol_m": Range(0.0, MAX_HEIGHT_M, "m", lo_open=True),
    "settle_hold_s": Range(0.0, MAX_DURATION_S, "s", lo_open=True),
    "glitch_jump_m": Range(0.0, MAX_HORIZONTAL_M, "m", lo_open=True),
    "glitch_window_s": Range(0.0, MAX_DURATION_S, "s", lo_open=True),
    "glitch_speed_mps": Range(0.0, 10 * MAX_SPEED_MPS, "m/s", lo_open=True),
}


def samples_in(t: np.ndarray, seconds: float) -> int:
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    return max(1, round(seconds / max(dt, 1e-6)))


def flag_glitches(t: np.ndarray, d: np.ndarray, cfg: SegmentConfig) -> np.ndarray:
    """Boolean mask of altitude samples that jump away from their neighbours."""
    win = samples_in(t, cfg.glitch_window_s) | 1
    med = pd.Series(d).rolling(win, center=True, min_periods=1).median().to_numpy()
    off = np.abs(d - med) > cfg.glitch_jump_m
    speed = np.abs(np.diff(d)) / np.maximum(np.diff(t), 1e-6)
    fast = np.zeros(len(d), dtype=bool)
    fast[1:] |= speed > cfg.glitch_speed_mps
    fast[:-1] |= speed > cfg.glitch_speed_mps
    # a fast step that the running median does not see is a real step only if it persists: keep only
    # fast samples that are also off the median, or isolated spikes (both neighbours fast)
    return off | (fast & (np.abs(d - med) > 0.5 * cfg.glitch_jump_m))


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) indices of the True runs."""
    if not mask.any():
        return []
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1))


def _rate(t: np.ndarray, h: np.ndarray, width_s: float) -> np.ndarray:
    """Descent rate (down-positive) of the up-positive height ``h``: the central difference of the
    linearly interpolated height over ``width_s`` (clipped at the log's ends), which is the derivative
    of its centred moving average over that time. Defined in time rather than in samples, so one
    flight logged at 125 Hz (PX4's ``.ulg``) and at a jittery 50 Hz (our ``.tlog``) gives the same
    rate, the same runs above the threshold and the same descents: a moving average over a number of
    samples differs with the rate, and near the threshold a slow creep then chatters into one log's
    runs and not the other's, which moved a probe descent's start by 1.8 s."""
    hi = np.minimum(t + 0.5 * width_s, t[-1])
    lo = np.maximum(t - 0.5 * width_s, t[0])
    return -(np.interp(hi, t, h) - np.interp(lo, t, h)) / np.maximum(hi - lo, 1e-9)


def _level(t: np.ndarray, h: np.ndarray, lo_s: float, hi_s: float, points: int = 201) -> float:
    """Median height over ``[lo_s, hi_s]`` (clipped to the log) of the linearly interpolated height,
    on a uniform grid: a time-weighted median, the same whatever the sampling (a median of samples
    shifts with where the samples fall when the vehicle is still moving)."""
    lo_s, hi_s = max(lo_s, float(t[0])), min(hi_s, float(t[-1]))
    if hi_s < lo_s:
        lo_s = hi_s = min(max(lo_s, float(t[0])), float(t[-1]))
    return float(np.median(np.interp(np.linspace(lo_s, hi_s, points), t, h)))


def _crossing(t: np.ndarray, h: np.ndarray, i: int, level: float) -> float:
    """Time where h crosses ``level`` between samples i−1 and i (linear)."""
    if i <= 0 or h[i] == h[i - 1]:
        return float(t[i])
    f = (level - h[i - 1]) / (h[i] - h[i - 1])
    return float(t[i - 1] + np.clip(f, 0.0, 1.0) * (t[i] - t[i - 1]))


# One row per glitch span, whichever found it: "jump" (here) or "disagreement" (heights.py). ``source``
# is the height that went wrong, ``sources`` what every height source said at the worst instant.
GLITCH_COLUMNS = ["start_s", "end_s", "duration_s", "max_jump_m", "kind", "source", "sources"]


def glitch_table(t: np.ndarray, d: np.ndarray, glitch: np.ndarray, source: str | None = None) -> pd.DataFrame:
    """The "jump" glitch spans of height ``d`` (NED down) flagged in ``glitch``."""
    rows = []
    for a, b in true_runs(glitch):
        ref = d[a - 1] if a > 0 else d[b + 1] if b + 1 < len(d) else np.nan
        rows.append(
            {
                "start_s": float(t[a]),
                "end_s": float(t[b]),
                "duration_s": float(t[b] - t[a]),
                "max_jump_m": float(np.nanmax(np.abs(d[a : b + 1] - ref))),
                "kind": "jump",
                "source": source,
                "sources": {},
            }
        )
    return pd.DataFrame(rows, columns=GLITCH_COLUMNS)


def find_descents(
    state: pd.DataFrame,
    cfg: SegmentConfig | None = None,
    bridged: np.ndarray | None = None,
    source: str | None = None,
    exclude: tuple[float, float] | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(descents, jump glitches). Sets ``state['glitch']`` (jumps and ``bridged`` samples). Descent
    columns: see module docstring and ``DESCENT_COLUMNS``; times on the state clock ``t_s``.
    ``source`` names the height ``d_m`` holds, for the glitch table; ``exclude`` (start, end) is a
    window no descent found here may touch (module docstring)."""
    cfg = cfg or SegmentConfig()
    t = state["t_s"].to_numpy(float)
    d_raw = state["d_m"].to_numpy(float)
    jump = flag_glitches(t, d_raw, cfg)
    glitch = jump if bridged is None else jump | np.asarray(bridged, dtype=bool)
    state["glitch"] = glitch
    d = d_raw.copy()
    if jump.any() and (~jump).sum() >= 2:
        d[jump] = np.interp(t[jump], t[~jump], d_raw[~jump])
    h = -d
    rate = _rate(t, h, cfg.smooth_s)
    falling = rate > cfg.rate_threshold_mps
    if exclude is not None:
        falling &= ~((t >= exclude[0]) & (t <= exclude[1]))
    runs = true_runs(falling)
    merged: list[list[int]] = []
    for a, b in runs:
        across = bool(merged) and exclude is not None and t[merged[-1][1]] < exclude[0] <= t[a]
        if merged and t[a] - t[merged[-1][1]] < cfg.merge_gap_s and not across:
            merged[-1][1] = b
        else:
            merged.append([a, b])
    i_excl = int(np.searchsorted(t, exclude[0])) if exclude is not None else len(t)

    n_e, e = state["n_m"].to_numpy(float), state["e_m"].to_numpy(float)
    rows = []
    for k, (a, b) in enumerate(merged):
        # a descent ends before the next one starts (an oscillating probe revisits old heights later)
        limit = merged[k + 1][0] if k + 1 < len(merged) else len(t)
        if a < i_excl:  # ... nor into the excluded window after it
            limit = min(limit, i_excl)
        before = (t >= t[a] - cfg.settle_window_s) & (t <= t[a])
        # the stretch from where the rate crosses the threshold (between samples), so the windows
        # below sit at the same instants however the log was sampled
        t_a = _crossing(t, rate, a, cfg.rate_threshold_mps)
        t_b = _crossing(t, rate, b + 1, cfg.rate_threshold_mps) if b + 1 < len(t) else float(t[b])
        h0 = _level(t, h, t_a - cfg.settle_window_s, t_a)
        # the end height is measured half a window later: the tail of a descent is still creeping
        if t_b + 0.5 * cfg.settle_window_s <= t[-1]:
            h1 = _level(t, h, t_b + 0.5 * cfg.settle_window_s, t_b + 1.5 * cfg.settle_window_s)
        else:
            h1 = _level(t, h, float(t[b]), float(t[-1]))
        if h0 - h1 < cfg.min_height_m:
            continue
        lo = int(np.flatnonzero(before)[0])
        # leave from the last sample still at the start height (a vehicle still creeping up to its
        # start height before the window's end has not started descending)
        at_start = np.flatnonzero(h[lo : a + 1] >= h0 - cfg.start_tol_m)
        first = lo + (int(at_start[-1]) if len(at_start) else 0)
        below = np.flatnonzero(h[first : b + 1] < h0 - cfg.start_tol_m)
        if len(below) == 0:
            continue
        i0 = first + int(below[0])
        t0 = _crossing(t, h, i0, h0 - cfg.start_tol_m)
        # end: first sample from which |h − h1| ≤ tol for settle_hold_s; unsettled descents end where
        # they first reach the end band (or just before the next descent starts)
        hold_n = samples_in(t, cfg.settle_hold_s)
        inside = np.abs(h[i0:limit] - h1) <= cfg.end_tol_m
        stay = pd.Series(inside[::-1]).rolling(hold_n, min_periods=1).min().to_numpy()[::-1].astype(bool)
        cand = np.flatnonzero(inside & stay)
        reached = np.flatnonzero(inside)
        if len(cand):
            i1 = i0 + int(cand[0])
        else:
            i1 = i0 + int(reached[0]) if len(reached) else max(limit - 1, i0)
        level = h1 + cfg.end_tol_m if h[i1 - 1] > h1 else h1 - cfg.end_tol_m
        t1 = _crossing(t, h, i1, level) if len(cand) or len(reached) else float(t[i1])
        span = slice(max(i0 - 1, 0), i1 + 1)
        horiz = np.hypot(n_e[span] - n_e[i0], e[span] - e[i0])
        mean = (h0 - h1) / max(t1 - t0, 1e-9)
        during = (t >= t0) & (t <= t1)
        fastest = float(np.nanmax(rate[during])) if np.isfinite(rate[during]).any() else mean
        rows.append(
            {
                "start_s": t0,
                "end_s": t1,
                "duration_s": t1 - t0,
                "height_m": h0 - h1,
                "start_alt_m": h0,
                "end_alt_m": h1,
                "mean_rate_mps": mean,
                # the height's own rate, as the mean; at least the mean (module docstring)
                "max_rate_mps": max(fastest, mean),
                "horizontal_excursion_m": float(np.nanmax(horiz)),
                "glitch": bool(glitch[span].any()),
                "settled": bool(len(cand)),
            }
        )
    descents = pd.DataFrame(rows, columns=DESCENT_COLUMNS)
    descents.insert(0, "descent", np.arange(1, len(descents) + 1))
    return descents, glitch_table(t, d_raw, jump, source)


DESCENT_COLUMNS = [
    "start_s",
    "end_s",
    "duration_s",
    "height_m",
    "start_alt_m",
    "end_alt_m",
    "mean_rate_mps",
    "max_rate_mps",
    "horizontal_excursion_m",
    "glitch",
    "settled",
]
