"""The plan a flight flew, placed where it was flown: for drawing under the flown path.

A flighttest log folder keeps the trajectory it streamed (``trajectory.csv`` + ``trajectory.json``,
positions relative to the plan's start) and the ``stream_start`` event with ``origin_ned``, where in the
vehicle's local frame that start was (docs/CONTRACTS.md, "Flight log folders"). The plan on the log's
clock and in the estimator's frame is :func:`flighttest.analysis.plan_track.plan_on_log` (what the
tracking error is measured against); for drawing beside the heights the descents were timed on, it
follows the trusted height's datum when the heights were arbitrated onto another source
(``state.d_est_m`` keeps the estimator's), by the offset between the two at the stream start, and
carries its ``w``/``u`` through the disk in still air. Any other log, or a folder without those files,
has no plan: None, never an error — a plot without it is still a plot.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from flighttest.analysis.schema import FlightLog
from flighttest.errors import FlighttestError

PLANNED_COLUMNS = ["t_s", "n_m", "e_m", "d_m", "vd_mps", "w_mps", "u_mps"]


def planned_path(log: FlightLog) -> pd.DataFrame | None:
    """The flown plan on the log's clock and in its frame (``PLANNED_COLUMNS``; ``w``/``u`` in still
    air, level where the plan has no attitude), or None when the log does not say what was planned."""
    from flighttest.analysis.plan_track import plan_on_log
    from flighttest.model.frames import blade_velocity_mps
    from flighttest.model.trajectory import Trajectory

    if log.source != "flighttest-folder":
        return None
    placed = plan_on_log(log)
    if placed is None:
        return None
    try:
        traj = Trajectory.load(log.path / "trajectory.csv")  # the attitude, for w and u
    except FlighttestError:  # a damaged copy: the flight is still worth a plot
        return None
    if len(traj.df) != len(placed):
        return None
    t0 = float(placed["t_s"].iloc[0])
    d = placed["d_m"].to_numpy(float)
    s = log.state
    if "d_est_m" in s and len(s):
        t = s["t_s"].to_numpy(float)
        offset = (s["d_m"] - s["d_est_m"]).to_numpy(float)
        ok = np.isfinite(offset)
        if ok.any():
            d = d + float(np.interp(t0, t[ok], offset[ok]))
    q = traj.attitude_quat()
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(traj.df), 1)) if q is None else q
    vn, ve, vd = (placed[c].to_numpy(float) for c in ("vn_mps", "ve_mps", "vd_mps"))
    w, u = blade_velocity_mps(vn, ve, vd, *q.T, 0.0, 0.0, 0.0)
    n, e = placed["n_m"].to_numpy(float), placed["e_m"].to_numpy(float)
    return pd.DataFrame({"t_s": placed["t_s"].to_numpy(float), "n_m": n, "e_m": e, "d_m": d, "vd_mps": vd,
                         "w_mps": w, "u_mps": u})  # fmt: skip
