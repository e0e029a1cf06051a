"""The three fluctuation measures, tied (``flighttest.analysis.fluctuation`` says why there are three).

One synthetic probe: a hover with sensor noise, then a descent in which an oscillation of the body
rates and the vertical acceleration grows out of the noise (the ring vortex's rocking). Fed sample by
sample to the live guard and as arrays to the analysis, it must give

- the guard and its vectorised replay (``live_fluctuation``) the same value after every sample, the
  same hover baseline, threshold and onset;
- the guard, the post-flight metric (``fluctuation``) and identify's power the same onset of the
  shaking, to within the guard's window.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from flighttest.analysis.fluctuation import (
    FluctuationConfig,
    fluct_threshold,
    fluctuation,
    hover_baseline,
    live_fluctuation,
    trailing_detrended_std,
)
from flighttest.analysis.identify import IdentifyConfig, probe_samples
from flighttest.analysis.schema import FlightLog
from flighttest.flying import guard as g
from flighttest.model.profiles import load_profile

X500 = load_profile("x500")
PERIOD_S = 0.02  # the guard's 50 Hz telemetry
CLOCK0_S = 1.0e4  # a monotonic clock hours after boot: the window sums must not cancel
WINDOW_S = 0.5  # the guard's fluct_window_s (GuardLimits and the probe mission's default)
RATIO = 3.0  # the probe mission's fluct_ratio
BASELINE_FROM_S, BASELINE_TO_S = 2.0, 9.5  # the settle: the guard collects its hover baseline here
SHAKE_FROM_S = 10.0  # the descent starts and the oscillation grows out of the noise
GROWTH_S = 0.3  # e-folding time of the oscillation's amplitude
SHAKE_HZ = 6.0
END_S = 16.0


def probe_signal(seed: int = 0) -> pd.DataFrame:
    """A state table (schema columns, ``t_s`` from 0) of the synthetic probe."""
    rng = np.random.default_rng(seed)
    t = np.arange(round(END_S / PERIOD_S)) * PERIOD_S
    grown = np.exp(np.clip(t - SHAKE_FROM_S, 0.0, None) / GROWTH_S)
    amp_dps = np.where(t >= SHAKE_FROM_S, np.minimum(0.2 * grown, 60.0), 0.0)
    ph = 2.0 * math.pi * SHAKE_HZ * t
    rates_dps = rng.normal(0.0, 1.0, (len(t), 3)) + np.column_stack(
        [amp_dps * np.sin(ph), amp_dps * np.cos(ph + 0.7), 0.3 * amp_dps * np.sin(ph + 2.0)]
    )
    vd = np.where(t >= SHAKE_FROM_S, 0.5, 0.0)  # hover, then a slow descent (not hover any more)
    return pd.DataFrame({
        "t_s": t, "n_m": 0.0, "e_m": 0.0, "d_m": -10.0 + np.cumsum(vd) * PERIOD_S,
        "vn_mps": 0.0, "ve_mps": 0.0, "vd_mps": vd, "qw": 1.0, "qx": 0.0, "qy": 0.0, "qz": 0.0,
        "p_radps": np.radians(rates_dps[:, 0]), "q_radps": np.radians(rates_dps[:, 1]),
        "r_radps": np.radians(rates_dps[:, 2]),
        "ad_mps2": rng.normal(0.0, 0.1, len(t)) + amp_dps / 20.0 * np.sin(ph + 1.1),
        "armed": 1.0, "wn_mps": 0.0, "we_mps": 0.0, "wd_mps": 0.0, "glitch": False,
    })  # fmt: skip


def fly_guard(t_rel: np.ndarray, rates: np.ndarray, a_down: np.ndarray) -> dict:
    """Feed the live guard one sample at a time, as the runner does (on the monotonic clock,
    ``CLOCK0_S + t_rel``): baseline in the settle, judged after. Onsets in ``t_rel``."""
    guard = g.Guard(g.GuardLimits(region=X500.guard_region(), fluct_window_s=WINDOW_S, fluct_ratio=RATIO))
    guard.fluct_active = False
    rate_std, accel_std = [], []
    onset = {"rate": None, "accel": None}
    for i, rel in enumerate(t_rel):
        t = CLOCK0_S + rel
        if math.isclose(rel, BASELINE_FROM_S):
            guard.start_baseline()
        if math.isclose(rel, BASELINE_TO_S):
            guard.freeze_baseline()
            guard.fluct_active = True
        for key, d in (("rate", guard.on_rates(t, *rates[i])), ("accel", guard.on_vertical_accel(t, a_down[i]))):
            if d is not None and onset[key] is None:
                assert d.verdict == g.FLUCTUATION
                onset[key] = float(rel)
        rate_std.append(guard.rate_std_dps)
        accel_std.append(guard.accel_std_mps2)
    return {
        "rate_std_dps": np.array(rate_std), "accel_std_mps2": np.array(accel_std), "onset_s": onset,
        "baseline": (guard.baseline_rate_std_dps, guard.baseline_accel_std_mps2),
        "threshold": guard.fluct_thresholds(),
    }  # fmt: skip


def first_above_s(t_s: np.ndarray, values: np.ndarray, threshold: float, after_s: float = 0.0) -> float:
    above = (np.nan_to_num(values, nan=-np.inf) > threshold) & (t_s >= after_s)
    assert above.any(), "never crossed"
    return float(t_s[np.argmax(above)])


def test_the_live_guard_and_its_vectorised_replay_agree_sample_by_sample():
    s = probe_signal()
    keep = ~((s["t_s"] > 5.0) & (s["t_s"] < 5.4))  # a telemetry gap: the window must span enough again
    s = s[keep].reset_index(drop=True)
    t_rel = s["t_s"].to_numpy()
    t = CLOCK0_S + t_rel
    rates = s[["p_radps", "q_radps", "r_radps"]].to_numpy(copy=True)
    a_down = s["ad_mps2"].to_numpy(copy=True)
    rates[[40, 41, 300], [0, 0, 2]] = np.nan  # dropped samples: no sample, in either form
    a_down[[77, 450, 451]] = np.nan
    live = fly_guard(t_rel, rates, a_down)
    rate_std, accel_std = live_fluctuation(t, rates, a_down, WINDOW_S)
    np.testing.assert_allclose(rate_std, live["rate_std_dps"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(accel_std, live["accel_std_mps2"], rtol=1e-9, atol=1e-12)
    assert rate_std.max() > 10.0 * np.median(rate_std[t_rel < SHAKE_FROM_S])  # it did shake
    # the same baseline, threshold and onset from the arrays
    settle = (t_rel >= BASELINE_FROM_S - 1e-9) & (t_rel < BASELINE_TO_S - 1e-9)
    base = (hover_baseline(rate_std[settle]), hover_baseline(accel_std[settle]))
    assert base == pytest.approx(live["baseline"], rel=1e-12)
    thr = tuple(fluct_threshold(None, RATIO, b, 0.0) for b in base)
    assert thr == pytest.approx(live["threshold"], rel=1e-12)
    for key, values, limit in (("rate", rate_std, thr[0]), ("accel", accel_std, thr[1])):
        assert first_above_s(t_rel, values, limit, BASELINE_TO_S) == live["onset_s"][key]
        assert SHAKE_FROM_S < live["onset_s"][key] < SHAKE_FROM_S + 2.0  # the shaking, not the hover's noise


def test_the_window_needs_enough_samples_spanning_half_its_length():
    t = np.arange(40) * 0.02
    x = np.sin(np.arange(40) * 1.3)
    std = trailing_detrended_std(t, x, WINDOW_S)
    assert np.all(std[t < 0.5 * WINDOW_S - 1e-9] == 0.0) and np.all(std[t > 0.5 * WINDOW_S + 1e-9] > 0.1)
    # a line, however steep, is a trend and not shaking (the square root of its rounding is ~1e-7)
    assert np.allclose(trailing_detrended_std(t, 5.0 + 30.0 * t, WINDOW_S), 0.0, atol=1e-6)
    with pytest.raises(ValueError, match="non-decreasing"):
        trailing_detrended_std(t[::-1], x, WINDOW_S)


@pytest.mark.parametrize("seed", [0, 1])
def test_guard_analysis_and_identify_see_the_shaking_start_within_one_window(seed):
    s = probe_signal(seed)
    t_rel = s["t_s"].to_numpy()
    rates = s[["p_radps", "q_radps", "r_radps"]].to_numpy()
    a_down = s["ad_mps2"].to_numpy()
    live = fly_guard(t_rel, rates, a_down)
    guard_rate_s, guard_accel_s = live["onset_s"]["rate"], live["onset_s"]["accel"]
    assert SHAKE_FROM_S < guard_rate_s < SHAKE_FROM_S + 2.0 and SHAKE_FROM_S < guard_accel_s < SHAKE_FROM_S + 2.0

    # post-flight: the same signal's metric over its own hover baseline, crossing the guard's ratio
    per_sample, _ = fluctuation(s, FluctuationConfig())
    analysis_rate_s = first_above_s(t_rel, per_sample["rate_rms_ratio"].to_numpy(), RATIO)
    analysis_accel_s = first_above_s(t_rel, per_sample["accz_rms_ratio"].to_numpy(), RATIO)
    assert abs(analysis_rate_s - guard_rate_s) <= WINDOW_S
    assert abs(analysis_accel_s - guard_accel_s) <= WINDOW_S

    # identify: its windowed power on the RMS × hover scale sweep_fluctuation plots (the rates only:
    # identify leaves the vertical acceleration out when the log has body rates)
    ps = probe_samples(FlightLog(path=Path("tie"), source="synthetic", state=s), X500, IdentifyConfig())
    assert ps.signals == ("p_radps", "q_radps", "r_radps")
    rms_ratio = np.sqrt(ps.power / np.nanmean(ps.power[ps.use & ps.hover]))
    identify_s = first_above_s(t_rel, rms_ratio, RATIO)
    assert abs(identify_s - guard_rate_s) <= WINDOW_S
    # and none of them fired in the hover
    assert min(analysis_rate_s, analysis_accel_s, identify_s) > SHAKE_FROM_S
