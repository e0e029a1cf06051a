"""The plan a flight flew, placed where it was flown: for drawing under the flown path.

A flighttest log folder keeps the trajectory it streamed (``trajectory.csv`` + ``trajectory.json``,
positions relative to the plan's start) and the ``stream_start`` event with ``origin_ned``, where in the
vehicle's local frame that start was (docs/CONTRACTS.md, "Flight log folders"). The plan is shifted
there and onto the log's clock (events are on it already). When the heights were arbitrated onto
another source (``state.d_est_m`` keeps the estimator's), the plan follows the trusted height's datum,
by the offset between the two at the stream start. Any other log, or a folder without those files,
has no plan: None, never an error — a plot without it is still a plot.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from flighttest.analysis.schema import FlightLog
from flighttest.errors import FlighttestError

PLANNED_COLUMNS = ["t_s", "n_m", "e_m", "d_m", "vd_mps", "w_mps", "u_mps"]


def _stream_start(log: FlightLog) -> tuple[float, tuple[float, float, float]] | None:
    for ev in log.events:
        if ev.get("event") != "stream_start":
            continue
        origin, t = ev.get("origin_ned"), ev.get("t_s")
        if (isinstance(origin, list) and len(origin) == 3 and isinstance(t, int | float)
                and all(isinstance(v, int | float) and math.isfinite(v) for v in (*origin, t))):  # fmt: skip
            return float(t), (float(origin[0]), float(origin[1]), float(origin[2]))
    return None


def planned_path(log: FlightLog) -> pd.DataFrame | None:
    """The flown plan on the log's clock and in its frame (``PLANNED_COLUMNS``; ``w``/``u`` in still
    air, level where the plan has no attitude), or None when the log does not say what was planned."""
    from flighttest.model.frames import blade_velocity_mps
    from flighttest.model.trajectory import Trajectory

    if log.source != "flighttest-folder" or not (log.path / "trajectory.csv").is_file():
        return None
    start = _stream_start(log)
    if start is None:
        return None
    try:
        traj = Trajectory.load(log.path / "trajectory.csv")
    except FlighttestError:  # a damaged copy: the flight is still worth a plot
        return None
    t0, (n0, e0, d0) = start
    s = log.state
    if "d_est_m" in s and len(s):
        t = s["t_s"].to_numpy(float)
        offset = (s["d_m"] - s["d_est_m"]).to_numpy(float)
        ok = np.isfinite(offset)
        if ok.any():
            d0 += float(np.interp(t0, t[ok], offset[ok]))
    q = traj.attitude_quat()
    q = np.tile([1.0, 0.0, 0.0, 0.0], (len(traj.df), 1)) if q is None else q
    w, u = blade_velocity_mps(traj.column("vn_mps"), traj.column("ve_mps"), traj.column("vd_mps"), *q.T, 0.0, 0.0, 0.0)
    return pd.DataFrame({
        "t_s": traj.t_s + t0, "n_m": traj.column("n_m") + n0, "e_m": traj.column("e_m") + e0,
        "d_m": traj.column("d_m") + d0, "vd_mps": traj.column("vd_mps"), "w_mps": w, "u_mps": u,
    })  # fmt: skip
