"""Wind: a steady NED vector plus gusts as a first-order Gauss-Markov process per axis.

``gust_mps`` is the standard deviation of the horizontal gust components; the vertical one gets half
of it. Correlation time 2 s: gusts that a position controller feels, not turbulence it filters out.
"""

from __future__ import annotations

import math
import random

GUST_CORRELATION_TIME_S = 2.0
VERTICAL_GUST_FRACTION = 0.5


class Wind:
    def __init__(self, steady_ned=(0.0, 0.0, 0.0), gust_mps: float = 0.0, seed: int = 0):
        self.steady = tuple(float(x) for x in steady_ned)
        self.gust_mps = float(gust_mps)
        self.rng = random.Random(seed + 7919)  # own stream: gusts do not shift the VRS noise
        self.gust = [0.0, 0.0, 0.0]
        self.ned = list(self.steady)

    def step(self, dt_s: float) -> list[float]:
        if self.gust_mps > 0.0:
            decay = math.exp(-dt_s / GUST_CORRELATION_TIME_S)
            kick = math.sqrt(1.0 - decay * decay)
            for i, scale in enumerate((1.0, 1.0, VERTICAL_GUST_FRACTION)):
                self.gust[i] = decay * self.gust[i] + kick * scale * self.gust_mps * self.rng.gauss(0.0, 1.0)
        for i in range(3):
            self.ned[i] = self.steady[i] + self.gust[i]
        return self.ned
