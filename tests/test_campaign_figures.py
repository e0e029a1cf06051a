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
    chart_limits,
    descent_profile,
    main_descent,
    plot_descent_comparison,
    plot_tracks_velocity_space,
)
from flighttest.errors import FlighttestError
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
    return [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]


def test_velocity_space_png(flights, tmp_path, drawn):
    out = tmp_path / "new" / "dir" / "tracks.png"
    v, h = flights["vertical"], flights["helix"]
    assert plot_tracks_velocity_space(v, h, out) == out
    assert out.stat().st_size > 10_000
    assert png_size(out) == (8 * 110, 6 * 110)
    labels = legend_texts(drawn[0])
    dv, dh = main_descent(v, "vertical")["duration_s"], main_descent(h, "helix")["duration_s"]
    assert f"vertical baseline, {dv:.2f} s" in labels and f"helix, {dh:.2f} s" in labels
    assert not any(label.startswith("probe") for label in labels)
    title = drawn[0].axes[0].get_title()
    assert "x500" in title and f"v_h = {h.profile.v_h_mps:.2f}" in title and "w_allow" in title


def test_velocity_space_tracks_are_the_main_descents(flights, tmp_path, drawn):
    v, h = flights["vertical"], flights["helix"]
    plot_tracks_velocity_space(v, h, tmp_path / "tracks.png")
    ax = drawn[0].axes[0]
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    for role, a in (("vertical baseline", v), ("helix", h)):
        d = main_descent(a, role)
        (line,) = [ln for label, ln in lines.items() if label.startswith(role + ",")]
        inside = a.track[(a.track["t_s"] >= d["start_s"]) & (a.track["t_s"] <= d["end_s"])]
        assert len(line.get_xdata()) == len(inside) < len(a.track)
    # the helix moves through the disk plane, the vertical baseline hardly
    x = {label.split(",")[0]: ln.get_xdata() for label, ln in lines.items() if "," in label}
    assert max(x["helix"]) > 0.15 and max(x["vertical baseline"]) < 0.01
    # every track sample lies inside the drawn axes
    (x_lo, x_hi), (y_lo, y_hi) = ax.get_xlim(), ax.get_ylim()
    for a in (v, h):
        assert x_lo <= a.track["v_H_n"].min() and a.track["v_H_n"].max() <= x_hi
        assert y_lo <= a.track["v_z_n"].min() and a.track["v_z_n"].max() <= y_hi


def test_velocity_space_with_probe(flights, tmp_path, drawn):
    out = plot_tracks_velocity_space(flights["vertical"], flights["helix"], tmp_path / "p.png", probe=flights["probe"])
    assert out.stat().st_size > 10_000
    assert any(label.startswith("probe") for label in legend_texts(drawn[0]))


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


def test_chart_limits():
    assert chart_limits([], []) == (1.0, -0.75, 0.25)
    assert chart_limits([[0.1, 0.5]], [[-0.5, 0.1]]) == (1.0, -0.75, 0.25)  # small tracks: the default view
    assert chart_limits([[3.0, float("nan")]], [[-4.0, 0.5]]) == pytest.approx((3.3, -4.4, 0.55))
    assert chart_limits([[100.0]], [[-100.0, 100.0]]) == (6.0, -6.0, 1.0)  # clamped
