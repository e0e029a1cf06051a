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
(never reversed). Where the autopilot shapes the setpoints it is sent (a profile's ``[autopilot]``
table, ``autopilot_limits``), the commanded acceleration ``a = v̇`` (what the trajectory exports as
``an/ae/ad``) is bounded too, ``a_D² ≤ accel_z_max²`` and ``a_N² + a_E² ≤ accel_h_max²`` as path
constraints (tightened between nodes like the others, below), and ``v_D`` lies between ``−climb_max``
and ``descent_max``. Hover to hover: start at the origin level with yaw 0, end at ``(N_f, E_f, h)``
(the start's XY by default) level, at rest, any yaw.

Initial guesses: helices with 1 and 2 turns on the circle through the start that fits in the
radius bound, heading along the path (the paper's "heading in the forward direction of motion").
Long descents (2–30 m and more: several turns) start instead from the steady helix, in closed form
(``steady_helix``): spiral out onto a circle at the radius bound, cruise at the fastest constant
descent rate and turn rate the cone, tilt and thrust allow, spiral back in. Their mesh grows with
the cruise (``long_descent_mesh``).

What is checked is the **dense** solution (``dense_path``): every mesh interval integrated at 1 kHz
from its own node, never one open-loop integration of the controls from the start, whose drift
over a long descent (metres after 10 s: attitude errors integrate twice into position) is a
numerical artefact, not a bound the plan breaks.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from flighttest.errors import FlighttestError
from flighttest.model.aero import G_MPS2
from flighttest.model.frames import quat_from_euler, quat_multiply, quat_to_rotmat, worst_blade_velocity_mps
from flighttest.model.profiles import VehicleProfile
from flighttest.planner.autopilot_limits import AUTOPILOT_LIMIT_FRACTION, capped, plan_limits
from flighttest.planner.cone import VelocityConstraint, ppos
from flighttest.planner.multistart import attempt_record, multistart_refined, refine
from flighttest.planner.ocp import (
    DenseSolution,
    MinTimeOcp,
    OcpResult,
    OcpSpec,
    SolvedOcp,
    resample_guess,
    rk4_piecewise,
)

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
    # fine mesh intervals (a long descent gets more: ``long_descent_mesh``) and the coarse multi-start's
    n_intervals: int = 80
    n_coarse: int = 40
    vehicle: str = ""
    # descent-speed bound (m/s, NED v_D): PX4 clips offboard velocity setpoints to MPC_Z_VEL_MAX_DN
    descent_max_mps: float | None = None
    # the autopilot's setpoint shaping (None: unbounded): climb speed (m/s, −v_D), and the commanded
    # acceleration's vertical |a_D| and horizontal |(a_N, a_E)| (m/s²), which ArduCopter's GUIDED ramps
    # at WP_ACC_Z / WP_ACC whatever the plan asks
    climb_max_mps: float | None = None
    accel_z_max_mps2: float | None = None
    accel_h_max_mps2: float | None = None
    # collective-thrust rate bound (m/s³): a plan's thrust steps become vertical jerks the autopilot's
    # velocity loop overshoots (None: unbounded, the paper's optimum)
    thrust_rate_max_mps3: float | None = None
    # planning for wind: the drag per unit mass (1/s, linear) that tilts the real disk beyond the plan's
    # attitude, and how far the wind may be off (m/s): the guard constraint holds for the worst air within
    # it (flighttest.model.frames.worst_blade_velocity_mps). Both 0: the still-air problem as ever
    drag_per_s: float = 0.0
    wind_radius_mps: float = 0.0

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
        for name, v in (("descent", self.descent_max_mps), ("climb", self.climb_max_mps),
                        ("vertical acceleration", self.accel_z_max_mps2),
                        ("horizontal acceleration", self.accel_h_max_mps2)):  # fmt: skip
            if v is not None and not (math.isfinite(v) and v > 0):
                raise FlighttestError(f"helix problem: {name} bound must be a positive number (got {v!r})")

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
            "climb_max_mps": self.climb_max_mps,
            "accel_z_max_mps2": self.accel_z_max_mps2,
            "accel_h_max_mps2": self.accel_h_max_mps2,
            "thrust_rate_max_mps3": self.thrust_rate_max_mps3,
            "wind_ned_mps": list(self.wind_ned_mps),
            "drag_per_s": self.drag_per_s,
            "wind_radius_mps": self.wind_radius_mps,
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
    limit_fraction: float = AUTOPILOT_LIMIT_FRACTION,
) -> HelixProblem:
    """Bounds from a vehicle profile; thrust ≥ the rotors' minimum (never reversed). Where the
    profile names its autopilot's setpoint-shaping limits (``[autopilot]``), the descent and climb
    speeds and the commanded acceleration stay within ``autopilot_limits.plan_limits`` of them.

    Planning/tracking margins (keyword only, all ≥ 0, default 0): ``extra_margin_mps`` is added to
    the constraint's margin (the plan keeps that much further inside the guard/cone bound than the
    guard itself), ``tilt_margin_deg`` and ``rate_margin_dps`` derate the tilt and body-rate limits
    (after ``tilt_max_deg`` / ``rate_max_dps`` and the profile's own limits are applied), leaving
    the attitude controller room to track. ``limit_fraction`` of the autopilot's limits are planned for.
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
    limits = plan_limits(profile, limit_fraction)
    if limits.jerk_h_max_mps3 is not None:
        # the autopilot ramps horizontal acceleration at its jerk limit, and a_h ≈ g tan θ: a tilt rate above
        # jerk / g arrives late, then overshoots (ArduCopter SITL's helix, bench/RESULTS.md)
        tilt_rate = limits.jerk_h_max_mps3 / G_MPS2
        rates = (min(rates[0], tilt_rate), min(rates[1], tilt_rate), rates[2])
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
        descent_max_mps=limits.descent_max_mps,
        climb_max_mps=limits.climb_max_mps,
        accel_z_max_mps2=limits.accel_z_max_mps2,
        accel_h_max_mps2=limits.accel_h_max_mps2,
        thrust_rate_max_mps3=limits.jerk_z_max_mps3,
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


def _wind_planned(p: HelixProblem) -> bool:
    return p.drag_per_s > 0 or p.wind_radius_mps > 0


def _blade(p: HelixProblem, x, u):
    """(w, u²) of the air-relative body velocity (CasADi); planning for wind, (w, u) at the worst air
    within ``wind_radius_mps`` of the disk the thrust really takes: the plan's net acceleration plus the
    drag of the air, ``z ∝ f·z_plan − drag·v_air`` (the autopilot tilts for both)."""
    v_air = x[3:6] - ca.DM(p.wind_ned_mps)
    if not _wind_planned(p):
        vb = _rot(x[6:10]).T @ v_air
        return vb[2], vb[0] ** 2 + vb[1] ** 2
    z = _rot(x[6:10])[:, 2] * u[0] - p.drag_per_s * v_air
    z = z / ca.norm_2(z)
    w = ca.dot(v_air, z)
    d = p.constraint.smoothing_mps
    u_air = ca.sqrt(ca.fmax(ca.sumsqr(v_air) - w * w, 0.0) + d * d) - d
    u_worst = ppos(u_air - p.wind_radius_mps, d)
    tilt_sin = ca.sqrt(z[0] ** 2 + z[1] ** 2 + 1e-8)  # smooth at level, where the tilt's direction is undefined
    return w + tilt_sin * p.wind_radius_mps, u_worst**2


def blade_velocity_np(p: HelixProblem, x: np.ndarray, u: np.ndarray | None = None):
    """(w, u) of the air-relative body velocity for states (M, 10); planning for wind (with the controls
    (M, 4)), at the worst air within the radius of the disk the thrust really takes (``_blade``)."""
    v_air = x[:, 3:6] - np.asarray(p.wind_ned_mps)
    r = quat_to_rotmat(x[:, 6:10] / np.linalg.norm(x[:, 6:10], axis=1, keepdims=True))
    if not _wind_planned(p) or u is None:
        vb = np.einsum("kji,kj->ki", r, v_air)
        return vb[:, 2], np.hypot(vb[:, 0], vb[:, 1])
    z = r[:, :, 2] * u[:, 0:1] - p.drag_per_s * v_air
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    w = np.einsum("ij,ij->i", v_air, z)
    u_air = np.sqrt(np.maximum(np.einsum("ij,ij->i", v_air, v_air) - w * w, 0.0))
    return worst_blade_velocity_mps(w, u_air, np.hypot(z[:, 0], z[:, 1]), p.wind_radius_mps)


def _spec(p: HelixProblem, n: int) -> OcpSpec:
    inf = np.inf
    big = 1e3
    vmax = p.speed_max_mps
    x_lb = np.array([-p.radius_m, -p.radius_m, -big, -vmax, -vmax, -vmax, -1.1, -1.1, -1.1, -1.1])
    x_ub = -x_lb
    x_ub[2] = big
    x_ub[5] = capped(vmax, p.descent_max_mps)
    x_lb[5] = -capped(vmax, p.climb_max_mps)
    xf = np.array([p.end_ne_m[0], p.end_ne_m[1], p.height_m, 0, 0, 0, 0, 0, 0, 0])
    xf_lb, xf_ub = xf.copy(), xf.copy()
    xf_lb[[6, 9]], xf_ub[[6, 9]] = -1.1, 1.1  # yaw free at the end
    hover = np.array([G_MPS2, 0.0, 0.0, 0.0])
    cos_tilt = math.cos(p.tilt_max_rad)
    con = p.constraint
    path_lb, path_ub = _path_bounds(p)

    def path(x, u):
        w, u_sq = _blade(p, x, u)
        q = x[6:10]
        rows = [
            con.slack_casadi(w, u_sq=u_sq),
            p.radius_m**2 - x[0] ** 2 - x[1] ** 2,
            1 - 2 * (q[1] ** 2 + q[2] ** 2) - cos_tilt,
            ca.sumsqr(x[3:6]) - 0.0,
        ]
        # the commanded acceleration, the dynamics' v̇, as slacks ``bound² − a²`` ≥ 0 (a lower bound the
        # tightening rounds can raise, as the radius's); rows only where bounded, so a problem without
        # the autopilot's limits is the same NLP as before they existed
        acc = _rot(q)[:, 2] * (-u[0]) + ca.vertcat(0, 0, G_MPS2)
        if p.accel_z_max_mps2 is not None:
            rows.append(p.accel_z_max_mps2**2 - acc[2] ** 2)
        if p.accel_h_max_mps2 is not None:
            rows.append(p.accel_h_max_mps2**2 - acc[0] ** 2 - acc[1] ** 2)
        return ca.vertcat(*rows)

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
        path_lb=path_lb,
        path_ub=path_ub,
        u_rate_max=np.concatenate([[p.thrust_rate_max_mps3 or inf], np.asarray(p.accel_max_rps2)]),
        smooth_weight=np.array([1e-6, 1e-4, 1e-4, 1e-4]),
        t_max_s=120.0,
    )


# The acceleration rows of the path constraints, in this order after the first four, where bounded:
# HelixProblem's ``accel_z_max_mps2`` (|a_D|) and ``accel_h_max_mps2`` (|(a_N, a_E)|).
_ACCEL_ROWS = ("accel_z", "accel_h")


def _accel_bounds(p: HelixProblem) -> dict[str, float]:
    """``{"accel_z": bound, "accel_h": bound}`` of the acceleration rows the problem has, in row order."""
    bounds = {key: getattr(p, f"{key}_max_mps2") for key in _ACCEL_ROWS}
    return {key: b for key, b in bounds.items() if b is not None}


def _path_bounds(p: HelixProblem) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of ``_spec``'s path rows: cone slack, radius, tilt, speed², then (where the problem
    bounds them) the vertical and the horizontal acceleration's slack, each ≥ 0."""
    inf = np.inf
    extra = len(_accel_bounds(p))
    return np.array([0.0] * (4 + extra)), np.array([inf, inf, inf, p.speed_max_mps**2] + [inf] * extra)


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
    return _guess_from_path(p, t, pos)


@dataclass(frozen=True)
class SteadyHelix:
    """The steady turn a long descent cruises on: a circle of ``radius_m`` about the start at
    horizontal speed ``speed_h_mps`` and descent rate ``descent_mps``, banked ``bank_rad``."""

    radius_m: float
    speed_h_mps: float
    descent_mps: float
    bank_rad: float

    @property
    def turn_rate_rps(self) -> float:
        return self.speed_h_mps / self.radius_m


# The steady helix of the warm start runs this far inside the radius and tilt bounds.
STEADY_RADIUS_FRACTION = 0.95
STEADY_BANK_FRACTION = 0.95


def steady_helix(p: HelixProblem) -> SteadyHelix:
    """The fastest steady helical descent the bounds allow (no wind), in closed form.

    On a circle of radius ``r`` at horizontal speed ``v_h`` and descent rate ``v_d`` the vehicle
    banks by ``φ`` with ``tan φ = v_h²/(r g)`` (thrust ``g/cos φ``) and its body z axis is
    ``(sin φ · outward, cos φ · down)``, so ``w = v_d cos φ`` and ``u² = v_h² + v_d² sin² φ``. Both a
    larger ``v_h`` and the larger bank it needs help the cone, so ``v_h`` sits on the tilt, thrust or
    speed bound and ``v_d`` is the largest the constraint allows there: the root of
    ``v_d cos φ + margin = tan(cone)·sqrt(v_h² + v_d² sin² φ)`` (or ``w_allow − margin`` when that is
    larger), capped by the speed and descent bounds.
    """
    r = STEADY_RADIUS_FRACTION * p.radius_m
    bank_max = min(p.tilt_max_rad, math.acos(min(1.0, G_MPS2 / p.f_max_mps2)))
    if p.accel_h_max_mps2 is not None:  # the steady turn's centripetal acceleration is g·tan(bank)
        bank_max = min(bank_max, math.atan(p.accel_h_max_mps2 / G_MPS2))
    bank = STEADY_BANK_FRACTION * bank_max
    v_h = min(math.sqrt(r * G_MPS2 * math.tan(bank)), 0.9 * p.speed_max_mps)
    bank = math.atan(v_h**2 / (r * G_MPS2))
    a, b = math.cos(bank), math.sin(bank)
    k = math.tan(math.radians(p.constraint.cone_deg))
    m = p.constraint.margin_mps + p.constraint.smoothing_mps
    qa = a * a - k * k * b * b
    if qa > 0:
        disc = (a * m) ** 2 - qa * (m * m - (k * v_h) ** 2)
        v_d = (-a * m + math.sqrt(max(disc, 0.0))) / qa
    else:
        v_d = p.speed_max_mps
    v_d = max(v_d, (p.constraint.w_allow_mps - m) / a, 0.1)
    v_d = min(v_d, math.sqrt(max((0.9 * p.speed_max_mps) ** 2 - v_h**2, 0.01)))
    if p.descent_max_mps is not None:
        v_d = min(v_d, p.descent_max_mps)
    return SteadyHelix(radius_m=r, speed_h_mps=v_h, descent_mps=v_d, bank_rad=bank)


def _envelope(t: np.ndarray, t_f: float, t_ramp: float) -> np.ndarray:
    """Min-jerk ramp up over ``t_ramp``, 1 in the middle, ramp down over the last ``t_ramp``."""
    up = np.clip(t / t_ramp, 0.0, 1.0)
    down = np.clip((t_f - t) / t_ramp, 0.0, 1.0)

    def mj(s):
        return 10 * s**3 - 15 * s**4 + 6 * s**5

    return mj(up) * mj(down)


def steady_helix_duration(p: HelixProblem, cruise: SteadyHelix | None = None) -> tuple[float, float]:
    """``(t_f, t_ramp)`` of the warm start: ramps long enough for the available horizontal
    acceleration, the cruise long enough to descend the height."""
    c = steady_helix(p) if cruise is None else cruise
    accel = G_MPS2 * math.tan(c.bank_rad)
    speed = math.hypot(c.speed_h_mps, c.descent_mps)
    t_ramp = max(1.0, 2.0 * speed / accel, 2.0 * math.sqrt(c.radius_m / accel))
    if p.accel_z_max_mps2 is not None:  # the envelope's min-jerk ramp peaks at 1.875 × descent rate / t_ramp
        t_ramp = max(t_ramp, 2.0 * c.descent_mps / p.accel_z_max_mps2)
    lo, hi = 1e-3, p.height_m / c.descent_mps + 2 * t_ramp
    tt = np.linspace(0.0, 1.0, 401)
    for _ in range(40):  # bisection: descent of the envelope's descent rate = height
        mid = 0.5 * (lo + hi)
        if np.trapezoid(_envelope(tt * mid, mid, t_ramp), tt * mid) * c.descent_mps < p.height_m:
            lo = mid
        else:
            hi = mid
    return hi, t_ramp


def steady_helix_guess(p: HelixProblem, n: int):
    """``(t_f, x, u)``: spiral out from the start onto the steady helix (``steady_helix``), cruise,
    spiral back in, on ``n`` intervals — the warm start of long descents. The radius, turn rate and
    descent rate follow one smooth envelope; attitude from the specific force, heading along the
    velocity (as ``helix_guess``)."""
    c = steady_helix(p)
    t_f, t_ramp = steady_helix_duration(p, c)
    t = np.linspace(0.0, t_f, n + 1)
    fine = np.linspace(0.0, t_f, 20 * n + 1)
    env = _envelope(fine, t_f, t_ramp)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (env[1:] + env[:-1]) * np.diff(fine))])
    theta = c.turn_rate_rps * cum
    rho = c.radius_m * _envelope(fine, t_f, t_ramp)
    s = np.interp(fine, [0, t_f], [0, 1])
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    north = rho * np.cos(theta) + s * p.end_ne_m[0]
    east = rho * np.sin(theta) + s * p.end_ne_m[1]
    down = p.height_m * cum / cum[-1]
    pos_f = np.stack([north, east, down], 1)
    pos = np.stack([np.interp(t, fine, pos_f[:, j]) for j in range(3)], 1)
    return t_f, *_guess_from_path(p, t, pos)


def _guess_from_path(p: HelixProblem, t: np.ndarray, pos: np.ndarray):
    """States and controls along a position path (flatness: attitude from the specific force,
    heading along the velocity), hover at both ends."""
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
    """The attempts row of a helix solve: the mesh size too (a long descent's grows with its length)."""
    return {**attempt_record(r), "n_intervals": len(r.t_s) - 1}


# What the 1 kHz dense re-simulation may exceed the limits by (between the mesh nodes).
CONE_TOL_MPS = 1e-3
TILT_TOL_DEG = 0.05
RADIUS_TOL_M = 1e-3
# Rates and thrust sit on their bounds up to IPOPT's bound relaxation (1e-8 relative).
CONTROL_TOL_REL = 1e-6
# The commanded acceleration (the autopilot's limits; between nodes it bulges at the end's flare), m/s²
ACCEL_TOL_MPS2 = 0.01
# What one mesh interval's integration may differ from the next node by (the NLP's one RK4 step
# per interval against the 1 kHz integration from the same node): position, m.
NODE_GAP_TOL_M = 0.01
TIGHTEN_ROUNDS = 3
# A round tightens a bound by this multiple of the overshoot it found (plus the tolerance), so one
# round usually suffices even though the solution moves when the bound does.
TIGHTEN_GAIN = 1.5
# Tightening is local (the interval that broke a bound and its neighbours) and never takes more
# than this off a bound: tilt 3°, radius 5 % of the radius, the cone 0.02 m/s (a fifth of the guard's
# usual margin). An overshoot that needs more is no between-node bulge but a broken plan, and the
# check reports it instead of the plan chasing it.
MAX_TILT_BACKOFF_DEG = 3.0
MAX_RADIUS_BACKOFF_FRACTION = 0.05
MAX_CONE_BACKOFF_MPS = 0.02
# ... and never more than this fraction off an acceleration bound (that bound is already
# AUTOPILOT_LIMIT_FRACTION of the autopilot's limit: an overshoot the tightening leaves stays below the limit)
MAX_ACCEL_BACKOFF_FRACTION = 0.05
# Long descents (the steady helix takes longer than LONG_DESCENT_S): no coarse multi-start (a coarse
# mesh cannot resolve their turns, it only costs iterations), the fine mesh starts from the steady
# helix, and its nodes are spaced by the manoeuvre: END_INTERVAL_S in the entry and exit (where the
# optimum plunges, rolls in and flares: what sets the time), CRUISE_INTERVAL_S on the steady helix
# between them, so the mesh grows with the cruise's length. For 20 m at x500 that is 67 intervals,
# and the time is within 0.2 % of a uniform mesh of twice as many.
LONG_DESCENT_S = 6.0
END_INTERVAL_S = 0.06
CRUISE_INTERVAL_S = 0.25
MAX_INTERVALS = 400
# Long descents only: IPOPT warm-started from the last round's multipliers (a tightening round then
# takes tens of iterations, not hundreds), and a small penalty on the yaw rate (rad²/s per second
# of flight: at most a few ms on the objective) that removes the helix's free heading, which otherwise
# leaves IPOPT a long degenerate tail.
LONG_IPOPT_OPTIONS = {"ipopt.warm_start_init_point": "yes", "ipopt.warm_start_bound_push": 1e-6,
                      "ipopt.warm_start_mult_bound_push": 1e-6}  # fmt: skip
LONG_YAW_RATE_WEIGHT = 1e-3


def _node_density(t: np.ndarray, t_f: float, t_ramp: float) -> np.ndarray:
    """Nodes per second of the long-descent mesh at times ``t`` (see ``END_INTERVAL_S``)."""
    lo, hi = 1.0 / CRUISE_INTERVAL_S, 1.0 / END_INTERVAL_S
    return lo + (hi - lo) * (np.exp(-((t / t_ramp) ** 2)) + np.exp(-(((t_f - t) / t_ramp) ** 2)))


def long_descent_mesh(p: HelixProblem, t_f: float) -> np.ndarray:
    """Interval fractions of the long-descent mesh for a descent of ``t_f`` s: as many intervals
    as the node density asks (at least ``n_intervals``), crowded in the entry and exit."""
    _, t_ramp = steady_helix_duration(p)
    fine = np.linspace(0.0, t_f, 4001)
    dens = _node_density(fine, t_f, t_ramp)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(fine))])
    n = int(min(max(p.n_intervals, math.ceil(cum[-1])), max(MAX_INTERVALS, p.n_intervals)))
    nodes = np.interp(np.linspace(0.0, cum[-1], n + 1), cum, fine)
    return np.diff(nodes) / t_f


def _long_spec(p: HelixProblem, n: int) -> OcpSpec:
    spec = _spec(p, n)
    spec.control_weight = np.array([0.0, 0.0, 0.0, LONG_YAW_RATE_WEIGHT])
    spec.ipopt_options = dict(LONG_IPOPT_OPTIONS)
    return spec


def _capped(spec: OcpSpec, max_solve_s: float | None) -> OcpSpec:
    if max_solve_s is not None:
        spec.ipopt_options = {**spec.ipopt_options, "ipopt.max_wall_time": float(max_solve_s)}
    return spec


def solve_helix(p: HelixProblem, verbose: bool = False, max_solve_s: float | None = None) -> HelixSolution:
    """Warm start, fine solve, then bounds tightened where the 1 kHz dense re-simulation leaves them
    between nodes (≤ 3 rounds). ``max_solve_s`` caps each IPOPT solve's wall time (one that runs out
    is not a success).

    Warm start: the steady helix (``steady_helix_guess``) sets the expected duration. A short
    descent (≤ ``LONG_DESCENT_S``) is solved as it always was: from helices of 1 and 2 turns on the
    coarse mesh, the best refined on the uniform fine mesh of ``n_intervals``. A long descent starts
    the fine mesh from the steady helix, its nodes crowded in the entry and exit
    (``long_descent_mesh``; at least ``n_intervals``).

    Path constraints hold at nodes and interval midpoints; between them the flown path can bulge
    past a bound that the optimum rides (the tilt limit, the radius, the cone, the autopilot's
    accelerations). Each round re-simulates every interval from its node (``dense_path``), measures
    the overshoot of tilt, radius, the cone and the accelerations interval by interval and re-solves
    (warm, same compiled NLP) with those bounds tightened where they broke (by ``TIGHTEN_GAIN`` × the
    overshoot plus the tolerance, on the interval and its neighbours; never by more than
    ``MAX_TILT_BACKOFF_DEG``, ``MAX_RADIUS_BACKOFF_FRACTION`` × radius, ``MAX_CONE_BACKOFF_MPS`` and
    ``MAX_ACCEL_BACKOFF_FRACTION`` × the bound), until the re-simulation is within ``TILT_TOL_DEG``,
    ``RADIUS_TOL_M``, ``CONE_TOL_MPS`` and ``ACCEL_TOL_MPS2``. Rates and
    thrust are controls, linear between nodes, so their box bounds hold exactly on the
    re-simulation; the check reports them too.
    """
    p.validate()
    t0 = time.perf_counter()
    t_steady, _ = steady_helix_duration(p)
    attempts: list[dict] = []
    if t_steady <= LONG_DESCENT_S:
        coarse = MinTimeOcp(_capped(_spec(p, p.n_coarse), max_solve_s), verbose=verbose)
        t_guess = max(2.0, 2.5 * math.sqrt(p.height_m))

        def solve_start(turns: float) -> OcpResult:
            xg, ug = helix_guess(p, p.n_coarse, turns, t_guess * (0.8 + 0.2 * turns))
            return coarse.solve(t_guess, xg, ug, name=f"helix{turns:g}")

        def refinement_for(_turns: float) -> _Tightening:
            fine = (coarse if p.n_intervals == p.n_coarse
                    else MinTimeOcp(_capped(_spec(p, p.n_intervals), max_solve_s), verbose=verbose))  # fmt: skip
            return _Tightening(p, fine, None)

        final = multistart_refined((1.0, 2.0), solve_start, refinement_for, TIGHTEN_ROUNDS, attempts,
                                   record=_attempt)  # fmt: skip
    else:
        mesh = long_descent_mesh(p, t_steady)
        n = len(mesh)
        fine = MinTimeOcp(_capped(_long_spec(p, n), max_solve_s), verbose=verbose)
        t_g, x_dense, u_dense = steady_helix_guess(p, 20 * n)
        t_dense = np.linspace(0.0, t_g, 20 * n + 1)
        t_s = t_g * np.concatenate([[0.0], np.cumsum(mesh)])
        start = OcpResult(status="warm start (not solved)", success=False, t_f_s=t_g, t_s=t_s,
                          x=_interp_rows(t_s, t_dense, x_dense), u=_interp_rows(t_s, t_dense, u_dense),
                          solve_s=0.0, iterations=0, max_defect=np.inf, mesh=mesh, guess="steady")  # fmt: skip
        final = refine(start, _Tightening(p, fine, mesh), TIGHTEN_ROUNDS, attempts)
    sol = HelixSolution(problem=p, result=final, attempts=attempts, solve_s=0.0, check={})
    sol.check = resimulation_check(sol)
    sol.solve_s = time.perf_counter() - t0
    return sol


def _interp_rows(t_new: np.ndarray, t: np.ndarray, arr: np.ndarray) -> np.ndarray:
    return np.stack([np.interp(t_new, t, arr[:, j]) for j in range(arr.shape[1])], 1)


class _Backoff:
    """How far the cone, radius and tilt bounds (and the acceleration bounds a problem has) are
    tightened at each constraint point of the mesh (the N+1 nodes, then the N midpoints): raised only
    where the path broke them."""

    def __init__(self, p: HelixProblem, n: int):
        self.p = p
        self.n = n
        self.cone_mps = np.zeros(2 * n + 1)
        self.radius_m = np.zeros(2 * n + 1)
        self.tilt_rad = np.zeros(2 * n + 1)
        self.max = {"cone_mps": MAX_CONE_BACKOFF_MPS, "radius_m": MAX_RADIUS_BACKOFF_FRACTION * p.radius_m,
                    "tilt_rad": math.radians(MAX_TILT_BACKOFF_DEG)}  # fmt: skip
        # m/s² off each acceleration bound the problem has (accel_z, accel_h)
        self.accel_mps2 = {key: np.zeros(2 * n + 1) for key in _accel_bounds(p)}
        self.max.update({key: MAX_ACCEL_BACKOFF_FRACTION * b for key, b in _accel_bounds(p).items()})

    def path_lb(self) -> np.ndarray:
        """Lower bounds of the path constraints ``(2N+1, rows)`` (``_spec``'s rows: cone, radius, tilt,
        speed, then the accelerations where bounded)."""
        r_bound, tilt = self.p.radius_m, self.p.tilt_max_rad
        lb = np.tile(_path_bounds(self.p)[0], (2 * self.n + 1, 1))
        lb[:, 0] = self.cone_mps
        lb[:, 1] = r_bound**2 - (r_bound - self.radius_m) ** 2
        lb[:, 2] = np.cos(np.maximum(tilt - self.tilt_rad, 0.0)) - math.cos(tilt)
        for col, (key, bound) in enumerate(_accel_bounds(self.p).items(), start=4):
            lb[:, col] = bound**2 - (bound - self.accel_mps2[key]) ** 2
        return lb

    def raise_where(self, key: str, over_per_interval: np.ndarray, step: np.ndarray) -> bool:
        """Raise ``key``'s backoff by ``step`` on each interval whose overshoot is > 0 and on its
        neighbours (nodes k−1 … k+2, midpoints k−1 … k+1); False when nothing could be raised.
        The cone stays untouched at the two hover nodes, where its slack is exactly 0."""
        arr = self.accel_mps2[key] if key in self.accel_mps2 else getattr(self, key)
        before = arr.copy()  # steps of neighbouring intervals overlap: each adds to the old value
        n = self.n
        moved = False
        for k in np.flatnonzero(over_per_interval > 0):
            nodes = np.arange(max(k - 1, 0), min(k + 2, n) + 1)
            mids = n + 1 + np.arange(max(k - 1, 0), min(k + 1, n - 1) + 1)
            if key == "cone_mps":
                nodes = nodes[(nodes > 0) & (nodes < n)]
            pts = np.concatenate([nodes, mids])
            new = min(before[pts].max() + step[k], self.max[key])
            moved |= bool(np.any(arr[pts] < new))
            arr[pts] = np.maximum(arr[pts], new)
        return moved

    def summary(self) -> dict:
        out = {"tilt_rad": float(self.tilt_rad.max()), "radius_m": float(self.radius_m.max()),
               "cone_mps": float(self.cone_mps.max()),
               "share": float(np.mean((self.tilt_rad > 0) | (self.radius_m > 0) | (self.cone_mps > 0)))}  # fmt: skip
        out.update({f"{key}_mps2": float(arr.max()) for key, arr in self.accel_mps2.items()})
        return out


class _Tightening:
    """The helix's fine solve and its tightening rounds (a ``multistart.Refinement``): bounds tightened
    where the dense re-simulation leaves them between nodes (``_Backoff``), on a fixed mesh."""

    word = "tighten"

    def __init__(self, p: HelixProblem, fine: MinTimeOcp, mesh: np.ndarray | None):
        self.p = p
        self.fine = fine
        self.mesh = mesh
        self.backoff = _Backoff(p, fine.spec.n_intervals)

    def solve(self, current: OcpResult, label: str, round_: int) -> OcpResult:
        n = self.fine.spec.n_intervals
        xg = resample_guess(current.t_s, current.x, n, self.mesh)
        ug = resample_guess(current.t_s, current.u, n, self.mesh)
        warm = current if round_ > 0 else None  # the same NLP's multipliers (used where IPOPT warm-starts)
        return self.fine.solve(current.t_f_s, xg, ug, name=label, path_lb=self.backoff.path_lb(), mesh=self.mesh,
                               warm=warm)  # fmt: skip

    def record(self, r: OcpResult) -> dict:
        return {**_attempt(r), "backoff": self.backoff.summary()}

    def again(self, r: OcpResult) -> bool:
        over, per = _overshoots(self.p, r)
        if all(v <= 0 for v in over.values()):
            return False
        moved = False
        bounds = (("cone_mps", "cone_mps", CONE_TOL_MPS, 1.0), ("radius_m", "radius_m", RADIUS_TOL_M, 1.0),
                  ("tilt_rad", "tilt_deg", TILT_TOL_DEG, math.radians(1.0)),
                  *((key, f"{key}_mps2", ACCEL_TOL_MPS2, 1.0) for key in _accel_bounds(self.p)))  # fmt: skip
        for key, over_key, tol, unit in bounds:
            if over[over_key] > 0:
                step = (TIGHTEN_GAIN * per[over_key] + tol) * unit
                moved |= self.backoff.raise_where(key, per[over_key], step)
        # nothing moved: every bound that still breaks is at its largest backoff, the check reports it
        return moved


def _overshoots(p: HelixProblem, r: OcpResult):
    """How far the dense re-simulation exceeds each bound beyond its tolerance (≤ 0: fine), overall
    and on each mesh interval: the cone (m/s), tilt (deg), radius (m), and the accelerations the
    problem bounds (``accel_z_mps2``, ``accel_h_mps2``: m/s²)."""
    d = dense_path(r)
    n = len(r.t_s) - 1
    m = (len(d.t) - 1) // n  # dense samples per interval (rk4_piecewise: the start node, then m per interval)
    k = np.concatenate([[0], np.arange(n * m) // m])
    w, u_air = blade_velocity_np(p, d.x, d.u)
    values = {
        "cone_mps": -p.constraint.margin(w, u_air) - CONE_TOL_MPS,
        "tilt_deg": _tilt_deg(d.x) - math.degrees(p.tilt_max_rad) - TILT_TOL_DEG,
        "radius_m": np.hypot(d.x[:, 0], d.x[:, 1]) - p.radius_m - RADIUS_TOL_M,
    }
    bounds = _accel_bounds(p)
    if bounds:
        acc = commanded_accel_np(d.x, d.u)
        size = {"accel_z": np.abs(acc[:, 2]), "accel_h": np.hypot(acc[:, 0], acc[:, 1])}
        values.update({f"{key}_mps2": size[key] - b - ACCEL_TOL_MPS2 for key, b in bounds.items()})
    per = {}
    for key, v in values.items():
        per[key] = np.full(n, -np.inf)
        np.maximum.at(per[key], k, v)
    return {key: float(v.max()) for key, v in per.items()}, per


def _tilt_deg(x: np.ndarray) -> np.ndarray:
    q = x[:, 6:10] / np.linalg.norm(x[:, 6:10], axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip(1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2), -1, 1)))


def dense_path(r: OcpResult, rate_hz: float = 1000.0) -> DenseSolution:
    """The solution at ``rate_hz`` or finer: every interval integrated from its own node with the
    interpolated controls (``ocp.rk4_piecewise``), the small gap to the next node spread over the
    interval. What the checks measure and what the trajectory file carries.

    Not one open-loop integration from the start: the rate-input rigid body integrates attitude
    errors twice into position, so over a 10 s descent the open-loop path of the node controls
    drifts by metres (a numerical artefact the autopilot's position loop removes, not a plan that
    breaks its radius), and bounds tightened against that drift ruin the plan.
    """
    return rk4_piecewise(dynamics, r.t_s, r.x, r.u, rate_hz)


def commanded_accel_np(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The acceleration ``v̇`` (M, 3), NED m/s², of states (M, 10) and controls (M, 4): what the
    trajectory file carries as ``an/ae/ad`` and the autopilot is asked to fly."""
    q = x[:, 6:10] / np.linalg.norm(x[:, 6:10], axis=1, keepdims=True)
    return quat_to_rotmat(q)[:, :, 2] * (-u[:, 0:1]) + np.array([0.0, 0.0, G_MPS2])


def _dense_figures(p: HelixProblem, r: OcpResult, rate_hz: float = 1000.0):
    d = dense_path(r, rate_hz)
    t, x, u = d.t, d.x, d.u
    w, u_air = blade_velocity_np(p, x, u)
    margin = p.constraint.margin(w, u_air)
    i = int(np.argmin(margin))
    radius = np.hypot(x[:, 0], x[:, 1])
    acc = commanded_accel_np(x, u)
    figures = {
        "rate_hz": rate_hz,
        "worst_margin_mps": float(margin[i]),
        "worst_margin_t_s": float(t[i]),
        "max_radius_m": float(radius.max()),
        "max_tilt_deg": float(_tilt_deg(x).max()),
        "max_rate_dps": float(np.degrees(np.abs(u[:, 1:]).max())),
        "min_thrust_mps2": float(u[:, 0].min()),
        "max_thrust_mps2": float(u[:, 0].max()),
        "max_speed_mps": float(np.linalg.norm(x[:, 3:6], axis=1).max()),
        "max_descent_mps": float(x[:, 5].max()),
        "max_climb_mps": float(max(0.0, -x[:, 5].min())),
        "max_accel_z_mps2": float(np.abs(acc[:, 2]).max()),
        "max_accel_h_mps2": float(np.hypot(acc[:, 0], acc[:, 1]).max()),
        "end_position_error_m": float(np.linalg.norm(x[-1, :3] - [*p.end_ne_m, p.height_m])),
        "end_speed_mps": float(np.linalg.norm(x[-1, 3:6])),
        "node_gap_m": float(np.abs(d.gaps[:, :3]).max()),
        "node_gap_mps": float(np.abs(d.gaps[:, 3:6]).max()),
        "node_gap_quat": float(np.abs(d.gaps[:, 6:10]).max()),
    }
    return figures


def resimulation_check(sol: HelixSolution, rate_hz: float = 1000.0) -> dict:
    """Figures of the dense re-simulation (``dense_path``, 1 kHz, what would be flown), the
    tolerances they are held to, whether each limit holds (``limits_ok``) and whether the mesh
    integrates the dynamics closely enough (``node_gap_ok``: every interval's 1 kHz integration ends
    within ``NODE_GAP_TOL_M`` of the next node)."""
    r = sol.result
    p = sol.problem
    c = _dense_figures(p, r, rate_hz)
    w_n, u_n = blade_velocity_np(p, r.x, r.u)
    tol = {"cone_mps": CONE_TOL_MPS, "tilt_deg": TILT_TOL_DEG, "radius_m": RADIUS_TOL_M,
           "controls_rel": CONTROL_TOL_REL, "node_gap_m": NODE_GAP_TOL_M, "accel_mps2": ACCEL_TOL_MPS2}  # fmt: skip
    rate_lim = math.degrees(max(p.rate_max_rps))
    accel_ok = all(c[f"max_{key}_mps2"] <= b + ACCEL_TOL_MPS2 for key, b in _accel_bounds(p).items())
    c.update({
        "node_worst_margin_mps": float(np.min(p.constraint.margin(w_n, u_n))),
        "turns": float(_turns(r.x)),
        "n_intervals": len(r.t_s) - 1,
        "tolerances": tol,
        "limits_ok": bool(
            c["worst_margin_mps"] >= -CONE_TOL_MPS
            and c["max_tilt_deg"] <= math.degrees(p.tilt_max_rad) + TILT_TOL_DEG
            and c["max_radius_m"] <= p.radius_m + RADIUS_TOL_M
            and c["max_rate_dps"] <= rate_lim * (1 + CONTROL_TOL_REL)
            and p.f_min_mps2 - CONTROL_TOL_REL * p.f_max_mps2 <= c["min_thrust_mps2"]
            and c["max_thrust_mps2"] <= p.f_max_mps2 * (1 + CONTROL_TOL_REL)
            and accel_ok
        ),
        "node_gap_ok": bool(c["node_gap_m"] <= NODE_GAP_TOL_M),
    })  # fmt: skip
    return c


def _turns(x: np.ndarray) -> float:
    """Revolutions of the horizontal velocity direction (a helix turns, an oblique path does not)."""
    speed = np.hypot(x[:, 3], x[:, 4])
    moving = speed > 0.05 * max(speed.max(), 1e-9)
    ang = np.unwrap(np.arctan2(x[moving, 4], x[moving, 3]))
    return abs(ang[-1] - ang[0]) / (2 * math.pi) if len(ang) > 1 else 0.0
