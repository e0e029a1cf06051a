"""The drag-calibration flight: level out-and-back legs at a few speeds along north–south and east–west.

Each leg cruises at one ground speed for ``cruise_s`` between trapezoidal accelerations, from one end of a
line through the start point to the other and back: the same speed in opposite directions,
so a steady wind adds to one leg what it takes from the other and cancels in the identification
(``flighttest.analysis.drag``). Speeds run from slow to fast: a vehicle whose drag surprises shows it
at the slow legs first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flighttest.errors import FlighttestError
from flighttest.model.trajectory import Trajectory

AXES = {"north": (1.0, 0.0), "east": (0.0, 1.0)}


@dataclass(frozen=True)
class CalibrationPlan:
    speeds_mps: tuple[float, ...] = (1.0, 2.0, 3.0)
    cruise_s: float = 2.0  # at speed, each way
    accel_mps2: float = 1.5
    pause_s: float = 1.0  # hovering between legs: each leg starts from rest
    axes: tuple[str, ...] = ("north", "east")

    def validate(self, radius_m: float) -> None:
        if not self.speeds_mps or not all(math.isfinite(v) and 0.2 <= v <= 10.0 for v in self.speeds_mps):
            raise FlighttestError("drag calibration: speeds must be between 0.2 and 10 m/s")
        for name, v, lo, hi in (("cruise_s", self.cruise_s, 0.5, 30.0), ("accel_mps2", self.accel_mps2, 0.2, 5.0),
                                ("pause_s", self.pause_s, 0.0, 10.0)):  # fmt: skip
            if not (math.isfinite(v) and lo <= v <= hi):
                raise FlighttestError(f"drag calibration: {name} must be between {lo:g} and {hi:g}")
        if not self.axes or any(a not in AXES for a in self.axes):
            raise FlighttestError(f"drag calibration: axes must be among {', '.join(AXES)}")
        if self.reach_m > radius_m:
            raise FlighttestError(
                f"drag calibration: the fastest leg reaches {self.reach_m:.1f} m from the start, beyond the "
                f"geofence radius {radius_m:g} m (fewer speeds, a shorter cruise)"
            )

    def leg_m(self, v: float) -> float:
        """One leg's length: up to speed, cruise, down again."""
        return v * v / self.accel_mps2 + v * self.cruise_s

    @property
    def reach_m(self) -> float:
        """How far from the start the legs go: half of each leg on either side."""
        return max(self.leg_m(v) for v in self.speeds_mps) / 2.0


def _move(dist_m: float, v_max: float, a: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance, speed and acceleration along a straight move of ``dist_m`` from rest to rest (trapezoid)."""
    v = min(v_max, math.sqrt(a * dist_m))
    t_acc = v / a
    t_tot = 2 * t_acc + (dist_m - v * t_acc) / v
    t = np.arange(0.0, t_tot + 1e-9, dt)
    s = np.where(t < t_acc, 0.5 * a * t * t,
                 np.where(t < t_tot - t_acc, 0.5 * a * t_acc**2 + v * (t - t_acc),
                          dist_m - 0.5 * a * (t_tot - t) ** 2))  # fmt: skip
    sp = np.where(t < t_acc, a * t, np.where(t < t_tot - t_acc, v, a * (t_tot - t)))
    ac = np.where(t < t_acc, a, np.where(t < t_tot - t_acc, 0.0, -a))
    s[-1], sp[-1], ac[-1] = dist_m, 0.0, 0.0
    return s, sp, ac


def calibration_trajectory(plan: CalibrationPlan, vehicle: str, radius_m: float, dt_s: float = 0.02) -> Trajectory:
    """The calibration flight relative to its start point, at constant height, yaw north."""
    plan.validate(radius_m)
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("n", "e", "vn", "ve", "an", "ae")}
    pos = np.zeros(2)
    legs = []

    def hold(seconds: float) -> None:
        n = max(round(seconds / dt_s), 1)
        for k, v in (("n", pos[0]), ("e", pos[1])):
            cols[k].append(np.full(n, v))
        for k in ("vn", "ve", "an", "ae"):
            cols[k].append(np.zeros(n))

    def go(target: np.ndarray, v_max: float) -> None:
        nonlocal pos
        d = target - pos
        dist = float(np.hypot(*d))
        if dist < 1e-9:
            return
        u = d / dist
        s, sp, ac = _move(dist, v_max, plan.accel_mps2, dt_s)
        for k, arr in (("n", pos[0] + u[0] * s), ("e", pos[1] + u[1] * s), ("vn", u[0] * sp), ("ve", u[1] * sp),
                       ("an", u[0] * ac), ("ae", u[1] * ac)):  # fmt: skip
            cols[k].append(arr[1:])  # the first sample is where the last move ended
        pos = target.astype(float)

    hold(plan.pause_s)
    for v in plan.speeds_mps:
        half = plan.leg_m(v) / 2.0
        for axis in plan.axes:
            u = np.asarray(AXES[axis])
            for b in (-u * half, u * half, -u * half, u * 0.0):  # a full leg each way between the ends
                go(b, v)
                hold(plan.pause_s)
            legs.append({"axis": axis, "speed_mps": v, "half_length_m": half})
    n = np.concatenate(cols["n"])
    t = np.arange(len(n)) * dt_s
    zero = np.zeros_like(t)
    meta = {"kind": "calibration", "vehicle": vehicle, "status": "closed_form", "objective": "drag calibration",
            "problem": {"speeds_mps": list(plan.speeds_mps), "cruise_s": plan.cruise_s, "accel_mps2": plan.accel_mps2,
                        "pause_s": plan.pause_s, "axes": list(plan.axes), "reach_m": plan.reach_m},
            "legs": legs, "t_f_s": float(t[-1]), "solve_s": 0.0}  # fmt: skip
    return Trajectory.from_arrays(meta, t_s=t, n_m=n, e_m=np.concatenate(cols["e"]), d_m=zero,
                                  vn_mps=np.concatenate(cols["vn"]), ve_mps=np.concatenate(cols["ve"]), vd_mps=zero,
                                  an_mps2=np.concatenate(cols["an"]), ae_mps2=np.concatenate(cols["ae"]), ad_mps2=zero,
                                  yaw_deg=zero)  # fmt: skip
