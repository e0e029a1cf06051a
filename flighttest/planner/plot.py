"""PNG of a planned trajectory: path, speeds, attitude, and blade-frame velocity against the cone."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from flighttest.errors import FlighttestError
from flighttest.model.aero import guard_bound_mps
from flighttest.model.frames import blade_velocity_mps
from flighttest.model.trajectory import Trajectory
from flighttest.planner.cone import VelocityConstraint


def blade_series(traj: Trajectory, wind_ned_mps=(0.0, 0.0, 0.0)):
    """(w, u) over the trajectory's samples; level attitude where the file has none."""
    q = traj.attitude_quat()
    if q is None:
        q = np.tile([1.0, 0.0, 0.0, 0.0], (len(traj.df), 1))
    return blade_velocity_mps(traj.column("vn_mps"), traj.column("ve_mps"), traj.column("vd_mps"),
                              q[:, 0], q[:, 1], q[:, 2], q[:, 3], *wind_ned_mps)  # fmt: skip


def plot_trajectory(traj: Trajectory, path: Path | str, constraint: VelocityConstraint,
                    wind_ned_mps=(0.0, 0.0, 0.0), title: str = "") -> Path:  # fmt: skip
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    t = traj.t_s
    fig, ax = plt.subplots(2, 2, figsize=(12, 8.5))
    a = ax[0, 0]
    n, e, d = traj.column("n_m"), traj.column("e_m"), traj.column("d_m")
    if np.ptp(n) < 1e-6:
        a.plot(e, d)
        a.set_xlabel("east (m)")
        a.set_ylabel("down (m)")
        a.invert_yaxis()
        a.set_aspect("equal", adjustable="datalim")
    else:
        sc = a.scatter(e, n, c=d, s=4, cmap="viridis")
        fig.colorbar(sc, ax=a, label="down (m)")
        a.set_xlabel("east (m)")
        a.set_ylabel("north (m)")
        a.set_aspect("equal", adjustable="datalim")
    a.set_title("path")
    a.grid(True, alpha=0.3)

    a = ax[0, 1]
    for c, lab in (("vn_mps", "v_N"), ("ve_mps", "v_E"), ("vd_mps", "v_D")):
        a.plot(t, traj.column(c), label=lab)
    a.plot(t, np.linalg.norm(traj.df[["vn_mps", "ve_mps", "vd_mps"]].to_numpy(), axis=1), "k--", label="|v|")
    a.set_xlabel("t (s)")
    a.set_ylabel("m/s")
    a.set_title("speeds (NED)")
    a.legend()
    a.grid(True, alpha=0.3)

    a = ax[1, 0]
    for c in ("roll_deg", "pitch_deg", "yaw_deg"):
        if c in traj.df:
            a.plot(t, traj.column(c), label=c.replace("_deg", ""))
    a.set_xlabel("t (s)")
    a.set_ylabel("deg")
    a.set_title("attitude")
    a.legend()
    a.grid(True, alpha=0.3)

    a = ax[1, 1]
    w, u = blade_series(traj, wind_ned_mps)
    bound = guard_bound_mps(u, constraint.w_allow_mps, constraint.cone_deg, constraint.margin_mps)
    a.plot(t, w, label="w = v_b,z (through disk)")
    a.plot(t, bound, "r--", label=f"allowed ({constraint.name}, {constraint.cone_deg:g}°)")
    a.fill_between(t, bound, np.maximum(w.max(), bound.max()) + 0.5, color="r", alpha=0.08)
    a.set_xlabel("t (s)")
    a.set_ylabel("m/s")
    a.set_title("blade-frame velocity vs the cone")
    a.legend()
    a.grid(True, alpha=0.3)
    fig.suptitle(title or f"{traj.kind} trajectory, t_f = {traj.duration_s:.2f} s")
    fig.tight_layout()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=110)
    except OSError as exc:
        raise FlighttestError(f"cannot write plot {path}: {exc.strerror}") from None
    finally:
        plt.close(fig)
    return path
