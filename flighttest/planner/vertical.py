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
accelerations at its vertical acceleration and the cruise at its descent speed, each derated to
``autopilot_limits.AUTOPILOT_LIMIT_FRACTION``: a step the autopilot ramps more slowly than planned
is flown late and overshoots into the guard.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flighttest.errors import FlighttestError
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import sample_times
from flighttest.planner.autopilot_limits import capped, plan_limits


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
                  rate_hz: float = 100.0) -> VerticalPlan:  # fmt: skip
    """Closed-form profile sampled at ``rate_hz`` (plus the exact switching times), within the
    autopilot's limits when the profile names them (``autopilot_limits.plan_limits``)."""
    if not (math.isfinite(height_m) and height_m > 0):
        raise FlighttestError(f"vertical plan: height must be a positive number (got {height_m!r})")
    if not 0 < accel_fraction <= 1:
        raise FlighttestError(f"vertical plan: accel fraction must lie in (0, 1] (got {accel_fraction})")
    w_allow = profile.w_allow_mps if w_allow_mps is None else w_allow_mps
    margin = profile.vrs.margin_mps if margin_mps is None else margin_mps
    limits = plan_limits(profile)
    cruise = w_allow - margin + wind_d_mps
    cruise = capped(min(cruise, profile.max_speed_mps), limits.descent_max_mps)
    if not cruise > 0:
        raise FlighttestError(
            f"vertical plan: no descent is allowed (w_allow {w_allow:.3g} − margin {margin:.3g} + wind_d "
            f"{wind_d_mps:.3g} ≤ 0 m/s)"
        )
    a_dn = capped(accel_fraction * profile.max_accel_down_mps2, limits.accel_z_max_mps2)
    a_up = capped(accel_fraction * profile.max_accel_up_mps2, limits.accel_z_max_mps2)
    # Distance to reach cruise and to stop from it.
    d_acc = cruise**2 / (2 * a_dn)
    d_dec = cruise**2 / (2 * a_up)
    if d_acc + d_dec > height_m:  # triangular: peak speed below cruise
        cruise = math.sqrt(2 * height_m / (1 / a_dn + 1 / a_up))
        d_acc = cruise**2 / (2 * a_dn)
        d_dec = cruise**2 / (2 * a_up)
    t1 = cruise / a_dn
    t2 = t1 + (height_m - d_acc - d_dec) / cruise
    t_f = t2 + cruise / a_up
    t = sample_times(t_f, rate_hz, (t1, t2))
    v = np.where(t < t1, a_dn * t, np.where(t < t2, cruise, cruise - a_up * (t - t2)))
    v = np.clip(v, 0.0, cruise)
    d = np.where(
        t < t1,
        0.5 * a_dn * t**2,
        np.where(t < t2, d_acc + cruise * (t - t1), height_m - 0.5 * a_up * np.maximum(t_f - t, 0.0) ** 2),
    )
    a = np.where(t < t1, a_dn, np.where(t < t2, 0.0, -a_up))
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
        **limits.summary(),
    }
    return VerticalPlan(t, d, v, a, cruise, a_dn, a_up, float(t_f), problem)
