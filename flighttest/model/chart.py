"""The normalised velocity-space chart of the paper's Fig. 5/8/9: VRS, TWS, WBS, the cone, the guard.

Also what every figure of flighttest shares, so a quantity looks the same wherever it is drawn: the
colours of ``w`` and the descent rate, the guard region's shading, start and end markers
(:func:`mark_ends`), and axes fitted to the data with the guard region in view (:func:`fitted_range`,
:func:`velocity_view`).
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import ListedColormap

from flighttest.errors import FlighttestError
from flighttest.inputs import IMAGE_SUFFIXES, atomic_write
from flighttest.model import aero
from flighttest.model.profiles import VehicleProfile

REGION_COLOURS = ["#d9f2d9", "#ffb366", "#e04040", "#6fa8dc"]  # normal, VRS, TWS, WBS
W_COLOUR = "tab:blue"  # w: descent through the rotor disk, air-relative
VD_COLOUR = "tab:green"  # v_D: descent rate over the ground (the same as w only straight down in still air)
GUARD_COLOUR = "m"  # the guard boundary
GUARD_SHADE = {"color": "tab:red", "alpha": 0.13, "lw": 0}  # the guard region: the forbidden side of that boundary
PLAN_COLOUR = "0.6"  # a plan drawn under what was flown
# the start a ring, the end a square that fits inside it: a plan back at its start shows both
START_STYLE = {"marker": "o", "ms": 12, "mfc": "none", "mec": "tab:green", "mew": 2.2, "ls": "none"}
END_STYLE = {"marker": "s", "ms": 6.5, "color": "tab:red", "mec": "black", "mew": 0.6, "ls": "none"}
# the normalised view never reaches beyond this (v_h): one glitched sample must not shrink a flight to a dot
VIEW_LIMIT_N = 6.0


def mark_ends(ax, *coords, label: bool = True, zorder: float = 6) -> None:
    """Mark the first and last finite point of a line given by its coordinates (2 or 3 arrays)."""
    arrays = [np.asarray(c, float) for c in coords]
    ok = np.logical_and.reduce([np.isfinite(a) for a in arrays])
    if not ok.any():
        return
    i, j = np.flatnonzero(ok)[[0, -1]]
    ax.plot(*[[a[i]] for a in arrays], **START_STYLE, label="start" if label else None, zorder=zorder)
    ax.plot(*[[a[j]] for a in arrays], **END_STYLE, label="end" if label else None, zorder=zorder)


def _finite(values) -> np.ndarray:
    """Every finite number of ``values`` (numbers and arrays, in any nesting of lists) as one array."""
    parts = [np.ravel(np.asarray(x, float)) for x in values]
    v = np.concatenate(parts) if parts else np.array([])
    return v[np.isfinite(v)]


def fitted_range(*values, pad: float = 0.06, min_span: float = 0.0) -> tuple[float, float]:
    """(lo, hi) holding every finite value given (arrays or numbers) with ``pad`` of the span either
    side, at least ``min_span`` wide (centred), so a flat line is not blown up to fill the panel."""
    v = _finite(values)
    if not v.size:
        return (-0.5 * max(min_span, 1.0), 0.5 * max(min_span, 1.0))
    lo, hi = float(v.min()), float(v.max())
    if hi - lo < min_span:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.5 * min_span, mid + 0.5 * min_span
    span = hi - lo or 1.0
    return lo - pad * span, hi + pad * span


def guard_boundary_n(profile: VehicleProfile, v_H_n) -> np.ndarray:
    """The guard boundary in the chart's axes: ``v_z/v_h`` (climb positive) where it lies at ``v_H_n``."""
    u = np.abs(np.asarray(v_H_n, float)) * profile.v_h_mps
    return -aero.guard_bound_mps(u, profile.w_allow_mps, profile.vrs.cone_deg, profile.vrs.margin_mps) / profile.v_h_mps


def velocity_view(profile: VehicleProfile, v_H_n: list, v_z_n: list, pad: float = 0.08) -> tuple[float, ...]:
    """(v_H lo, v_H hi, v_z lo, v_z hi) of a normalised chart fitted to the tracks (lists of arrays)
    with the guard region in view: the boundary across the drawn width and a band of the forbidden
    side below it. The in-plane speed is never negative, so the view starts just left of 0; at least
    0.1 v_h wide, so a straight-down flight is a track with a shape, not a line at 0."""
    h, z = _finite(v_H_n), _finite(v_z_n)
    h_hi = min(max(float(h.max()) if h.size else 0.0, 0.1), VIEW_LIMIT_N)
    x_hi = h_hi * (1 + pad)
    x_lo = -pad * h_hi
    deepest_boundary = float(guard_boundary_n(profile, x_hi))
    z_lo = max(min(float(z.min()) if z.size else 0.0, deepest_boundary), -VIEW_LIMIT_N)
    z_hi = min(max(float(z.max()) if z.size else 0.0, 0.0), VIEW_LIMIT_N)
    span = z_hi - z_lo or 1.0
    # the forbidden side gets a quarter of the track's height below the boundary, the top a little room
    return x_lo, x_hi, z_lo - max(0.25 * span, 0.05), z_hi + pad * span


def draw_chart(ax, profile: VehicleProfile, v_H_max_n: float = 2.0, v_z_min_n: float = -3.0, n: int = 400,
               v_H_min_n: float | None = None, v_z_max_n: float = 1.0) -> None:  # fmt: skip
    """Draw the regions, the simplified cone, the guard boundary and its forbidden side on ``ax``
    (normalised axes, ``v_H`` from ``v_H_min_n`` (default ``−v_H_max_n``: the paper's mirrored chart)
    to ``v_H_max_n``, ``v_z`` from ``v_z_min_n`` to ``v_z_max_n``)."""
    lo = -v_H_max_n if v_H_min_n is None else v_H_min_n
    mu = np.linspace(lo, v_H_max_n, n)
    eta = np.linspace(v_z_min_n, v_z_max_n, n)
    MU, ETA = np.meshgrid(mu, eta)
    vrs = profile.vrs
    reg = aero.classify_n(MU, ETA, vrs.onera_k, vrs.eps_vrs, vrs.eps_tws, vrs.cone_deg)
    # rasterized: 160 000 cells as vector paths take ~20 s to write as .svg or .pdf
    ax.pcolormesh(MU, ETA, reg, cmap=ListedColormap(REGION_COLOURS), vmin=-0.5, vmax=3.5, shading="auto",
                  rasterized=True)
    t = math.tan(math.radians(vrs.cone_deg))
    ax.plot(mu, -t * np.abs(mu), "k--", lw=1.2, label=f"simplified {vrs.cone_deg:g}° cone")
    boundary = guard_boundary_n(profile, mu)
    ax.fill_between(mu, boundary, v_z_min_n, facecolor="none", edgecolor=GUARD_COLOUR, hatch="//", lw=0,
                    alpha=0.45, label="guard region (the guard aborts here)")  # fmt: skip
    ax.plot(mu, boundary, "-", color=GUARD_COLOUR, lw=2, label="guard boundary (w_allow, cone, margin)")
    for code, name in ((1, "VRS"), (2, "TWS"), (3, "WBS")):
        ax.fill_between([], [], color=REGION_COLOURS[code], label=name)
    ax.axhline(0, color="0.5", lw=0.6)
    ax.axvline(0, color="0.5", lw=0.6)
    ax.set_xlabel("v_H / v_h  (in-plane, blade frame)")
    ax.set_ylabel("v_z / v_h  (climb positive, blade frame)")
    ax.set_xlim(mu[0], mu[-1])
    ax.set_ylim(eta[0], eta[-1])


def write_chart(profile: VehicleProfile, out: Path | str, track_n: tuple[np.ndarray, np.ndarray] | None = None) -> Path:
    """Write the chart PNG; ``track_n`` optionally overlays a flight's normalised (v_H, v_z) track."""
    fig, ax = plt.subplots(figsize=(7.5, 6.5), dpi=110)
    draw_chart(ax, profile)
    if track_n is not None:
        ax.plot(track_n[0], track_n[1], ".", ms=2, color="k", alpha=0.6, label="flight track")
    ax.set_title(
        f"{profile.name}: v_h = {profile.v_h_mps:.2f} m/s, w_allow = {profile.w_allow_mps:.2f} m/s"
        f" ({profile.w_allow_mps / profile.v_h_mps:.3f} v_h)"
    )
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
    out = Path(out)
    # the format from the name, checked before drawing: matplotlib would otherwise pick one from an
    # unknown suffix (or none) only after the work is done, or write '.png' for an empty name
    fmt = out.suffix.lower().removeprefix(".")
    if f".{fmt}" not in IMAGE_SUFFIXES:
        plt.close(fig)
        raise FlighttestError(f"{out}: a chart is written as {' or '.join(IMAGE_SUFFIXES)} (got '{out.suffix}')")
    try:
        fig.tight_layout()
        with atomic_write(out) as tmp:  # whole or not at all; missing folders created
            fig.savefig(tmp, format=fmt)
    finally:
        plt.close(fig)
    return out
