"""An estimate that is not the truth, as PX4's EKF2 on SIH: a height offset and a slow horizontal wander.

PX4 flies its estimate, so the fake's controller does too and its telemetry reports it; the truth log
keeps the truth. How far off EKF2 is depends on the firmware (estimate − SIH's ground truth in the
``.ulg``, in the air; bench/RESULTS.md, "The fake's EKF2 on today's PX4"):

- PX4 main ``0d4ae424`` (2026-08; ``../shared/wind_sitl`` and our own builds, eight flights): velocity
  errors of 0.013–0.036 m/s (horizontal) and 0.008–0.022 m/s (vertical) standard deviation,
  decorrelating in 1–3 s; position within 0.01–0.08 m. The defaults of ``EstimateError``.
- PX4 main ``02e73e3b`` (2026-03; ``../shared/px4_sih`` and 30 flights of our own): about ten times
  further off — horizontal velocity 0.12–0.29 m/s, vertical 0.09–0.22 m/s (median 0.15 over 2.8 s),
  height 0.3–0.7 m, a "vertical" descent wandering 0.3–0.8 m sideways: enough for the EKF to trail a slow
  descent (bench/RESULTS.md, "This change: the catch-up limit, the helix's thrust-rate bound, settling on
  the position's rate"). ``PX4_SIH_2026_03``; the fake's ``--estimate-error 8`` comes close.

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
    """Standard deviations and correlation times of the estimate's errors (defaults: PX4 main 0d4ae424)."""

    horizontal_sigma_m: float = 0.02
    horizontal_tau_s: float = 3.0
    height_sigma_m: float = 0.04
    height_tau_s: float = 3.0
    smoothing_s: float = 0.5  # the lag that keeps the position offsets' rate small
    horizontal_vel_sigma_mps: float = 0.022
    horizontal_vel_tau_s: float = 2.0
    vertical_vel_sigma_mps: float = 0.015
    vertical_vel_tau_s: float = 2.0
    position_leak_s: float = 3.0  # how fast GPS pulls the integrated velocity error back
    # PX4's velocity error is smooth at short time scales (0.006-0.02 m/s of std faster than 1 s on
    # 02e73e3b): the Ornstein–Uhlenbeck process goes through this lag, so its steps are not white
    velocity_smoothing_s: float = 0.3

    def scaled(self, k: float) -> EstimateError:
        return replace(
            self,
            horizontal_sigma_m=k * self.horizontal_sigma_m,
            height_sigma_m=k * self.height_sigma_m,
            horizontal_vel_sigma_mps=k * self.horizontal_vel_sigma_mps,
            vertical_vel_sigma_mps=k * self.vertical_vel_sigma_mps,
        )


# PX4 main 02e73e3b (2026-03), the firmware of ../shared/px4_sih: what the tests replaying those flights use
PX4_SIH_2026_03 = EstimateError(
    horizontal_sigma_m=0.15, horizontal_tau_s=15.0, height_sigma_m=0.4, height_tau_s=20.0, smoothing_s=2.0,
    horizontal_vel_sigma_mps=0.2, horizontal_vel_tau_s=3.5, vertical_vel_sigma_mps=0.16, vertical_vel_tau_s=3.0,
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
