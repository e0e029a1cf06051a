"""The probe's fluctuation plot: the sweep only, binned by descent speed, hover at 1×, the detector's
threshold, the live guard's ratio, w_allow and the onset with its band (or "no onset up to X").

A synthetic probe folder stands in for a flight (no flying here): a flighttest log folder around a
synthetic tlog, with the mission's phases in ``setpoints.csv`` and an abort in ``events.jsonl`` after
which the synthetic sweep goes on faster and shakes more, so a plot that kept post-abort samples
would show it. The real PX4 SIH probe (no VRS physics) must plot without an onset.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from flighttest.analysis.identify import IdentifyConfig, identify_onset, probe_samples, sweep_fluctuation
from flighttest.analysis.loaders import load_log
from flighttest.analysis.pipeline import analyse
from flighttest.analysis.report import draw_fluctuation, plot_fluctuation, probe_fluctuation_bins
from flighttest.errors import FlighttestError
from synthetic import UNIX0, SyntheticFlight, write_tlog

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
SIH_PROBE = SHARED / "px4_sih" / "probe-full-sweep"
ONSET_MPS = 0.7
STREAM_S = 10.0  # the sweep starts (the hover before it is the settle phase)
ABORT_S = 38.0  # just after the sweep's 1.0 m/s peak at 35 s; it would go on to 1.42 m/s at 45 s
PROBE = (STREAM_S, 2.0, 0.01, 40.0)


def _flight(descents: list[tuple[float, float, float]] | None = None) -> SyntheticFlight:
    return SyntheticFlight(duration_s=60.0, descents=descents or [], probe=PROBE, onset_mps=ONSET_MPS)


def write_probe_folder(folder: Path) -> Path:
    """A flighttest probe log folder: climb, settle (hover), stream (the sweep), abort at ``ABORT_S``."""
    folder.mkdir(parents=True)
    write_tlog(_flight(), folder / "flight.tlog")
    t = np.arange(2.0, ABORT_S + 0.5, 0.02)  # the mission streams on briefly (the recovery), then stops
    phase = np.where(t < 6.0, "climb", np.where(t < STREAM_S, "settle", "stream"))
    pd.DataFrame({"t_s": t, "unix_s": UNIX0 + t, "phase": phase}).to_csv(folder / "setpoints.csv", index=False)
    events = [
        {"t_s": STREAM_S, "unix_s": UNIX0 + STREAM_S, "event": "phase", "phase": "stream"},
        {"t_s": ABORT_S, "unix_s": UNIX0 + ABORT_S, "event": "abort", "phase": "stream", "reason": "fluctuation"},
    ]
    (folder / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events))
    meta = {"mission": "probe", "start_unix_s": UNIX0, "vehicle": {"name": "x500"},
            "config": {"guard": {"fluct_ratio": 3.0}}}  # fmt: skip
    (folder / "meta.json").write_text(json.dumps(meta))
    return folder


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    a = analyse(load_log(write_probe_folder(tmp_path_factory.mktemp("probe") / "20260101-000000-probe")), "x500")
    return a, sweep_fluctuation(a.log, a.profile, descents=a.descents)


def test_only_the_sweep_before_the_abort_is_binned(probe):
    a, sweep = probe
    state = a.log.state
    after = state["t_s"] > ABORT_S + 1.0
    assert state.loc[after, "vd_mps"].max() > 1.3  # the log does go faster after the abort
    assert sweep.attrs["phased"] and "stream phase up to the abort" in sweep.attrs["selection"]
    assert sweep["t_s"].min() >= STREAM_S - 0.05  # no hover before the sweep
    assert sweep["t_s"].max() < ABORT_S  # no recovery after the abort
    assert (sweep["w_mps"] > IdentifyConfig().min_speed_mps).all()  # descending only
    bins = probe_fluctuation_bins(sweep, a.profile.v_h_mps)
    assert bins["samples"].sum() == len(sweep)
    assert bins["w_hi_mps"].max() <= 1.1 and np.allclose(bins["w_hi_mps"] - bins["w_lo_mps"], 0.05)
    assert np.allclose(bins["w_n"], bins["w_mps"] / a.profile.v_h_mps)
    assert (bins["q25"] <= bins["median"]).all() and (bins["median"] <= bins["q75"]).all()
    # hover reads 1× in the slow bins; past the onset the shaking is far above the threshold
    slow = bins[bins["w_hi_mps"] <= 0.3]
    assert len(slow) >= 4 and np.allclose(slow["median"], 1.0, atol=0.15)
    assert (bins.loc[bins["w_lo_mps"] >= 0.9, "median"] > 5.0).all()


def test_the_plot_draws_the_table_it_returns_and_marks_the_onset(probe, tmp_path):
    a, sweep = probe
    onset = identify_onset(a.log, a.profile, IdentifyConfig(n_boot=3))
    assert abs(onset.w_onset_mps - ONSET_MPS) < 0.05
    fig = plt.figure()
    bins = draw_fluctuation(fig, a, onset)
    ax = fig.axes[0]
    pd.testing.assert_frame_equal(bins, probe_fluctuation_bins(sweep, a.profile.v_h_mps))
    median_line = next(ln for ln in ax.lines if ln.get_linestyle() == "-" and len(ln.get_ydata()) >= len(bins))
    drawn = np.asarray(median_line.get_ydata(), float)
    assert np.allclose(drawn[np.isfinite(drawn)], bins["median"])
    levels = {round(float(ln.get_ydata()[0]), 3) for ln in ax.lines if len(ln.get_ydata()) == 2}
    assert {1.0, 2.0, 3.0} <= levels  # hover, identify's threshold, the live guard's ratio (from meta)
    verticals = {round(float(ln.get_xdata()[0]), 4) for ln in ax.lines if len(set(ln.get_xdata())) == 1}
    assert round(onset.w_onset_mps, 4) in verticals and round(a.profile.w_allow_mps, 4) in verticals
    texts = " ".join(t.get_text() for t in ax.texts)
    assert f"onset {onset.w_onset_mps:.3f} ± {onset.uncertainty_mps:.3f} m/s" in texts
    plt.close(fig)
    out = plot_fluctuation(a, tmp_path / "probe.png", onset)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000


def test_a_log_without_phases_takes_the_descents_but_not_the_landing(tmp_path):
    """Someone else's tlog: the sweep is the span of its descents; the final landing is left out."""
    f = _flight(descents=[(52.0, 9.5, 5.0)])  # after the sweep (ends at 50 s, 10.6 m) down to 1.1 m
    a = analyse(load_log(write_tlog(f, tmp_path / "probe.tlog")), "x500")
    assert a.descents["start_s"].max() == pytest.approx(52.0, abs=0.5)  # the landing is one of the descents
    sweep = sweep_fluctuation(a.log, a.profile, descents=a.descents)
    assert not sweep.attrs["phased"] and "no flight phases" in sweep.attrs["selection"]
    assert sweep["t_s"].min() >= STREAM_S and sweep["t_s"].max() <= STREAM_S + PROBE[3]
    bins = probe_fluctuation_bins(sweep, a.profile.v_h_mps)
    assert np.allclose(bins.loc[bins["w_hi_mps"] <= 0.3, "median"], 1.0, atol=0.15)
    assert bins["w_hi_mps"].max() > 1.4  # no abort here: the whole sweep
    fig = plt.figure()
    draw_fluctuation(fig, a)
    assert "no flight phases" in " ".join(t.get_text() for t in fig.texts)  # said on the plot
    plt.close(fig)


@pytest.mark.skipif(not SIH_PROBE.is_dir(), reason="needs ../shared/px4_sih (reference logs)")
def test_the_px4_sih_probe_plots_without_an_onset():
    a = analyse(load_log(SIH_PROBE), None)
    assert a.profile is not None and a.profile.name == "x500"
    with pytest.raises(FlighttestError, match="no onset found"):  # SIH has no vortex-ring physics
        identify_onset(a.log, a.profile)
    # the mission's landing (after its last setpoint) is not part of what identify fits
    stream_end = next(e["t_s"] for e in a.log.events if e.get("event") == "stream_end")
    land = next(e["t_s"] for e in a.log.events if e.get("event") == "phase" and e.get("phase") == "land")
    ps = probe_samples(a.log, a.profile, IdentifyConfig())
    assert ps.t_s[ps.use].max() <= land + 0.1
    fig = plt.figure()
    bins = draw_fluctuation(fig, a, None)
    texts = " ".join(t.get_text() for t in fig.axes[0].texts)
    plt.close(fig)
    assert 1.25 < bins["w_hi_mps"].max() <= 1.4  # the sweep went to 1.31 m/s through the disk
    assert "no onset identified up to 1.3" in texts and "stays below 2× hover" in texts
    assert bins["median"].max() < 2.0 and np.allclose(bins.loc[bins["w_hi_mps"] <= 0.3, "median"], 1.0, atol=0.2)
    sweep = sweep_fluctuation(a.log, a.profile, descents=a.descents)
    assert sweep["t_s"].max() < stream_end and "stream phase" in sweep.attrs["selection"]
