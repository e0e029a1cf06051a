"""Probe reference: a one-sided chirp in altitude that slowly raises the descent speed.

The paper's reference ``Z_des = Z0 + A·sin(ω0·t²)`` oscillates *about* Z0, so half of every cycle is
a climb above the start and the descent speed at each zero crossing is ``2·A·ω0·t``. We use the
one-sided form (NED, down positive, relative to the start)

    d(t) = r(t) · A/2 · (1 − cos(ω0·t²)),     r(t) = smoothstep(t / t_ramp)

which goes down by at most A and comes back up to the start on every cycle, so the vehicle never
climbs above its start point and the depth budget is exactly A (the altitude floor sets it). Its
frequency still grows linearly (``ω0·t²`` has rate ``2ω0·t``) and the peak descent speed of each
cycle grows with time (``≈ A·ω0·t``). The ramp ``r`` starts the motion at zero velocity and
acceleration. The reference ends at the end of the last whole cycle (back at the start point, at
rest) whose descent speed stays below the cap, or before ``duration``.

Output includes, for each descent speed on a grid, the time it is first reached (sidecar key
``speed_first_reached``), so the analysis can relate the onset of fluctuations to a speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flighttest.errors import FlighttestError


@dataclass(frozen=True)
class ProbePlan:
    t_s: np.ndarray
    d_m: np.ndarray
    vd_mps: np.ndarray
    ad_mps2: np.ndarray
    t_f_s: float
    cycles: int
    max_descent_mps: float
    speed_first_reached: list[dict]
    problem: dict


def plan_probe(amplitude_m: float = 2.0, omega0_rps2: float = 0.05, ramp_s: float = 3.0,
               max_descent_mps: float = 3.0, duration_s: float = 60.0, start_alt_m: float = 10.0,
               floor_alt_m: float = 2.0, speed_step_mps: float = 0.1, rate_hz: float = 100.0,
               max_accel_down_mps2: float = math.inf, max_accel_up_mps2: float = math.inf) -> ProbePlan:  # fmt: skip
    """The probe reference sampled at ``rate_hz``; ω0 in rad/s² (phase ``ω0·t²``).

    It also ends before its acceleration exceeds the vehicle's (``max_accel_*``, positive numbers):
    as the frequency grows, the acceleration grows faster than the speed.
    """
    for name, v in (("amplitude", amplitude_m), ("omega0", omega0_rps2), ("ramp", ramp_s),
                    ("max descent speed", max_descent_mps), ("duration", duration_s),
                    ("speed step", speed_step_mps), ("rate", rate_hz)):  # fmt: skip
        if not (math.isfinite(v) and v > 0):
            raise FlighttestError(f"probe: {name} must be a positive number (got {v!r})")
    if not (math.isfinite(start_alt_m) and math.isfinite(floor_alt_m) and floor_alt_m >= 0):
        raise FlighttestError("probe: start and floor altitudes must be finite, floor ≥ 0")
    room = start_alt_m - floor_alt_m
    if amplitude_m > room + 1e-9:
        raise FlighttestError(
            f"probe: amplitude {amplitude_m:g} m would go below the altitude floor ({floor_alt_m:g} m; start at "
            f"{start_alt_m:g} m leaves {room:g} m)"
        )
    t = np.arange(0.0, duration_s + 0.5 / rate_hz, 1.0 / rate_hz)
    d, v, a = _profile(t, amplitude_m, omega0_rps2, ramp_s)
    over = np.flatnonzero((v > max_descent_mps) | (a > max_accel_down_mps2) | (-a > max_accel_up_mps2))
    t_limit = t[over[0]] if len(over) else duration_s
    # Whole cycles end where ω0·t² = 2πk (back at the start with zero velocity once the ramp is done).
    k = math.floor(omega0_rps2 * t_limit**2 / (2 * math.pi) + 1e-12)
    t_end = math.sqrt(2 * math.pi * k / omega0_rps2) if k > 0 else 0.0
    if k < 1 or t_end < ramp_s:
        raise FlighttestError(
            "probe: not one whole cycle after the ramp fits within the speed cap, the acceleration limits "
            "and the duration (raise --duration or --max-descent-speed, or lower --omega0 / --ramp)"
        )
    t = np.union1d(t[t < t_end], [t_end])
    d, v, a = _profile(t, amplitude_m, omega0_rps2, ramp_s)
    d[-1] = v[-1] = 0.0
    firsts = []
    top = float(v.max())
    for s in np.arange(speed_step_mps, top + 1e-9, speed_step_mps):
        i = int(np.argmax(v >= s - 1e-12))
        firsts.append({"speed_mps": round(float(s), 6), "t_s": float(t[i])})
    problem = {
        "amplitude_m": amplitude_m,
        "omega0_rps2": omega0_rps2,
        "ramp_s": ramp_s,
        "max_descent_mps": max_descent_mps,
        "duration_s": duration_s,
        "start_alt_m": start_alt_m,
        "floor_alt_m": floor_alt_m,
        "speed_step_mps": speed_step_mps,
        "max_accel_down_mps2": max_accel_down_mps2 if math.isfinite(max_accel_down_mps2) else None,
        "max_accel_up_mps2": max_accel_up_mps2 if math.isfinite(max_accel_up_mps2) else None,
        "formula": "d = smoothstep(t/ramp) * A/2 * (1 - cos(omega0 t^2)) (NED down, one-sided)",
    }
    return ProbePlan(t, d, v, a, float(t_end), k, top, firsts, problem)


def _profile(t: np.ndarray, amp: float, om0: float, ramp: float):
    """``d, ḋ, d̈`` of the ramped one-sided chirp (analytic derivatives)."""
    s = np.clip(t / ramp, 0.0, 1.0)
    inside = (t < ramp).astype(float)
    r = 3 * s**2 - 2 * s**3
    r1 = inside * 6 * s * (1 - s) / ramp
    r2 = inside * (6 - 12 * s) / ramp**2
    ph = om0 * t**2
    g = 0.5 * amp * (1 - np.cos(ph))
    g1 = amp * om0 * t * np.sin(ph)
    g2 = amp * om0 * (np.sin(ph) + 2 * ph * np.cos(ph))
    return r * g, r1 * g + r * g1, r2 * g + 2 * r1 * g1 + r * g2
