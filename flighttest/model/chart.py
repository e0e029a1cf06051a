"""The normalised velocity-space chart of the paper's Fig. 5/8/9: VRS, TWS, WBS, the cone, the guard."""

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


def draw_chart(ax, profile: VehicleProfile, v_H_max_n: float = 2.0, v_z_min_n: float = -3.0, n: int = 400):
    """Draw the regions, the simplified cone and the guard boundary on ``ax`` (normalised axes)."""
    mu = np.linspace(-v_H_max_n, v_H_max_n, n)
    eta = np.linspace(v_z_min_n, 1.0, n)
    MU, ETA = np.meshgrid(mu, eta)
    vrs = profile.vrs
    reg = aero.classify_n(MU, ETA, vrs.onera_k, vrs.eps_vrs, vrs.eps_tws, vrs.cone_deg)
    # rasterized: 160 000 cells as vector paths take ~20 s to write as .svg or .pdf
    ax.pcolormesh(MU, ETA, reg, cmap=ListedColormap(REGION_COLOURS), vmin=-0.5, vmax=3.5, shading="auto",
                  rasterized=True)
    t = math.tan(math.radians(vrs.cone_deg))
    ax.plot(mu, -t * np.abs(mu), "k--", lw=1.2, label=f"simplified {vrs.cone_deg:g}° cone")
    bound = aero.guard_bound_mps(np.abs(mu) * profile.v_h_mps, profile.w_allow_mps, vrs.cone_deg, vrs.margin_mps)
    ax.plot(mu, -bound / profile.v_h_mps, "m-", lw=2, label="guard boundary (w_allow, cone, margin)")
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
