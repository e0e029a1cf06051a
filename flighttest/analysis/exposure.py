"""VRS exposure of a flight, measured the way the live guard measures it.

Each state sample goes through ``GuardRegion.check`` (air-relative velocity rotated into the blade
frame = body frame, CONVENTIONS §1-2) and through ``aero.classify_n`` on the normalised ``(u, −w)/v_h``,
so the analysis and the guard cannot disagree about where the vehicle was. Where the log has no
wind the air is taken as still; where it has no attitude the vehicle is taken as level (both are
listed in ``FlightLog.missing``).

Per descent: time inside the guard region (margin < 0), time near it (0 ≤ margin < ``near_mps``),
the minimum margin and the deepest point (its normalised ``v_H_n``, ``v_z_n``), and the time in
Onera's VRS and TWS and in the WBS cone.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from flighttest.model import aero
from flighttest.model.profiles import VehicleProfile

NEAR_MPS = 0.3  # "near the region": within this margin (m/s) of the guard boundary

TRACK_COLUMNS = ["t_s", "w_mps", "u_mps", "margin_mps", "allowed", "v_H_n", "v_z_n", "region"]
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
]


def velocity_track(state: pd.DataFrame, profile: VehicleProfile) -> pd.DataFrame:
    """Per-sample blade-frame velocity, guard margin and Onera region (``TRACK_COLUMNS``)."""
    region = profile.guard_region()
    s = state
    q = s[["qw", "qx", "qy", "qz"]].to_numpy(float, copy=True)
    level = ~np.isfinite(q).all(axis=1)
    q[level] = (1.0, 0.0, 0.0, 0.0)
    wind = np.nan_to_num(s[["wn_mps", "we_mps", "wd_mps"]].to_numpy(float))
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
    sel = (t >= start_s) & (t <= end_s)
    if not sel.any():
        return dict.fromkeys(EXPOSURE_COLUMNS, np.nan)
    dt = sample_durations(t)[sel]
    m = track["margin_mps"].to_numpy()[sel]
    reg = track["region"].to_numpy()[sel]
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
    }
