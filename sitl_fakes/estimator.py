"""An estimate that is not the truth, as PX4's EKF2 on SIH: a height offset and a slow horizontal wander.

In the reference flights (``../shared/px4_sih``) PX4's height is 0.3–0.7 m off the simulator's truth in
flight and a "vertical" descent wanders 0.3–0.8 m sideways. PX4 flies its estimate, so the fake's
controller does too and its telemetry reports it; the truth log keeps the truth.

Measured on those flights (estimate − SIH's ground truth, in the air): velocity errors of 0.09–0.15
m/s (vertical) and 0.12–0.29 m/s (horizontal) standard deviation, correlated over about 1.5 s
(vertical) and 3.5 s (horizontal). The vertical figures below are those of 30 flights of our own on
PX4 SITL, larger and slower (median 0.15 m/s over 2.8 s): enough for the EKF to trail a slow descent
(bench/RESULTS.md, "This change: the catch-up limit, the helix's thrust-rate bound, settling on the
position's rate."). Position offsets: 0.3–0.7 m in height, 0.1–0.2 m horizontally, drifting over tens
of seconds.

Each error is a seeded Ornstein–Uhlenbeck process; the position offset is a slow one (smoothed by a
first-order lag) plus the velocity error integrated with a leak (GPS pulls the EKF back within
seconds), so holding its estimated position the vehicle really drifts — and, as on PX4, a vehicle
that follows its estimate down a slow descent falls behind the plan. On the ground the velocity
error is zero (PX4 fuses zero velocity when landed).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, replace

from sitl_fakes.physics import RigidBodyState


@dataclass(frozen=True)
class EstimateError:
    horizontal_sigma_m: float = 0.15
    horizontal_tau_s: float = 15.0
    height_sigma_m: float = 0.4
    height_tau_s: float = 20.0
    smoothing_s: float = 2.0  # the lag that keeps the position offsets' rate small
    horizontal_vel_sigma_mps: float = 0.2
    horizontal_vel_tau_s: float = 3.5
    vertical_vel_sigma_mps: float = 0.16
    vertical_vel_tau_s: float = 3.0
    position_leak_s: float = 3.0  # how fast GPS pulls the integrated velocity error back
    # PX4's velocity error is smooth at short time scales (0.006-0.02 m/s of std faster than 1 s):
    # the Ornstein–Uhlenbeck process goes through this lag, so its steps are not white
    velocity_smoothing_s: float = 0.3

    def scaled(self, k: float) -> EstimateError:
        return replace(
            self,
            horizontal_sigma_m=k * self.horizontal_sigma_m,
            height_sigma_m=k * self.height_sigma_m,
            horizontal_vel_sigma_mps=k * self.horizontal_vel_sigma_mps,
            vertical_vel_sigma_mps=k * self.vertical_vel_sigma_mps,
        )


class Estimator:
    def __init__(self, error: EstimateError, seed: int) -> None:
        self.error = error
        self._rng = random.Random(seed * 7919 + 17)
        e = error
        self._sigma = (e.horizontal_sigma_m, e.horizontal_sigma_m, e.height_sigma_m)
        self._tau = (e.horizontal_tau_s, e.horizontal_tau_s, e.height_tau_s)
        # start somewhere on the process's own distribution: PX4 boots with an offset already
        self._target = [self._rng.gauss(0.0, s) for s in self._sigma]
        self.offset_m = list(self._target)
        self._vel_sigma = (e.horizontal_vel_sigma_mps, e.horizontal_vel_sigma_mps, e.vertical_vel_sigma_mps)
        self._vel_tau = (e.horizontal_vel_tau_s, e.horizontal_vel_tau_s, e.vertical_vel_tau_s)
        self.vel_error_mps = [0.0, 0.0, 0.0]
        self._vel_ou = [0.0, 0.0, 0.0]
        self._integrated_m = [0.0, 0.0, 0.0]

    def _ou(self, x: float, sigma: float, tau: float, dt_s: float) -> float:
        if sigma <= 0.0:
            return 0.0
        return x - x * dt_s / tau + sigma * math.sqrt(2.0 * dt_s / tau) * self._rng.gauss(0.0, 1.0)

    def step(self, dt_s: float) -> None:
        for i in range(3):
            self._target[i] = self._ou(self._target[i], self._sigma[i], self._tau[i], dt_s)
            self.offset_m[i] += (self._target[i] - self.offset_m[i]) * dt_s / self.error.smoothing_s
            self._vel_ou[i] = self._ou(self._vel_ou[i], self._vel_sigma[i], self._vel_tau[i], dt_s)
            self.vel_error_mps[i] += (self._vel_ou[i] - self.vel_error_mps[i]) * dt_s / self.error.velocity_smoothing_s
            leak = self._integrated_m[i] / self.error.position_leak_s
            self._integrated_m[i] += (self.vel_error_mps[i] - leak) * dt_s

    def estimate(self, truth: RigidBodyState) -> RigidBodyState:
        """The state PX4 would report: truth plus the offsets (attitude and rates as measured)."""
        o = [a + b for a, b in zip(self.offset_m, self._integrated_m)]
        r = self.vel_error_mps
        return replace(
            truth,
            n_m=truth.n_m + o[0],
            e_m=truth.e_m + o[1],
            d_m=truth.d_m + o[2],
            vn_mps=truth.vn_mps + (r[0] if not truth.on_ground else 0.0),
            ve_mps=truth.ve_mps + (r[1] if not truth.on_ground else 0.0),
            vd_mps=truth.vd_mps + (r[2] if not truth.on_ground else 0.0),
            thrust_n=truth.thrust_n,
        )
