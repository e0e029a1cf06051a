"""Wind: a steady NED vector plus turbulence, Dryden-like.

The turbulence is a first-order Gauss-Markov process per axis in the mean wind's frame (along it, across it,
vertical): the Dryden model's longitudinal form (MIL-F-8785C) on all three axes, with its low-altitude
proportions:

- standard deviations: ``gust_mps`` along and across the wind (MIL-F-8785C's σ_u = σ_v below 1000 ft), half
  of it vertically (σ_w/σ_u = (0.177 + 0.000823 h)^0.4 = 0.51-0.53 between 2 and 15 m);
- correlation times L/V: length scales ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2`` and ``L_w = h`` (h in
  feet, taken as at least 2 m), carried past the vehicle at its airspeed V (Taylor's frozen turbulence: the
  steady wind less the vehicle's velocity, at least 1 m/s). Hovering 7 m up in 3 m/s of wind: 16 s along
  and across, 2.3 s vertically; 2 m up, 5 s and 0.7 s.
- ``gust_tau_s`` replaces the Dryden times by one correlation time for every axis (tests of the statistics).

The process starts from its stationary distribution: the turbulence is there from the first step. It has its
own random stream (the VRS fluctuation's noise does not shift with it). ArduCopter SITL's ``SIM_WIND_TURB``
is a speed low-passed by 0.98 per physics step (40 ms at its 1200 Hz) in a direction redrawn every step,
nearly white; PX4 SIH has no turbulence.
"""

from __future__ import annotations

import math
import random

FT_PER_M = 3.28084
VERTICAL_GUST_FRACTION = 0.5
MIN_HEIGHT_M = 2.0  # Dryden's scales vanish at the ground: below this, the 2 m ones
MIN_AIRSPEED_MPS = 1.0  # the speed the turbulence passes the vehicle at, at least
CALM_MPS = 0.1  # a steady wind slower than this has no direction: the turbulence frame is north/east


def dryden_length_scales_m(height_m: float) -> tuple[float, float]:
    """(L_u = L_v, L_w) in metres at this height (MIL-F-8785C low altitude)."""
    h_ft = max(height_m, MIN_HEIGHT_M) * FT_PER_M
    l_u_ft = h_ft / (0.177 + 0.000823 * h_ft) ** 1.2
    return l_u_ft / FT_PER_M, h_ft / FT_PER_M


class Wind:
    def __init__(self, steady_ned=(0.0, 0.0, 0.0), gust_mps: float = 0.0, seed: int = 0,
                 gust_tau_s: float | None = None):  # fmt: skip
        self.steady = tuple(float(x) for x in steady_ned)
        self.gust_mps = float(gust_mps)
        self.gust_tau_s = gust_tau_s
        self.rng = random.Random(seed + 7919)  # own stream: gusts do not shift the VRS noise
        horizontal = math.hypot(self.steady[0], self.steady[1])
        # unit vector along the mean wind (north when calm)
        calm = horizontal <= CALM_MPS
        self._along = (1.0, 0.0) if calm else (self.steady[0] / horizontal, self.steady[1] / horizontal)
        self.sd = (self.gust_mps, self.gust_mps, VERTICAL_GUST_FRACTION * self.gust_mps)
        # along, across, vertical: drawn from the stationary distribution
        self._g = [s * self.rng.gauss(0.0, 1.0) for s in self.sd] if self.gust_mps > 0.0 else [0.0, 0.0, 0.0]
        self.gust = [0.0, 0.0, 0.0]  # NED
        self.tau_s = (math.inf, math.inf, math.inf)  # the last step's correlation times (along, across, vertical)
        self._rotate()
        self.ned = [self.steady[i] + self.gust[i] for i in range(3)]

    def correlation_times_s(self, height_m: float, airspeed_mps: float) -> tuple[float, float, float]:
        if self.gust_tau_s is not None:
            return (self.gust_tau_s,) * 3
        l_u, l_w = dryden_length_scales_m(height_m)
        v = max(airspeed_mps, MIN_AIRSPEED_MPS)
        return l_u / v, l_u / v, l_w / v

    def _rotate(self) -> None:
        cn, ce = self._along
        along, across, vertical = self._g
        self.gust[0] = cn * along - ce * across
        self.gust[1] = ce * along + cn * across
        self.gust[2] = vertical

    def step(self, dt_s: float, height_m: float = 7.0, vel_ned=(0.0, 0.0, 0.0)) -> list[float]:
        """Advance by ``dt_s`` at the vehicle's height (m above home) and true velocity; the wind now (NED)."""
        if self.gust_mps > 0.0:
            airspeed = math.sqrt((vel_ned[0] - self.steady[0]) ** 2 + (vel_ned[1] - self.steady[1]) ** 2
                                 + (vel_ned[2] - self.steady[2]) ** 2)  # fmt: skip
            self.tau_s = self.correlation_times_s(height_m, airspeed)
            g = self._g
            gauss = self.rng.gauss
            for i in range(3):
                decay = math.exp(-dt_s / self.tau_s[i])
                g[i] = decay * g[i] + math.sqrt(1.0 - decay * decay) * self.sd[i] * gauss(0.0, 1.0)
            self._rotate()
        for i in range(3):
            self.ned[i] = self.steady[i] + self.gust[i]
        return self.ned
