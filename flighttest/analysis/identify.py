"""Identify the VRS onset from a probe flight: the descent speed where the shaking starts.

Every airborne, descending sample of the probe contributes its ``fluct_index`` (fluctuation
against the flight's own hover, :mod:`.fluctuation`, over a window of ``window_s``) and the
**highest** blade-frame, air-relative descent speed ``w`` (as the guard measures it) reached within
that same window: a window turns loud as soon as any part of it is past the onset, so pairing it
with the window's top speed removes the bias a centre-sample speed would have. Samples are binned
by that speed (``bin_mps``); the **onset** is where the binned median index first rises above
``threshold_ratio`` and stays above it in the next populated bin, interpolated linearly between
the last quiet bin and the first loud one. The **uncertainty** combines a bootstrap over the
samples (``n_boot`` resamples, same procedure) with the bin quantisation (``bin/√12``). The result
is also given normalised by the profile's ``v_h``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd

from flighttest.analysis.exposure import velocity_track
from flighttest.analysis.fluctuation import FluctuationConfig, fluctuation
from flighttest.analysis.schema import FlightLog
from flighttest.errors import FlighttestError
from flighttest.profiles import VehicleProfile


@dataclass(frozen=True)
class IdentifyConfig:
    threshold_ratio: float = 2.0  # fluctuation at least this many times the hover's
    bin_mps: float = 0.05
    min_samples_per_bin: int = 5
    window_s: float = 0.5  # fluctuation window (shorter than for reports: the probe's speed changes)
    n_boot: int = 200
    min_speed_mps: float = 0.05  # slower than this is hover, not descent


@dataclass(frozen=True)
class Onset:
    w_onset_mps: float
    uncertainty_mps: float
    w_onset_n: float
    uncertainty_n: float
    v_h_mps: float
    threshold_ratio: float
    max_speed_mps: float
    samples: int
    bins: pd.DataFrame

    def summary(self) -> dict:
        d = asdict(self)
        d.pop("bins")
        return d


def _onset_from_bins(centers: np.ndarray, med: np.ndarray, thr: float) -> float:
    loud = med > thr
    for k in np.flatnonzero(loud):
        if k + 1 < len(loud) and not loud[k + 1]:
            continue  # a single loud bin followed by a quiet one is noise
        if k == 0:
            return float(centers[0])
        f = (thr - med[k - 1]) / (med[k] - med[k - 1])
        return float(centers[k - 1] + np.clip(f, 0, 1) * (centers[k] - centers[k - 1]))
    return math.nan


def _binned(w: np.ndarray, idx: np.ndarray, cfg: IdentifyConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    b = np.floor(w / cfg.bin_mps).astype(np.int64)
    frame = pd.DataFrame({"b": b, "i": idx}).groupby("b")["i"].agg(["median", "size"])
    frame = frame[frame["size"] >= cfg.min_samples_per_bin]
    centers = (frame.index.to_numpy() + 0.5) * cfg.bin_mps
    return centers, frame["median"].to_numpy(), frame["size"].to_numpy()


def identify_onset(log: FlightLog, profile: VehicleProfile, cfg: IdentifyConfig | None = None) -> Onset:
    cfg = cfg or IdentifyConfig()
    state = log.state
    if "glitch" not in state:
        from flighttest.analysis.segment import find_descents

        find_descents(state)
    fl, _ = fluctuation(state, FluctuationConfig(window_s=cfg.window_s))
    if not np.isfinite(fl["fluct_index"]).any():
        raise FlighttestError(f"{log.name}: no fluctuation signal (needs body rates, IMU or motor outputs)")
    track = velocity_track(state, profile)
    t = state["t_s"].to_numpy()
    n_win = max(3, round(cfg.window_s / max(float(np.median(np.diff(t))), 1e-6)))
    w = pd.Series(track["w_mps"].to_numpy()).rolling(n_win, center=True, min_periods=1).max().to_numpy()
    idx = fl["fluct_index"].to_numpy()
    h = -state["d_m"].to_numpy()
    use = (w > cfg.min_speed_mps) & np.isfinite(idx) & ~state["glitch"].to_numpy(bool) & (h > np.nanmin(h) + 0.5)
    if use.sum() < 3 * cfg.min_samples_per_bin:
        raise FlighttestError(f"{log.name}: too few descending samples to identify an onset ({int(use.sum())})")
    w_use, idx_use = w[use], idx[use]
    centers, med, size = _binned(w_use, idx_use, cfg)
    onset = _onset_from_bins(centers, med, cfg.threshold_ratio)
    if not math.isfinite(onset):
        raise FlighttestError(
            f"{log.name}: fluctuation never rose above {cfg.threshold_ratio:g}× hover up to "
            f"{float(w_use.max()):.2f} m/s descent: no onset found (w_allow is at least that)"
        )
    rng = np.random.default_rng(0)
    boots = []
    for _ in range(cfg.n_boot):
        pick = rng.integers(0, len(w_use), len(w_use))
        c, m, _ = _binned(w_use[pick], idx_use[pick], cfg)
        boots.append(_onset_from_bins(c, m, cfg.threshold_ratio))
    boots = np.asarray(boots)
    boot_sd = float(np.nanstd(boots)) if np.isfinite(boots).sum() > 1 else 0.0
    unc = math.sqrt(boot_sd**2 + cfg.bin_mps**2 / 12)
    v_h = profile.v_h_mps
    bins = pd.DataFrame({"w_mps": centers, "fluct_index_median": med, "samples": size})
    return Onset(
        w_onset_mps=onset,
        uncertainty_mps=unc,
        w_onset_n=onset / v_h,
        uncertainty_n=unc / v_h,
        v_h_mps=v_h,
        threshold_ratio=cfg.threshold_ratio,
        max_speed_mps=float(w_use.max()),
        samples=int(use.sum()),
        bins=bins,
    )
