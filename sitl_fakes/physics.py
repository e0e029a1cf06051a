"""Rigid-body quadcopter as PX4's SIH: quaternion attitude, four rotor thrusts with motor lag, the airframe's
own drag (``sitl_fakes.drag``: linear and quadratic per body axis), ground contact.

Plain-float arithmetic on purpose: at 250 Hz a 3-vector through numpy costs more than the maths.
Frames as in CONVENTIONS §1: NED inertial, FRD body, ``q = (w, x, y, z)`` rotates body → NED.
Rotor order and spin follow PX4's quad-X: 1 front-right CCW, 2 rear-left CCW, 3 front-left CW,
4 rear-right CW. A CCW rotor's drag torque yaws the body clockwise (+yaw in FRD).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from flighttest.model.aero import G_MPS2
from flighttest.model.profiles import VehicleProfile
from sitl_fakes.drag import TruthDrag, truth_drag_for

# PX4 SIH's defaults (../shared/px4_sih): motor time constant SIH_T_TAU and rotational damping SIH_KDW
# (N m per rad/s). The drag is the airframe's truth (sitl_fakes.drag), which the autopilot does not know.
MOTOR_TIME_CONSTANT_S = 0.05
ROT_DAMPING_NM_PER_RADPS = 0.025
# rotor i: (x sign, y sign, spin sign: +1 CCW)
ROTOR_LAYOUT = ((1.0, 1.0, 1.0), (-1.0, -1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0))


def rotate_body_to_ned(
    bx: float, by: float, bz: float, qw: float, qx: float, qy: float, qz: float
) -> tuple[float, float, float]:
    """``R(q) v_b`` for one vector, plain floats. Vector first, then the quaternion (w, x, y, z): the
    order of every rotation helper, flighttest's (``flighttest.model.frames``) and the fake's alike."""
    tx = 2.0 * (qy * bz - qz * by)
    ty = 2.0 * (qz * bx - qx * bz)
    tz = 2.0 * (qx * by - qy * bx)
    return (
        bx + qw * tx + (qy * tz - qz * ty),
        by + qw * ty + (qz * tx - qx * tz),
        bz + qw * tz + (qx * ty - qy * tx),
    )


def rotate_ned_to_body(
    vn: float, ve: float, vd: float, qw: float, qx: float, qy: float, qz: float
) -> tuple[float, float, float]:
    """``R(q)ᵀ v_ned`` for one vector, plain floats (vector first, then the quaternion)."""
    return rotate_body_to_ned(vn, ve, vd, qw, -qx, -qy, -qz)


@dataclass
class RigidBodyState:
    n_m: float = 0.0
    e_m: float = 0.0
    d_m: float = 0.0
    vn_mps: float = 0.0
    ve_mps: float = 0.0
    vd_mps: float = 0.0
    qw: float = 1.0
    qx: float = 0.0
    qy: float = 0.0
    qz: float = 0.0
    p_radps: float = 0.0  # body rates FRD
    q_radps: float = 0.0
    r_radps: float = 0.0
    an_mps2: float = 0.0  # last NED acceleration (for the IMU)
    ae_mps2: float = 0.0
    ad_mps2: float = 0.0
    # last specific force in the body frame (what the IMU measures: thrust and drag over the mass), and the drag
    fx_mps2: float = 0.0
    fy_mps2: float = 0.0
    fz_mps2: float = -G_MPS2
    drag_body_n: tuple[float, float, float] = (0.0, 0.0, 0.0)
    thrust_n: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0, 0.0])  # actual rotor thrusts
    on_ground: bool = True

    def yaw_rad(self) -> float:
        return math.atan2(2.0 * (self.qw * self.qz + self.qx * self.qy), 1.0 - 2.0 * (self.qy**2 + self.qz**2))

    def tilt_rad(self) -> float:
        """Angle between body z and NED down."""
        c = 1.0 - 2.0 * (self.qx * self.qx + self.qy * self.qy)
        return math.acos(max(-1.0, min(1.0, c)))


class QuadBody:
    """Integrates the rigid body from commanded rotor thrusts and per-rotor thrust factors."""

    def __init__(self, profile: VehicleProfile, drag: TruthDrag | None = None):
        self.profile = profile
        self.mass_kg = profile.mass_kg
        self.ixx, self.iyy, self.izz = profile.inertia_kgm2
        self.arm_xy_m = profile.arm_length_m / math.sqrt(2.0)
        self.k_yaw_m = profile.yaw_moment_per_thrust_m
        self.max_thrust_n = profile.max_thrust_per_rotor_n
        self.motor_tau_s = MOTOR_TIME_CONSTANT_S
        self.drag = truth_drag_for(profile) if drag is None else drag
        # the momentum drag's thrust scale: Σ√T_i against n·√T_hover
        self._inv_hover_sqrt = 1.0 / (profile.n_rotors * math.sqrt(profile.mass_kg * G_MPS2 / profile.n_rotors))
        self.rot_damping = ROT_DAMPING_NM_PER_RADPS
        self.state = RigidBodyState()

    def step(self, dt_s, thrust_cmd_n, thrust_factor, wind_ned) -> float:
        """Advance by ``dt_s``; returns the downward speed at ground contact (0 if none this step)."""
        s = self.state
        alpha = dt_s / (self.motor_tau_s + dt_s)
        thrusts = s.thrust_n
        for i in range(4):
            thrusts[i] += alpha * (thrust_cmd_n[i] * thrust_factor[i] - thrusts[i])
            if thrusts[i] < 0.0:
                thrusts[i] = 0.0
        t1, t2, t3, t4 = thrusts
        a = self.arm_xy_m
        mx = -a * (t1 - t2 - t3 + t4)
        my = a * (t1 - t2 + t3 - t4)
        mz = self.k_yaw_m * (t1 + t2 - t3 - t4)
        total = t1 + t2 + t3 + t4

        qw, qx, qy, qz = s.qw, s.qx, s.qy, s.qz
        # drag on the air-relative velocity in the body frame; thrust along −z_body
        bx, by, bz = rotate_ned_to_body(s.vn_mps - wind_ned[0], s.ve_mps - wind_ned[1], s.vd_mps - wind_ned[2],
                                        qw, qx, qy, qz)  # fmt: skip
        drag = self.drag
        scale = 1.0
        if drag.momentum:
            scale = (math.sqrt(t1) + math.sqrt(t2) + math.sqrt(t3) + math.sqrt(t4)) * self._inv_hover_sqrt
        dx, dy, dz = drag.force_body_n(bx, by, bz, scale)
        fn, fe, fd = rotate_body_to_ned(dx, dy, dz - total, qw, qx, qy, qz)
        m = self.mass_kg
        an = fn / m
        ae = fe / m
        ad = fd / m + G_MPS2

        # Euler's equations, body frame
        p, q, r = s.p_radps, s.q_radps, s.r_radps
        kw = self.rot_damping
        pd = (mx - kw * p - (self.izz - self.iyy) * q * r) / self.ixx
        qd = (my - kw * q - (self.ixx - self.izz) * p * r) / self.iyy
        rd = (mz - kw * r - (self.iyy - self.ixx) * p * q) / self.izz

        contact_speed = 0.0
        if s.on_ground:
            # resting on the ground: only lift-off moves it
            if ad < 0.0:
                s.on_ground = False
            else:
                an = ae = ad = 0.0
                s.vn_mps = s.ve_mps = s.vd_mps = 0.0
                s.p_radps = s.q_radps = s.r_radps = 0.0
                s.an_mps2 = s.ae_mps2 = s.ad_mps2 = 0.0
                self._level(keep_yaw=True)
                s.fx_mps2, s.fy_mps2, s.fz_mps2 = rotate_ned_to_body(0.0, 0.0, -G_MPS2, s.qw, s.qx, s.qy, s.qz)
                s.drag_body_n = (0.0, 0.0, 0.0)
                return 0.0

        s.vn_mps += an * dt_s
        s.ve_mps += ae * dt_s
        s.vd_mps += ad * dt_s
        s.n_m += s.vn_mps * dt_s
        s.e_m += s.ve_mps * dt_s
        s.d_m += s.vd_mps * dt_s
        s.an_mps2, s.ae_mps2, s.ad_mps2 = an, ae, ad
        s.fx_mps2, s.fy_mps2, s.fz_mps2 = dx / m, dy / m, (dz - total) / m
        s.drag_body_n = (dx, dy, dz)
        p += pd * dt_s
        q += qd * dt_s
        r += rd * dt_s
        s.p_radps, s.q_radps, s.r_radps = p, q, r
        # q̇ = ½ q ⊗ (0, ω)
        h = 0.5 * dt_s
        nw = qw + h * (-qx * p - qy * q - qz * r)
        nx = qx + h * (qw * p + qy * r - qz * q)
        ny = qy + h * (qw * q - qx * r + qz * p)
        nz = qz + h * (qw * r + qx * q - qy * p)
        inv = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
        s.qw, s.qx, s.qy, s.qz = nw * inv, nx * inv, ny * inv, nz * inv

        if s.d_m >= 0.0:  # ground plane at the home altitude
            contact_speed = max(s.vd_mps, 1e-6)
            s.d_m = 0.0
            s.on_ground = True
            s.vn_mps = s.ve_mps = s.vd_mps = 0.0
            s.p_radps = s.q_radps = s.r_radps = 0.0
        return contact_speed

    def _level(self, keep_yaw: bool) -> None:
        s = self.state
        yaw = s.yaw_rad() if keep_yaw else 0.0
        s.qw, s.qx, s.qy, s.qz = math.cos(0.5 * yaw), 0.0, 0.0, math.sin(0.5 * yaw)
