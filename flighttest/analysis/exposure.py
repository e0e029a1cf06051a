"""VRS exposure of a flight, measured the way the live guard measures it.

Each state sample goes through ``GuardRegion.check`` (air-relative velocity rotated into the blade
frame = body frame, CONVENTIONS §1-2) and through ``aero.classify_n`` on the normalised ``(u, −w)/v_h``,
so the analysis and the guard cannot disagree about where the vehicle was. The air is the log's wind
(``FlightLog.wind``: the one :mod:`flighttest.analysis.wind` chose for it, per sample, with its 1 σ);
where the log has no attitude the vehicle is taken as level (listed in ``FlightLog.missing``).

Two judgements of the same samples:

- **at the wind's estimate** (``margin_mps``; ``time_inside_s``, ``time_near_s``, ``min_margin_mps``, the
  deepest point, the Onera times): where the vehicle most likely was;
- **at the worst air within the wind's uncertainty** (``margin_worst_mps``; ``time_inside_worst_s``,
  ``min_margin_worst_mps``), as the live guard judges: every horizontal wind within
  ``WIND_COVERAGE_SIGMAS`` (2.45) σ of the estimate (its 1 σ, per sample) — 95 % of a 2-D normal —
  through :func:`flighttest.model.frames.worst_blade_velocity_mps`, with the updraft the live guard allowed for
  the gusts it measured (``guard.csv`` ``gust_sd_mps``; none where not logged). NaN where the wind's
  uncertainty is unknown (still air assumed).

Per descent (and over the whole time airborne): time inside the guard region (margin < 0), time near it
(0 ≤ margin < ``near_mps``), the minimum margin and the deepest point (its normalised ``v_H_n``,
``v_z_n``), the time in Onera's VRS and TWS and in the WBS cone, and the same inside/minimum at the
worst air.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from flighttest.flying.wind import UPDRAFT_SIGMAS, WIND_COVERAGE_SIGMAS
from flighttest.model import aero
from flighttest.model.frames import disk_tilt_sin, worst_blade_velocity_mps
from flighttest.model.profiles import VehicleProfile

NEAR_MPS = 0.3  # "near the region": within this margin (m/s) of the guard boundary

TRACK_COLUMNS = ["t_s", "w_mps", "u_mps", "margin_mps", "allowed", "v_H_n", "v_z_n", "region", "margin_worst_mps"]
EXPOSURE_COLUMNS = [
    "time_inside_s",
    "time_near_s",
    "min_margin_mps",
    "deepest_s",
    "deepest_v_H_n",
    "deepest_v_z_n",
    "time_vrs_s",
    "time_tws_s",
    "time_wbs_s",
    "time_inside_worst_s",
    "min_margin_worst_mps",
]


def velocity_track(state: pd.DataFrame, profile: VehicleProfile, wind=None) -> pd.DataFrame:
    """Per-sample blade-frame velocity, guard margin and Onera region (``TRACK_COLUMNS``) in the air of
    ``wind`` (a :class:`flighttest.analysis.wind.LogWind` of this state: the log's ``FlightLog.wind``), else
    of the state's own wind columns (still air where NaN, its uncertainty unknown)."""
    region = profile.guard_region()
    s = state
    q = s[["qw", "qx", "qy", "qz"]].to_numpy(float, copy=True)
    level = ~np.isfinite(q).all(axis=1)
    q[level] = (1.0, 0.0, 0.0, 0.0)
    gust = 0.0
    if wind is not None:
        gust = wind.gust_sd_mps if wind.gust_sd_mps is not None else 0.0
        wind, sd = np.nan_to_num(wind.ned_mps), wind.sd_mps
    else:
        wind, sd = np.nan_to_num(s[["wn_mps", "we_mps", "wd_mps"]].to_numpy(float)), np.full(len(s), np.nan)
    allowed, w, u, margin = region.check(
        s["vn_mps"].to_numpy(float),
        s["ve_mps"].to_numpy(float),
        s["vd_mps"].to_numpy(float),
        q[:, 0],
        q[:, 1],
        q[:, 2],
        q[:, 3],
        wind[:, 0],
        wind[:, 1],
        wind[:, 2],
    )
    w_worst, u_worst = worst_blade_velocity_mps(w, u, disk_tilt_sin(q[:, 0], q[:, 1], q[:, 2], q[:, 3]),
                                                WIND_COVERAGE_SIGMAS * sd, UPDRAFT_SIGMAS * gust)  # fmt: skip
    margin_worst = np.where(np.isfinite(sd), region.margin(w_worst, u_worst), np.nan)
    v_H_n, v_z_n = region.normalised(w, u)
    vrs = profile.vrs
    codes = aero.classify_n(v_H_n, v_z_n, vrs.onera_k, vrs.eps_vrs, vrs.eps_tws, vrs.cone_deg)
    return pd.DataFrame(
        {
            "t_s": s["t_s"].to_numpy(float),
            "w_mps": w,
            "u_mps": u,
            "margin_mps": margin,
            "allowed": allowed,
            "v_H_n": v_H_n,
            "v_z_n": v_z_n,
            "region": codes,
            "margin_worst_mps": margin_worst,
        }
    )


def sample_durations(t: np.ndarray) -> np.ndarray:
    """Time each sample stands for (s): the forward difference, the last one repeated."""
    if len(t) < 2:
        return np.zeros(len(t))
    dt = np.diff(t)
    return np.concatenate([dt, dt[-1:]])


def descent_exposure(track: pd.DataFrame, start_s: float, end_s: float, near_mps: float = NEAR_MPS) -> dict:
    """Exposure numbers (``EXPOSURE_COLUMNS``) over ``[start_s, end_s]``."""
    t = track["t_s"].to_numpy()
    return exposure_over(track, (t >= start_s) & (t <= end_s), near_mps)


def exposure_over(track: pd.DataFrame, sel: np.ndarray, near_mps: float = NEAR_MPS) -> dict:
    """Exposure numbers (``EXPOSURE_COLUMNS``) over the samples ``sel`` (each standing for the time to
    the next sample of the whole track)."""
    t = track["t_s"].to_numpy()
    sel = np.asarray(sel, bool) & np.isfinite(track["margin_mps"].to_numpy(float))
    if not sel.any():
        return dict.fromkeys(EXPOSURE_COLUMNS, np.nan)
    dt = sample_durations(t)[sel]
    m = track["margin_mps"].to_numpy()[sel]
    reg = track["region"].to_numpy()[sel]
    mw = track["margin_worst_mps"].to_numpy(float)[sel] if "margin_worst_mps" in track else np.full(len(m), np.nan)
    worst_known = np.isfinite(mw).any()
    k = int(np.argmin(m))
    return {
        "time_inside_s": float(dt[m < 0].sum()),
        "time_near_s": float(dt[(m >= 0) & (m < near_mps)].sum()),
        "min_margin_mps": float(m[k]),
        "deepest_s": float(t[sel][k]),
        "deepest_v_H_n": float(track["v_H_n"].to_numpy()[sel][k]),
        "deepest_v_z_n": float(track["v_z_n"].to_numpy()[sel][k]),
        "time_vrs_s": float(dt[(reg == aero.Region.VRS) | (reg == aero.Region.TWS)].sum()),
        "time_tws_s": float(dt[reg == aero.Region.TWS].sum()),
        "time_wbs_s": float(dt[reg == aero.Region.WBS].sum()),
        "time_inside_worst_s": float(dt[mw < 0].sum()) if worst_known else np.nan,
        "min_margin_worst_mps": float(np.nanmin(mw)) if worst_known else np.nan,
    }
