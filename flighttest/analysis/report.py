"""PNG plots (matplotlib Agg) and a Markdown summary that embeds them, one section per log.

Per log: altitude and descent rate over time (descents shaded, glitches marked), the path in plan
view and 3D, the velocity-space chart (paper Fig. 5/8: VRS/TWS/WBS regions, the cone, the guard
boundary) with the flight's normalised blade-frame track, and the fluctuation index over descent
speed (the probe's picture; the identified onset is drawn when there is one).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from flighttest.analysis.pipeline import Analysis
from flighttest.chart import draw_chart
from flighttest.errors import FlighttestError

TABLE_COLUMNS = {
    "descent": "#",
    "start_s": "start s",
    "duration_s": "duration s",
    "height_m": "height m",
    "mean_rate_mps": "mean m/s",
    "max_rate_mps": "max m/s",
    "horizontal_excursion_m": "horiz. m",
    "time_inside_s": "inside s",
    "time_near_s": "near s",
    "min_margin_mps": "min margin m/s",
    "fluct_index_max": "fluct. max",
    "phase": "phase",
}


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "log"


def _shade(ax, a: Analysis) -> None:
    for row in a.descents.itertuples():
        ax.axvspan(row.start_s, row.end_s, color="tab:orange", alpha=0.15, lw=0)
    for row in a.glitches.itertuples():
        ax.axvspan(row.start_s, row.start_s + max(row.duration_s, 0.05), color="red", alpha=0.4, lw=0)


def plot_altitude(a: Analysis, out: Path) -> Path:
    s = a.log.state
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True, dpi=100)
    ax1.plot(s["t_s"], -s["d_m"], lw=1.2, label="altitude (−d)")
    _shade(ax1, a)
    ax1.set_ylabel("altitude above origin, m")
    ax1.legend(loc="best", fontsize=8)
    ax2.plot(s["t_s"], s["vd_mps"], lw=1.0, label="descent rate vd")
    if a.track is not None:
        ax2.plot(a.track["t_s"], a.track["w_mps"], lw=0.8, alpha=0.7, label="w through the disk (air-relative)")
        ax2.axhline(a.profile.w_allow_mps, color="m", ls="--", lw=1, label=f"w_allow {a.profile.w_allow_mps:.2f} m/s")
    _shade(ax2, a)
    ax2.set_ylabel("m/s (down positive)")
    ax2.set_xlabel("time, s")
    ax2.legend(loc="best", fontsize=8)
    fig.suptitle(f"{a.log.name}: altitude and descent rate (descents shaded)")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def plot_path(a: Analysis, out: Path) -> Path:
    s = a.log.state
    fig = plt.figure(figsize=(11, 5), dpi=100)
    ax = fig.add_subplot(1, 2, 1)
    ax.plot(s["e_m"], s["n_m"], lw=1)
    ax.set_xlabel("east, m")
    ax.set_ylabel("north, m")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("plan view")
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    ax3.plot(s["e_m"], s["n_m"], -s["d_m"], lw=1)
    for row in a.descents.itertuples():
        sel = (s["t_s"] >= row.start_s) & (s["t_s"] <= row.end_s)
        ax3.plot(s.loc[sel, "e_m"], s.loc[sel, "n_m"], -s.loc[sel, "d_m"], lw=2.2, color="tab:orange")
    ax3.set_xlabel("east, m")
    ax3.set_ylabel("north, m")
    ax3.set_zlabel("altitude, m")
    ax3.set_title("3D path (descents bold)")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def plot_velocity_space(a: Analysis, out: Path) -> Path:
    fig, ax = plt.subplots(figsize=(7.5, 6.5), dpi=100)
    tr = a.track
    lim_H = max(2.0, float(np.nanmax(tr["v_H_n"])) * 1.1) if len(tr) else 2.0
    lim_z = min(-1.0, float(np.nanmin(tr["v_z_n"])) * 1.1) if len(tr) else -3.0
    draw_chart(ax, a.profile, v_H_max_n=min(lim_H, 6.0), v_z_min_n=max(lim_z, -6.0))
    ax.plot(tr["v_H_n"], tr["v_z_n"], ".", ms=1.5, color="0.3", alpha=0.4, label="flight track")
    t = tr["t_s"].to_numpy()
    for row in a.descents.itertuples():
        sel = (t >= row.start_s) & (t <= row.end_s)
        ax.plot(tr["v_H_n"][sel], tr["v_z_n"][sel], ".", ms=2.5, label=f"descent {row.descent}")
    ax.set_title(f"{a.log.name}: blade-frame track, v_h = {a.profile.v_h_mps:.2f} m/s ({a.profile.name})")
    ax.legend(loc="lower left", fontsize=7, framealpha=0.9)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def plot_fluctuation(a: Analysis, out: Path, onset=None) -> Path:
    fig, ax = plt.subplots(figsize=(8, 5), dpi=100)
    w = a.track["w_mps"].to_numpy() / a.profile.v_h_mps
    idx = a.fluct["fluct_index"].to_numpy()
    sel = np.isfinite(idx) & (w > 0)
    ax.plot(w[sel], idx[sel], ".", ms=2, alpha=0.5, label="fluctuation index (1 = hover)")
    ax.axhline(1.0, color="0.5", lw=0.8)
    ax.axvline(a.profile.w_allow_mps / a.profile.v_h_mps, color="m", ls="--", lw=1, label="profile w_allow")
    if onset is not None:
        ax.axvline(onset.w_onset_n, color="r", lw=1.5, label=f"identified onset {onset.w_onset_mps:.2f} m/s")
        ax.axvspan(onset.w_onset_n - onset.uncertainty_n, onset.w_onset_n + onset.uncertainty_n, color="r", alpha=0.15)
    ax.set_xlabel("w / v_h (descent through the disk, air-relative)")
    ax.set_ylabel("fluctuation / hover")
    ax.set_yscale("log")
    ax.set_title(f"{a.log.name}: fluctuation over descent speed")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, float):
        return f"{v:.2f}"
    return str(v)


def markdown_table(df: pd.DataFrame, columns: dict[str, str]) -> str:
    cols = [c for c in columns if c in df]
    lines = ["| " + " | ".join(columns[c] for c in cols) + " |", "|" + "---|" * len(cols)]
    for row in df[cols].itertuples(index=False):
        lines.append("| " + " | ".join(_fmt(v) for v in row) + " |")
    return "\n".join(lines)


def write_report(analyses: list[Analysis], out_dir: Path, onsets: dict | None = None) -> Path:
    """Write the PNGs and ``report.md`` into ``out_dir``; returns the Markdown path."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise FlighttestError(f"{out_dir}: cannot create report folder ({exc.strerror})") from None
    onsets = onsets or {}
    md = ["# flighttest flight report", ""]
    used: set[str] = set()
    for a in analyses:
        slug = _slug(a.log.path.stem if a.log.path.is_file() else a.log.name)
        while slug in used:
            slug += "_"
        used.add(slug)
        md += [
            f"## {a.log.name}",
            "",
            f"- source: `{a.log.path}` ({a.log.source})",
            f"- duration: {float(a.log.state['t_s'].iloc[-1]):.1f} s, {len(a.log.state)} samples",
        ]
        if a.log.mission_name:
            md.append(f"- mission: {a.log.mission_name}")
        if a.profile:
            md.append(
                f"- vehicle: {a.profile.name} (v_h {a.profile.v_h_mps:.2f} m/s, "
                f"w_allow {a.profile.w_allow_mps:.2f} m/s: {a.profile.w_allow_source})"
            )
        for k, v in a.log.missing.items():
            md.append(f"- missing {k}: {v}")
        md += [f"- note: {n}" for n in a.notes]
        md += ["", f"### Descents ({len(a.descents)})", ""]
        md.append(markdown_table(a.descents, TABLE_COLUMNS) if len(a.descents) else "No descent found.")
        md.append("")
        images = [
            ("Altitude and descent rate", plot_altitude(a, out_dir / f"{slug}_altitude.png")),
            ("Path", plot_path(a, out_dir / f"{slug}_path.png")),
        ]
        if a.profile is not None and a.track is not None:
            images.append(("Velocity space", plot_velocity_space(a, out_dir / f"{slug}_velocity_space.png")))
            onset = onsets.get(str(a.log.path))
            if onset is not None or np.isfinite(a.fluct["fluct_index"]).any():
                images.append(
                    ("Fluctuation over descent speed", plot_fluctuation(a, out_dir / f"{slug}_fluctuation.png", onset))
                )
            if onset is not None:
                md += [
                    f"Identified onset: **{onset.w_onset_mps:.3f} ± {onset.uncertainty_mps:.3f} m/s** "
                    f"({onset.w_onset_n:.4f} ± {onset.uncertainty_n:.4f} v_h)",
                    "",
                ]
        else:
            md += ["Velocity-space chart and fluctuation plot need a vehicle profile (--vehicle).", ""]
        for title, path in images:
            md += [f"### {title}", "", f"![{title}]({path.name})", ""]
    out = out_dir / "report.md"
    out.write_text("\n".join(md) + "\n", encoding="utf-8")
    return out
