"""The campaign's comparison figures, drawn from analyses of synthetic logs of known motion."""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path

import pytest

from flighttest.analysis.pipeline import Analysis, analyse_path
from flighttest.analysis.segment import SegmentConfig
from flighttest.campaign import figures
from flighttest.campaign.figures import (
    descent_profile,
    main_descent,
    plot_descent_comparison,
    plot_tracks_velocity_space,
)
from flighttest.errors import FlighttestError
from flighttest.model.chart import guard_boundary_n, velocity_view
from flighttest.model.profiles import load_profile
from synthetic import SyntheticFlight, write_tlog

H_M, T0_S = 5.0, 8.0
VERTICAL_S, HELIX_S = 8.4, 5.6  # raised-cosine durations; the segmenter's trimmed windows are a bit shorter
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _analyse(flight: SyntheticFlight, path: Path) -> Analysis:
    return analyse_path(write_tlog(flight, path), vehicle="x500")


@pytest.fixture(scope="module")
def flights(tmp_path_factory) -> dict[str, Analysis]:
    d = tmp_path_factory.mktemp("logs")
    return {
        "vertical": _analyse(SyntheticFlight(duration_s=22.0, descents=[(T0_S, H_M, VERTICAL_S)]), d / "vertical.tlog"),
        # a helix-like descent: faster, with in-plane speed through the disk
        "helix": _analyse(
            SyntheticFlight(duration_s=22.0, descents=[(T0_S, H_M, HELIX_S)], east_speed_mps=1.5), d / "helix.tlog"
        ),
        "probe": _analyse(
            SyntheticFlight(duration_s=30.0, descents=[], probe=(5.0, 1.0, 0.02, 20.0), onset_mps=0.7), d / "probe.tlog"
        ),
    }


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


@pytest.fixture
def drawn(monkeypatch) -> list:
    """Every figure the module saves, with its texts readable (it closes them afterwards)."""
    figs: list = []
    save = figures._save

    def keep(fig, out):
        figs.append(fig)
        return save(fig, out)

    monkeypatch.setattr(figures, "_save", keep)
    return figs


def legend_texts(fig) -> list[str]:
    """Every legend entry of the figure: the axes' legends and the figure's own (under the panels)."""
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend()] + list(fig.legends)
    return [t.get_text() for leg in legends for t in leg.get_texts()]


def _panels(fig) -> dict:
    """The velocity-space figure's panels by flight: the first word of each title."""
    return {ax.get_title().split(" ")[0]: ax for ax in fig.axes if ax.get_title()}


def test_velocity_space_png(flights, tmp_path, drawn):
    out = tmp_path / "new" / "dir" / "tracks.png"
    v, h = flights["vertical"], flights["helix"]
    assert plot_tracks_velocity_space(v, h, out) == out
    assert out.stat().st_size > 10_000
    assert png_size(out) == (14 * 110, int(7.5 * 110))
    labels = legend_texts(drawn[0])
    dv, dh = main_descent(v, "vertical")["duration_s"], main_descent(h, "helix")["duration_s"]
    assert f"vertical baseline, {dv:.2f} s" in labels and f"helix, {dh:.2f} s" in labels
    assert {"start", "end", "guard region (the guard aborts here)"} <= set(labels)
    assert not any(label.startswith("probe") for label in labels)
    title = drawn[0]._suptitle.get_text()
    assert "x500" in title and f"v_h = {h.profile.v_h_mps:.2f}" in title and "w_allow" in title
    assert set(_panels(drawn[0])) == {"vertical", "helix"}


def test_velocity_space_tracks_are_the_main_descents(flights, tmp_path, drawn):
    v, h = flights["vertical"], flights["helix"]
    plot_tracks_velocity_space(v, h, tmp_path / "tracks.png")
    panels = _panels(drawn[0])
    for role, a, ax in (("vertical baseline", v, panels["vertical"]), ("helix", h, panels["helix"])):
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        d = main_descent(a, role)
        (line,) = [ln for label, ln in lines.items() if label.startswith(role + ",")]
        inside = a.track[(a.track["t_s"] >= d["start_s"]) & (a.track["t_s"] <= d["end_s"])]
        assert len(line.get_xdata()) == len(inside) < len(a.track)
        # the ring and the square sit on the descent's first and last sample
        starts = [ln for ln in ax.get_lines() if ln.get_marker() == "o" and ln.get_linestyle() == "None"]
        ends = [ln for ln in ax.get_lines() if ln.get_marker() == "s"]
        assert starts[0].get_xdata()[0] == pytest.approx(line.get_xdata()[0])
        assert ends[0].get_ydata()[0] == pytest.approx(line.get_ydata()[-1])
        # every sample of the flight inside its panel, and the guard boundary at 0 with room below it
        (x_lo, x_hi), (y_lo, y_hi) = ax.get_xlim(), ax.get_ylim()
        assert x_lo <= a.track["v_H_n"].min() and a.track["v_H_n"].max() <= x_hi
        assert y_lo <= a.track["v_z_n"].min() and a.track["v_z_n"].max() <= y_hi
        assert y_lo < guard_boundary_n(a.profile, x_hi) < y_hi
    # each panel fitted to its flight: the vertical one narrow (its track has a shape), the helix one wide
    vx, hx = panels["vertical"].get_xlim(), panels["helix"].get_xlim()
    assert vx[1] == pytest.approx(0.1 * 1.08) and hx[1] > 2 * vx[1]
    assert -0.01 < vx[0] < 0 and panels["vertical"].get_ylim() == panels["helix"].get_ylim()


def test_velocity_space_with_probe(flights, tmp_path, drawn):
    out = plot_tracks_velocity_space(flights["vertical"], flights["helix"], tmp_path / "p.png", probe=flights["probe"])
    assert out.stat().st_size > 10_000
    assert any(label.startswith("probe") for label in legend_texts(drawn[0]))
    # the probe sweeps straight down: drawn in the vertical baseline's panel, which holds all of it
    ax = _panels(drawn[0])["vertical"]
    assert ax.get_ylim()[0] <= flights["probe"].track["v_z_n"].min()


def test_descent_comparison_png(flights, tmp_path, drawn):
    out = tmp_path / "cmp" / "descent_time.png"
    v, h = flights["vertical"], flights["helix"]
    assert plot_descent_comparison(v, h, out) == out
    assert out.stat().st_size > 10_000
    assert png_size(out) == (12 * 110, 5 * 110)
    dv, dh = main_descent(v, "vertical")["duration_s"], main_descent(h, "helix")["duration_s"]
    assert dv / dh == pytest.approx(VERTICAL_S / HELIX_S, rel=0.05)
    left, right = drawn[0].axes
    assert f"{dv / dh:.2f}×" in right.get_title()
    bar_widths = sorted(p.get_width() for p in right.patches)
    assert bar_widths == pytest.approx(sorted([dv, dh]))
    texts = {t.get_text() for t in right.texts}
    assert {f"{dv:.2f} s", f"{dh:.2f} s"} <= texts


def test_descent_profile_runs_from_height_to_zero(flights):
    a = flights["vertical"]
    d = main_descent(a, "vertical")
    t, alt = descent_profile(a, d, context_s=1.0)
    assert t[0] == pytest.approx(-1.0, abs=0.05) and t[-1] == pytest.approx(d["duration_s"] + 1.0, abs=0.05)
    at_start = alt[abs(t).argmin()]
    at_end = alt[abs(t - d["duration_s"]).argmin()]
    # the segmenter's window starts/ends this close to the hover heights; the zero is the settled end height
    cfg = SegmentConfig()
    assert at_start == pytest.approx(d["height_m"] - cfg.start_tol_m, abs=0.03)
    assert at_end == pytest.approx(cfg.end_tol_m, abs=0.03)
    assert alt[0] == pytest.approx(H_M, abs=0.02)  # hovering before the descent: the full height above its end
    assert alt[-1] == pytest.approx(0.0, abs=0.02)


def test_no_descent_raises(flights, tmp_path):
    v, h = flights["vertical"], flights["helix"]
    none = dataclasses.replace(h, descents=h.descents.iloc[0:0])
    with pytest.raises(FlighttestError, match=r"helix flight .*no descent"):
        plot_descent_comparison(v, none, tmp_path / "x.png")
    with pytest.raises(FlighttestError, match="no descent"):
        plot_tracks_velocity_space(none, h, tmp_path / "y.png")
    assert not (tmp_path / "x.png").exists() and not (tmp_path / "y.png").exists()


def test_no_profile_raises(flights, tmp_path):
    v, h = flights["vertical"], flights["helix"]
    bare = dataclasses.replace(v, profile=None, track=None)
    with pytest.raises(FlighttestError, match=r"vertical flight .*no vehicle profile"):
        plot_tracks_velocity_space(bare, h, tmp_path / "z.png")
    with pytest.raises(FlighttestError, match=r"probe flight .*no vehicle profile"):
        plot_tracks_velocity_space(v, h, tmp_path / "z.png", probe=bare)
    # time and altitude need no profile
    assert plot_descent_comparison(bare, h, tmp_path / "ok.png").exists()


def test_unwritable_output_is_one_line_error(flights, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(FlighttestError, match="cannot write figure"):
        plot_descent_comparison(flights["vertical"], flights["helix"], blocker / "sub" / "x.png")


def test_velocity_view_fits_the_track_with_the_region_in_view():
    x500 = load_profile("x500")
    bound0 = float(guard_boundary_n(x500, 0.0))  # −(w_allow − margin) / v_h
    # straight down at 0.3 m/s: narrow (0.1 v_h) but not a line at 0, the flat boundary and room below it
    x_lo, x_hi, y_lo, y_hi = velocity_view(x500, [[0.0, 0.01, 0.02]], [[0.0, -0.05]])
    assert (x_lo, x_hi) == pytest.approx((-0.008, 0.108))
    assert y_lo < bound0 < -0.05 and y_hi > 0.0
    # a helix far out: the deeper cone boundary at the right edge stays in view
    x_lo, x_hi, y_lo, y_hi = velocity_view(x500, [[0.0, 0.7, float("nan")]], [[-0.1, 0.05]])
    assert x_hi == pytest.approx(0.756) and y_lo < float(guard_boundary_n(x500, x_hi)) < bound0
    # nothing finite: the default view; a wild sample is clamped
    assert velocity_view(x500, [], [])[1] == pytest.approx(0.108)
    assert velocity_view(x500, [[100.0]], [[-100.0]])[2] >= -6.0 - 0.25 * 6.0 - 1e-9
