"""The campaign's two comparison figures: vertical baseline against helix descent.

``plot_tracks_velocity_space`` overlays the air-relative blade-frame tracks of both main descents on the
paper's normalised velocity-space chart (where each flight went relative to VRS and the guard boundary; the
wind each was judged with in its legend: :mod:`flighttest.analysis.wind`);
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
from flighttest.errors import FlighttestError
from flighttest.model.chart import draw_chart

DPI = 110
VERTICAL_COLOUR = "black"
HELIX_COLOUR = "#0046ad"  # dark blue: readable on all four region colours, unlike the magenta guard line
PROBE_COLOUR = "#6a3d9a"
CONTEXT_S = 1.0  # seconds of hover shown before and after each descent in the altitude panel
# Field-day descents stay near the guard boundary (|v_z| ~ w_allow ~ 0.1-0.2 v_h), so the view is zoomed
# tighter than the per-log report's (2, -1) but still shows the top of the TWS below the VRS band.
LIM_H_N = (1.0, 6.0)  # v_H/v_h axis half-width: at least / at most
LIM_Z_N = (-0.75, -6.0)  # v_z/v_h axis bottom: at least this far down / at most
TOP_N = (0.25, 1.0)  # v_z/v_h axis top (climbs matter little here): at least / at most (draw_chart's top)


def _name(a: Analysis) -> str:
    return a.log.name or str(a.log.path)


PLAN_COLOUR = "0.55"  # the plans: grey, dashed, as in the per-flight report


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


def _finite_extreme(values: list[np.ndarray], fn) -> float | None:
    v = np.concatenate([np.asarray(x, float) for x in values]) if values else np.array([])
    v = v[np.isfinite(v)]
    return float(fn(v)) if v.size else None


def chart_limits(v_H_n: list[np.ndarray], v_z_n: list[np.ndarray]) -> tuple[float, float, float]:
    """(v_H_max_n, v_z_min_n, v_z_max_n) showing every track with 10 % room, within the LIM_*/TOP_N bounds."""
    h = _finite_extreme(v_H_n, np.max)
    z = _finite_extreme(v_z_n, np.min)
    top = _finite_extreme(v_z_n, np.max)
    lim_H = LIM_H_N[0] if h is None else min(max(LIM_H_N[0], 1.1 * h), LIM_H_N[1])
    lim_z = LIM_Z_N[0] if z is None else max(min(LIM_Z_N[0], 1.1 * z), LIM_Z_N[1])
    lim_top = TOP_N[0] if top is None else min(max(TOP_N[0], 1.1 * top), TOP_N[1])
    return lim_H, lim_z, lim_top


def _save(fig, out: Path) -> Path:
    out = Path(out)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.tight_layout()
        fig.savefig(out)
    except OSError as exc:
        raise FlighttestError(f"{out}: cannot write figure ({exc.strerror or exc})") from None
    finally:
        plt.close(fig)
    return out


def plot_tracks_velocity_space(vertical: Analysis, helix: Analysis, out: Path, probe: Analysis | None = None) -> Path:
    """Both main descents' normalised blade-frame tracks on the velocity-space chart of ``helix.profile``."""
    flights = [("vertical", vertical, "vertical baseline", VERTICAL_COLOUR), ("helix", helix, "helix", HELIX_COLOUR)]
    tracks = {role: _track(a, role) for role, a, _, _ in flights}
    descents = {role: main_descent(a, role) for role, a, _, _ in flights}
    probe_track = _track(probe, "probe") if probe is not None else None
    profile = helix.profile

    shown = [tracks[r] for r in tracks] + ([probe_track] if probe_track is not None else [])
    lim_H, lim_z, lim_top = chart_limits([t["v_H_n"] for t in shown], [t["v_z_n"] for t in shown])
    fig, ax = plt.subplots(figsize=(8, 6), dpi=DPI)
    draw_chart(ax, profile, v_H_max_n=lim_H, v_z_min_n=lim_z)
    ax.set_ylim(lim_z, lim_top)
    # the hover, climb and landing around the descents, and the probe: faint context; the legend gets
    # proxies because 1-pixel dots would not show in it
    for t in tracks.values():
        ax.plot(t["v_H_n"], t["v_z_n"], ".", ms=1.2, color="0.45", alpha=0.3)
    ax.plot([], [], ".", ms=6, color="0.45", alpha=0.6, label="rest of both flights")
    if probe_track is not None:
        ax.plot(probe_track["v_H_n"], probe_track["v_z_n"], ".", ms=1.5, color=PROBE_COLOUR, alpha=0.25)
        ax.plot([], [], ".", ms=6, color=PROBE_COLOUR, alpha=0.6, label=f"probe ({_name(probe)})")
    for role, _, label, colour in flights:
        t, d = tracks[role], descents[role]
        sel = _in_window(t["t_s"], d)
        v_H, v_z = t["v_H_n"][sel].to_numpy(float), t["v_z_n"][sel].to_numpy(float)
        ax.plot(v_H, v_z, ".-", lw=2.0, ms=4, color=colour, label=f"{label}, {float(d['duration_s']):.2f} s")
        if np.isfinite(v_z).any():  # the deepest point: where the descent came closest to (or went into) VRS
            k = int(np.nanargmin(v_z))
            ax.plot([v_H[k]], [v_z[k]], "v", ms=9, color=colour, mec="white", mew=0.8)
    winds = "; ".join(f"{label.split()[0]}{flights_wind(a, descents[role])}" for role, a, label, _ in flights)
    ax.set_title(
        f"{profile.name}: main descents in velocity space, air-relative\n"
        f"v_h = {profile.v_h_mps:.2f} m/s, w_allow = {profile.w_allow_mps:.2f} m/s"
        f" ({profile.w_allow_mps / profile.v_h_mps:.3f} v_h)\n{winds}",
        fontsize=9,
    )
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
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
    ax1.set_title("main descents (end marked)")
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
