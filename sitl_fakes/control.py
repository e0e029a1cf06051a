"""A PX4-like multicopter cascade: position → velocity → acceleration/thrust vector → attitude → rates.

Setpoints follow PX4's trajectory_setpoint semantics: per axis a position, a velocity and an
acceleration, each NaN when not given. Position error feeds a velocity command, the velocity error a
PI acceleration command, feed-forwards add on. Tilt is limited with vertical priority, velocity with
``MPC_*`` limits, rates with the profile, rotor thrusts with the profile (mixer desaturation keeps
roll/pitch authority first, yaw last), as PX4 does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from flighttest.aero import G_MPS2
from flighttest.profiles import VehicleProfile
from sitl_fakes.physics import RigidBodyState

NAN = float("nan")
RATE_GAIN_RP_PER_S = 25.0
RATE_GAIN_Y_PER_S = 10.0
RATE_I_GAIN = 5.0


def _finite(x: float) -> bool:
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
    vel_xy_max_mps: float = 12.0
    vel_up_max_mps: float = 3.0
    vel_dn_max_mps: float = 1.5
    tilt_max_rad: float = math.radians(45.0)
    xy_p: float = 0.95
    z_p: float = 1.0
    xy_vel_p: float = 1.8
    xy_vel_i: float = 0.4
    z_vel_p: float = 4.0
    z_vel_i: float = 2.0
    roll_p: float = 6.5
    yaw_p: float = 2.8
    tilt_rate_ff_tau_s: float = 0.04  # low-pass of the tilt-rate feed-forward; 0 turns it off
    yaw_weight: float = 0.4  # MC_YAW_WEIGHT: tilt first, yaw follows at this weight (as PX4)


class Controller:
    def __init__(self, profile: VehicleProfile):
        self.profile = profile
        self.mass_kg = profile.mass_kg
        self.inertia = profile.inertia_kgm2
        self.t_min_n = profile.min_thrust_per_rotor_n
        self.t_max_n = profile.max_thrust_per_rotor_n
        self.rate_max_radps = [math.radians(r) for r in profile.max_rate_dps]
        self.arm_xy_m = profile.arm_length_m / math.sqrt(2.0)
        self.k_yaw_m = profile.yaw_moment_per_thrust_m
        self.vel_int = [0.0, 0.0, 0.0]
        self.rate_int = [0.0, 0.0, 0.0]
        self.yaw_hold_rad = 0.0
        self.last_acc_cmd = (0.0, 0.0, 0.0)
        self.last_collective_n = 0.0

    def reset(self, s: RigidBodyState) -> None:
        self.vel_int = [0.0, 0.0, 0.0]
        self.rate_int = [0.0, 0.0, 0.0]
        self.yaw_hold_rad = s.yaw_rad()

    # -- outer loops ---------------------------------------------------------------------------------
    def acceleration_command(self, dt_s: float, s: RigidBodyState, t: Target, lim: Limits):
        pos = (s.n_m, s.e_m, s.d_m)
        vel = (s.vn_mps, s.ve_mps, s.vd_mps)
        vcmd = [NAN, NAN, NAN]
        for i in range(3):
            gain = lim.z_p if i == 2 else lim.xy_p
            if _finite(t.pos[i]):
                vcmd[i] = gain * (t.pos[i] - pos[i]) + (t.vel[i] if _finite(t.vel[i]) else 0.0)
            elif _finite(t.vel[i]):
                vcmd[i] = t.vel[i]
        if _finite(vcmd[0]) and _finite(vcmd[1]):
            h = math.hypot(vcmd[0], vcmd[1])
            if h > lim.vel_xy_max_mps:
                vcmd[0] *= lim.vel_xy_max_mps / h
                vcmd[1] *= lim.vel_xy_max_mps / h
        if _finite(vcmd[2]):
            vcmd[2] = min(max(vcmd[2], -lim.vel_up_max_mps), lim.vel_dn_max_mps)
        acc = [0.0, 0.0, 0.0]
        for i in range(3):
            ff = t.acc[i] if _finite(t.acc[i]) else 0.0
            if _finite(vcmd[i]):
                kp, ki = (lim.z_vel_p, lim.z_vel_i) if i == 2 else (lim.xy_vel_p, lim.xy_vel_i)
                err = vcmd[i] - vel[i]
                self.vel_int[i] = min(max(self.vel_int[i] + ki * err * dt_s, -G_MPS2 * 0.6), G_MPS2 * 0.6)
                acc[i] = kp * err + self.vel_int[i] + ff
            else:
                acc[i] = ff
        return acc

    def thrust_vector(self, acc, lim: Limits):
        """Desired body z axis (NED) and collective thrust (N) for an acceleration, tilt-limited."""
        max_total = 4.0 * self.t_max_n
        min_total = max(4.0 * self.t_min_n, 0.08 * max_total)
        m = self.mass_kg
        fn, fe, fd = acc[0], acc[1], acc[2] - G_MPS2
        fd = min(fd, -min_total / m)  # keep some upward thrust: no commanded flips
        fd = max(fd, -max_total / m)
        h_max = min(-fd * math.tan(lim.tilt_max_rad), math.sqrt(max(0.0, (max_total / m) ** 2 - fd * fd)))
        h = math.hypot(fn, fe)
        if h > h_max:
            fn, fe = fn * h_max / h, fe * h_max / h
        norm = math.sqrt(fn * fn + fe * fe + fd * fd)
        return (-fn / norm, -fe / norm, -fd / norm), min(max(m * norm, min_total), max_total)

    # -- inner loops ---------------------------------------------------------------------------------
    def rotor_thrusts(self, dt_s, s: RigidBodyState, bz, collective_n, yaw_rad, lim: Limits):
        """Attitude P → rate PI → mixer with desaturation; returns four rotor thrust commands (N)."""
        q = (s.qw, s.qx, s.qy, s.qz)
        qd = _reduced_attitude_setpoint(q, _quat_from_z_and_yaw(bz, yaw_rad), lim.yaw_weight)
        # error quaternion q_e = q⁻¹ ⊗ q_d, canonical (shortest way round)
        ew, ex, ey, ez = _qmul(_qconj(q), qd)
        if ew < 0.0:
            ex, ey, ez = -ex, -ey, -ez
        yaw_gain = lim.yaw_p / lim.yaw_weight if lim.yaw_weight > 1e-4 else lim.yaw_p
        rate_sp = [2.0 * lim.roll_p * ex, 2.0 * lim.roll_p * ey, 2.0 * yaw_gain * ez]
        ff = self._tilt_rate_feedforward(dt_s, q, bz, lim)
        rate_sp = [rate_sp[0] + ff[0], rate_sp[1] + ff[1], rate_sp[2]]
        for i in range(3):
            r = self.rate_max_radps[i]
            rate_sp[i] = min(max(rate_sp[i], -r), r)
        rates = (s.p_radps, s.q_radps, s.r_radps)
        ixx, iyy, izz = self.inertia
        moments = []
        for i, (inertia, gain) in enumerate(
            ((ixx, RATE_GAIN_RP_PER_S), (iyy, RATE_GAIN_RP_PER_S), (izz, RATE_GAIN_Y_PER_S))
        ):
            err = rate_sp[i] - rates[i]
            self.rate_int[i] = min(max(self.rate_int[i] + RATE_I_GAIN * err * dt_s, -3.0), 3.0)
            moments.append(inertia * (gain * err + self.rate_int[i]))
        self.last_collective_n = collective_n
        return self.mix(collective_n, moments[0], moments[1], moments[2])

    def _tilt_rate_feedforward(self, dt_s, q, bz, lim: Limits):
        """Body rates (FRD) that turn the thrust axis as fast as its setpoint turns: ``ḃ_z × b_z``
        in the world frame, from the setpoint's change per step, low-passed (the setpoint arrives in
        steps at the offboard rate). Without it the attitude loop trails a turning thrust vector by
        ``rate / MC_ROLL_P`` and a helix is flown with a persistent acceleration error."""
        prev = self._bz_prev
        self._bz_prev = bz
        if prev is None or lim.tilt_rate_ff_tau_s <= 0:
            return (0.0, 0.0)
        dn, de, dd = ((bz[i] - prev[i]) / dt_s for i in range(3))
        wn = bz[1] * dd - bz[2] * de
        we = bz[2] * dn - bz[0] * dd
        wd = bz[0] * de - bz[1] * dn
        a = dt_s / (lim.tilt_rate_ff_tau_s + dt_s)
        f = self._ff_world
        self._ff_world = (f[0] + a * (wn - f[0]), f[1] + a * (we - f[1]), f[2] + a * (wd - f[2]))
        # world → body: R(q)ᵀ v
        bx, by, _ = _rotate_ned_to_body(q, self._ff_world)
        return (bx, by)

    _bz_prev = None
    _ff_world = (0.0, 0.0, 0.0)

    def mix(self, collective_n, mx, my, mz):
        a, k = self.arm_xy_m, self.k_yaw_m
        rp = (
            (-mx + my) / (4 * a),
            (mx - my) / (4 * a),
            (mx + my) / (4 * a),
            (-mx - my) / (4 * a),
        )
        yw = (mz / (4 * k), mz / (4 * k), -mz / (4 * k), -mz / (4 * k))
        lo_t, hi_t = self.t_min_n, self.t_max_n
        base = collective_n / 4.0
        lo, hi = min(rp), max(rp)
        span = hi_t - lo_t
        scale = 1.0
        if hi - lo > span:  # roll/pitch alone saturate: keep their ratio, drop the collective request
            scale = span / (hi - lo)
            base = lo_t - lo * scale
        else:
            base = min(max(base, lo_t - lo), hi_t - hi)
        out = [base + scale * r for r in rp]
        # yaw last: as much as fits
        ys = 1.0
        for o, y in zip(out, yw):
            if y > 0 and o + y > hi_t:
                ys = min(ys, max(0.0, (hi_t - o) / y))
            elif y < 0 and o + y < lo_t:
                ys = min(ys, max(0.0, (lo_t - o) / y))
        return [min(max(o + ys * y, lo_t), hi_t) for o, y in zip(out, yw)]


def _qmul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def _rotate_ned_to_body(q, v):
    w, x, y, z = q
    vx, vy, vz = v
    return (
        (1 - 2 * (y * y + z * z)) * vx + 2 * (x * y + w * z) * vy + 2 * (x * z - w * y) * vz,
        2 * (x * y - w * z) * vx + (1 - 2 * (x * x + z * z)) * vy + 2 * (y * z + w * x) * vz,
        2 * (x * z + w * y) * vx + 2 * (y * z - w * x) * vy + (1 - 2 * (x * x + y * y)) * vz,
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
    yx, yy, yz = zy * 0.0 - zz * cy, zz * cx - zx * 0.0, zx * cy - zy * cx
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
