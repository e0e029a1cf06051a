"""Probe reference: a one-sided chirp in altitude that slowly raises the descent speed.

The paper's reference ``Z_des = Z0 + A·sin(ω0·t²)`` oscillates *about* Z0, so half of every cycle is
a climb above the start and the descent speed at each zero crossing is ``2·A·ω0·t``. We use the
one-sided form (NED, down positive, relative to the start)

    d(t) = r(t) · A/2 · (1 − cos(ω0·t²)),     r(t) = smoothstep(t / t_ramp)

which goes down by at most A and comes back up to the start on every cycle, so the vehicle never
climbs above its start point and the depth budget is exactly A (the altitude floor sets it). Its
frequency still grows linearly (``ω0·t²`` has rate ``2ω0·t``) and the peak descent speed of each
cycle grows with time (``≈ A·ω0·t``). The ramp ``r`` starts the motion at zero velocity and
acceleration. Once a cycle's peak would pass the speed cap (or its acceleration the vehicle's), the
frequency stops growing: the sweep reaches the cap instead of stopping a whole cycle short of it
(with few, deep cycles that gap is large: a probe capped at 1.5 m/s could end at 1.1 m/s and never
see an onset at 1.2 m/s), and flies ``hold_cycles`` more cycles at that top speed. The reference ends
at the end of a whole cycle (back at the start point, at rest), and before ``duration``.

Output includes, for each descent speed on a grid, the time it is first reached (sidecar key
``speed_first_reached``), so the analysis can relate the onset of fluctuations to a speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flighttest.errors import FlighttestError
from flighttest.model.trajectory import SAMPLE_MIN_GAP_FRACTION


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
               max_accel_down_mps2: float = math.inf, max_accel_up_mps2: float = math.inf,
               hold_cycles: int = 2) -> ProbePlan:  # fmt: skip
    """The probe reference sampled at ``rate_hz``; ω0 in rad/s² (phase ``ω0·t²``).

    Its frequency stops growing where the peak speed reaches the cap or the acceleration the
    vehicle's (``max_accel_*``, positive numbers: as the frequency grows, the acceleration grows
    faster than the speed); ``hold_cycles`` whole cycles are flown at that frequency.
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
    # a ramp shorter than a sample divides by its square into infinite accelerations
    if ramp_s < 1.0 / rate_hz:
        raise FlighttestError(f"probe: ramp {ramp_s:.3g} s is shorter than one sample ({1.0 / rate_hz:g} s)")
    if duration_s <= ramp_s:
        raise FlighttestError(f"probe: duration {duration_s:.3g} s must be longer than the ramp ({ramp_s:g} s)")
    # the chirp's phase ω0·t² must reach one cycle within the duration; a slower ω0 puts the phase's
    # saturation ~1/ω0 seconds out, where its square overflows
    if omega0_rps2 * duration_s * duration_s < 2 * math.pi:
        raise FlighttestError(
            f"probe: omega0 {omega0_rps2:.3g} rad/s² does not sweep one cycle in {duration_s:g} s (the phase ω0·t² "
            f"must reach 2π: omega0 ≥ {2 * math.pi / (duration_s * duration_s):.3g} rad/s² for this duration)"
        )
    if int(hold_cycles) != hold_cycles or hold_cycles < 0:
        raise FlighttestError(f"probe: hold cycles must be a whole number ≥ 0 (got {hold_cycles!r})")
    t = np.arange(0.0, duration_s + 0.5 / rate_hz, 1.0 / rate_hz)
    # the frequency φ' = A·v/2 at which a cycle peaks at the cap (steady: v = A/2·φ'·sin φ,
    # a = A/2·φ'²·cos φ), a little below so the chirp's own φ'' keeps it inside; then checked
    a_lim = min(max_accel_down_mps2, max_accel_up_mps2)
    rate_sat = 0.98 * min(2.0 * max_descent_mps / amplitude_m, math.sqrt(2.0 * a_lim / amplitude_m))
    for _ in range(50):
        d, v, a = _profile(t, amplitude_m, omega0_rps2, ramp_s, rate_sat)
        over = np.flatnonzero((v > max_descent_mps) | (a > max_accel_down_mps2) | (-a > max_accel_up_mps2))
        if not len(over) or t[over[0]] >= ramp_s + 2 * math.pi / rate_sat:
            break
        rate_sat *= 0.98  # the ramp's own acceleration: slow the saturated sweep until it fits
    t_limit = t[over[0]] if len(over) else duration_s
    t_sat = rate_sat / (2 * omega0_rps2)  # the frequency stops growing here
    k_sat = math.ceil(_phase(t_sat, omega0_rps2, rate_sat) / (2 * math.pi) - 1e-9)
    # whole cycles end where the phase is 2πk (back at the start with zero velocity after the ramp)
    k = min(math.floor(_phase(t_limit, omega0_rps2, rate_sat) / (2 * math.pi) + 1e-12), k_sat + int(hold_cycles))
    t_end = _phase_time(2 * math.pi * k, omega0_rps2, rate_sat) if k > 0 else 0.0
    if k < 1 or t_end < ramp_s:
        raise FlighttestError(
            "probe: not one whole cycle after the ramp fits within the speed cap, the acceleration limits "
            "and the duration (raise --duration or --max-descent-speed, or lower --omega0 / --ramp)"
        )
    # no grid time within a hundredth of a period of the end: the file would print the two as one time
    t = np.union1d(t[t < t_end - SAMPLE_MIN_GAP_FRACTION / rate_hz], [t_end])
    d, v, a = _profile(t, amplitude_m, omega0_rps2, ramp_s, rate_sat)
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
        "hold_cycles": int(hold_cycles),
        "saturated_rate_rps": rate_sat,
        "saturated_from_s": min(t_sat, float(t_end)),
        "max_accel_down_mps2": max_accel_down_mps2 if math.isfinite(max_accel_down_mps2) else None,
        "max_accel_up_mps2": max_accel_up_mps2 if math.isfinite(max_accel_up_mps2) else None,
        "formula": (
            "d = smoothstep(t/ramp) * A/2 * (1 - cos(phi)), phi' = min(2 omega0 t, saturated_rate) "
            "(NED down, one-sided)"
        ),
    }
    return ProbePlan(t, d, v, a, float(t_end), k, top, firsts, problem)


def _phase(t, om0: float, rate_sat: float):
    """``φ(t)``: ``ω0·t²`` until its rate ``2ω0·t`` reaches ``rate_sat``, then linear."""
    t_sat = rate_sat / (2 * om0)
    return np.where(t < t_sat, om0 * np.square(t), om0 * t_sat * t_sat + rate_sat * (t - t_sat))


def _phase_time(phase: float, om0: float, rate_sat: float) -> float:
    t_sat = rate_sat / (2 * om0)
    if phase <= om0 * t_sat * t_sat:
        return math.sqrt(phase / om0)
    return t_sat + (phase - om0 * t_sat * t_sat) / rate_sat


def _profile(t: np.ndarray, amp: float, om0: float, ramp: float, rate_sat: float = math.inf):
    """``d, ḋ, d̈`` of the ramped one-sided chirp (analytic derivatives)."""
    s = np.clip(t / ramp, 0.0, 1.0)
    inside = (t < ramp).astype(float)
    r = 3 * s**2 - 2 * s**3
    r1 = inside * 6 * s * (1 - s) / ramp
    r2 = inside * (6 - 12 * s) / ramp**2
    chirping = 2 * om0 * t < rate_sat
    ph = _phase(t, om0, rate_sat) if math.isfinite(rate_sat) else om0 * t**2
    ph1 = np.where(chirping, 2 * om0 * t, rate_sat)
    ph2 = np.where(chirping, 2 * om0, 0.0)
    g = 0.5 * amp * (1 - np.cos(ph))
    g1 = 0.5 * amp * ph1 * np.sin(ph)
    g2 = 0.5 * amp * (ph2 * np.sin(ph) + ph1**2 * np.cos(ph))
    return r * g, r1 * g + r * g1, r2 * g + 2 * r1 * g1 + r * g2
