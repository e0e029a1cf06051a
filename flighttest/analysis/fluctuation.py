"""Fluctuation: how much the vehicle shakes, against its own hover. The one home of its definitions.

Three parts of flighttest measure it, for three jobs. One measure cannot serve all three without
changing what each already decides, so each is defined once, and ``tests/test_fluctuation_tie.py``
ties them: the same signal (hover noise, then a growing oscillation) gives the live guard and this
module's replay of it the same value sample for sample, and all three the same onset to within a
window.

1. **The live guard's measure** (:func:`window_detrended_std`, :func:`trailing_detrended_std`,
   :func:`live_fluctuation`, :func:`hover_baseline`, :func:`fluct_threshold`): per signal, the
   standard deviation about its least-squares line over the *trailing* ``window_s`` (the guard
   cannot look ahead; the line, not a mean, so a steady turn or the probe's slow sweep of the
   commanded acceleration is not shaking); the largest of the three body rates in deg/s, and the
   vertical acceleration; against the median over the hover before streaming times a ratio, never
   below a minimum. The guard takes its window rules (``LIVE_MIN_SAMPLES``,
   ``LIVE_MIN_SPAN_FRACTION``), its baseline and its threshold from here. Its streaming form,
   ``flighttest.flying.guard.FluctuationDetector``, stays separate from :func:`trailing_detrended_std`
   for a reason: it sees one sample at a time on the flying process's event loop, four windows per
   IMU sample, and in plain floats a 25-sample window costs about 6 µs where a numpy call on it
   costs about 45 µs; a replay has the whole series and does every window in one vectorised pass.
2. **The post-flight metrics** (:func:`fluctuation`, below): a log can look both ways, so the
   windows are centred on when the shaking happened (a descent's maximum belongs to that descent,
   not to half a window after it); the trend removed is a centred moving average; the RMS is over a
   longer window for steadier per-descent maxima, the axes add in quadrature, the motors' spread
   counts too, and the hover is found in the log itself (speed, height). Every stored analysis and
   report is in these terms.
3. **Identify's fluctuation power** (``flighttest.analysis.identify.fluctuation_power``): the
   squared first difference of each signal over its hover variance, for the hinge fit of the onset:
   a difference never spreads the shaking onto earlier, slower samples, and its windowed mean has
   the gamma-like scatter the fit assumes (that module says more).

The post-flight metrics in detail: each signal is first high-passed (minus its centred moving
average over ``trend_s``) so that the manoeuvre itself (a descent's planned acceleration, a helix's
steady turn rate) does not count as shaking; then over a centred window of ``window_s`` seconds
(:class:`FluctuationConfig`):

- ``rate_rms_radps``: RMS of the high-passed body rates, ``sqrt(rms(p)² + rms(q)² + rms(r)²)``;
- ``accz_rms_mps2``: RMS of the high-passed vertical (NED down) acceleration;
- ``motor_dtt``: motor-output spread as a ΔT/T proxy, ``sqrt(mean_i rms(m_i)²) / mean_i(m_i)``.

The **hover baseline** of each metric is its median over the flight's hover samples: speed below
``hover_speed_mps``, at least ``hover_min_height_m`` above the lowest point of the log (off the
ground), armed where the log says, and never below the metric's noise floor (``NOISE_FLOOR``: a
simulator's hover can be perfectly still, and a zero baseline would make every ratio infinite). Each
metric divided by its baseline is a ``*_ratio``; ``fluct_index`` is the mean of the ratios the log
allows (1 ≈ hover, 2 = twice the hover shake).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from flighttest.analysis.schema import RATES, motor_columns
from flighttest.inputs import MAX_DURATION_S, MAX_HEIGHT_M, MAX_SPEED_MPS, Range

METRICS = ["rate_rms_radps", "accz_rms_mps2", "motor_dtt"]
NOISE_FLOOR = {"rate_rms_radps": 0.005, "accz_rms_mps2": 0.05, "motor_dtt": 0.005}


@dataclass(frozen=True)
class FluctuationConfig:
    window_s: float = 1.0
    trend_s: float = 0.4
    hover_speed_mps: float = 0.2
    hover_min_height_m: float = 0.5

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            FLUCTUATION_RANGES[name].check(value, f"fluctuation setting {name}")


# positive and physically bounded (as flighttest.inputs bounds durations, speeds and heights): a window
# of 1e308 s would overflow into a sample count
FLUCTUATION_RANGES: dict[str, Range] = {
    "window_s": Range(0.0, MAX_DURATION_S, "s", lo_open=True),
    "trend_s": Range(0.0, MAX_DURATION_S, "s", lo_open=True),
    "hover_speed_mps": Range(0.0, MAX_SPEED_MPS, "m/s", lo_open=True),
    "hover_min_height_m": Range(0.0, MAX_HEIGHT_M, "m", lo_open=True),
}


def _rolling_rms(x: np.ndarray, n: int, n_trend: int) -> np.ndarray:
    """RMS over ``n`` samples of ``x`` minus its moving average over ``n_trend`` samples (columns)."""
    frame = pd.DataFrame(x)
    hp = frame - frame.rolling(n_trend, center=True, min_periods=1).mean()
    return np.sqrt((hp**2).rolling(n, center=True, min_periods=max(2, n // 2)).mean().to_numpy())


def hover_mask(state: pd.DataFrame, cfg: FluctuationConfig) -> np.ndarray:
    speed = np.linalg.norm(state[["vn_mps", "ve_mps", "vd_mps"]].to_numpy(float), axis=1)
    h = -state["d_m"].to_numpy(float)
    airborne = h > np.nanmin(h) + cfg.hover_min_height_m
    armed = state["armed"].to_numpy(float)
    not_disarmed = ~(armed == 0)
    glitch = state["glitch"].to_numpy(bool) if "glitch" in state else np.zeros(len(h), bool)
    return (speed < cfg.hover_speed_mps) & airborne & not_disarmed & ~glitch


def fluctuation(state: pd.DataFrame, cfg: FluctuationConfig | None = None) -> tuple[pd.DataFrame, dict[str, float]]:
    """Per-sample metrics, ratios and ``fluct_index`` (one row per state row) and the baselines."""
    cfg = cfg or FluctuationConfig()
    t = state["t_s"].to_numpy(float)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    n = max(3, round(cfg.window_s / max(dt, 1e-6)))
    n_trend = max(3, round(cfg.trend_s / max(dt, 1e-6)))
    out = pd.DataFrame({"t_s": t})
    rates = state[RATES].to_numpy(float)
    out["rate_rms_radps"] = (
        np.sqrt(np.sum(_rolling_rms(rates, n, n_trend) ** 2, axis=1)) if np.isfinite(rates).any() else np.nan
    )
    out["accz_rms_mps2"] = _rolling_rms(state[["ad_mps2"]].to_numpy(float), n, n_trend)[:, 0]
    motors = motor_columns(state)
    if motors:
        m = state[motors].to_numpy(float)
        mean = pd.Series(m.mean(axis=1)).rolling(n, center=True, min_periods=2).mean().to_numpy()
        with np.errstate(invalid="ignore", divide="ignore"):
            out["motor_dtt"] = np.sqrt(np.mean(_rolling_rms(m, n, n_trend) ** 2, axis=1)) / np.abs(mean)
    else:
        out["motor_dtt"] = np.nan
    hover = hover_mask(state, cfg)
    if hover.sum() < n:
        hover = np.ones(len(t), dtype=bool)  # no hover found: compare with the flight's median
    baselines: dict[str, float] = {}
    ratios = []
    for col in METRICS:
        vals = out[col].to_numpy(float)
        base = float(np.nanmedian(vals[hover])) if np.isfinite(vals[hover]).any() else np.nan
        base = max(base, NOISE_FLOOR[col]) if np.isfinite(base) else base
        baselines[col] = base
        if np.isfinite(base) and base > 0:
            out[col.rsplit("_", 1)[0] + "_ratio"] = vals / base
            ratios.append(vals / base)
        else:
            out[col.rsplit("_", 1)[0] + "_ratio"] = np.nan
    out["fluct_index"] = np.nanmean(np.vstack(ratios), axis=0) if ratios else np.nan
    baselines["hover_samples"] = int(hover.sum())
    return out, baselines


# -- the live guard's measure ------------------------------------------------------------------------
# A window of fewer samples, or spanning less than this fraction of its length (the first samples
# after the guard starts, a telemetry gap), is not yet a window: its std reads 0, which no threshold
# acts on.
LIVE_MIN_SAMPLES = 5
LIVE_MIN_SPAN_FRACTION = 0.5
# windows replayed at once: bounds the (windows × samples per window) arrays to a few MB
_REPLAY_CELLS = 1 << 20


def window_detrended_std(t_s: np.ndarray, x: np.ndarray, window_s: float) -> np.ndarray:
    """Standard deviation of ``x`` about its least-squares line in ``t_s``, over the last axis: one
    window per row (shape ``(..., m)``; NaN marks a cell that is not a sample, as padding).

    ``sqrt(Σ r² / n)`` with ``r`` the residuals of the line (the population std: the window *is*
    the population the guard judges); 0 for a window of fewer than ``LIVE_MIN_SAMPLES`` or spanning
    less than ``LIVE_MIN_SPAN_FRACTION × window_s``. The sums are taken about the window's own means
    (times from its first sample): running sums of ``t²`` on a monotonic clock would cancel.
    """
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(x, dtype=float)
    ok = np.isfinite(t) & np.isfinite(v)
    n = ok.sum(axis=-1)
    t0 = np.min(np.where(ok, t, np.inf), axis=-1, keepdims=True)
    t1 = np.max(np.where(ok, t, -np.inf), axis=-1, keepdims=True)
    # an empty window (t0 = inf, n = 0) computes NaN and reads 0 below, as a short one does
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(ok, t - t0, 0.0)
        vz = np.where(ok, v, 0.0)
        mt = rel.sum(axis=-1, keepdims=True) / n[..., None]
        mv = vz.sum(axis=-1, keepdims=True) / n[..., None]
        dt = np.where(ok, rel - mt, 0.0)
        dv = np.where(ok, v - mv, 0.0)
        stt = (dt * dt).sum(axis=-1)
        svt = (dt * dv).sum(axis=-1)
        svv = (dv * dv).sum(axis=-1)
        resid = svv - np.where(stt > 0, svt * svt / np.where(stt > 0, stt, 1.0), 0.0)
        std = np.sqrt(np.maximum(resid, 0.0) / n)
    span = (t1 - t0)[..., 0]
    is_window = (n >= LIVE_MIN_SAMPLES) & (span >= LIVE_MIN_SPAN_FRACTION * window_s)
    return np.where(is_window, std, 0.0)


def trailing_detrended_std(t_s: np.ndarray, x: np.ndarray, window_s: float) -> np.ndarray:
    """:func:`window_detrended_std` over the trailing window of every sample: the samples ``j`` with
    ``t_i − window_s ≤ t_j ≤ t_i`` (``t_s`` non-decreasing, as a log's clock). A non-finite sample
    is no sample: it is left out of every window and its own value is NaN — exactly what
    ``FluctuationDetector.add`` returns fed the same samples one at a time."""
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(x, dtype=float)
    if t.shape != v.shape or t.ndim != 1:
        raise ValueError("t_s and x must be 1-D arrays of the same length")
    out = np.full(len(v), np.nan)
    idx = np.flatnonzero(np.isfinite(v) & np.isfinite(t))
    if not len(idx):
        return out
    tf, vf = t[idx], v[idx]
    if np.any(np.diff(tf) < 0):
        raise ValueError("t_s must be non-decreasing")
    first = np.searchsorted(tf, tf - window_s, side="left")
    width = int((np.arange(len(tf)) - first).max()) + 1
    cols = np.arange(width)
    res = np.empty(len(tf))
    rows = max(1, _REPLAY_CELLS // width)
    for lo in range(0, len(tf), rows):
        hi = min(lo + rows, len(tf))
        k = first[lo:hi, None] + cols[None, :]
        inside = k <= np.arange(lo, hi)[:, None]
        k = np.minimum(k, len(tf) - 1)
        res[lo:hi] = window_detrended_std(np.where(inside, tf[k], np.nan), np.where(inside, vf[k], np.nan), window_s)
    out[idx] = res
    return out


def live_fluctuation(
    t_s: np.ndarray, rates_radps: np.ndarray, a_down_mps2: np.ndarray, window_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """The live guard's fluctuation after each sample of a recorded series: ``(rate_std_dps,
    accel_std_mps2)``, as ``Guard.rate_std_dps`` and ``Guard.accel_std_mps2`` read after
    ``on_rates`` and ``on_vertical_accel`` with the same samples.

    ``rates_radps`` is ``(n, 3)`` body rates p, q, r; the rate measure is the largest axis's
    :func:`trailing_detrended_std` in deg/s (axes without a value left out; 0 when none has one).
    The acceleration's measure holds its last value over a non-finite sample (0 before the first).
    The runner feeds the guard the accelerometer's body-z specific force and the analysis has the
    NED-down acceleration: they differ by g (a constant, which the line absorbs) and by the tilt's
    cosine (under 2 % below 11° of tilt), so either series may be replayed.
    """
    t = np.asarray(t_s, dtype=float)
    rates = np.atleast_2d(np.asarray(rates_radps, dtype=float))
    if rates.shape != (len(t), 3):
        raise ValueError("rates_radps must be (n, 3): p, q, r in rad/s")
    per_axis = np.column_stack([trailing_detrended_std(t, np.degrees(rates[:, i]), window_s) for i in range(3)])
    any_axis = np.isfinite(per_axis).any(axis=1)
    rate_std_dps = np.where(any_axis, np.max(np.where(np.isfinite(per_axis), per_axis, -np.inf), axis=1), 0.0)
    accel = trailing_detrended_std(t, np.asarray(a_down_mps2, dtype=float), window_s)
    last = np.maximum.accumulate(np.where(np.isfinite(accel), np.arange(len(accel)), -1))
    accel_std_mps2 = np.where(last >= 0, accel[np.maximum(last, 0)], 0.0)
    return rate_std_dps, accel_std_mps2


def hover_baseline(window_stds: np.ndarray | list[float]) -> float | None:
    """The hover's fluctuation: the median of the window stds measured while hovering, ``None``
    without a finite one (the guard then judges only its absolute limits)."""
    v = np.asarray(window_stds, dtype=float)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if len(v) else None


def fluct_threshold(absolute: float | None, ratio: float | None, baseline: float | None, floor: float) -> float | None:
    """The std the guard acts above: the lower of the absolute limit and ``ratio × baseline``, the
    latter never below ``floor`` (a still simulator hovers with no shake, and any ratio of zero is
    zero); ``None`` when neither is set."""
    candidates = [absolute] if absolute is not None else []
    if ratio is not None and baseline is not None:
        candidates.append(max(ratio * baseline, floor))
    return min(candidates) if candidates else None
