"""ArduCopter's position controller: the kinematic input shaping of ``AC_PosControl`` feeding the fake's cascade.

What real ArduCopter (master 2026) does with a GUIDED target, ported from ``libraries/AP_Math/control.cpp``
and ``libraries/AC_AttitudeControl/AC_PosControl.cpp``: every loop the *input* (the setpoint as last
received) is propagated forward by its own velocity and acceleration, and the controller's *desired*
state (position, velocity, acceleration) is shaped towards it by a square-root controller whose
correction acceleration is limited to ``accel_max`` and whose acceleration changes at most ``jerk_max``
per second. The desired state — never the raw setpoint — is what the position and velocity loops
track. So a step in the setpoint's acceleration passes through only as fast as the jerk limit lets it,
its velocity is reached at the correction's acceleration limit, and a position that has fallen behind
is caught up by overshooting the velocity (``../shared/ardupilot_sitl``: ``vertical-guard-abort``).

Limits as GUIDED sets them (``ModeGuided::pva_control_start``): horizontal speed/acceleration ``WP_SPD`` /
``WP_ACC``, vertical ``WP_SPD_DN`` / ``WP_SPD_UP`` / ``WP_ACC_Z``; jerk ``PSC_JERK_NE`` / ``PSC_JERK_D``
(the latter capped by the vertical acceleration filter, ``D_set_max_speed_accel_m``). ``WP_JERK`` belongs to
the waypoint S-curves, not to GUIDED's targets. With ``limit_output`` false (what GUIDED passes) the speed
limits bound only the *correction*: a setpoint that itself asks for more than ``WP_SPD_DN`` gets it, with
acceleration and jerk raised by the overspeed gain (the probe reference: 1.53 m/s against 1.5).

The loops after the shaping are the fake's cascade (``sitl_fakes.control``: position P plus velocity
feed-forward, velocity PID plus acceleration feed-forward, thrust vector, attitude, rates, allocation)
with ArduCopter's gains (``copter_limits``), the motors' 2 Hz throttle filter and the velocity integrator's
hand-over at a controller (re)start (``sitl_fakes.ardupilot_vehicle``).

Calibration (``tests/test_fake_ardupilot.py``; reference = DataFlash PSCD/PSCN/PSCE of the reference flights,
fake = ``sitl_fakes.ardupilot_replay`` of the same GUIP setpoints on the ``arducopter_sitl`` airframe — SITL's
own quad, which the reference flew — with a perfect estimate; in brackets the fake on the x500):

- ``vertical-guard-abort`` (step to 0.60 m/s down asking 4.9 m/s²): desired acceleration 0.42 / 0.92 /
  1.00 m/s² at 0.1 / 0.2 / 0.3 s (fake 0.44 / 0.94 / 1.00: jerk PSC_JERK_D 5 m/s³, cap WP_ACC_Z); desired
  velocity 0.78 m/s at 0.9 s in both (within 0.003 m/s up to the abort); the vehicle 0.223 m behind the
  setpoint at 0.8 s (fake 0.244 [0.271]); descent peak 0.99 m/s (fake 1.03 [1.00]) against a desired peak
  of 0.92.
- ``helix-guard-abort``: at 1.02 s v = (1.11, 0.49, 1.09) m/s (fake 1.09, 0.37, 1.14 [0.98, 0.34, 1.09])
  against a setpoint of (1.23, −2.57, 1.29); after the recover command north speed runs on to 2.05 m/s
  (fake 1.84 [1.67]), descent peaks at 1.31 m/s (fake 1.36 [1.34]).
- ``probe-completed`` (48.6 s sweep, 1.45 m/s planned): peak descent 1.53 m/s (fake 1.53 [1.59]), height
  error ≤ 0.11 m (fake 0.11 [0.14] m).
- A vertical of this project on ArduCopter SITL (its DataFlash PSCD/PIDA/SIM2; bench/RESULTS.md,
  "This change: the vertical ramps its acceleration at the jerk; the fake's vertical loop is ArduCopter's"): GUIDED's
  desired descent peaked at 0.55 m/s on a 0.3 m/s plan whose acceleration stepped, and the vehicle peaked
  at 0.55 too, 0.2 s later (fake, the same setpoints: 0.61). Its EKF3 stayed within 0.015 m/s of the truth
  (``ardupilot.SITL_ESTIMATE_ERROR``).
- BRAKE's vertical shaping (ref. ``vertical-guard-abort``): the desired climb rate decays at 0.70 per second
  (shaper gain jerk/accel = 5/7.5 = 0.67 per second).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from flighttest.model.aero import G_MPS2
from flighttest.model.profiles import VehicleProfile
from sitl_fakes.control import NAN, Limits, Target, finite, lowpass_alpha

OVERSPEED_GAIN_U = 2.0  # POSCONTROL_OVERSPEED_GAIN_U
ACCEL_D_MAX_MPS2 = 7.5  # the vertical shaping never asks for more than 7.5 m/s² up (constrain_float(…, 0, 7.5))
STOPPING_DIST_UP_MAX_M = 3.0  # POSCONTROL_STOPPING_DIST_UP_MAX_M
STOPPING_DIST_DOWN_MAX_M = 2.0  # POSCONTROL_STOPPING_DIST_DOWN_MAX_M
# the lowest collective the fake's allocation flies with (ArduCopter: ATC_THR_MIX_MIN 0.1 keeps attitude
# authority at low throttle)
THR_MIN = 0.1
HORIZONTAL_MARGIN = 0.3  # share of thrust kept for tilt when the collective saturates (PX4's MPC_THR_XY_MARG)
VEL_DOWN_UNCAPPED_MPS = 20.0  # the cascade does not cap the sum of feed-forward and correction (see module doc)


# -- AP_Math/control.cpp ---------------------------------------------------------------------------------
def sqrt_controller(error: float, p: float, second_ord_lim: float, dt_s: float) -> float:
    """Linear near the target, ``sqrt(2·a·Δx)`` beyond ``a/p²``; never overshoots the error in one step."""
    if second_ord_lim <= 0.0:
        rate = error * p
    elif p == 0.0:
        rate = math.copysign(math.sqrt(2.0 * second_ord_lim * abs(error)), error) if error else 0.0
    else:
        linear_dist = second_ord_lim / (p * p)
        if error > linear_dist:
            rate = math.sqrt(2.0 * second_ord_lim * (error - linear_dist / 2.0))
        elif error < -linear_dist:
            rate = -math.sqrt(2.0 * second_ord_lim * (-error - linear_dist / 2.0))
        else:
            rate = error * p
    if dt_s > 0.0:
        lim = abs(error) / dt_s
        return min(max(rate, -lim), lim)
    return rate


def sqrt_controller_accel(error: float, rate_cmd: float, rate_state: float, p: float, second_ord_lim: float) -> float:
    """The rate of change of ``sqrt_controller``'s output implied by the closing rate (chain rule)."""
    if not rate_cmd * rate_state > 0.0:
        return 0.0
    if second_ord_lim <= 0.0:
        return -p * rate_state
    if p <= 0.0:
        return -(second_ord_lim / abs(rate_cmd)) * rate_state if rate_cmd else 0.0
    if abs(error) <= second_ord_lim / (p * p):
        return -p * rate_state
    return -(second_ord_lim / abs(rate_cmd)) * rate_state if rate_cmd else 0.0


def inv_sqrt_controller(output: float, p: float, d_max: float) -> float:
    if d_max > 0.0 and p == 0.0:
        return output * output / (2.0 * d_max)
    if d_max <= 0.0:
        return output / p if p else 0.0
    if abs(output) < d_max / p:
        return output / p
    stopping = d_max / (p * p) * 0.5 + output * output / (2.0 * d_max)
    return stopping if output > 0 else -stopping


def shape_accel(accel_desired: float, accel: float, jerk_max: float, dt_s: float) -> float:
    step = jerk_max * dt_s
    return accel + min(max(accel_desired - accel, -step), step)


def shape_accel_xy(accel_desired: tuple[float, float], accel: list[float], jerk_max: float, dt_s: float) -> None:
    dx, dy = accel_desired[0] - accel[0], accel_desired[1] - accel[1]
    n = math.hypot(dx, dy)
    step = jerk_max * dt_s
    if n > step > 0.0:
        dx, dy = dx / n * step, dy / n * step
    accel[0] += dx
    accel[1] += dy


def _limit_length(x: float, y: float, lim: float) -> tuple[float, float]:
    n = math.hypot(x, y)
    if n > lim > 0.0:
        return x / n * lim, y / n * lim
    return x, y


def limit_accel_corner_xy(
    vel: tuple[float, float], accel: tuple[float, float], accel_max: float
) -> tuple[float, float]:
    """Braking along the velocity first, then what is left across it (AP_Math ``limit_accel_corner_xy``)."""
    if accel_max <= 0.0:
        return accel
    speed = math.hypot(*vel)
    if speed == 0.0:
        return _limit_length(accel[0], accel[1], accel_max)
    ax, ay = _limit_length(accel[0], accel[1], 2.0 * accel_max)
    ux, uy = vel[0] / speed, vel[1] / speed
    along = ax * ux + ay * uy
    cx, cy = ax - along * ux, ay - along * uy
    if along > 0.0:
        cross = min(math.hypot(cx, cy), accel_max)
        along_max = math.sqrt(max(accel_max * accel_max - cross * cross, 0.0))
        cx, cy = _limit_length(cx, cy, accel_max)
        along = min(along, along_max)
        return cx + along * ux, cy + along * uy
    along = max(along, -accel_max)
    cross_max = math.sqrt(max(accel_max * accel_max - along * along, 0.0))
    cx, cy = _limit_length(cx, cy, cross_max)
    return cx + along * ux, cy + along * uy


def shape_vel_accel(vel_desired: float, accel_desired: float, vel: float, accel: float, accel_min: float,
                    accel_max: float, jerk_max: float, dt_s: float, limit_total: bool) -> float:  # fmt: skip
    """The jerk-limited acceleration that brings ``vel`` to ``vel_desired`` (1-D); returns the new accel."""
    vel_error = vel_desired - vel
    kpa = jerk_max / accel_max if vel_error > 0.0 else jerk_max / -accel_min
    accel_target = min(max(sqrt_controller(vel_error, kpa, jerk_max, dt_s), accel_min), accel_max)
    accel_target += accel_desired
    if limit_total:
        accel_target = min(max(accel_target, accel_min), accel_max)
    return shape_accel(accel_target, accel, jerk_max, dt_s)


def shape_vel_accel_xy(vel_desired, accel_desired, vel, accel: list[float], accel_max: float, jerk_max: float,
                       dt_s: float, limit_total: bool) -> None:  # fmt: skip
    kpa = jerk_max / accel_max
    ex, ey = vel_desired[0] - vel[0], vel_desired[1] - vel[1]
    n = math.hypot(ex, ey)
    if n > 0.0:
        c = sqrt_controller(n, kpa, jerk_max, dt_s) / n
        tx, ty = ex * c, ey * c
    else:
        tx = ty = 0.0
    tx, ty = limit_accel_corner_xy((vel[0], vel[1]), (tx, ty), accel_max)
    tx, ty = tx + accel_desired[0], ty + accel_desired[1]
    if limit_total:
        tx, ty = _limit_length(tx, ty, accel_max)
    shape_accel_xy((tx, ty), accel, jerk_max, dt_s)


def shape_pos_vel_accel(pos_desired: float, vel_desired: float, accel_desired: float, pos: float, vel: float,
                        accel: float, vel_min: float, vel_max: float, accel_min: float, accel_max: float,
                        jerk_max: float, dt_s: float, limit_total: bool) -> float:  # fmt: skip
    """One axis of the square-root position/velocity/acceleration shaper; returns the new acceleration."""
    pos_error = pos_desired - pos
    accel_lim = -accel_min if pos_error > 0.0 else accel_max
    k_v = jerk_max / accel_lim
    vel_corr = vel - vel_desired
    vel_corr_cmd = sqrt_controller(pos_error, k_v, accel_lim, dt_s)
    vel_corr_cmd += sqrt_controller_accel(pos_error, vel_corr_cmd, vel_corr, k_v, accel_lim) / k_v
    if vel_min < 0.0:
        vel_corr_cmd = max(vel_corr_cmd, vel_min)
    if vel_max > 0.0:
        vel_corr_cmd = min(vel_corr_cmd, vel_max)
    vel_target = vel_desired + vel_corr_cmd
    if limit_total:
        if vel_min < 0.0:
            vel_target = max(vel_target, vel_min)
        if vel_max > 0.0:
            vel_target = min(vel_target, vel_max)
    accel_target = min(max((vel_target - vel) * k_v, accel_min), accel_max) + accel_desired
    if limit_total:
        accel_target = min(max(accel_target, accel_min), accel_max)
    return shape_accel(accel_target, accel, jerk_max, dt_s)


def shape_pos_vel_accel_xy(pos_desired, vel_desired, accel_desired, pos, vel, accel: list[float], vel_max: float,
                           accel_max: float, jerk_max: float, dt_s: float, limit_total: bool) -> None:  # fmt: skip
    k_v = jerk_max / accel_max
    ex, ey = pos_desired[0] - pos[0], pos_desired[1] - pos[1]
    n = math.hypot(ex, ey)
    cx = cy = 0.0
    if n > 0.0:
        proj = ((vel[0] - vel_desired[0]) * ex + (vel[1] - vel_desired[1]) * ey) / n
        length = sqrt_controller(n, k_v, accel_max, dt_s)
        length += sqrt_controller_accel(n, length, proj, k_v, accel_max) / k_v
        if vel_max > 0.0:
            length = min(max(length, -vel_max), vel_max)
        cx, cy = ex * length / n, ey * length / n
    tvx, tvy = vel_desired[0] + cx, vel_desired[1] + cy
    if limit_total and vel_max > 0.0:
        tvx, tvy = _limit_length(tvx, tvy, vel_max)
    ax, ay = limit_accel_corner_xy((vel[0], vel[1]), ((tvx - vel[0]) * k_v, (tvy - vel[1]) * k_v), accel_max)
    ax, ay = ax + accel_desired[0], ay + accel_desired[1]
    if limit_total:
        ax, ay = _limit_length(ax, ay, accel_max)
    shape_accel_xy((ax, ay), accel, jerk_max, dt_s)


def kinematic_limit(direction: tuple[float, float, float], max_ne: float, max_up: float, max_down: float) -> float:
    """The largest speed along ``direction`` (NED) within the horizontal, climb and descent limits."""
    n = math.sqrt(sum(c * c for c in direction))
    if n == 0.0 or max_ne == 0.0 or max_up == 0.0 or max_down == 0.0:
        return 0.0
    dn, de, dd = (c / n for c in direction)
    ne = math.hypot(dn, de)
    vz_max = max_down if dd > 0 else max_up
    if ne == 0.0:
        return vz_max
    if dd == 0.0:
        return max_ne
    if abs(dd / ne) < vz_max / max_ne:
        return max_ne / ne
    return abs(vz_max / dd)


# -- AC_PosControl's kinematic layer ---------------------------------------------------------------------
class PosControl:
    """The desired state that ArduCopter's position controller tracks, and the input shaping that moves it.

    ``p(name)`` reads a parameter. Call ``init_ne``/``init_d`` when a mode starts its controller (as
    ``NE_init_controller``/``D_init_controller``), set the limits, then one ``input_*`` per axis per step.
    """

    def __init__(self, p: Callable[[str], float]):
        self.p = p
        self.pos_ned = [0.0, 0.0, 0.0]
        self.vel_ned = [0.0, 0.0, 0.0]
        self.acc_ned = [0.0, 0.0, 0.0]
        self.vel_max_ne_mps = 10.0
        self.accel_max_ne_mps2 = 2.5
        self.jerk_max_ne_mps3 = 5.0
        self.vel_max_up_mps = 2.5
        self.vel_max_down_mps = 1.5
        self.accel_max_d_mps2 = 1.0
        self.jerk_max_d_mps3 = 5.0

    # limits
    def set_ne_limits(self, speed_mps: float, accel_mps2: float) -> None:
        """``NE_set_max_speed_accel_m``: jerk is PSC_JERK_NE (the attitude limits of the reference, ATC_ACC_*_MAX
        1100 deg/s², would allow 10.8 m/s³: they do not bind)."""
        self.vel_max_ne_mps = abs(speed_mps)
        self.accel_max_ne_mps2 = max(abs(accel_mps2), 1e-3)
        snap = math.radians(min(self.p("ATC_ACC_R_MAX"), self.p("ATC_ACC_P_MAX"))) * G_MPS2
        jerk = self.p("PSC_JERK_NE")
        if snap > 0.0:
            jerk = min(jerk, 0.5 * math.sqrt(self.accel_max_ne_mps2 * snap))
        self.jerk_max_ne_mps3 = max(jerk, 1e-3)

    def set_d_limits(self, down_mps: float, up_mps: float, accel_mps2: float) -> None:
        """``D_set_max_speed_accel_m``: jerk is PSC_JERK_D, capped so the acceleration PID's filters
        (PSC_D_ACC_FLTT, _FLTE 20 Hz) can follow it: min(g, accel)·2π·f/5."""
        if down_mps:
            self.vel_max_down_mps = abs(down_mps)
        if up_mps:
            self.vel_max_up_mps = abs(up_mps)
        if accel_mps2:
            self.accel_max_d_mps2 = abs(accel_mps2)
        jerk = self.p("PSC_JERK_D")
        for name in ("PSC_D_ACC_FLTT", "PSC_D_ACC_FLTE"):
            hz = self.p(name)
            if hz > 0.0:
                jerk = min(jerk, min(G_MPS2, self.accel_max_d_mps2) * 2.0 * math.pi * hz / 5.0)
        self.jerk_max_d_mps3 = max(jerk, 1e-3)

    def overspeed_gain(self) -> float:
        vd = self.vel_ned[2]
        if vd > self.vel_max_down_mps > 0.0:
            return OVERSPEED_GAIN_U * vd / self.vel_max_down_mps
        if vd < -self.vel_max_up_mps < 0.0:
            return -OVERSPEED_GAIN_U * vd / self.vel_max_up_mps
        return 1.0

    # initialisation (desired := estimate)
    def init_ne(self, pos_ned, vel_ned) -> None:
        """``NE_init_controller``: desired position and velocity are the estimate's, desired acceleration zero."""
        self.pos_ned[0], self.pos_ned[1] = pos_ned[0], pos_ned[1]
        self.vel_ned[0], self.vel_ned[1] = vel_ned[0], vel_ned[1]
        self.acc_ned[0] = self.acc_ned[1] = 0.0

    def init_d(self, pos_d_m: float, vel_d_mps: float, accel_d_mps2: float) -> None:
        """``D_init_controller``: the estimate, with the measured acceleration within the limit."""
        self.pos_ned[2] = pos_d_m
        self.vel_ned[2] = vel_d_mps
        self.acc_ned[2] = min(max(accel_d_mps2, -self.accel_max_d_mps2), self.accel_max_d_mps2)

    def stopping_point_ne(self, pos_ned, vel_ned) -> tuple[float, float]:
        speed = math.hypot(vel_ned[0], vel_ned[1])
        if speed <= 0.0:
            return pos_ned[0], pos_ned[1]
        dist = inv_sqrt_controller(min(speed, self.vel_max_ne_mps), self.p("PSC_NE_POS_P"), self.accel_max_ne_mps2)
        return pos_ned[0] + vel_ned[0] * dist / speed, pos_ned[1] + vel_ned[1] * dist / speed

    def stopping_point_d(self, pos_d_m: float, vel_d_mps: float) -> float:
        dist = inv_sqrt_controller(vel_d_mps, self.p("PSC_D_POS_P"), self.accel_max_d_mps2)
        return pos_d_m + min(max(dist, -STOPPING_DIST_UP_MAX_M), STOPPING_DIST_DOWN_MAX_M)

    # propagation of the desired state (update_pos_vel_accel with the limit vector at zero: the fake's
    # motors saturate rarely, and ArduCopter only freezes the desired state while they do)
    def _advance_ne(self, dt_s: float) -> None:
        for i in (0, 1):
            self.pos_ned[i] += self.vel_ned[i] * dt_s + 0.5 * self.acc_ned[i] * dt_s * dt_s
            self.vel_ned[i] += self.acc_ned[i] * dt_s

    def _advance_d(self, dt_s: float) -> None:
        self.pos_ned[2] += self.vel_ned[2] * dt_s + 0.5 * self.acc_ned[2] * dt_s * dt_s
        self.vel_ned[2] += self.acc_ned[2] * dt_s

    # inputs (each returns the input propagated by dt, as ArduCopter writes it back into GUIDED's target)
    def input_pos_vel_accel_ne(self, pos_ne, vel_ne, acc_ne, dt_s: float, limit_output: bool = False):
        self._advance_ne(dt_s)
        acc = [self.acc_ned[0], self.acc_ned[1]]
        shape_pos_vel_accel_xy(pos_ne, vel_ne, acc_ne, self.pos_ned[:2], self.vel_ned[:2], acc, self.vel_max_ne_mps,
                               self.accel_max_ne_mps2, self.jerk_max_ne_mps3, dt_s, limit_output)  # fmt: skip
        self.acc_ned[0], self.acc_ned[1] = acc
        pos = [pos_ne[i] + vel_ne[i] * dt_s + 0.5 * acc_ne[i] * dt_s * dt_s for i in (0, 1)]
        vel = [vel_ne[i] + acc_ne[i] * dt_s for i in (0, 1)]
        return pos, vel

    def input_pos_vel_accel_d(self, pos_d: float, vel_d: float, acc_d: float, dt_s: float,
                              limit_output: bool = False) -> tuple[float, float]:  # fmt: skip
        gain = self.overspeed_gain()
        accel_max = self.accel_max_d_mps2 * gain
        self._advance_d(dt_s)
        self.acc_ned[2] = shape_pos_vel_accel(
            pos_d, vel_d, acc_d, self.pos_ned[2], self.vel_ned[2], self.acc_ned[2], -self.vel_max_up_mps,
            self.vel_max_down_mps, -accel_max, min(max(accel_max, 0.0), ACCEL_D_MAX_MPS2),
            self.jerk_max_d_mps3 * gain, dt_s, limit_output,
        )  # fmt: skip
        return pos_d + vel_d * dt_s + 0.5 * acc_d * dt_s * dt_s, vel_d + acc_d * dt_s

    def input_vel_accel_ne(self, vel_ne, acc_ne, dt_s: float, limit_output: bool = False) -> list[float]:
        self._advance_ne(dt_s)
        acc = [self.acc_ned[0], self.acc_ned[1]]
        shape_vel_accel_xy(vel_ne, acc_ne, self.vel_ned[:2], acc, self.accel_max_ne_mps2, self.jerk_max_ne_mps3, dt_s,
                           limit_output)  # fmt: skip
        self.acc_ned[0], self.acc_ned[1] = acc
        return [vel_ne[i] + acc_ne[i] * dt_s for i in (0, 1)]

    def input_vel_accel_d(self, vel_d: float, acc_d: float, dt_s: float, limit_output: bool = False) -> float:
        gain = self.overspeed_gain()
        accel_max = self.accel_max_d_mps2 * gain
        self._advance_d(dt_s)
        self.acc_ned[2] = shape_vel_accel(vel_d, acc_d, self.vel_ned[2], self.acc_ned[2], -accel_max,
                                          min(max(accel_max, 0.0), ACCEL_D_MAX_MPS2), self.jerk_max_d_mps3 * gain,
                                          dt_s, limit_output)  # fmt: skip
        return vel_d + acc_d * dt_s

    def input_accel_ne(self, acc_ne, dt_s: float) -> None:
        self._advance_ne(dt_s)
        acc = [self.acc_ned[0], self.acc_ned[1]]
        shape_accel_xy((acc_ne[0], acc_ne[1]), acc, self.jerk_max_ne_mps3, dt_s)
        self.acc_ned[0], self.acc_ned[1] = acc

    def input_accel_d(self, acc_d: float, dt_s: float) -> None:
        jerk = self.jerk_max_d_mps3 * self.overspeed_gain()
        self._advance_d(dt_s)
        self.acc_ned[2] = shape_accel(acc_d, self.acc_ned[2], jerk, dt_s)

    def input_pos_ned(self, pos_ned, dt_s: float) -> None:
        """A position-only target (GUIDED ``Pos`` submode, ``input_pos_NED_m``): the speed along the way to
        it is limited by WP_SPD / WP_SPD_UP / WP_SPD_DN."""
        gain = self.overspeed_gain()
        accel_d = self.accel_max_d_mps2 * gain
        self._advance_ne(dt_s)
        self._advance_d(dt_s)
        travel = [pos_ned[i] - self.pos_ned[i] for i in range(3)]
        n = math.sqrt(sum(c * c for c in travel))
        vmax_ne = vmax_d = 0.0
        if n > 0.0:
            vmax = kinematic_limit(tuple(travel), self.vel_max_ne_mps, self.vel_max_up_mps, self.vel_max_down_mps)
            vmax_ne = vmax * math.hypot(travel[0], travel[1]) / n
            vmax_d = abs(vmax * travel[2] / n)
        acc = [self.acc_ned[0], self.acc_ned[1]]
        shape_pos_vel_accel_xy(pos_ned[:2], (0.0, 0.0), (0.0, 0.0), self.pos_ned[:2], self.vel_ned[:2], acc, vmax_ne,
                               self.accel_max_ne_mps2, self.jerk_max_ne_mps3, dt_s, False)  # fmt: skip
        self.acc_ned[0], self.acc_ned[1] = acc
        self.acc_ned[2] = shape_pos_vel_accel(pos_ned[2], 0.0, 0.0, self.pos_ned[2], self.vel_ned[2], self.acc_ned[2],
                                              -vmax_d, vmax_d, -accel_d, min(accel_d, ACCEL_D_MAX_MPS2),
                                              self.jerk_max_d_mps3 * gain, dt_s, False)  # fmt: skip

    def target(self, yaw_rad: float = NAN, yaw_rate_radps: float = NAN, ne: bool = True) -> Target:
        """What the cascade tracks; ``ne`` False leaves the horizontal axes to attitude only (ALT_HOLD)."""
        if ne:
            return Target(pos=list(self.pos_ned), vel=list(self.vel_ned), acc=list(self.acc_ned), yaw_rad=yaw_rad,
                          yaw_rate_radps=yaw_rate_radps)  # fmt: skip
        return Target(pos=[NAN, NAN, self.pos_ned[2]], vel=[NAN, NAN, self.vel_ned[2]], acc=[0.0, 0.0, self.acc_ned[2]],
                      yaw_rad=yaw_rad, yaw_rate_radps=yaw_rate_radps)  # fmt: skip


class VerticalAccelPid:
    """The end of ArduCopter's vertical loop (``AC_PosControl::D_update_controller``): throttle = hover +
    P·e + I·∫e, e the upward acceleration asked (velocity loop plus feed-forward) less the one measured
    (the IMU's, low-passed at INS_ACCEL_FILTER), filtered at PSC_D_ACC_FLTE; the integrator is frozen
    while the throttle is at a limit and clipped at PSC_D_ACC_IMAX.

    Its P (0.05 of throttle per m/s² by default, where a 0.39 hover throttle gives 25 m/s² per unit)
    reaches only about half of a step in the target at once; the integrator brings the rest within a few
    tenths of a second, behind the motors' 2 Hz throttle filter. That is why ArduCopter SITL's descent
    follows GUIDED's shaped velocity 0.2 s late and peaks where that velocity peaked (bench/RESULTS.md,
    "This change: the vertical ramps its acceleration at the jerk; the fake's vertical loop is ArduCopter's")."""

    def __init__(self, p: Callable[[str], float]):
        self.p = p
        self.integrator = 0.0  # of throttle
        self._meas_up_mps2 = 0.0
        self._err_mps2 = 0.0

    def reset(self, integrator: float = 0.0) -> None:
        """``D_init_controller``: the integrator takes over the throttle flown now less the hover's."""
        self.integrator = integrator
        self._err_mps2 = 0.0

    def throttle(self, target_up_mps2: float, measured_up_mps2: float, hover: float, limited: bool,
                 dt_s: float) -> float:  # fmt: skip
        self._meas_up_mps2 += lowpass_alpha(self.p("INS_ACCEL_FILTER"), dt_s) * (measured_up_mps2 - self._meas_up_mps2)
        err = target_up_mps2 - self._meas_up_mps2
        self._err_mps2 += lowpass_alpha(self.p("PSC_D_ACC_FLTE"), dt_s) * (err - self._err_mps2)
        if not limited:
            imax = self.p("PSC_D_ACC_IMAX")
            self.integrator = min(max(self.integrator + self.p("PSC_D_ACC_I") * self._err_mps2 * dt_s, -imax), imax)
        return hover + self.p("PSC_D_ACC_P") * self._err_mps2 + self.integrator


def copter_limits(p: Callable[[str], float], profile: VehicleProfile) -> Limits:
    """The fake's cascade with ArduCopter's gains: PSC_* for the position and velocity loops, ATC_* for
    attitude and rates, ATC_ANGLE_MAX (or PSC_ANGLE_MAX) for the tilt, MOT_THST_HOVER for the hover thrust."""
    tilt_deg = p("PSC_ANGLE_MAX") if p("PSC_ANGLE_MAX") > 0 else p("ATC_ANGLE_MAX")
    rate_max = tuple(math.radians(r) for r in profile.max_rate_dps)
    yaw_weight = 0.5  # heading after the thrust vector (input_thrust_vector_heading); gain below keeps ATC_ANG_YAW_P
    return Limits(
        vel_xy_max_mps=profile.max_speed_mps,
        vel_up_max_mps=profile.max_climb_mps,
        vel_dn_max_mps=VEL_DOWN_UNCAPPED_MPS,
        tilt_max_rad=math.radians(min(tilt_deg, profile.max_tilt_deg)),
        xy_p=p("PSC_NE_POS_P"),
        z_p=p("PSC_D_POS_P"),
        xy_vel_p=p("PSC_NE_VEL_P"),
        xy_vel_i=p("PSC_NE_VEL_I"),
        xy_vel_d=p("PSC_NE_VEL_D"),
        z_vel_p=p("PSC_D_VEL_P"),
        z_vel_i=p("PSC_D_VEL_I"),  # the trim is the acceleration PID's (VerticalAccelPid)
        z_vel_d=p("PSC_D_VEL_D"),
        z_vel_err_lp_hz=p("PSC_D_VEL_FLTE"),
        veld_lp_hz=5.0,  # PSC_NE_VEL_FLTD
        thr_hover=min(max(p("MOT_THST_HOVER"), 0.05), 0.95),
        thr_min=THR_MIN,
        thr_max=1.0,
        thr_xy_marg=HORIZONTAL_MARGIN,
        acc_decouple=True,  # accel_NE_mss_to_lean_angles_rad: tilt from the horizontal acceleration against g
        roll_p=p("ATC_ANG_RLL_P"),
        pitch_p=p("ATC_ANG_PIT_P"),
        yaw_p=p("ATC_ANG_YAW_P") * yaw_weight,
        yaw_weight=yaw_weight,
        rate_p=(p("ATC_RAT_RLL_P"), p("ATC_RAT_PIT_P"), p("ATC_RAT_YAW_P")),
        rate_i=(p("ATC_RAT_RLL_I"), p("ATC_RAT_PIT_I"), p("ATC_RAT_YAW_I")),
        rate_d=(p("ATC_RAT_RLL_D"), p("ATC_RAT_PIT_D"), p("ATC_RAT_YAW_D")),
        rate_k=(1.0, 1.0, 1.0),
        rate_int_lim=(0.5, 0.5, 0.5),  # ATC_RAT_*_IMAX
        rate_max_radps=rate_max,  # type: ignore[arg-type]  # ATC_RATE_*_MAX 0: only the vehicle limits
    )


__all__ = [
    "PosControl",
    "VerticalAccelPid",
    "copter_limits",
    "finite",
    "kinematic_limit",
    "shape_pos_vel_accel",
    "sqrt_controller",
]
