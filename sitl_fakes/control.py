"""PX4's multicopter cascade, ported: position → velocity → thrust vector → attitude → rates → allocation.

What flighttest sends reaches real PX4 as a ``trajectory_setpoint`` (per axis a position, a velocity
and an acceleration, NaN when not given) and goes through, in order (PX4 main 2026-03, the firmware of
``../shared/px4_sih``):

- ``PositionControl``: position P (``MPC_XY_P``, ``MPC_Z_P``) added to the velocity feed-forward, the
  horizontal part constrained with the position error first; velocity PID (``MPC_*_VEL_P/I/D_ACC``,
  D on the velocity derivative low-passed at ``MPC_VELD_LP``) added to the acceleration feed-forward;
  the thrust vector with ``MPC_ACC_DECOUPLE`` (tilt from the horizontal acceleration against gravity
  only), ``MPC_TILTMAX_AIR``, ``MPC_THR_MIN``/``MPC_THR_MAX`` and the horizontal margin
  ``MPC_THR_XY_MARG``, in normalised thrust with ``MPC_THR_HOVER``; anti-windup as PX4 does it;
- ``AttitudeControl``: the thrust axis first, yaw at ``MC_YAW_WEIGHT``, a P law (``MC_ROLL_P`` …)
  with **no feed-forward of the tilt rate**: a turning thrust vector is followed ``1/MC_ROLL_P``
  behind (0.25 s with SIH's 4.0), the first lag the reference flights show;
- ``RateControl``: PID on the (40 Hz-filtered) body rates in normalised torque (``MC_*RATE_P/I/D/K``,
  the I term shrinking with the error, ``MC_*_INT_LIM``), rates limited to ``MC_*RATE_MAX``;
- ``ControlAllocationSequentialDesaturation`` with ``MC_AIRMODE`` 0 for a quad X: roll and pitch
  torques of 1 move each motor by ±1/√2, yaw by ±1; a motor below 0 is desaturated by **cutting roll
  and pitch**, never by raising the collective. At the low collective of a plunge (motors at 0.13–0.22
  in ``helix-5m-guard-abort-1``) little torque is left: the second lag the reference flights show.

Motor commands ``u`` ∈ [0, 1] are fractions of the rotor's maximum thrust (SIH: thrust = ``SIH_T_MAX``
× ``u``, after the motor lag in ``physics``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from flighttest.model.aero import G_MPS2
from flighttest.model.profiles import VehicleProfile
from sitl_fakes.physics import RigidBodyState, rotate_ned_to_body

NAN = float("nan")
ROLL_PITCH_MIX = 1.0 / math.sqrt(2.0)  # PX4's normalised quad-X allocation (see module docstring)
# motor order and signs as PX4's quad X (CA_ROTOR0..3): front-right, rear-left, front-left, rear-right
ROLL_SIGNS = (-1.0, 1.0, 1.0, -1.0)
PITCH_SIGNS = (1.0, -1.0, 1.0, -1.0)
YAW_SIGNS = (1.0, 1.0, -1.0, -1.0)
GYRO_CUTOFF_HZ = 40.0  # IMU_GYRO_CUTOFF
DGYRO_CUTOFF_HZ = 20.0  # IMU_DGYRO_CUTOFF
YAW_HEADROOM = 0.15  # PX4 lets yaw use 15 % above full scale before cutting it


def finite(x: float) -> bool:
    return x == x and x not in (math.inf, -math.inf)


@dataclass
class Target:
    """One controller setpoint (NED, m, m/s, m/s², rad); NaN = not controlled on that axis."""

    pos: list[float] = field(default_factory=lambda: [NAN, NAN, NAN])
    vel: list[float] = field(default_factory=lambda: [NAN, NAN, NAN])
    acc: list[float] = field(default_factory=lambda: [NAN, NAN, NAN])
    yaw_rad: float = NAN
    yaw_rate_radps: float = NAN


@dataclass
class Limits:
    """The PX4 parameters the cascade reads (defaults: PX4 SIH quadx, ``../shared/px4_sih``)."""

    vel_xy_max_mps: float = 12.0  # MPC_XY_VEL_MAX
    vel_up_max_mps: float = 3.0  # MPC_Z_VEL_MAX_UP
    vel_dn_max_mps: float = 1.5  # MPC_Z_VEL_MAX_DN
    tilt_max_rad: float = math.radians(45.0)  # MPC_TILTMAX_AIR
    xy_p: float = 0.95
    z_p: float = 1.0
    xy_vel_p: float = 1.8
    xy_vel_i: float = 0.4
    xy_vel_d: float = 0.2
    z_vel_p: float = 4.0
    z_vel_i: float = 2.0
    z_vel_d: float = 0.0
    # low-pass of the vertical velocity error before its P and I (0: none, PX4; ArduCopter's PSC_D_VEL_FLTE)
    z_vel_err_lp_hz: float = 0.0
    veld_lp_hz: float = 5.0  # MPC_VELD_LP
    thr_hover: float = 0.5  # MPC_THR_HOVER (the fake sets the vehicle's true hover thrust)
    thr_min: float = 0.12  # MPC_THR_MIN
    thr_max: float = 1.0  # MPC_THR_MAX
    thr_xy_marg: float = 0.3  # MPC_THR_XY_MARG
    acc_decouple: bool = True  # MPC_ACC_DECOUPLE
    roll_p: float = 4.0  # MC_ROLL_P
    pitch_p: float = 4.0  # MC_PITCH_P
    yaw_p: float = 2.8  # MC_YAW_P
    yaw_weight: float = 0.4  # MC_YAW_WEIGHT
    rate_p: tuple[float, float, float] = (0.15, 0.15, 0.2)  # MC_ROLLRATE_P, MC_PITCHRATE_P, MC_YAWRATE_P
    rate_i: tuple[float, float, float] = (0.2, 0.2, 0.1)
    rate_d: tuple[float, float, float] = (0.003, 0.003, 0.0)
    rate_k: tuple[float, float, float] = (1.0, 1.0, 1.0)
    rate_int_lim: tuple[float, float, float] = (0.3, 0.3, 0.3)  # MC_RR_INT_LIM, MC_PR_INT_LIM, MC_YR_INT_LIM
    rate_max_radps: tuple[float, float, float] = (math.radians(220.0), math.radians(220.0), math.radians(200.0))

    @classmethod
    def from_params(cls, p: Callable[[str], float], profile: VehicleProfile) -> Limits:
        """The limits PX4 flies with, from its parameters (``p(name)``), within what the vehicle can do."""
        names = ("MC_ROLLRATE_MAX", "MC_PITCHRATE_MAX", "MC_YAWRATE_MAX")
        rate_max = tuple(math.radians(min(p(n), r)) for n, r in zip(names, profile.max_rate_dps))
        return cls(
            vel_xy_max_mps=min(p("MPC_XY_VEL_MAX"), profile.max_speed_mps),
            vel_up_max_mps=min(p("MPC_Z_VEL_MAX_UP"), profile.max_climb_mps),
            vel_dn_max_mps=p("MPC_Z_VEL_MAX_DN"),
            tilt_max_rad=math.radians(min(p("MPC_TILTMAX_AIR"), profile.max_tilt_deg)),
            xy_p=p("MPC_XY_P"),
            z_p=p("MPC_Z_P"),
            xy_vel_p=p("MPC_XY_VEL_P_ACC"),
            xy_vel_i=p("MPC_XY_VEL_I_ACC"),
            xy_vel_d=p("MPC_XY_VEL_D_ACC"),
            z_vel_p=p("MPC_Z_VEL_P_ACC"),
            z_vel_i=p("MPC_Z_VEL_I_ACC"),
            z_vel_d=p("MPC_Z_VEL_D_ACC"),
            veld_lp_hz=p("MPC_VELD_LP"),
            thr_hover=min(max(p("MPC_THR_HOVER"), 0.05), 0.95),
            thr_min=p("MPC_THR_MIN"),
            thr_max=p("MPC_THR_MAX"),
            thr_xy_marg=p("MPC_THR_XY_MARG"),
            acc_decouple=bool(p("MPC_ACC_DECOUPLE")),
            roll_p=p("MC_ROLL_P"),
            pitch_p=p("MC_PITCH_P"),
            yaw_p=p("MC_YAW_P"),
            yaw_weight=min(max(p("MC_YAW_WEIGHT"), 0.0), 1.0),
            rate_p=(p("MC_ROLLRATE_P"), p("MC_PITCHRATE_P"), p("MC_YAWRATE_P")),
            rate_i=(p("MC_ROLLRATE_I"), p("MC_PITCHRATE_I"), p("MC_YAWRATE_I")),
            rate_d=(p("MC_ROLLRATE_D"), p("MC_PITCHRATE_D"), p("MC_YAWRATE_D")),
            rate_k=(p("MC_ROLLRATE_K"), p("MC_PITCHRATE_K"), p("MC_YAWRATE_K")),
            rate_int_lim=(p("MC_RR_INT_LIM"), p("MC_PR_INT_LIM"), p("MC_YR_INT_LIM")),
            rate_max_radps=rate_max,  # type: ignore[arg-type]
        )


def _constrain_xy(v0: tuple[float, float], v1: tuple[float, float], vmax: float) -> tuple[float, float]:
    """PX4 ``ControlMath::constrainXY``: ``v0 + s·v1`` within ``vmax``, keeping ``v0`` first."""
    sx, sy = v0[0] + v1[0], v0[1] + v1[1]
    if math.hypot(sx, sy) <= vmax:
        return sx, sy
    n0 = math.hypot(*v0)
    if n0 >= vmax:
        return (v0[0] / n0 * vmax, v0[1] / n0 * vmax) if n0 > 0 else (0.0, 0.0)
    n1 = math.hypot(*v1)
    if n1 < 1e-9:
        return v0
    # |v0 + s·u1| = vmax along the unit u1, s ≥ 0
    ux, uy = v1[0] / n1, v1[1] / n1
    b = v0[0] * ux + v0[1] * uy
    s = -b + math.sqrt(max(b * b - (n0 * n0 - vmax * vmax), 0.0))
    return v0[0] + s * ux, v0[1] + s * uy


def _limit_tilt(bz: list[float], max_angle: float) -> list[float]:
    """PX4 ``ControlMath::limitTilt`` against NED down."""
    dot = min(max(bz[2], -1.0), 1.0)
    angle = min(math.acos(dot), max_angle)
    rx, ry = bz[0], bz[1]
    n = math.hypot(rx, ry)
    if n < 1e-7:
        rx, ry, n = 1.0, 0.0, 1.0
    return [math.sin(angle) * rx / n, math.sin(angle) * ry / n, math.cos(angle)]


def lowpass_alpha(cutoff_hz: float, dt_s: float) -> float:
    """The gain of a first-order low-pass at ``cutoff_hz`` stepped by ``dt_s`` (≤ 0 Hz: no filter)."""
    return dt_s / (dt_s + 1.0 / (2.0 * math.pi * cutoff_hz)) if cutoff_hz > 0.0 else 1.0


class Controller:
    """The cascade's state (integrators, filters) for one vehicle; every gain comes in ``Limits``."""

    def __init__(self, profile: VehicleProfile):
        self.profile = profile
        self.t_max_n = profile.max_thrust_per_rotor_n
        self.vel_int = [0.0, 0.0, 0.0]
        self.rate_int = [0.0, 0.0, 0.0]
        self.yaw_hold_rad = 0.0
        self.last_collective_n = 0.0
        self.last_u = [0.0, 0.0, 0.0, 0.0]
        # the last acceleration setpoint (NED, velocity loop plus feed-forward): ArduCopter's personality
        # closes its own vertical acceleration loop on it
        self.acc_setpoint_ned = [0.0, 0.0, 0.0]
        self._z_vel_err_f = 0.0
        self._vel_prev: tuple[float, float, float] | None = None
        self._vel_dot = [0.0, 0.0, 0.0]
        self._rates_f: list[float] | None = None
        self._rates_f_prev = [0.0, 0.0, 0.0]
        self._ang_acc = [0.0, 0.0, 0.0]

    def reset(self, s: RigidBodyState) -> None:
        self.vel_int = [0.0, 0.0, 0.0]
        self.rate_int = [0.0, 0.0, 0.0]
        self._z_vel_err_f = 0.0
        self.yaw_hold_rad = s.yaw_rad()

    # -- PositionControl -----------------------------------------------------------------------------
    def thrust_setpoint(self, dt_s: float, s: RigidBodyState, t: Target, lim: Limits):
        """Body z axis (NED unit vector) and collective thrust (0..1 of the rotors' maximum)."""
        pos = (s.n_m, s.e_m, s.d_m)
        vel = (s.vn_mps, s.ve_mps, s.vd_mps)
        self._update_vel_dot(dt_s, vel, lim)
        # position P, added to the velocity feed-forward (NaN-aware, as addIfNotNanVector3f)
        vsp_pos = [(t.pos[i] - pos[i]) * (lim.z_p if i == 2 else lim.xy_p) if finite(t.pos[i]) else NAN
                   for i in range(3)]  # fmt: skip
        vel_sp = [_add_if_not_nan(t.vel[i], vsp_pos[i]) for i in range(3)]
        p0 = [v if finite(v) else 0.0 for v in vsp_pos]
        if finite(vel_sp[0]) and finite(vel_sp[1]):
            vel_sp[0], vel_sp[1] = _constrain_xy(
                (p0[0], p0[1]), (vel_sp[0] - p0[0], vel_sp[1] - p0[1]), lim.vel_xy_max_mps
            )
        if finite(vel_sp[2]):
            vel_sp[2] = min(max(vel_sp[2], -lim.vel_up_max_mps), lim.vel_dn_max_mps)
        # velocity PID, added to the acceleration feed-forward
        self.vel_int[2] = min(max(self.vel_int[2], -G_MPS2), G_MPS2)
        gp = (lim.xy_vel_p, lim.xy_vel_p, lim.z_vel_p)
        gi = (lim.xy_vel_i, lim.xy_vel_i, lim.z_vel_i)
        gd = (lim.xy_vel_d, lim.xy_vel_d, lim.z_vel_d)
        vel_err = [vel_sp[i] - vel[i] for i in range(3)]
        if lim.z_vel_err_lp_hz > 0.0 and finite(vel_err[2]):
            self._z_vel_err_f += lowpass_alpha(lim.z_vel_err_lp_hz, dt_s) * (vel_err[2] - self._z_vel_err_f)
            vel_err[2] = self._z_vel_err_f
        acc_sp = [
            _add_if_not_nan(t.acc[i], vel_err[i] * gp[i] + self.vel_int[i] - self._vel_dot[i] * gd[i]) for i in range(3)
        ]
        acc_sp = [a if finite(a) else 0.0 for a in acc_sp]
        self.acc_setpoint_ned = acc_sp
        thr = self._acceleration_control(acc_sp, lim)
        # vertical anti-windup
        if (thr[2] >= -lim.thr_min and vel_err[2] >= 0.0) or (thr[2] <= -lim.thr_max and vel_err[2] <= 0.0):
            vel_err[2] = 0.0
        # vertical priority with a horizontal margin
        thr_xy = math.hypot(thr[0], thr[1])
        alloc_h = min(thr_xy, lim.thr_xy_marg)
        thr[2] = max(thr[2], -math.sqrt(max(lim.thr_max**2 - alloc_h**2, 0.0)))
        thr_max_xy = math.sqrt(max(lim.thr_max**2 - thr[2] ** 2, 0.0))
        if thr_xy > thr_max_xy:
            thr[0], thr[1] = thr[0] / thr_xy * thr_max_xy, thr[1] / thr_xy * thr_max_xy
        # horizontal tracking anti-windup (Rundqwist)
        prod = (thr[0] * G_MPS2 / lim.thr_hover, thr[1] * G_MPS2 / lim.thr_hover)
        lim_xy = prod if acc_sp[0] ** 2 + acc_sp[1] ** 2 > prod[0] ** 2 + prod[1] ** 2 else (acc_sp[0], acc_sp[1])
        arw = 2.0 / lim.xy_vel_p if lim.xy_vel_p > 0 else 0.0
        vel_err[0] -= arw * (acc_sp[0] - lim_xy[0])
        vel_err[1] -= arw * (acc_sp[1] - lim_xy[1])
        for i in range(3):
            if finite(vel_err[i]):
                self.vel_int[i] += vel_err[i] * gi[i] * dt_s
        norm = math.sqrt(thr[0] ** 2 + thr[1] ** 2 + thr[2] ** 2)
        if norm < 1e-6:
            return (0.0, 0.0, 1.0), 0.0
        return (-thr[0] / norm, -thr[1] / norm, -thr[2] / norm), norm

    def _acceleration_control(self, acc_sp: list[float], lim: Limits) -> list[float]:
        z_force = -G_MPS2 + (0.0 if lim.acc_decouple else acc_sp[2])
        n = math.sqrt(acc_sp[0] ** 2 + acc_sp[1] ** 2 + z_force**2)
        bz = _limit_tilt([-acc_sp[0] / n, -acc_sp[1] / n, -z_force / n], lim.tilt_max_rad)
        thrust_ned_z = acc_sp[2] * (lim.thr_hover / G_MPS2) - lim.thr_hover
        collective = min(thrust_ned_z / bz[2], -lim.thr_min)
        return [bz[0] * collective, bz[1] * collective, bz[2] * collective]

    def _update_vel_dot(self, dt_s: float, vel, lim: Limits) -> None:
        prev = self._vel_prev
        self._vel_prev = vel
        if prev is None or dt_s <= 0:
            return
        a = lowpass_alpha(lim.veld_lp_hz, dt_s)
        for i in range(3):
            self._vel_dot[i] += a * ((vel[i] - prev[i]) / dt_s - self._vel_dot[i])

    # -- AttitudeControl, RateControl, allocation ----------------------------------------------------
    def rotor_thrusts(self, dt_s, s: RigidBodyState, bz, collective, yaw_rad, lim: Limits):
        """Four rotor thrust commands (N) for a thrust axis and a collective (0..1)."""
        q = (s.qw, s.qx, s.qy, s.qz)
        qd = _reduced_attitude_setpoint(q, _quat_from_z_and_yaw(bz, yaw_rad), lim.yaw_weight)
        ew, ex, ey, ez = _qmul(_qconj(q), qd)
        if ew < 0.0:
            ex, ey, ez = -ex, -ey, -ez
        yaw_gain = lim.yaw_p / lim.yaw_weight if lim.yaw_weight > 1e-4 else lim.yaw_p
        rate_sp = [2.0 * lim.roll_p * ex, 2.0 * lim.pitch_p * ey, 2.0 * yaw_gain * ez]
        for i in range(3):
            r = lim.rate_max_radps[i]
            rate_sp[i] = min(max(rate_sp[i], -r), r)
        rates = self._filtered_rates(dt_s, (s.p_radps, s.q_radps, s.r_radps))
        torque = []
        for i in range(3):
            k = lim.rate_k[i]
            err = rate_sp[i] - rates[i]
            torque.append(k * lim.rate_p[i] * err + self.rate_int[i] - k * lim.rate_d[i] * self._ang_acc[i])
            i_factor = max(0.0, 1.0 - (err / math.radians(400.0)) ** 2)
            self.rate_int[i] = min(max(self.rate_int[i] + i_factor * k * lim.rate_i[i] * err * dt_s,
                                       -lim.rate_int_lim[i]), lim.rate_int_lim[i])  # fmt: skip
        self.last_collective_n = collective * 4.0 * self.t_max_n
        u = allocate(collective, torque[0], torque[1], torque[2])
        self.last_u = u
        return [x * self.t_max_n for x in u]

    def _filtered_rates(self, dt_s: float, rates):
        if self._rates_f is None:
            self._rates_f = list(rates)
            self._rates_f_prev = list(rates)
            return self._rates_f
        a = lowpass_alpha(GYRO_CUTOFF_HZ, dt_s)
        b = lowpass_alpha(DGYRO_CUTOFF_HZ, dt_s)
        for i in range(3):
            prev = self._rates_f[i]
            self._rates_f[i] += a * (rates[i] - prev)
            self._ang_acc[i] += b * ((self._rates_f[i] - prev) / dt_s - self._ang_acc[i])
        return self._rates_f


def _add_if_not_nan(setpoint: float, addition: float) -> float:
    if finite(setpoint) and finite(addition):
        return setpoint + addition
    return addition if not finite(setpoint) else setpoint


def _desaturation_gain(vec, sp, lo: float, hi: float) -> float:
    k_min = k_max = 0.0
    for v, x in zip(vec, sp):
        if abs(v) < 0.2:
            continue
        if x < lo:
            k = (lo - x) / v
            k_min, k_max = min(k_min, k), max(k_max, k)
        if x > hi:
            k = (hi - x) / v
            k_min, k_max = min(k_min, k), max(k_max, k)
    return k_min + k_max


def _desaturate(sp: list[float], vec, lo: float, hi: float, reduce_only: bool = False) -> None:
    for factor in (1.0, 0.5):
        gain = factor * _desaturation_gain(vec, sp, lo, hi)
        if reduce_only and gain > 0.0:
            return
        for i in range(4):
            sp[i] += gain * vec[i]


def allocate(collective: float, roll: float, pitch: float, yaw: float) -> list[float]:
    """PX4's sequential desaturation with airmode off: motor commands 0..1 from a collective (0..1)
    and normalised torques. Thrust may only be cut to fit; roll and pitch are cut next; yaw last."""
    sp = [collective + ROLL_PITCH_MIX * (ROLL_SIGNS[i] * roll + PITCH_SIGNS[i] * pitch) for i in range(4)]
    ones = (1.0, 1.0, 1.0, 1.0)
    _desaturate(sp, ones, 0.0, 1.0, reduce_only=True)
    _desaturate(sp, [ROLL_PITCH_MIX * r for r in ROLL_SIGNS], 0.0, 1.0)
    _desaturate(sp, [ROLL_PITCH_MIX * p for p in PITCH_SIGNS], 0.0, 1.0)
    for i in range(4):
        sp[i] += YAW_SIGNS[i] * yaw
    _desaturate(sp, YAW_SIGNS, 0.0, 1.0 + YAW_HEADROOM)
    _desaturate(sp, ones, 0.0, 1.0, reduce_only=True)
    return [min(max(x, 0.0), 1.0) for x in sp]


def _qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def _qconj(a):
    return (a[0], -a[1], -a[2], -a[3])


def _reduced_attitude_setpoint(q, qd, yaw_weight: float):
    """PX4's ``AttitudeControl::update`` setpoint: first the shortest rotation that brings the thrust
    axis onto the desired one (the tilt, which moves the vehicle), then only ``yaw_weight`` of the
    remaining rotation about it (the heading). Without this, a large heading error drags the thrust
    axis off its setpoint and the position loops see it as an acceleration error."""
    ez = (2 * (q[1] * q[3] + q[0] * q[2]), 2 * (q[2] * q[3] - q[0] * q[1]), 1 - 2 * (q[1] ** 2 + q[2] ** 2))
    ezd = (2 * (qd[1] * qd[3] + qd[0] * qd[2]), 2 * (qd[2] * qd[3] - qd[0] * qd[1]), 1 - 2 * (qd[1] ** 2 + qd[2] ** 2))
    cx = ez[1] * ezd[2] - ez[2] * ezd[1]
    cy = ez[2] * ezd[0] - ez[0] * ezd[2]
    cz = ez[0] * ezd[1] - ez[1] * ezd[0]
    dot = ez[0] * ezd[0] + ez[1] * ezd[1] + ez[2] * ezd[2]
    w = dot + math.sqrt(dot * dot + cx * cx + cy * cy + cz * cz)
    n = math.sqrt(w * w + cx * cx + cy * cy + cz * cz)
    if n < 1e-6:  # thrust axes opposite: no unique shortest rotation, use the full setpoint
        return qd
    red = _qmul((w / n, cx / n, cy / n, cz / n), q)  # world-frame tilt rotation applied to q
    mw, _, _, mz = _qmul(_qconj(red), qd)  # what is left: a rotation about the thrust axis
    if mw < 0.0:
        mw, mz = -mw, -mz
    mw, mz = min(max(mw, -1.0), 1.0), min(max(mz, -1.0), 1.0)
    return _qmul(red, (math.cos(yaw_weight * math.acos(mw)), 0.0, 0.0, math.sin(yaw_weight * math.asin(mz))))


def _quat_from_z_and_yaw(bz, yaw_rad):
    """Quaternion whose body z axis is ``bz`` (NED unit vector) with heading ``yaw_rad``."""
    zx, zy, zz = bz
    cx, cy = math.cos(yaw_rad), math.sin(yaw_rad)
    # body y = z × x_c
    yx, yy, yz = -zz * cy, zz * cx, zx * cy - zy * cx
    n = math.sqrt(yx * yx + yy * yy + yz * yz)
    yx, yy, yz = yx / n, yy / n, yz / n
    # body x = y × z
    xx, xy, xz = yy * zz - yz * zy, yz * zx - yx * zz, yx * zy - yy * zx
    # rotation matrix columns x, y, z → quaternion (Shepperd)
    r00, r11, r22 = xx, yy, zz
    tr = r00 + r11 + r22
    if tr > 0:
        sq = math.sqrt(tr + 1.0) * 2
        return (0.25 * sq, (yz - zy) / sq, (zx - xz) / sq, (xy - yx) / sq)
    if r00 > r11 and r00 > r22:
        sq = math.sqrt(1.0 + r00 - r11 - r22) * 2
        return ((yz - zy) / sq, 0.25 * sq, (yx + xy) / sq, (zx + xz) / sq)
    if r11 > r22:
        sq = math.sqrt(1.0 + r11 - r00 - r22) * 2
        return ((zx - xz) / sq, (yx + xy) / sq, 0.25 * sq, (zy + yz) / sq)
    sq = math.sqrt(1.0 + r22 - r00 - r11) * 2
    return ((xy - yx) / sq, (zx + xz) / sq, (zy + yz) / sq, 0.25 * sq)


__all__ = ["NAN", "Controller", "Limits", "Target", "allocate", "finite", "lowpass_alpha", "rotate_ned_to_body"]
