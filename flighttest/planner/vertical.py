"""Vertical baseline: the fastest straight-down hover-to-hover descent that keeps ``w ≤ w_allow``.

Closed form (bang-cruise-bang in speed): accelerate down at ``a_down``, cruise at
``v_c = w_allow − margin``, brake at ``a_up``, where the accelerations are the vehicle's
(``profile.max_accel_down_mps2`` / ``max_accel_up_mps2``) times ``accel_fraction`` (default 0.8: the
rest is left to the position controller). Level flight with no wind means ``w = v_D`` (the body z
axis is the down axis), so the descent speed *is* the through-disk speed the guard checks; with a
vertical wind ``w = v_D − wind_D`` and the cruise speed is shifted by it. When the height is too
short to reach the cruise speed the profile is triangular. This is what the paper flew in 8.3 s for
5 m on the Mambo (against 2.5 s on the helix).

A profile whose autopilot shapes setpoints (its ``[autopilot]`` table: ArduCopter's GUIDED) caps both
accelerations at its vertical acceleration and the cruise at its descent speed, and ramps each
acceleration at its vertical jerk (an S-curve), all derated to ``autopilot_limits.AUTOPILOT_LIMIT_FRACTION``:
a step the autopilot ramps more slowly than planned is flown late and caught up by overshooting (on
ArduCopter SITL GUIDED's own desired descent ran to 0.55 m/s on a 0.3 m/s plan with stepped accelerations).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flighttest.errors import FlighttestError
from flighttest.inputs import MAX_DURATION_S
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import sample_times
from flighttest.planner.autopilot_limits import AUTOPILOT_LIMIT_FRACTION, capped, plan_limits


@dataclass(frozen=True)
class VerticalPlan:
    t_s: np.ndarray
    d_m: np.ndarray
    vd_mps: np.ndarray
    ad_mps2: np.ndarray
    cruise_mps: float
    a_down_mps2: float
    a_up_mps2: float
    t_f_s: float
    problem: dict


def plan_vertical(profile: VehicleProfile, height_m: float = 5.0, w_allow_mps: float | None = None,
                  margin_mps: float | None = None, accel_fraction: float = 0.8, wind_d_mps: float = 0.0,
                  rate_hz: float = 100.0, limit_fraction: float = AUTOPILOT_LIMIT_FRACTION,
                  jerk_mps3: float | None = None) -> VerticalPlan:  # fmt: skip
    """Closed-form profile sampled at ``rate_hz`` (plus the exact switching times), within
    ``limit_fraction`` of the autopilot's limits when the profile names them (``autopilot_limits.plan_limits``);
    the acceleration changes no faster than ``jerk_mps3`` (None: as fast as the autopilot's limit allows)."""
    if not (math.isfinite(height_m) and height_m > 0):
        raise FlighttestError(f"vertical plan: height must be a positive number (got {height_m!r})")
    if not 0 < accel_fraction <= 1:
        raise FlighttestError(f"vertical plan: accel fraction must lie in (0, 1] (got {accel_fraction})")
    w_allow = profile.w_allow_mps if w_allow_mps is None else w_allow_mps
    margin = profile.vrs.margin_mps if margin_mps is None else margin_mps
    limits = plan_limits(profile, limit_fraction)
    cruise = w_allow - margin + wind_d_mps
    cruise = capped(min(cruise, profile.max_speed_mps), limits.descent_max_mps)
    if not cruise > 0:
        raise FlighttestError(
            f"vertical plan: no descent is allowed (w_allow {w_allow:.3g} − margin {margin:.3g} + wind_d "
            f"{wind_d_mps:.3g} ≤ 0 m/s)"
        )
    a_dn = capped(accel_fraction * profile.max_accel_down_mps2, limits.accel_z_max_mps2)
    a_up = capped(accel_fraction * profile.max_accel_up_mps2, limits.accel_z_max_mps2)
    if jerk_mps3 is not None and not (math.isfinite(jerk_mps3) and jerk_mps3 > 0):
        raise FlighttestError(f"vertical plan: jerk must be a positive number (got {jerk_mps3!r})")
    jerk = min(limits.jerk_z_max_mps3 or math.inf, jerk_mps3 or math.inf)
    cruise_cap = cruise
    if _ramps(cruise, a_dn, a_up, jerk)[2] > height_m:  # too short to reach cruise: the fastest peak that fits
        lo, hi = 0.0, cruise
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _ramps(mid, a_dn, a_up, jerk)[2] <= height_m else (lo, mid)
        cruise = lo
    # a near-zero acceleration (fraction) or descent speed makes the descent last for ever: refused here,
    # before the bisection's peak rounds to 0 (a division by zero) or the sampling asks for terabytes
    given = (
        f"with a cruise of at most {cruise_cap:.3g} m/s and accelerations {a_dn:.3g} down / {a_up:.3g} up m/s²"
        + (f" changing at {jerk:.3g} m/s³" if math.isfinite(jerk) else "")
        + " (raise the accel fraction, the descent speed or the autopilot's limits in the profile)"
    )
    if not cruise > 0:
        raise FlighttestError(f"vertical plan: {height_m:g} m would take more than {MAX_DURATION_S:g} s {given}")
    down, up, d_ramps = _ramps(cruise, a_dn, a_up, jerk)
    t1 = down.duration_s
    t2 = t1 + (height_m - d_ramps) / cruise
    t_f = t2 + up.duration_s
    if not t_f <= MAX_DURATION_S:
        took = f"{t_f:.4g} s (at most {MAX_DURATION_S:g})"
        raise FlighttestError(f"vertical plan: {height_m:g} m would take {took} {given}")
    t = sample_times(t_f, rate_hz, (*down.breaks_s, t1, t2, *(t2 + b for b in up.breaks_s)))
    a_acc, v_acc, d_acc = down.at(np.minimum(t, t1))
    tau = np.clip(t - t2, 0.0, up.duration_s)  # time into the braking
    a_brk, v_brk, d_brk = up.at(tau)
    d_t2 = down.distance_m + cruise * (t2 - t1)
    v = np.where(t < t1, v_acc, np.where(t < t2, cruise, cruise - v_brk))
    d = np.where(t < t1, d_acc, np.where(t < t2, down.distance_m + cruise * (t - t1), d_t2 + cruise * tau - d_brk))
    a = np.where(t < t1, a_acc, np.where(t < t2, 0.0, -a_brk))
    v = np.clip(v, 0.0, cruise)
    a[-1] = 0.0
    v[-1], d[-1] = 0.0, height_m
    problem = {
        "height_m": height_m,
        "w_allow_mps": w_allow,
        "margin_mps": margin,
        "wind_d_mps": wind_d_mps,
        "accel_fraction": accel_fraction,
        "a_down_mps2": a_dn,
        "a_up_mps2": a_up,
        "cruise_mps": cruise,
        "jerk_z_mps3": jerk if math.isfinite(jerk) else None,
        **limits.summary(),
    }
    return VerticalPlan(t, d, v, a, cruise, a_dn, a_up, float(t_f), problem)


@dataclass(frozen=True)
class _SpeedRamp:
    """From rest to ``speed_mps`` with acceleration ≤ ``accel_mps2`` changing at ≤ ``jerk_mps3`` (inf: a
    step): the acceleration ramps up, holds, ramps down, symmetric about its middle."""

    speed_mps: float
    accel_mps2: float  # the peak reached (below the limit when the speed change is too small for it)
    jerk_mps3: float

    @property
    def ramp_s(self) -> float:
        return self.accel_mps2 / self.jerk_mps3 if math.isfinite(self.jerk_mps3) else 0.0

    @property
    def duration_s(self) -> float:
        # a jerk limit near zero leaves a peak acceleration of 0: never reached, not a division by zero
        return self.speed_mps / self.accel_mps2 + self.ramp_s if self.accel_mps2 > 0 else math.inf

    @property
    def distance_m(self) -> float:  # the speed is point-symmetric about the ramp's middle
        return 0.5 * self.speed_mps * self.duration_s

    @property
    def breaks_s(self) -> tuple[float, ...]:
        return (self.ramp_s, self.duration_s - self.ramp_s) if self.ramp_s > 0 else ()

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Acceleration, speed and distance at times ``t`` in [0, duration]."""
        j, a_pk, c, big_t, tj = self.jerk_mps3, self.accel_mps2, self.speed_mps, self.duration_s, self.ramp_s
        t = np.clip(t, 0.0, big_t)
        if tj == 0.0:
            return np.where(t < big_t, a_pk, 0.0), a_pk * t, 0.5 * a_pk * t**2
        rest = big_t - t
        v_tj = 0.5 * j * tj**2
        first, last = t < tj, t > big_t - tj
        acc = np.where(first, j * t, np.where(last, j * rest, a_pk))
        vel = np.where(first, 0.5 * j * t**2, np.where(last, c - 0.5 * j * rest**2, v_tj + a_pk * (t - tj)))
        dist = np.where(first, j * t**3 / 6.0,
                        np.where(last, c * t - 0.5 * c * big_t + j * rest**3 / 6.0,
                                 j * tj**3 / 6.0 + v_tj * (t - tj) + 0.5 * a_pk * (t - tj) ** 2))  # fmt: skip
        return acc, vel, dist


def _speed_ramp(speed_mps: float, accel_mps2: float, jerk_mps3: float) -> _SpeedRamp:
    if math.isfinite(jerk_mps3) and speed_mps < accel_mps2**2 / jerk_mps3:  # the acceleration never levels off
        accel_mps2 = math.sqrt(speed_mps * jerk_mps3)
    return _SpeedRamp(speed_mps, accel_mps2, jerk_mps3)


def _ramps(cruise_mps: float, a_dn: float, a_up: float, jerk: float) -> tuple[_SpeedRamp, _SpeedRamp, float]:
    """The speeding-up and the braking ramps of a cruise, and the height they take together."""
    down, up = _speed_ramp(cruise_mps, a_dn, jerk), _speed_ramp(cruise_mps, a_up, jerk)
    return down, up, down.distance_m + up.distance_m
