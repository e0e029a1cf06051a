"""3D minimum-time descent (paper §IV-C): rigid body with quaternions; the optimum is a helix.

Model choice: **collective thrust and body rates** as inputs (not four rotor thrusts). States
``(N, E, D, v_N, v_E, v_D, q_w, q_x, q_y, q_z)`` (NED, q body → NED), inputs ``(f, p, q, r)`` with
``f`` the collective thrust per unit mass (m/s², along −z_body) and body rates in rad/s:

    ṗ = v,   v̇ = R(q)·(0, 0, −f) + (0, 0, g),   q̇ = ½ q ⊗ (0, ω) + k(1 − |q|²) q

(the last term keeps |q| = 1 against integration drift). Why rates and not rotor thrusts: it is
what PX4 offboard takes (rates + thrust), the inner rate loop is an order of magnitude faster than
the manoeuvre, and the rigid-body rotational dynamics enter through bounds that come from the
vehicle profile: body rates ≤ ``max_rate_dps`` and angular acceleration ≤ the torque the rotors
can give about each axis (``half`` of the differential thrust around hover, the other half left to
the attitude controller), with collective thrust ≤ ``thrust_fraction`` of the rotors' maximum.

Constraints: the air-relative body-frame velocity ``v_b = R(q)ᵀ(v − wind)`` must satisfy
``VelocityConstraint`` (cone or guard region, ``cone.py``); horizontal radius from the start
``N² + E² ≤ R²``; tilt ``R₃₃ = 1 − 2(q_x² + q_y²) ≥ cos(tilt_max)``; thrust ≥ the rotors' minimum
(never reversed). Hover to hover: start at the origin level with yaw 0, end at ``(N_f, E_f, h)``
(the start's XY by default) level, at rest, any yaw.

Initial guesses: helices with 1 and 2 turns on the circle through the start that fits in the
radius bound, heading along the path (the paper's "heading in the forward direction of motion").
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from flighttest.aero import G_MPS2
from flighttest.errors import FlighttestError
from flighttest.frames import quat_from_euler, quat_multiply, quat_to_rotmat
from flighttest.planner.cone import VelocityConstraint
from flighttest.planner.ocp import (
    MinTimeOcp,
    OcpResult,
    OcpSpec,
    SolvedOcp,
    refined_mesh,
    resample_guess,
    rk4_resimulate_compiled,
    violation_times,
)
from flighttest.profiles import VehicleProfile

NX, NU = 10, 4
QUAT_STAB = 1.0


@dataclass(frozen=True)
class HelixProblem:
    """A 3D hover-to-hover descent for one vehicle (m, m/s, m/s², rad, rad/s)."""

    height_m: float
    radius_m: float
    f_min_mps2: float
    f_max_mps2: float
    rate_max_rps: tuple[float, float, float]
    accel_max_rps2: tuple[float, float, float]
    tilt_max_rad: float
    speed_max_mps: float
    constraint: VelocityConstraint = field(default_factory=VelocityConstraint)
    wind_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    end_ne_m: tuple[float, float] = (0.0, 0.0)
    n_intervals: int = 80
    n_coarse: int = 40
    vehicle: str = ""
    # descent-speed bound (m/s, NED v_D): PX4 clips offboard velocity setpoints to MPC_Z_VEL_MAX_DN
    descent_max_mps: float | None = None

    def validate(self) -> None:
        for name, v in (("height", self.height_m), ("radius", self.radius_m), ("max speed", self.speed_max_mps),
                        ("tilt", self.tilt_max_rad)):  # fmt: skip
            if not (math.isfinite(v) and v > 0):
                raise FlighttestError(f"helix problem: {name} must be a positive number (got {v!r})")
        if self.tilt_max_rad >= math.pi / 2:
            raise FlighttestError("helix problem: tilt limit must be below 90°")
        if not (self.f_min_mps2 < G_MPS2 < self.f_max_mps2):
            raise FlighttestError("helix problem: the thrust range must contain hover")
        if math.hypot(*self.end_ne_m) > self.radius_m:
            raise FlighttestError("helix problem: the end point lies outside the radius bound")
        if not all(math.isfinite(w) for w in self.wind_ned_mps):
            raise FlighttestError("helix problem: wind must be finite")
        if self.n_intervals < 10 or self.n_coarse < 10:
            raise FlighttestError("helix problem: need at least 10 mesh intervals")
        if self.descent_max_mps is not None and not (math.isfinite(self.descent_max_mps) and self.descent_max_mps > 0):
            got = self.descent_max_mps
            raise FlighttestError(f"helix problem: descent bound must be a positive number (got {got!r})")

    def summary(self) -> dict:
        return {
            "height_m": self.height_m,
            "radius_m": self.radius_m,
            "end_n_m": self.end_ne_m[0],
            "end_e_m": self.end_ne_m[1],
            "f_min_mps2": self.f_min_mps2,
            "f_max_mps2": self.f_max_mps2,
            "rate_max_dps": [math.degrees(r) for r in self.rate_max_rps],
            "accel_max_dps2": [math.degrees(a) for a in self.accel_max_rps2],
            "tilt_max_deg": math.degrees(self.tilt_max_rad),
            "speed_max_mps": self.speed_max_mps,
            "descent_max_mps": self.descent_max_mps,
            "wind_ned_mps": list(self.wind_ned_mps),
            "n_intervals": self.n_intervals,
            **self.constraint.summary(),
        }


def problem_for_vehicle(
    profile: VehicleProfile,
    height_m: float = 5.0,
    radius_m: float = 2.0,
    constraint: VelocityConstraint | None = None,
    thrust_fraction: float = 0.9,
    tilt_max_deg: float | None = None,
    rate_max_dps: float | None = None,
    wind_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0),
    end_ne_m: tuple[float, float] = (0.0, 0.0),
    n_intervals: int = 80,
    n_coarse: int = 40,
    *,
    extra_margin_mps: float = 0.0,
    tilt_margin_deg: float = 0.0,
    rate_margin_dps: float = 0.0,
) -> HelixProblem:
    """Bounds from a vehicle profile; thrust ≥ the rotors' minimum (never reversed).

    Planning/tracking margins (keyword only, all ≥ 0, default 0): ``extra_margin_mps`` is added to
    the constraint's margin (the plan keeps that much further inside the guard/cone bound than the
    guard itself), ``tilt_margin_deg`` and ``rate_margin_dps`` derate the tilt and body-rate limits
    (after ``tilt_max_deg`` / ``rate_max_dps`` and the profile's own limits are applied), leaving
    the attitude controller room to track.
    """
    if not 0 < thrust_fraction <= 1:
        raise FlighttestError(f"thrust fraction must lie in (0, 1] (got {thrust_fraction})")
    for name, v in (("extra margin", extra_margin_mps), ("tilt margin", tilt_margin_deg),
                    ("rate margin", rate_margin_dps)):  # fmt: skip
        if not (math.isfinite(v) and v >= 0):
            raise FlighttestError(f"helix problem: {name} must be a number ≥ 0 (got {v!r})")
    n = profile.n_rotors
    m = profile.mass_kg
    t_h = profile.hover_thrust_per_rotor_n
    d_t = profile.max_thrust_per_rotor_n - t_h  # differential thrust available around hover, N
    arm_xy = profile.arm_length_m * math.sqrt(0.5)  # X frame: each rotor's lever about roll/pitch
    ixx, iyy, izz = profile.inertia_kgm2
    # Half of the torque authority for the trajectory, half left to the attitude controller.
    accel = (
        0.5 * n * arm_xy * d_t / ixx,
        0.5 * n * arm_xy * d_t / iyy,
        0.5 * n * profile.yaw_moment_per_thrust_m * d_t / izz,
    )
    rates = tuple(math.radians(r) for r in profile.max_rate_dps)
    if rate_max_dps is not None:
        rates = tuple(min(r, math.radians(rate_max_dps)) for r in rates)
    rates = tuple(r - math.radians(rate_margin_dps) for r in rates)
    tilt = profile.max_tilt_deg if tilt_max_deg is None else min(tilt_max_deg, profile.max_tilt_deg)
    tilt -= tilt_margin_deg
    if not (tilt > 0 and min(rates) > 0):
        raise FlighttestError("helix problem: the tilt and rate margins leave no tilt or rate to fly with")
    if constraint is None:
        constraint = VelocityConstraint(cone_deg=profile.vrs.cone_deg, margin_mps=profile.vrs.margin_mps)
    if extra_margin_mps:
        constraint = replace(constraint, margin_mps=constraint.margin_mps + extra_margin_mps)
    return HelixProblem(
        height_m=height_m,
        radius_m=radius_m,
        f_min_mps2=n * profile.min_thrust_per_rotor_n / m,
        f_max_mps2=thrust_fraction * n * profile.max_thrust_per_rotor_n / m,
        rate_max_rps=rates,
        accel_max_rps2=accel,
        tilt_max_rad=math.radians(tilt),
        speed_max_mps=profile.max_speed_mps,
        constraint=constraint,
        wind_ned_mps=wind_ned_mps,
        end_ne_m=end_ne_m,
        n_intervals=n_intervals,
        n_coarse=n_coarse,
        vehicle=profile.name,
    )


def _rot(q):
    """Rotation matrix body → NED (CasADi) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    return ca.vertcat(
        ca.horzcat(1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)),
        ca.horzcat(2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)),
        ca.horzcat(2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)),
    )


def dynamics(x, u):
    v = x[3:6]
    q = x[6:10]
    f = u[0]
    p, qq, r = u[1], u[2], u[3]
    r_mat = _rot(q)
    acc = r_mat[:, 2] * (-f) + ca.vertcat(0, 0, G_MPS2)
    w, qx, qy, qz = q[0], q[1], q[2], q[3]
    qdot = (
        0.5
        * ca.vertcat(
            -qx * p - qy * qq - qz * r,
            w * p + qy * r - qz * qq,
            w * qq + qz * p - qx * r,
            w * r + qx * qq - qy * p,
        )
        + QUAT_STAB * (1 - ca.sumsqr(q)) * q
    )
    return ca.vertcat(v, acc, qdot)


def _dynamics_np(x, u):
    q = x[6:10]
    r_mat = quat_to_rotmat(q)
    acc = r_mat[:, 2] * (-u[0]) + np.array([0.0, 0.0, G_MPS2])
    omega = np.array([0.0, u[1], u[2], u[3]])
    qdot = 0.5 * quat_multiply(q, omega) + QUAT_STAB * (1 - q @ q) * q
    return np.concatenate([x[3:6], acc, qdot])


def _blade(p: HelixProblem, x):
    """(w, u²) of the air-relative body velocity (CasADi)."""
    vb = _rot(x[6:10]).T @ (x[3:6] - ca.DM(p.wind_ned_mps))
    return vb[2], vb[0] ** 2 + vb[1] ** 2


def blade_velocity_np(p: HelixProblem, x: np.ndarray):
    """(w, u) of the air-relative body velocity for states (M, 10)."""
    r = quat_to_rotmat(x[:, 6:10] / np.linalg.norm(x[:, 6:10], axis=1, keepdims=True))
    vb = np.einsum("kji,kj->ki", r, x[:, 3:6] - np.asarray(p.wind_ned_mps))
    return vb[:, 2], np.hypot(vb[:, 0], vb[:, 1])


def _spec(p: HelixProblem, n: int) -> OcpSpec:
    inf = np.inf
    big = 1e3
    vmax = p.speed_max_mps
    x_lb = np.array([-p.radius_m, -p.radius_m, -big, -vmax, -vmax, -vmax, -1.1, -1.1, -1.1, -1.1])
    x_ub = -x_lb
    x_ub[2] = big
    if p.descent_max_mps is not None:
        x_ub[5] = min(vmax, p.descent_max_mps)
    xf = np.array([p.end_ne_m[0], p.end_ne_m[1], p.height_m, 0, 0, 0, 0, 0, 0, 0])
    xf_lb, xf_ub = xf.copy(), xf.copy()
    xf_lb[[6, 9]], xf_ub[[6, 9]] = -1.1, 1.1  # yaw free at the end
    hover = np.array([G_MPS2, 0.0, 0.0, 0.0])
    cos_tilt = math.cos(p.tilt_max_rad)
    con = p.constraint

    def path(x, u):
        w, u_sq = _blade(p, x)
        q = x[6:10]
        return ca.vertcat(
            con.slack_casadi(w, u_sq=u_sq),
            p.radius_m**2 - x[0] ** 2 - x[1] ** 2,
            1 - 2 * (q[1] ** 2 + q[2] ** 2) - cos_tilt,
            ca.sumsqr(x[3:6]) - 0.0,
        )

    rates = np.asarray(p.rate_max_rps)
    return OcpSpec(
        dynamics=dynamics,
        nx=NX,
        nu=NU,
        n_intervals=n,
        x_lb=x_lb,
        x_ub=x_ub,
        u_lb=np.concatenate([[p.f_min_mps2], -rates]),
        u_ub=np.concatenate([[p.f_max_mps2], rates]),
        x_initial=np.array([0, 0, 0, 0, 0, 0, 1.0, 0, 0, 0]),
        xf_lb=xf_lb,
        xf_ub=xf_ub,
        u_initial_lb=hover,
        u_initial_ub=hover,
        uf_lb=hover,
        uf_ub=hover,
        path=path,
        path_lb=np.array([0.0, 0.0, 0.0, 0.0]),
        path_ub=np.array([inf, inf, inf, vmax**2]),
        u_rate_max=np.concatenate([[inf], np.asarray(p.accel_max_rps2)]),
        smooth_weight=np.array([1e-6, 1e-4, 1e-4, 1e-4]),
        t_max_s=120.0,
    )


def _quat_from_thrust_and_yaw(spec_force: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Attitude whose −z_body points along the specific force, with the given heading."""
    z_b = -spec_force / np.linalg.norm(spec_force, axis=1, keepdims=True)
    x_c = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], 1)
    y_b = np.cross(z_b, x_c)
    y_b /= np.linalg.norm(y_b, axis=1, keepdims=True)
    x_b = np.cross(y_b, z_b)
    pitch = -np.arcsin(np.clip(x_b[:, 2], -1, 1))
    roll = np.arctan2(y_b[:, 2], z_b[:, 2])
    hdg = np.arctan2(x_b[:, 1], x_b[:, 0])
    return quat_from_euler(roll, pitch, hdg)


def helix_guess(p: HelixProblem, n: int, turns: float, t_f: float, direction: int = 1):
    """A helix on the circle through the start inside the radius bound, min-jerk in time."""
    tau = np.linspace(0.0, 1.0, n + 1)
    s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
    t = tau * t_f
    rc = 0.45 * p.radius_m
    theta = 2 * math.pi * turns * s
    north = rc * (1 - np.cos(theta))
    east = direction * rc * np.sin(theta)
    # Blend toward the requested end point.
    north += s * p.end_ne_m[0]
    east += s * p.end_ne_m[1]
    down = p.height_m * s
    pos = np.stack([north, east, down], 1)
    vel = np.gradient(pos, t, axis=0)
    acc = np.gradient(vel, t, axis=0)
    spec_force = acc - np.array([0, 0, G_MPS2])
    heading = np.unwrap(np.arctan2(vel[:, 1], vel[:, 0] + 1e-9))
    heading[0], heading[-1] = heading[1], heading[-2]
    q = _quat_from_thrust_and_yaw(spec_force, heading)
    for i in range(1, len(q)):
        if q[i] @ q[i - 1] < 0:
            q[i] = -q[i]
    q[0] = [1, 0, 0, 0] if q[0][0] >= 0 else [-1, 0, 0, 0]
    f = np.clip(np.linalg.norm(spec_force, axis=1), p.f_min_mps2, p.f_max_mps2)
    qdot = np.gradient(q, t, axis=0)
    conj = q * np.array([1, -1, -1, -1])
    omega = 2 * quat_multiply(conj, qdot)[:, 1:]
    rates = np.asarray(p.rate_max_rps)
    omega = np.clip(omega, -rates, rates)
    f[0] = f[-1] = G_MPS2
    omega[0] = omega[-1] = 0
    x = np.concatenate([pos, vel, q], 1)
    u = np.concatenate([f[:, None], omega], 1)
    return x, u


@dataclass
class HelixSolution(SolvedOcp):
    problem: HelixProblem
    result: OcpResult
    attempts: list[dict]
    solve_s: float
    check: dict


def _attempt(r: OcpResult) -> dict:
    return {"guess": r.guess, "status": r.status, "t_f_s": r.t_f_s, "solve_s": r.solve_s, "iterations": r.iterations}


# What the 1 kHz re-simulation of the controls may exceed the limits by (between the mesh nodes).
CONE_TOL_MPS = 1e-3
TILT_TOL_DEG = 0.05
RADIUS_TOL_M = 1e-3
# Rates and thrust sit on their bounds up to IPOPT's bound relaxation (1e-8 relative).
CONTROL_TOL_REL = 1e-6
TIGHTEN_ROUNDS = 3
# A round tightens a bound by this multiple of the overshoot it found (plus the tolerance), so one
# round usually suffices even though the solution moves when the bound does.
TIGHTEN_GAIN = 1.5


def solve_helix(p: HelixProblem, verbose: bool = False) -> HelixSolution:
    """Multi-start (helices of 1 and 2 turns) on a coarse mesh, best refined on the fine mesh, then
    bounds tightened where the 1 kHz re-simulation leaves them between nodes (≤ 3 rounds).

    Path constraints hold at nodes and interval midpoints; between them the flown path can bulge
    past a bound that the optimum rides (the tilt limit along the whole helix, the radius, the
    cone). Each round re-simulates, measures the overshoot of tilt, radius and the cone and re-solves
    (warm, same compiled NLP) with those constraints' lower bounds raised by ``TIGHTEN_GAIN`` × the
    overshoot, until the re-simulation is within ``TILT_TOL_DEG``, ``RADIUS_TOL_M`` and
    ``CONE_TOL_MPS``. Rates and thrust are controls, linear between nodes, so their box bounds hold
    exactly on the re-simulation; the check reports them too.
    """
    p.validate()
    t0 = time.perf_counter()
    coarse = MinTimeOcp(_spec(p, p.n_coarse), verbose=verbose)
    t_guess = max(2.0, 2.5 * math.sqrt(p.height_m))
    attempts: list[dict] = []
    best: OcpResult | None = None
    fallback: OcpResult | None = None
    for turns in (1.0, 2.0):
        xg, ug = helix_guess(p, p.n_coarse, turns, t_guess * (0.8 + 0.2 * turns))
        r = coarse.solve(t_guess, xg, ug, name=f"helix{turns:g}")
        attempts.append(_attempt(r))
        if r.success and (best is None or r.t_f_s < best.t_f_s):
            best = r
        elif fallback is None or r.max_defect < fallback.max_defect:
            fallback = r
    final = best if best is not None else fallback
    if best is not None:
        fine = coarse if p.n_intervals == p.n_coarse else MinTimeOcp(_spec(p, p.n_intervals), verbose=verbose)
        final = _fine_and_tighten(p, fine, best, attempts)
    sol = HelixSolution(problem=p, result=final, attempts=attempts, solve_s=0.0, check={})
    sol.check = resimulation_check(sol)
    sol.solve_s = time.perf_counter() - t0
    return sol


def _fine_and_tighten(p: HelixProblem, fine: MinTimeOcp, start: OcpResult, attempts: list[dict]) -> OcpResult:
    n = p.n_intervals
    cos_tilt = math.cos(p.tilt_max_rad)
    backoff = {"tilt_rad": 0.0, "radius_m": 0.0}
    hot: list[float] = []
    mesh = None
    current = start
    for round_ in range(TIGHTEN_ROUNDS + 1):
        path_lb = np.array([
            0.0,
            p.radius_m**2 - (p.radius_m - backoff["radius_m"]) ** 2,
            math.cos(max(p.tilt_max_rad - backoff["tilt_rad"], 0.0)) - cos_tilt,
            0.0,
        ])  # fmt: skip
        xg = resample_guess(current.t_s, current.x, n, mesh)
        ug = resample_guess(current.t_s, current.u, n, mesh)
        label = f"{start.guess} fine" + (f" tighten{round_}" if round_ else "")
        r = fine.solve(current.t_f_s, xg, ug, name=label, path_lb=path_lb, mesh=mesh)
        attempts.append({**_attempt(r), "backoff": dict(backoff), "refined_at_s": list(hot)})
        if not r.success:
            break  # keep the last solution that converged (its check reports what it breaks)
        current = r
        over, t_re, margin = _overshoots(p, current)
        if all(v <= 0 for v in over.values()) or round_ == TIGHTEN_ROUNDS:
            break
        for key, tol in (("tilt_deg", TILT_TOL_DEG), ("radius_m", RADIUS_TOL_M)):
            if over[key] > 0:
                step = TIGHTEN_GAIN * over[key] + tol
                backoff["tilt_rad" if key == "tilt_deg" else key] += math.radians(step) if key == "tilt_deg" else step
        if over["cone_mps"] > 0:
            # The cone is tight at hover (w = u = 0), so it cannot be tightened uniformly: crowd the
            # nodes where it breaks instead, as the planar solver does.
            hot.extend(violation_times(t_re, margin, CONE_TOL_MPS))
            mesh = refined_mesh(np.linspace(0.0, current.t_f_s, n + 1), np.array(hot))
    return current


def _overshoots(p: HelixProblem, r: OcpResult):
    """How far the 1 kHz re-simulation exceeds each bound beyond its tolerance (≤ 0: fine), and the
    re-simulated cone margin over time."""
    c, t, margin = _resim_figures(p, r, with_margin=True)
    over = {
        "cone_mps": -c["worst_margin_mps"] - CONE_TOL_MPS,
        "tilt_deg": c["max_tilt_deg"] - math.degrees(p.tilt_max_rad) - TILT_TOL_DEG,
        "radius_m": c["max_radius_m"] - p.radius_m - RADIUS_TOL_M,
    }
    return over, t, margin


def resimulate(r: OcpResult, rate_hz: float = 1000.0):
    """``(t, x, u)`` of the solution's controls integrated from its first state at ``rate_hz``."""
    return rk4_resimulate_compiled(dynamics, r.t_s, r.x[0], r.u, rate_hz)


def _resim_figures(p: HelixProblem, r: OcpResult, rate_hz: float = 1000.0, with_margin: bool = False):
    t, x, u = resimulate(r, rate_hz)
    w, u_air = blade_velocity_np(p, x)
    margin = p.constraint.margin(w, u_air)
    i = int(np.argmin(margin))
    radius = np.hypot(x[:, 0], x[:, 1])
    q = x[:, 6:10] / np.linalg.norm(x[:, 6:10], axis=1, keepdims=True)
    r33 = 1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2)
    figures = {
        "rate_hz": rate_hz,
        "worst_margin_mps": float(margin[i]),
        "worst_margin_t_s": float(t[i]),
        "max_radius_m": float(radius.max()),
        "max_tilt_deg": float(np.degrees(np.arccos(np.clip(r33, -1, 1))).max()),
        "max_rate_dps": float(np.degrees(np.abs(u[:, 1:]).max())),
        "min_thrust_mps2": float(u[:, 0].min()),
        "max_thrust_mps2": float(u[:, 0].max()),
        "max_speed_mps": float(np.linalg.norm(x[:, 3:6], axis=1).max()),
        "max_descent_mps": float(x[:, 5].max()),
        "end_position_error_m": float(np.linalg.norm(x[-1, :3] - [*p.end_ne_m, p.height_m])),
        "end_speed_mps": float(np.linalg.norm(x[-1, 3:6])),
    }
    return (figures, t, margin) if with_margin else figures


def resimulation_check(sol: HelixSolution, rate_hz: float = 1000.0) -> dict:
    """Figures of the 1 kHz re-simulation with the interpolated controls (what would be flown),
    the tolerances they are held to and whether each limit holds (``limits_ok``)."""
    r = sol.result
    p = sol.problem
    c = _resim_figures(p, r, rate_hz)
    w_n, u_n = blade_velocity_np(p, r.x)
    tol = {"cone_mps": CONE_TOL_MPS, "tilt_deg": TILT_TOL_DEG, "radius_m": RADIUS_TOL_M,
           "controls_rel": CONTROL_TOL_REL}  # fmt: skip
    rate_lim = math.degrees(max(p.rate_max_rps))
    c.update({
        "node_worst_margin_mps": float(np.min(p.constraint.margin(w_n, u_n))),
        "turns": float(_turns(r.x)),
        "tolerances": tol,
        "limits_ok": bool(
            c["worst_margin_mps"] >= -CONE_TOL_MPS
            and c["max_tilt_deg"] <= math.degrees(p.tilt_max_rad) + TILT_TOL_DEG
            and c["max_radius_m"] <= p.radius_m + RADIUS_TOL_M
            and c["max_rate_dps"] <= rate_lim * (1 + CONTROL_TOL_REL)
            and p.f_min_mps2 - CONTROL_TOL_REL * p.f_max_mps2 <= c["min_thrust_mps2"]
            and c["max_thrust_mps2"] <= p.f_max_mps2 * (1 + CONTROL_TOL_REL)
        ),
    })  # fmt: skip
    return c


def _turns(x: np.ndarray) -> float:
    """Revolutions of the horizontal velocity direction (a helix turns, an oblique path does not)."""
    speed = np.hypot(x[:, 3], x[:, 4])
    moving = speed > 0.05 * max(speed.max(), 1e-9)
    ang = np.unwrap(np.arctan2(x[moving, 4], x[moving, 3]))
    return abs(ang[-1] - ang[0]) / (2 * math.pi) if len(ang) > 1 else 0.0
