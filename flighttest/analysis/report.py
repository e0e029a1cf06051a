"""PNG plots (matplotlib Agg) and a Markdown summary that embeds them, one section per log.

The report opens with every flight at a glance (outcome, descent time against the plan's, the main
descent) and what each column means (``flighttest.analysis.legend``), and ends with the parameters,
once: the ones every flight shared, then those that differ, side by side. Every table fits 80
columns (``MAX_TABLE_WIDTH``): long names go into numbered lists, wide tables are split.

Per log: how it ended and why, its main descent and the plan's time for it, which profile judged it,
which height the descents were timed on (the arbitration's verdict on every height source,
:mod:`flighttest.analysis.heights`), the attitude source, the estimator glitches with what each
height source said; altitude and descent rate over time (descents shaded, glitch spans marked with
their kind, the estimator's own height drawn beside the trusted one where they differ), the path in
plan view and 3D, with the plan under the flown path and speeds where the log has one
(``flighttest.analysis.planned``) and the tracking error over time (``flighttest.analysis.plan_track``),
the start and end of each track marked, ``w`` against the guard's boundary, the velocity-space chart
(paper Fig. 5/8: VRS/TWS/WBS regions, the cone, the guard boundary) with the flight's normalised
air-relative blade-frame track (the wind it was judged with in its title and in the log's bullets:
:mod:`flighttest.analysis.wind`), and the probe plot: the sweep alone, its
RMS fluctuation × hover binned over descent speed, with the hover level, the detector's threshold
and the identified onset with its band (:func:`draw_fluctuation`).
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

from flighttest.analysis import legend
from flighttest.analysis.pipeline import Analysis
from flighttest.errors import FlighttestError
from flighttest.inputs import display_path
from flighttest.model.chart import PLAN_COLOUR, draw_chart

MAX_TABLE_WIDTH = 80  # every Markdown table line, so report.md reads in a terminal as well as rendered
# the per-descent table in three parts that each fit MAX_TABLE_WIDTH: when and how fast, the guard
# region, then sideways, wind and shaking
TIMING_COLUMNS = {
    "descent": "#",
    "phase": "phase",
    "start_s": "start s",
    "duration_s": "duration s",
    "height_m": "height m",
    "mean_rate_mps": "mean m/s",
    "max_rate_mps": "max m/s",
}
EXPOSURE_TABLE_COLUMNS = {
    "descent": "#",
    "time_inside_s": "inside s",
    "time_inside_worst_s": "inside, worst air s",
    "time_near_s": "near s",
    "min_margin_mps": "min margin m/s",
}
CONTEXT_COLUMNS = {
    "descent": "#",
    "horizontal_excursion_m": "horiz. m",
    "wind_speed_mps": "wind m/s",
    "fluct_index_max": "fluct. max",
}
DESCENT_TABLES = (("When and how fast", TIMING_COLUMNS), ("The guard region", EXPOSURE_TABLE_COLUMNS),
                  ("Sideways, wind, shaking", CONTEXT_COLUMNS))  # fmt: skip
TABLE_COLUMNS = {**TIMING_COLUMNS, **EXPOSURE_TABLE_COLUMNS, **CONTEXT_COLUMNS}


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "log"


GLITCH_STYLE = {  # glitch kind → (colour, legend text)
    "jump": ("red", "glitch: altitude jump"),
    "disagreement": ("tab:purple", "glitch: height sources disagree"),
}


def _shade(ax, a: Analysis, label: bool = False) -> None:
    """Descents shaded; glitch spans marked in their kind's colour (named in the legend and, with
    ``label``, written over the span with the source that went wrong)."""
    for row in a.descents.itertuples():
        ax.axvspan(row.start_s, row.end_s, color="tab:orange", alpha=0.15, lw=0)
    seen: set[str] = set()
    for row in a.glitches.itertuples():
        colour, text = GLITCH_STYLE.get(row.kind, ("red", f"glitch: {row.kind}"))
        ax.axvspan(row.start_s, row.start_s + max(row.duration_s, 0.05), color=colour, alpha=0.3, lw=0,
                   label=text if label and row.kind not in seen else None)  # fmt: skip
        seen.add(row.kind)
        if label:
            ax.text(row.start_s, 0.98, f" {row.kind}" + (f": {row.source}" if row.source else ""), color=colour,
                    transform=ax.get_xaxis_transform(), fontsize=7, va="top", rotation=90, clip_on=True)  # fmt: skip


def _differs(s: pd.DataFrame, col: str, orig: str) -> bool:
    """The state has the estimator's original column ``orig`` and it is not the same as ``col``."""
    if orig not in s:
        return False
    a, b = s[col].to_numpy(float), s[orig].to_numpy(float)
    return not np.allclose(a, b, atol=1e-3, equal_nan=True)


def plot_altitude(a: Analysis, out: Path) -> Path:
    """Height and descent rate over time. The height drawn is the one the descents were timed on
    (the trusted source); where the arbitration replaced or bridged the estimator's, the estimator's
    own height (``d_est_m``, in its own datum) and vertical velocity are drawn beside it, dashed. The
    plan, where the log has it (:func:`flighttest.analysis.planned.planned_path`), runs under both;
    ``w`` through the disk is drawn against the guard's boundary at the flight's in-plane speed, its
    forbidden side shaded."""
    from flighttest.analysis.planned import planned_path
    from flighttest.model.aero import guard_bound_mps
    from flighttest.model.chart import GUARD_COLOUR, GUARD_SHADE, VD_COLOUR, W_COLOUR, mark_ends

    s = a.log.state
    h = a.heights
    plan = planned_path(a.log)
    if plan is not None and len(s):  # the flight's time axis: a sweep stopped early does not stretch it
        plan = plan[plan["t_s"] <= float(s["t_s"].iloc[-1])]
    estimator = a.log.heights[0].name if a.log.heights else "estimator"
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 7), sharex=True, dpi=100)
    trusted = "altitude (−d)"
    if h is not None:
        trusted = f"height from {h.source} ({h.kind}, trusted)" + (", glitches bridged" if h.bridged.any() else "")
    if plan is not None:
        ax1.plot(plan["t_s"], -plan["d_m"], lw=3.0, color=PLAN_COLOUR, alpha=0.7, label="the plan")
    if _differs(s, "d_m", "d_est_m"):
        ax1.plot(s["t_s"], -s["d_est_m"], lw=1.0, ls="--", color="0.45", label=f"estimator {estimator} as logged")
    ax1.plot(s["t_s"], -s["d_m"], lw=1.2, color="tab:blue", label=trusted)
    mark_ends(ax1, s["t_s"], -s["d_m"])
    _shade(ax1, a, label=True)
    _mark_ends(ax1, a)
    ax1.set_ylabel("height, m (up)" if h is None or h.is_estimator else "height above home, m")
    ax1.legend(loc="best", fontsize=8)
    if plan is not None:
        ax2.plot(plan["t_s"], plan["vd_mps"], lw=3.0, color=PLAN_COLOUR, alpha=0.7, label="planned descent rate")
    if _differs(s, "vd_mps", "vd_est_mps"):
        ax2.plot(s["t_s"], s["vd_est_mps"], lw=0.9, ls="--", color="0.45", label="estimator vd as logged")
    # wider than w, which lies on it in a straight-down descent in still air
    ax2.plot(s["t_s"], s["vd_mps"], lw=2.4, color=VD_COLOUR, label="descent rate vd (over the ground)")
    if a.track is not None:
        tr, vrs = a.track, a.profile.vrs
        t = tr["t_s"].to_numpy(float)
        bound = guard_bound_mps(tr["u_mps"].to_numpy(float), a.profile.w_allow_mps, vrs.cone_deg, vrs.margin_mps)
        top = max(float(np.nanmax(tr["w_mps"])) if len(tr) else 0.0, float(np.nanmax(bound)) if len(tr) else 0.0)
        ax2.fill_between(t, bound, top + 10.0, **GUARD_SHADE, label="guard region (w beyond the boundary)")
        ax2.plot(t, bound, lw=1.0, color=GUARD_COLOUR,
                 label=f"guard boundary at the flight's u (w_allow {a.profile.w_allow_mps:.2f} m/s)")  # fmt: skip
        ax2.plot(t, tr["w_mps"], lw=1.0, color=W_COLOUR, label="w through the disk (air-relative)")
    lo, hi = _data_limits(s["vd_mps"], *([a.track["w_mps"]] if a.track is not None else []))
    if a.track is not None and len(a.track):
        hi = max(hi, float(np.nanmax(bound)) + 0.25 * (hi - lo))  # the region in view
    ax2.set_ylim(lo, hi)
    _shade(ax2, a)
    _mark_ends(ax2, a, label=False)
    ax2.set_ylabel("m/s (down positive)")
    ax2.set_xlabel("time, s")
    ax2.legend(loc="best", fontsize=8)
    fig.suptitle(f"{a.log.name}: altitude and descent rate (descents shaded)")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def _data_limits(*series) -> tuple[float, float]:
    from flighttest.model.chart import fitted_range

    return fitted_range(*[np.asarray(x, float) for x in series], 0.0, min_span=0.5)


def ends(a: Analysis) -> dict[str, float]:
    """When the main descent began, ended as flown, and would have ended as planned (log clock)."""
    m = a.main or {}
    out = {}
    start, flown, planned = m.get("start_s"), m.get("descent_time_s"), m.get("planned_descent_s")
    if isinstance(start, int | float) and m.get("basis") == "planned descent":
        out["start"] = float(start)
        if isinstance(flown, int | float):
            out["flown"] = float(start) + float(flown)
        if isinstance(planned, int | float):
            out["planned"] = float(start) + float(planned)
    return out


# the flown end's line: not green (the start ring, the descent rate) nor red (the end square, the guard region)
FLOWN_END_COLOUR = "tab:purple"


def _mark_ends(ax, a: Analysis, label: bool = True) -> None:
    """The main descent's end as planned (dashed grey) and as flown (solid purple), with their times."""
    e, m = ends(a), a.main or {}
    lines = (("planned", "planned_descent_s", "--", PLAN_COLOUR, "planned end"),
             ("flown", "descent_time_s", "-", FLOWN_END_COLOUR, "flown end"))  # fmt: skip
    for key, dur_key, style, colour, text in lines:
        if key in e:
            ax.axvline(e[key], color=colour, ls=style, lw=1.2,
                       label=f"{text}, {m[dur_key]:.2f} s after the first setpoint" if label else None)  # fmt: skip


def plot_tracking(a: Analysis, out: Path) -> Path:
    """Flown minus planned position over the descent (``plan_track.tracking_error``): how far off the plan,
    sideways and vertically, and when the descent was planned and flown to end."""
    err = a.tracking
    fig, ax = plt.subplots(figsize=(9, 4), dpi=100)
    ax.plot(err["t_s"], err["total_m"], lw=1.4, color="black", label="total")
    ax.plot(err["t_s"], err["horizontal_m"], lw=1.0, color="tab:blue", label="sideways (horizontal)")
    ax.plot(err["t_s"], err["down_m"], lw=1.0, color="tab:orange", label="vertical (+: below the plan)")
    ax.axhline(0.0, color="0.6", lw=0.8)
    _mark_ends(ax, a)
    ax.set_xlabel("time, s")
    ax.set_ylabel("flown − planned position, m")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(f"{a.log.name}: tracking error against the plan (the estimate's position)")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def plot_path(a: Analysis, out: Path) -> Path:
    """The flown path seen from above and in 3D, the plan under it where the log has it, the
    descents bold, the flight's first and last sample marked."""
    from flighttest.analysis.planned import planned_path
    from flighttest.model.chart import mark_ends

    s = a.log.state
    plan = planned_path(a.log)
    fig = plt.figure(figsize=(12, 5.5), dpi=100)
    ax = fig.add_subplot(1, 2, 1)
    if plan is not None and max(np.ptp(plan["e_m"]), np.ptp(plan["n_m"])) < 0.01:  # straight down: a point
        ax.plot(plan["e_m"].iloc[:1], plan["n_m"].iloc[:1], "P", ms=14, color=PLAN_COLOUR,
                label="the plan (straight down)")  # fmt: skip
    elif plan is not None:
        ax.plot(plan["e_m"], plan["n_m"], lw=3.5, color=PLAN_COLOUR, alpha=0.7, label="the plan")
    ax.plot(s["e_m"], s["n_m"], lw=1, color="tab:blue", label="flown")
    mark_ends(ax, s["e_m"], s["n_m"])
    ax.set_xlabel("east, m")
    ax.set_ylabel("north, m")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("seen from above")
    ax.legend(loc="best", fontsize=8)
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    if plan is not None:
        ax3.plot(plan["e_m"], plan["n_m"], -plan["d_m"], lw=3.5, color=PLAN_COLOUR, alpha=0.7)
    ax3.plot(s["e_m"], s["n_m"], -s["d_m"], lw=1, color="tab:blue")
    for row in a.descents.itertuples():
        sel = (s["t_s"] >= row.start_s) & (s["t_s"] <= row.end_s)
        ax3.plot(s.loc[sel, "e_m"], s.loc[sel, "n_m"], -s.loc[sel, "d_m"], lw=2.2, color="tab:orange")
    mark_ends(ax3, s["e_m"], s["n_m"], -s["d_m"], label=False)
    ax3.set_xlabel("east, m")
    ax3.set_ylabel("north, m")
    ax3.set_zlabel("altitude, m")
    ax3.set_title("3D (descents bold orange)")
    fig.suptitle(f"{a.log.name}: path")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


# one colour per descent, none of them the start ring's green or the end square's red
DESCENT_COLOURS = ["tab:blue", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:cyan", "tab:olive"]


def plot_velocity_space(a: Analysis, out: Path) -> Path:
    """The flight's blade-frame track on the velocity-space chart, the axes fitted to it with the guard
    region in view, each descent coloured from its start (ring) to its end (square), the plan under it."""
    from flighttest.analysis.planned import planned_path
    from flighttest.model.chart import mark_ends, velocity_view

    fig, ax = plt.subplots(figsize=(10.5, 6.5), dpi=100)
    tr, v_h = a.track, a.profile.v_h_mps
    plan = planned_path(a.log)
    x_lo, x_hi, y_lo, y_hi = velocity_view(a.profile, [tr["v_H_n"]], [tr["v_z_n"]])
    draw_chart(ax, a.profile, v_H_max_n=x_hi, v_z_min_n=y_lo, v_H_min_n=x_lo, v_z_max_n=y_hi)
    if plan is not None:
        ax.plot(plan["u_mps"] / v_h, -plan["w_mps"] / v_h, lw=3.0, color=PLAN_COLOUR, alpha=0.8,
                label="the plan (still air)")  # fmt: skip
    ax.plot(tr["v_H_n"], tr["v_z_n"], ".", ms=1.5, color="0.3", alpha=0.4)
    ax.plot([], [], ".", ms=6, color="0.3", alpha=0.6, label="flight track")  # a legend proxy: 1.5 px dots vanish
    t = tr["t_s"].to_numpy()
    for k, row in enumerate(a.descents.itertuples()):
        sel = (t >= row.start_s) & (t <= row.end_s)
        x, y = tr["v_H_n"][sel].to_numpy(float), tr["v_z_n"][sel].to_numpy(float)
        ax.plot(x, y, ".-", lw=0.8, ms=2.5, color=DESCENT_COLOURS[k % len(DESCENT_COLOURS)],
                label=f"descent {row.descent}")  # fmt: skip
        mark_ends(ax, x, y, label=k == 0)
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(y_lo, y_hi)
    ax.set_title(f"{a.log.name}: blade-frame track, air-relative\nv_h = {v_h:.2f} m/s, w_allow = "
                 f"{a.profile.w_allow_mps:.2f} m/s ({a.profile.name})"
                 + (f"\nwind {a.log.wind.describe()}" if a.log.wind is not None else ""), fontsize=9)  # fmt: skip
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)  # beside the chart: inside it hides the track
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


FLUCT_BIN_MPS = 0.05  # speed bins of the probe plot
FLUCT_MIN_BIN_SAMPLES = 5  # bins with fewer samples are drawn hollow: their median is little more than a guess
BIN_COLUMNS = ["w_lo_mps", "w_hi_mps", "w_mps", "w_n", "samples", "median", "q25", "q75"]


def probe_fluctuation_bins(sweep: pd.DataFrame, v_h_mps: float, width_mps: float = FLUCT_BIN_MPS) -> pd.DataFrame:
    """The probe plot's table: the sweep's samples (:func:`flighttest.analysis.identify.sweep_fluctuation`)
    binned by descent speed ``w`` in bins ``[w_lo_mps, w_hi_mps)`` of ``width_mps``, with the median and
    interquartile range of the fluctuation × hover and the number of samples. Medians, not means: a
    bin the sweep crossed quickly holds a few samples, and one burst would pull its mean off. Only bins
    with samples appear; ``attrs`` are the sweep's (selection, hover level)."""
    if len(sweep) == 0:
        out = pd.DataFrame(columns=BIN_COLUMNS)
    else:
        k = np.floor(sweep["w_mps"].to_numpy(float) / width_mps).astype(np.int64)
        g = pd.DataFrame({"k": k, "r": sweep["fluct_ratio"].to_numpy(float)}).groupby("k")["r"]
        idx = g.size().index.to_numpy()
        out = pd.DataFrame({
            "w_lo_mps": idx * width_mps, "w_hi_mps": (idx + 1) * width_mps, "w_mps": (idx + 0.5) * width_mps,
            "w_n": (idx + 0.5) * width_mps / v_h_mps, "samples": g.size().to_numpy(),
            "median": g.median().to_numpy(), "q25": g.quantile(0.25).to_numpy(), "q75": g.quantile(0.75).to_numpy(),
        })  # fmt: skip
    out.attrs.update(sweep.attrs, width_mps=width_mps)
    return out


def _guard_fluct_ratio(a: Analysis) -> float | None:
    """The live guard's fluctuation ratio from the mission config the log carries, if any."""
    cfg = a.log.meta.get("config")
    guard = cfg.get("guard") if isinstance(cfg, dict) else None
    r = guard.get("fluct_ratio") if isinstance(guard, dict) else None
    return float(r) if isinstance(r, int | float) and math.isfinite(r) and r > 0 else None


def _no_data(ax, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, fontsize=10, wrap=True)
    ax.set_xticks([])
    ax.set_yticks([])


def draw_fluctuation(fig, a: Analysis, onset=None) -> pd.DataFrame:
    """Draw the probe plot into ``fig`` (two panels: fluctuation × hover over descent speed, samples per
    bin) and return the binned table drawn (:func:`probe_fluctuation_bins`). The medians and their
    interquartile band are what to read; the raw samples sit faintly behind. Marked: hover (1×), the
    detector's threshold, the live guard's ratio when the log's mission config has one, the profile's
    ``w_allow``, and the identified onset with its band — or, with no onset, how fast the sweep went
    without one."""
    import textwrap

    from matplotlib.ticker import NullFormatter

    from flighttest.analysis.identify import IdentifyConfig, sweep_fluctuation

    v_h = a.profile.v_h_mps
    traj = a.log.meta.get("trajectory_meta")
    kind = f"{a.log.mission_name or ''} {traj.get('kind', '') if isinstance(traj, dict) else ''}"
    what = ", probe sweep" if "probe" in kind.lower() else ""
    fig.suptitle(f"{a.log.name}: fluctuation over descent rate{what}", fontsize=11, y=0.99)
    try:
        sweep = sweep_fluctuation(a.log, a.profile, descents=a.descents)
    except FlighttestError as exc:
        _no_data(fig.add_subplot(), textwrap.fill(f"no fluctuation to plot: {exc}", 90))
        return probe_fluctuation_bins(pd.DataFrame(columns=["w_mps", "fluct_ratio"]), v_h)
    bins = probe_fluctuation_bins(sweep, v_h)
    if bins.empty:
        why = textwrap.fill(sweep.attrs["selection"], 90)
        _no_data(fig.add_subplot(), f"no descending samples in the sweep:\n{why}")
        return bins
    # room at the top for the title, the note on which samples these are (up to two lines) and the w/v_h axis
    gs = fig.add_gridspec(2, 1, height_ratios=[4, 1], hspace=0.08, left=0.11, right=0.97, top=0.835, bottom=0.09)
    ax = fig.add_subplot(gs[0])
    axn = fig.add_subplot(gs[1], sharex=ax)
    fig.text(0.5, 0.952, textwrap.fill(sweep.attrs["selection"], 130), ha="center", va="top", fontsize=8.5,
             color="0.3")  # fmt: skip

    threshold = onset.threshold_ratio if onset is not None else IdentifyConfig().threshold_ratio
    guard = _guard_fluct_ratio(a)
    w_top = float(sweep["w_mps"].max())
    ax.plot(sweep["w_mps"], sweep["fluct_ratio"], ".", ms=2, color="0.55", alpha=0.25, rasterized=True,
            label=f"sweep samples ({len(sweep)}, descending)", zorder=1)  # fmt: skip
    # a full grid of bins, so the band and the median line break where the sweep left a bin empty
    full = pd.DataFrame({"w_lo_mps": np.arange(bins["w_lo_mps"].min(), bins["w_hi_mps"].max() - 1e-9, FLUCT_BIN_MPS)})
    full["key"] = np.round(full["w_lo_mps"] / FLUCT_BIN_MPS).astype(np.int64)
    grid = full.merge(bins.assign(key=np.round(bins["w_lo_mps"] / FLUCT_BIN_MPS).astype(np.int64)), "left", "key")
    centre = grid["w_lo_mps_x"] + 0.5 * FLUCT_BIN_MPS
    ax.fill_between(centre, grid["q25"], grid["q75"], color="tab:blue", alpha=0.22, lw=0, zorder=2,
                    label="interquartile range per bin")  # fmt: skip
    ax.plot(centre, grid["median"], "-", color="tab:blue", lw=1.8, zorder=3)
    solid = bins["samples"] >= FLUCT_MIN_BIN_SAMPLES
    ax.plot(bins["w_mps"][solid], bins["median"][solid], "o", color="tab:blue", ms=4.5, zorder=4,
            label=f"median per {FLUCT_BIN_MPS:g} m/s bin")  # fmt: skip
    if (~solid).any():
        ax.plot(bins["w_mps"][~solid], bins["median"][~solid], "o", mfc="white", mec="tab:blue", ms=4.5, zorder=4,
                label=f"median of < {FLUCT_MIN_BIN_SAMPLES} samples")  # fmt: skip

    ax.axhline(1.0, color="0.2", lw=1.0, zorder=2, label="hover level (1×)")
    ax.axhline(threshold, color="tab:orange", ls="--", lw=1.3, zorder=2,
               label=f"detector threshold {threshold:g}× hover (identify, RMS)")  # fmt: skip
    if guard is not None:
        ax.axhline(guard, color="tab:brown", ls=":", lw=1.3, zorder=2,
                   label=f"live guard stops at {guard:g}× its hover (its own rate-std measure)")  # fmt: skip
    w_allow = a.profile.w_allow_mps
    ax.axvline(w_allow, color="m", ls="--", lw=1.1, zorder=2, label=f"profile w_allow {w_allow:.3f} m/s")
    x_hi = max(w_top, w_allow)
    if onset is not None:
        lo, hi = onset.w_onset_mps - onset.uncertainty_mps, onset.w_onset_mps + onset.uncertainty_mps
        ax.axvspan(lo, hi, color="tab:red", alpha=0.18, lw=0, zorder=1)
        ax.axvline(onset.w_onset_mps, color="tab:red", lw=1.8, zorder=5,
                   label=f"identified onset {onset.w_onset_mps:.3f} ± {onset.uncertainty_mps:.3f} m/s")  # fmt: skip
        b = onset.bins.attrs
        hover_power = sweep.attrs["hover_power"]
        if {"b0", "b1", "w0_mps"} <= b.keys() and hover_power > 0:
            wf = np.linspace(0.0, w_top, 300)
            fit = np.sqrt((b["b0"] + b["b1"] * np.maximum(wf - b["w0_mps"], 0.0) ** 2) / hover_power)
            ax.plot(wf, fit, "-", color="tab:red", lw=1.0, alpha=0.8, zorder=4, label="identify's hinge fit")
        text = (f"onset {onset.w_onset_mps:.3f} ± {onset.uncertainty_mps:.3f} m/s\n"
                f"= {onset.w_onset_n:.4f} ± {onset.uncertainty_n:.4f} v_h\n"
                f"(rise {onset.rise_ratio:.1f}× hover at {onset.max_speed_mps:.2f} m/s)")  # fmt: skip
        ax.annotate(text, xy=(hi, 0.04), xycoords=("data", "axes fraction"), xytext=(8, 0),
                    textcoords="offset points", fontsize=9, color="tab:red", va="bottom",
                    bbox={"boxstyle": "round", "fc": "white", "ec": "tab:red", "alpha": 0.9})  # fmt: skip
        x_hi = max(x_hi, hi)
    else:
        peak = float(bins.loc[solid, "median"].max()) if solid.any() else float(bins["median"].max())
        why = (f"the binned fluctuation stays below {threshold:g}× hover (peak {peak:.1f}×)" if peak < threshold
               else f"the binned fluctuation reaches {peak:.1f}× hover: run flighttest identify")  # fmt: skip
        ax.text(0.02, 0.96, f"no onset identified up to {w_top:.2f} m/s ({w_top / v_h:.3f} v_h):\n{why}",
                transform=ax.transAxes, va="top", fontsize=10, fontweight="bold", color="0.15",
                bbox={"boxstyle": "round", "fc": "lightyellow", "ec": "0.5", "alpha": 0.95}, zorder=6)  # fmt: skip

    ax.set_yscale("log")
    marks = [1.0, threshold] + ([guard] if guard else [])
    y_lo = min(0.5, float(np.nanmin(bins["q25"])) * 0.8)
    y_hi = max(max(marks) * 1.6, float(np.nanmax(bins["q75"])) * 1.3)
    ax.set_ylim(y_lo, y_hi)
    ticks = [t for t in (0.2, 0.3, 0.5, 1, 2, 3, 5, 10, 20, 30, 50, 100, 200, 500) if y_lo <= t <= y_hi]
    ax.set_yticks(ticks, [f"{t:g}×" for t in ticks])
    ax.yaxis.set_minor_formatter(NullFormatter())
    ax.set_ylabel("RMS fluctuation × hover\n(body-rate shaking, log scale)")
    ax.grid(True, which="major", color="0.9", lw=0.6)
    ax.set_xlim(0.0, x_hi * 1.05 + FLUCT_BIN_MPS)
    top = ax.secondary_xaxis("top", functions=(lambda w: w / v_h, lambda n: n * v_h))
    top.set_xlabel(f"w / v_h   (v_h = {v_h:.2f} m/s, {a.profile.name})", fontsize=9)
    ax.tick_params(labelbottom=False)
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, 0.84) if onset is None else (0.0, 1.0), fontsize=7.5,
              framealpha=0.92, markerscale=2.0)  # fmt: skip

    axn.bar(bins["w_mps"], bins["samples"], width=0.85 * FLUCT_BIN_MPS, color="tab:blue", alpha=0.5)
    axn.set_ylabel("samples\nper bin", fontsize=8)
    axn.set_xlabel("w: descent rate through the rotor disk, air-relative, m/s")
    axn.grid(True, axis="y", color="0.9", lw=0.6)
    return bins


def plot_fluctuation(a: Analysis, out: Path, onset=None) -> Path:
    """The probe plot (:func:`draw_fluctuation`) as a PNG."""
    fig = plt.figure(figsize=(9, 6.5), dpi=100)
    draw_fluctuation(fig, a, onset)
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
        cells = []
        for c, v in zip(cols, row):
            main = c == "descent" and "main" in df and bool(df.loc[df["descent"] == v, "main"].any())
            cells.append(f"{v}{legend.MAIN_MARK}" if main else _fmt(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def params_markdown(params: dict, pairs_per_row: int = 2) -> str:
    """Parameters as a compact table: name/value pairs side by side (two pairs fit 80 columns), so
    ArduPilot's hundred ATC_* gains take half the lines."""
    from flighttest.analysis.params import format_value

    items = [(f"`{k}`", format_value(v)) for k, v in params.items()]
    n = max(1, min(pairs_per_row, len(items)))
    lines = ["| " + " | ".join(["parameter", "value"] * n) + " |", "|" + "---|---:|" * n]
    for i in range(0, len(items), n):
        chunk = items[i : i + n] + [("", "")] * (n - len(items[i : i + n]))
        lines.append("| " + " | ".join(c for pair in chunk for c in pair) + " |")
    return "\n".join(lines)


def params_section(analyses: list[Analysis], labels: list[str] | None = None) -> list[str]:
    """Markdown lines: the parameters that shape these tests, once for the whole report: where each
    flight's came from, those every flight carrying parameters shared, then those that differ, one
    column per flight (``labels``, numbered like the report's flights)."""
    from flighttest.analysis.params import differences, relevant

    labels = labels or [str(i) for i in range(1, len(analyses) + 1)]
    snaps = [relevant(a.log.params) for a in analyses]
    md = ["## Parameters", ""]
    for label, a, snap in zip(labels, analyses, snaps):
        src = f" from {a.log.params_source}" if a.log.params_source else ""
        if snap:
            md.append(f"- {label}: {len(snap)} that shape these tests{src}")
        elif a.log.params:
            md.append(f"- {label}: none of the log's {len(a.log.params)} parameters is one that shapes these tests")
        else:
            md.append(f"- {label}: none in the log")
    md.append("")
    carrying = [snap for snap in snaps if snap]
    if not carrying:
        return md
    diff = differences(snaps) if len(carrying) > 1 else {}
    shared = {k: v for k, v in carrying[0].items() if k not in diff and all(k in snap for snap in carrying)}
    if shared:
        every = "every flight that carries parameters" if len(carrying) > 1 else "the flight"
        md += [f"### The same in {every} ({len(shared)})", "", params_markdown(shared), ""]
    if len(carrying) > 1:
        md += param_differences_section(analyses, labels)
    return md


def param_differences_section(analyses: list[Analysis], names: list[str]) -> list[str]:
    """Markdown lines: the relevant parameters not the same in every flight of the report, one column
    per flight (``names``: short labels), split into tables that each fit ``MAX_TABLE_WIDTH``."""
    from flighttest.analysis.params import differences, format_value, relevant

    snaps = [relevant(a.log.params) for a in analyses]
    md = ["### Parameters that differ between these flights", ""]
    with_params = sum(bool(s) for s in snaps)
    if with_params < 2:
        return [*md, f"Only {with_params} of {len(snaps)} flights carry parameters: nothing to compare.", ""]
    diff = differences(snaps)
    if not diff:
        return [*md, f"None: the {with_params} flights with parameters were set up alike.", ""]
    width = max(len(f"`{k}`") for k in diff) + 4
    cells = [[format_value(v) for v in vals] for vals in diff.values()]
    col = [max(len(names[j]), *(len(c[j]) for c in cells)) + 3 for j in range(len(names))]
    start = 0
    while start < len(names):
        stop, used = start, width + 1
        while stop < len(names) and (stop == start or used + col[stop] <= MAX_TABLE_WIDTH):
            used += col[stop]
            stop += 1
        md.append("| parameter | " + " | ".join(names[start:stop]) + " |")
        md.append("|---|" + "---:|" * (stop - start))
        md += [f"| `{k}` | " + " | ".join(c[start:stop]) + " |" for k, c in zip(diff, cells)]
        md.append("")
        start = stop
    return [*md, "– : the flight's log does not have the parameter (or no parameters at all).", ""]


def source_lines(a: Analysis) -> list[str]:
    """Markdown bullets naming the height the descents were timed on and the attitude source."""
    h = a.heights
    if h is None:
        height = "the state's own (not arbitrated)"
    else:
        est = a.log.heights[0].name if a.log.heights else "state.d_m"
        why = "" if h.is_estimator else f"; the estimator `{est}` is not consistent with the ground and the others"
        height = f"`{h.source}` ({h.kind}, of {len(h.sources)} source{'s' if len(h.sources) != 1 else ''}{why})"
    att = f"`{a.log.attitude_source}`" if a.log.attitude_source else "none (exposure assumes level attitude)"
    return [f"- height source: {height}", f"- attitude source: {att}"]


def wind_lines(a: Analysis) -> list[str]:
    """Markdown bullets: the wind the exposure was judged with (flighttest.analysis.wind), and the exposure
    over all the time airborne."""
    from flighttest.flying.wind import WIND_COVERAGE_SIGMAS

    w = a.log.wind
    if w is None:
        return []
    air = a.wind_summary()
    sd = air["wind_sd_mps"]
    speed = "unknown" if air["wind_ned_mps"][0] is None else f"{math.hypot(*air['wind_ned_mps'][:2]):.2f} m/s"
    vec = "" if air["wind_ned_mps"][0] is None else " (N {:+.2f}, E {:+.2f}, D {:+.2f})".format(*air["wind_ned_mps"])
    md = [f"- wind: **{speed}**{vec}" + (f" ± {sd:.2f} m/s (1 σ)" if sd is not None else ", uncertainty unknown")
          + f", `{w.source}`: {w.detail}; exposure and the velocity space are air-relative, the worst air "
          f"within {WIND_COVERAGE_SIGMAS:g} σ of it beside"]  # fmt: skip
    e = a.airborne
    if e and math.isfinite(e.get("time_inside_s", math.nan)):
        md.append(f"- airborne {e['airborne_s']:.1f} s: inside the guard region {_fmt(e['time_inside_s'])} s "
                  f"({_fmt(e['time_inside_worst_s'])} s at the worst air), min margin {_fmt(e['min_margin_mps'])} m/s "
                  f"({_fmt(e['min_margin_worst_mps'])} at the worst air)")  # fmt: skip
    return md


def heights_section(a: Analysis) -> list[str]:
    """Markdown lines: every height source with the arbitration's verdict, then the glitch spans and,
    below the table, what each source said (referred to home) at each one's worst instant."""
    md: list[str] = []
    if a.heights is not None and len(a.heights.sources) > 1:
        md += ["### Height sources", ""]
        for src in a.heights.sources.itertuples():
            why = f" ({src.reason})" if not src.consistent and isinstance(src.reason, str) and src.reason else ""
            md.append(f"- `{src.name}` ({src.kind}): {'consistent' if src.consistent else 'not consistent'}; ground "
                      f"error {_fmt(src.ground_error_m)} m, below ground {_fmt(src.below_ground_m)} m, max "
                      f"disagreement {_fmt(src.max_disagreement_m)} m{why}")  # fmt: skip
        md.append("")
    md += [f"### Estimator glitches ({len(a.glitches)})", ""]
    if not len(a.glitches):
        return [*md, "None: the height sources agree with each other and with the ground.", ""]
    md += ["| # | start s | end s | duration s | max jump m | kind | source |", "|---:|---:|---:|---:|---:|---|---|"]
    said_lines = []
    for k, g in enumerate(a.glitches.itertuples(), start=1):
        md.append(f"| {k} | {_fmt(g.start_s)} | {_fmt(g.end_s)} | {_fmt(g.duration_s)} | {_fmt(g.max_jump_m)} | "
                  f"{g.kind} | {f'`{g.source}`' if g.source else '–'} |")  # fmt: skip
        said = g.sources if isinstance(g.sources, dict) else {}
        if said:
            said_lines.append(f"- glitch {k}, what each source said (m above home): "
                              + ", ".join(f"`{name}` {_fmt(float(v))}" for name, v in said.items()))  # fmt: skip
    return [*md, "", *said_lines, *([""] if said_lines else [])]


def _outcome_text(a: Analysis) -> str | None:
    from flighttest.analysis.pipeline import flight_summary

    s = flight_summary(a.log.meta)
    outcome = s.get("outcome")
    if not isinstance(outcome, str):
        return None
    why = s.get("abort_reason")
    return f"{outcome}: {why}" if isinstance(why, str) and why else outcome


def _main_row(a: Analysis) -> pd.Series | None:
    d = a.descents
    if "main" not in d or not d["main"].astype(bool).any():
        return None
    return d[d["main"].astype(bool)].iloc[0]


OVERVIEW_HEADERS = ("#", "outcome", "descent s", "planned s", "start m", "height m", "inside s")


def overview_section(analyses: list[Analysis], labels: list[str]) -> list[str]:
    """Markdown lines: every flight at a glance, numbered, then one table row each."""
    md = ["## The flights", ""]
    for label, a in zip(labels, analyses):
        what = a.log.mission_name or (a.descents["trajectory"].iloc[0] if len(a.descents) else None) or a.log.source
        md.append(f"{label}. `{a.log.name}` ({what})")
    md += ["", "| " + " | ".join(OVERVIEW_HEADERS) + " |", "|---:|---|---:|---:|---:|---:|---:|"]
    for label, a in zip(labels, analyses):
        m = a.main or {}
        row = _main_row(a)
        inside = row.get("time_inside_s") if row is not None else None
        # flighttest's own logs: the descent time (none for a probe); other programs': the duration
        descent = m.get("descent_time_s") if a.log.source == "flighttest-folder" else m.get("duration_s")
        outcome = (_outcome_text(a) or "–").split(":")[0]
        md.append(f"| {label} | {outcome} | {_fmt(descent)} | {_fmt(m.get('planned_descent_s'))} | "
                  f"{_fmt(m.get('start_height_m'))} | {_fmt(m.get('height_m'))} | {_fmt(inside)} |")  # fmt: skip
    md += ["", "Descent s: the main descent's time (logs of other programs: its duration); each flight's section "
           "says why a figure is missing.", ""]  # fmt: skip
    return md


def legend_section() -> list[str]:
    """What every column of the report's tables means (``flighttest.analysis.legend``)."""
    headers = [*OVERVIEW_HEADERS, *(h for _, columns in DESCENT_TABLES for h in columns.values())]
    md = ["## What the columns mean", ""]
    md += [f"- **{h}**: {legend.COLUMNS[h]}" for h in dict.fromkeys(headers) if h in legend.COLUMNS]
    return [*md, ""]


def flight_lines(a: Analysis) -> list[str]:
    """Markdown bullets: how the flight ended, its main descent against the plan, which profile judged it."""
    md = []
    outcome = _outcome_text(a)
    if outcome:
        md.append(f"- outcome: {outcome}")
    m = a.main or {}
    if m.get("basis") == "planned descent":
        flown = m.get("descent_time_s")
        planned = f"{_fmt(m.get('planned_descent_s'))} s"
        md.append(f"- descent time: {_fmt(flown)} s against {planned} planned" if flown is not None
                  else f"- descent time: not reached ({planned} planned)")  # fmt: skip
    md.append(f"- main descent: {legend.main_text(a.main, a.main_note)}")
    t = a.tracking_summary()
    if t:
        md.append(f"- off the plan: at most {_fmt(t['max_m'])} m at {_fmt(t['at_max_s'])} s (rms {_fmt(t['rms_m'])} m; "
                  f"sideways at most {_fmt(t['max_horizontal_m'])} m, vertically {_fmt(t['max_vertical_m'])} m)")
    md.append(f"- judged with: {legend.judged_text(a.judged_with)}")
    return md


def write_report(analyses: list[Analysis], out_dir: Path, onsets: dict | None = None) -> Path:
    """Write the PNGs and ``report.md`` into ``out_dir``; returns the Markdown path."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise FlighttestError(f"{out_dir}: cannot create report folder ({exc.strerror})") from None
    onsets = onsets or {}
    labels = [str(i) for i in range(1, len(analyses) + 1)]
    md = ["# flighttest flight report", "", *overview_section(analyses, labels), *legend_section()]
    used: set[str] = set()
    for label, a in zip(labels, analyses):
        slug = _slug(a.log.path.stem if a.log.path.is_file() else a.log.name)
        while slug in used:
            slug += "_"
        used.add(slug)
        md += [f"## {label}. {a.log.name}", "", *flight_lines(a),
               f"- source: `{display_path(a.log.path)}` ({a.log.source})",
               f"- duration: {float(a.log.state['t_s'].iloc[-1]):.1f} s, {len(a.log.state)} samples"]  # fmt: skip
        if a.log.mission_name:
            md.append(f"- mission: {a.log.mission_name}")
        if a.profile:
            md.append(f"- vehicle: {a.profile.name} (v_h {a.profile.v_h_mps:.2f} m/s, "
                      f"w_allow {a.profile.w_allow_mps:.3f} m/s: {a.profile.w_allow_source})")  # fmt: skip
        md += source_lines(a)
        md += wind_lines(a)
        for k, v in a.log.missing.items():
            md.append(f"- missing {k}: {v}")
        md += [f"- note: {n}" for n in a.notes]
        md += ["", f"### Descents ({len(a.descents)})", ""]
        if len(a.descents):
            for k, (what, columns) in enumerate(DESCENT_TABLES):
                md += ([""] if k else []) + [f"{what}:", "", markdown_table(a.descents, columns)]
        else:
            md.append("No descent found.")
        md.append("")
        md += heights_section(a)
        over = ", flown over planned" if a.plan is not None else ""
        images = [
            (f"Altitude and descent rate{over}", plot_altitude(a, out_dir / f"{slug}_altitude.png")),
            (f"Path{over}", plot_path(a, out_dir / f"{slug}_path.png")),
        ]
        if a.tracking is not None and len(a.tracking):
            images.append(("Tracking error against the plan", plot_tracking(a, out_dir / f"{slug}_tracking.png")))
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
    md += params_section(analyses, labels)
    out = out_dir / "report.md"
    out.write_text("\n".join(md) + "\n", encoding="utf-8")
    return out
