"""Planner outputs → ``flighttest.model.trajectory.Trajectory`` (one file format for every planner)."""

from __future__ import annotations

import math

import numpy as np

from flighttest.model.aero import G_MPS2
from flighttest.model.frames import quat_to_euler
from flighttest.model.trajectory import Trajectory
from flighttest.planner import helix as helix_mod
from flighttest.planner import planar as planar_mod
from flighttest.planner.probe import ProbePlan
from flighttest.planner.vertical import VerticalPlan

OUTPUT_RATE_HZ = 100.0


def _decimate(t: np.ndarray, rate_hz: float) -> np.ndarray:
    """Indices of a fine clock ``t`` at about ``rate_hz``, always including the last sample."""
    step = max(round(1.0 / (rate_hz * (t[1] - t[0]))), 1)
    idx = np.arange(0, len(t), step)
    return idx if idx[-1] == len(t) - 1 else np.append(idx, len(t) - 1)


def _solver_meta(sol, kind: str, vehicle: str, extra: dict) -> dict:
    r = sol.result
    return {
        "kind": kind,
        "vehicle": vehicle,
        "problem": sol.problem.summary(),
        "status": sol.status,
        "objective": "minimum time",
        "t_f_s": float(r.t_f_s),
        "solve_s": float(sol.solve_s),
        "solver": {
            "name": "ipopt (casadi nlpsol)",
            "ipopt_status": r.status,
            "iterations": r.iterations,
            "guess": r.guess,
            "n_intervals": len(r.t_s) - 1,
        },
        "check": sol.check,
        **extra,
    }


def planar_trajectory(
    sol: planar_mod.PlanarSolution, vehicle: str, mass_kg: float, extra: dict | None = None
) -> Trajectory:
    """The planar optimum flown in the east-down plane (Y → east, Z → down, roll about north).

    States come from the 1 kHz re-simulation with the optimal controls (so position, velocity,
    acceleration and attitude are mutually consistent), written at 100 Hz.
    """
    r = sol.result
    t, x, u = planar_mod.resimulate(r, 1000.0)
    i = _decimate(t, OUTPUT_RATE_HZ)
    t, x, u = t[i], x[i], u[i]
    phi = x[:, planar_mod.IPHI]
    f = u[:, 0]
    zero = np.zeros_like(t)
    meta = _solver_meta(sol, "planar", vehicle, {"manoeuvre": sol.manoeuvre(), **(extra or {})})
    return Trajectory.from_arrays(
        meta,
        t_s=t,
        n_m=zero,
        e_m=x[:, planar_mod.IY] - x[0, planar_mod.IY],
        d_m=x[:, planar_mod.IZ] - x[0, planar_mod.IZ],
        vn_mps=zero,
        ve_mps=x[:, planar_mod.IVY],
        vd_mps=x[:, planar_mod.IVZ],
        an_mps2=zero,
        ae_mps2=f * np.sin(phi),
        ad_mps2=-f * np.cos(phi) + G_MPS2,
        yaw_deg=zero,
        qw=np.cos(phi / 2),
        qx=np.sin(phi / 2),
        qy=zero,
        qz=zero,
        thrust_n=f * mass_kg,
        roll_deg=np.degrees((phi + math.pi) % (2 * math.pi) - math.pi),
        pitch_deg=zero,
    )


def helix_trajectory(
    sol: helix_mod.HelixSolution, vehicle: str, mass_kg: float, extra: dict | None = None
) -> Trajectory:
    """The helix written at 100 Hz from its dense re-simulation (``helix.dense_path``: each mesh
    interval integrated at 1 kHz from its own node, so position, velocity, acceleration and
    attitude agree, and a long descent carries no open-loop drift), linearly interpolated."""
    r = sol.result
    d = helix_mod.dense_path(r, 1000.0)
    t = np.linspace(0.0, d.t[-1], max(int(np.ceil(d.t[-1] * OUTPUT_RATE_HZ - 1e-9)), 1) + 1)
    x = np.stack([np.interp(t, d.t, d.x[:, j]) for j in range(d.x.shape[1])], 1)
    u = np.stack([np.interp(t, d.t, d.u[:, j]) for j in range(d.u.shape[1])], 1)
    q = x[:, 6:10] / np.linalg.norm(x[:, 6:10], axis=1, keepdims=True)
    acc = helix_mod.commanded_accel_np(x, u)
    roll, pitch, yaw = quat_to_euler(q)
    meta = _solver_meta(sol, "helix", vehicle, extra or {})
    return Trajectory.from_arrays(
        meta,
        t_s=t,
        n_m=x[:, 0] - x[0, 0],
        e_m=x[:, 1] - x[0, 1],
        d_m=x[:, 2] - x[0, 2],
        vn_mps=x[:, 3],
        ve_mps=x[:, 4],
        vd_mps=x[:, 5],
        an_mps2=acc[:, 0],
        ae_mps2=acc[:, 1],
        ad_mps2=acc[:, 2],
        yaw_deg=np.degrees(yaw),
        qw=q[:, 0],
        qx=q[:, 1],
        qy=q[:, 2],
        qz=q[:, 3],
        thrust_n=u[:, 0] * mass_kg,
        roll_deg=np.degrees(roll),
        pitch_deg=np.degrees(pitch),
    )


def _level(t: np.ndarray, d: np.ndarray, v: np.ndarray, a: np.ndarray, meta: dict, mass_kg: float) -> Trajectory:
    zero = np.zeros_like(t)
    return Trajectory.from_arrays(
        meta,
        t_s=t,
        n_m=zero,
        e_m=zero,
        d_m=d,
        vn_mps=zero,
        ve_mps=zero,
        vd_mps=v,
        an_mps2=zero,
        ae_mps2=zero,
        ad_mps2=a,
        yaw_deg=zero,
        thrust_n=mass_kg * (G_MPS2 - a),
    )


def vertical_trajectory(plan: VerticalPlan, vehicle: str, mass_kg: float) -> Trajectory:
    meta = {"kind": "vertical", "vehicle": vehicle, "problem": plan.problem, "status": "closed_form",
            "objective": "minimum time", "t_f_s": plan.t_f_s, "solve_s": 0.0}  # fmt: skip
    return _level(plan.t_s, plan.d_m, plan.vd_mps, plan.ad_mps2, meta, mass_kg)


def probe_trajectory(plan: ProbePlan, vehicle: str, mass_kg: float) -> Trajectory:
    meta = {"kind": "probe", "vehicle": vehicle, "problem": plan.problem, "status": "closed_form",
            "objective": "none (reference)", "t_f_s": plan.t_f_s, "solve_s": 0.0, "cycles": plan.cycles,
            "max_descent_mps": plan.max_descent_mps,
            "speed_first_reached": plan.speed_first_reached}  # fmt: skip
    return _level(plan.t_s, plan.d_m, plan.vd_mps, plan.ad_mps2, meta, mass_kg)
