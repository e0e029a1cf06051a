"""The campaign's two comparison figures: vertical baseline against helix descent.

``plot_tracks_velocity_space`` draws the air-relative blade-frame track of each main descent on the
paper's normalised velocity-space chart (where each flight went relative to VRS and the guard boundary;
the wind each was judged with in its panel's title: :mod:`flighttest.analysis.wind`), one panel per
flight with its axes fitted to that flight and the guard region in view — on one pair of axes the
vertical baseline, whose in-plane speed stays near 0, would be a line at the origin beside the helix;
``plot_descent_comparison`` sets the two descents side by side in time (altitude over time with each
plan under it, and the descent times as bars with the planned times and the speed-up). Both go in the
README and the campaign report. A flight's main descent is the analysis's (``compare.primary_descent``:
for flighttest's own logs, one descent from the first setpoint until at the end height and settled).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from flighttest.analysis.compare import primary_descent
from flighttest.analysis.pipeline import Analysis
from flighttest.analysis.planned import planned_path
from flighttest.errors import FlighttestError
from flighttest.model.chart import PLAN_COLOUR, draw_chart, mark_ends, velocity_view

DPI = 110
VERTICAL_COLOUR = "black"
HELIX_COLOUR = "#0046ad"  # dark blue: readable on all four region colours, unlike the magenta guard line
PROBE_COLOUR = "#6a3d9a"
CONTEXT_S = 1.0  # seconds of hover shown before and after each descent in the altitude panel


def _name(a: Analysis) -> str:
    return a.log.name or str(a.log.path)


def main_descent(a: Analysis, role: str) -> pd.Series:
    """The flight's main descent, as ``analyse`` and ``compare`` give it (``primary_descent``: never the
    abort ladder's); a one-line error when there is none."""
    d = primary_descent(a.descents, a.log.events)
    if d is None:
        raise FlighttestError(f"{role} flight {_name(a)}: no descent found, nothing to compare")
    return d


def _track(a: Analysis, role: str) -> pd.DataFrame:
    if a.profile is None or a.track is None:
        raise FlighttestError(f"{role} flight {_name(a)}: no vehicle profile, so no blade-frame track (give --vehicle)")
    return a.track


def _in_window(t_s: pd.Series, d: pd.Series) -> np.ndarray:
    t = t_s.to_numpy(float)
    return (t >= float(d["start_s"])) & (t <= float(d["end_s"]))


def _save(fig, out: Path) -> Path:
    out = Path(out)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.tight_layout(rect=(0, 0.13, 1, 1) if fig.legends else (0, 0, 1, 1))  # room for a legend below
        fig.savefig(out)
    except OSError as exc:
        raise FlighttestError(f"{out}: cannot write figure ({exc.strerror or exc})") from None
    finally:
        plt.close(fig)
    return out


def plot_tracks_velocity_space(vertical: Analysis, helix: Analysis, out: Path, probe: Analysis | None = None) -> Path:
    """Each main descent's normalised blade-frame track on the velocity-space chart of ``helix.profile``:
    the vertical baseline (and the probe, which sweeps straight down too) on the left, the helix on the
    right, each panel fitted to its own flight (``chart.velocity_view``) on one shared v_z axis, the
    rest of each flight faint, the plan under it, the descent from a ring to a square."""
    flights = [("vertical", vertical, "vertical baseline", VERTICAL_COLOUR), ("helix", helix, "helix", HELIX_COLOUR)]
    tracks = {role: _track(a, role) for role, a, _, _ in flights}
    descents = {role: main_descent(a, role) for role, a, _, _ in flights}
    probe_track = _track(probe, "probe") if probe is not None else None
    profile = helix.profile
    v_h = profile.v_h_mps

    shown = {"vertical": [tracks["vertical"]] + ([probe_track] if probe_track is not None else []),
             "helix": [tracks["helix"]]}  # fmt: skip
    views = {role: velocity_view(profile, [t["v_H_n"] for t in ts], [t["v_z_n"] for t in ts])
             for role, ts in shown.items()}  # fmt: skip
    y_lo, y_hi = min(v[2] for v in views.values()), max(v[3] for v in views.values())
    fig, axes = plt.subplots(1, 2, figsize=(14, 7.5), dpi=DPI, sharey=True, gridspec_kw={"width_ratios": [2, 3]})
    for ax, (role, a, label, colour) in zip(axes, flights):
        x_lo, x_hi = views[role][:2]
        draw_chart(ax, profile, v_H_max_n=x_hi, v_z_min_n=y_lo, v_H_min_n=x_lo, v_z_max_n=y_hi)
        t, d = tracks[role], descents[role]
        # the hover, climb and landing around the descent, and the probe: faint context; the legend
        # gets proxies because 1-pixel dots would not show in it
        ax.plot(t["v_H_n"], t["v_z_n"], ".", ms=1.2, color="0.45", alpha=0.3)
        if role == "vertical" and probe_track is not None:
            ax.plot(probe_track["v_H_n"], probe_track["v_z_n"], ".", ms=1.5, color=PROBE_COLOUR, alpha=0.25)
            ax.plot([], [], ".", ms=6, color=PROBE_COLOUR, alpha=0.6, label=f"probe ({_name(probe)})")
        plan = planned_path(a.log)
        if plan is not None:
            ax.plot(plan["u_mps"] / v_h, -plan["w_mps"] / v_h, lw=3.0, color=PLAN_COLOUR, alpha=0.8,
                    label="its plan (still air)")  # fmt: skip
        sel = _in_window(t["t_s"], d)
        v_H, v_z = t["v_H_n"][sel].to_numpy(float), t["v_z_n"][sel].to_numpy(float)
        ax.plot(v_H, v_z, ".-", lw=1.2, ms=2.5, color=colour, label=f"{label}, {float(d['duration_s']):.2f} s")
        mark_ends(ax, v_H, v_z)
        if np.isfinite(v_z).any():  # the deepest point: where the descent came closest to (or went into) VRS
            k = int(np.nanargmin(v_z))
            ax.plot([v_H[k]], [v_z[k]], "v", ms=9, color=colour, mec="white", mew=0.8, label="deepest point")
        ax.plot([], [], ".", ms=6, color="0.45", alpha=0.6, label="rest of the flight")
        ax.set_xlim(x_lo, x_hi)
        ax.set_ylim(y_lo, y_hi)
        ax.set_title(f"{label} ({_name(a)}),{flights_wind(a, d)}", fontsize=10)
    axes[1].set_ylabel("")
    # one legend under both panels: inside, it hid the probe's deepest samples
    legend = {}
    for ax in axes:
        for handle, text in zip(*ax.get_legend_handles_labels()):
            legend.setdefault(text, handle)
    fig.legend(list(legend.values()), list(legend), loc="lower center", ncol=5, fontsize=8, frameon=False)
    fig.suptitle(
        f"{profile.name}: main descents in velocity space, air-relative (each panel fitted to its flight)\n"
        f"v_h = {profile.v_h_mps:.2f} m/s, w_allow = {profile.w_allow_mps:.2f} m/s"
        f" ({profile.w_allow_mps / profile.v_h_mps:.3f} v_h)"
    )
    return _save(fig, out)


def flights_wind(a: Analysis, d: pd.Series) -> str:
    """" wind 3.0 ± 0.2 m/s (source)": the wind over the descent ``d`` its track was judged with."""
    w = a.log.wind
    if w is None:
        return " wind not resolved"
    sel = _in_window(a.log.state["t_s"], d)
    o = w.over(sel if sel.any() else None)
    if o["wind_ned_mps"][0] is None:
        return f" wind unknown ({w.source})"
    sd = f" ± {o['wind_sd_mps']:.1f}" if o["wind_sd_mps"] is not None else ""
    return f" wind {np.hypot(*o['wind_ned_mps'][:2]):.1f}{sd} m/s ({w.source})"


def descent_profile(a: Analysis, d: pd.Series, context_s: float = CONTEXT_S) -> tuple[np.ndarray, np.ndarray]:
    """(time since the descent start, altitude above the descent's end) from ``context_s`` before to after it."""
    s = a.log.state
    t = s["t_s"].to_numpy(float)
    alt = -s["d_m"].to_numpy(float)
    if "glitch" in s:  # altitude jumps of a bad sensor would swamp the scale
        alt = np.where(s["glitch"].to_numpy(bool), np.nan, alt)
    start, end = float(d["start_s"]), float(d["end_s"])
    ok = np.isfinite(alt)
    if not ok.any():
        raise FlighttestError(f"{_name(a)}: no altitude samples in the log")
    # the settled end height, where the segmenter found one: the curve then flattens onto zero
    alt_end = float(d.get("end_alt_m", np.nan))
    if not np.isfinite(alt_end):
        alt_end = float(np.interp(end, t[ok], alt[ok]))
    sel = (t >= start - context_s) & (t <= end + context_s)
    return t[sel] - start, alt[sel] - alt_end


def planned_profile(a: Analysis, d: pd.Series) -> tuple[np.ndarray, np.ndarray] | None:
    """(time since the descent start, planned height above the plan's end) of the flight's plan, None
    when the log has none or its main descent is not the planned one."""
    if a.plan is None or not bool(d.get("main", False)):
        return None
    t = a.plan["t_s"].to_numpy(float) - float(d["start_s"])
    h = -(a.plan["d_m"].to_numpy(float) - float(a.plan["d_m"].iloc[-1]))
    return t, h


def plot_descent_comparison(vertical: Analysis, helix: Analysis, out: Path) -> Path:
    """Altitude over time of both main descents (left) and their descent times with the speed-up (right)."""
    flights = [("vertical", vertical, "vertical baseline", VERTICAL_COLOUR), ("helix", helix, "helix", HELIX_COLOUR)]
    descents = {role: main_descent(a, role) for role, a, _, _ in flights}
    durations = {role: float(d["duration_s"]) for role, d in descents.items()}
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 5), dpi=DPI, gridspec_kw={"width_ratios": [3, 2]})

    planned = {role: (a.main or {}).get("planned_descent_s") for role, a, _, _ in flights}
    for role, a, label, colour in flights:
        d = descents[role]
        t, h = descent_profile(a, d)
        plan = planned_profile(a, d)
        if plan is not None:
            ax1.plot(*plan, "--", lw=1.4, color=colour, alpha=0.45, label=f"{label}, planned")
        ax1.plot(t, h, "-", lw=1.8, color=colour, label=f"{label} ({_name(a)})")
        ax1.axvline(durations[role], color=colour, ls="--", lw=1)
        fin = np.isfinite(h)
        h_end = float(np.interp(durations[role], t[fin], h[fin])) if fin.any() else 0.0
        ax1.plot([durations[role]], [h_end], "o", color=colour, ms=6)
        ax1.annotate(
            f"{durations[role]:.2f} s",
            (durations[role], h_end),
            xytext=(5, 8),
            textcoords="offset points",
            color=colour,
            fontsize=9,
        )
    ax1.axvline(0.0, color="0.5", lw=0.8)
    ax1.axhline(0.0, color="0.5", lw=0.8)
    ax1.set_xlabel("time since the descent start, s")
    ax1.set_ylabel("altitude above the descent's end, m")
    ax1.set_title("main descents as flown (end marked), the plans dashed")
    ax1.legend(loc="upper right", fontsize=8)
    ax1.grid(alpha=0.3)

    labels = [label for _, _, label, _ in flights]
    values = [durations[role] for role, _, _, _ in flights]
    bars = ax2.barh(labels, values, color=[colour for _, _, _, colour in flights], height=0.55)
    for bar, v in zip(bars, values, strict=True):
        ax2.text(
            bar.get_width() / 2,
            bar.get_y() + bar.get_height() / 2,
            f"{v:.2f} s",
            ha="center",
            va="center",
            color="white",
            fontsize=12,
            fontweight="bold",
        )
    plans = [planned[role] for role, _, _, _ in flights]
    for k, v in enumerate(plans):
        if isinstance(v, int | float):  # the plan's time by the same rule: what flying it exactly takes
            ax2.plot([v, v], [k - 0.38, k + 0.38], "-", color=PLAN_COLOUR, lw=3)
            ax2.annotate(f"planned {v:.2f} s", (v, k - 0.38), xytext=(3, 2), textcoords="offset points",
                         fontsize=8, color="0.3", va="bottom")  # fmt: skip
    ax2.invert_yaxis()  # the baseline on top, as on the left
    ax2.set_xlabel("descent time, s (grey: planned)")
    ax2.set_xlim(0, 1.15 * max([*values, *(v for v in plans if isinstance(v, int | float))]))
    speedup = values[0] / values[1] if values[1] > 0 else float("nan")
    ax2.set_title(f"descent time: helix speed-up {speedup:.2f}× (vertical / helix)")
    ax2.grid(axis="x", alpha=0.3)
    return _save(fig, out)


def plot_build_up(build_up: dict[str, list[dict]], out: Path) -> Path:
    """The build-up of each descent, flight by flight (``flighttest.campaign.build_up``): the margin each was
    planned with and the least the guard saw (left), hover to hover against the optimum (right). A flight that
    did not complete with the guard silent is a cross."""
    fig, (ax_m, ax_t) = plt.subplots(1, 2, figsize=(10, 4), dpi=DPI)
    for mission, colour in (("vertical", VERTICAL_COLOUR), ("helix", HELIX_COLOUR)):
        rows = build_up.get(mission) or []
        if not rows:
            continue
        k = np.array([r["flight"] for r in rows], float)
        clean = np.array([r.get("outcome") == "completed" and bool(r.get("guard_silent")) for r in rows])

        def col(key: str, rows=rows) -> np.ndarray:
            return np.array([np.nan if r.get(key) is None else float(r[key]) for r in rows])

        for ax, y, label in ((ax_m, col("margin_mps"), f"{mission}: planned margin"),
                             (ax_t, col("flown_over_optimum"), f"{mission}: flown / optimum")):  # fmt: skip
            ax.plot(k, y, "-", color=colour, label=label)
            ax.plot(k[clean], y[clean], "o", color=colour)
            ax.plot(k[~clean], y[~clean], "x", color="red", markersize=9)
        ax_m.plot(k, col("min_margin_mps"), "--", color=colour, label=f"{mission}: guard's least margin")
    ax_m.axhline(0.0, color="0.6", lw=0.8)
    ax_m.set(xlabel="build-up flight", ylabel="m/s", title="margin inside the guard's bound")
    ax_t.axhline(1.0, color="0.6", lw=0.8)
    ax_t.set(xlabel="build-up flight", ylabel="× optimum", title="hover to hover / the planner's optimum")
    for ax in (ax_m, ax_t):
        ax.xaxis.get_major_locator().set_params(integer=True)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return _save(fig, out)
