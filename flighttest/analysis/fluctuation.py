"""Fluctuation metrics: how much the vehicle shakes, against its own hover.

Each signal is first high-passed (minus its centred moving average over ``trend_s``) so that the
manoeuvre itself (a descent's planned acceleration, a helix's steady turn rate) does not count as
shaking; then over a centred window of ``window_s`` seconds (:class:`FluctuationConfig`):

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
