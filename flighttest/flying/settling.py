"""When a hover counts as settled: near its point and slow, judged on the autopilot's estimate.

Slow means the estimated velocity *or* the estimated position's own rate over ``window_s`` is below
``speed_mps``. The position's rate is there because an EKF's velocity can be biased for seconds while
its position holds, and a hover judged on velocity alone then never settles (PX4 SITL: bench/RESULTS.md,
"This change: the catch-up limit, the helix's thrust-rate bound, settling on the position's rate.").
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass, field

Vec3 = tuple[float, float, float]


@dataclass
class SettleCheck:
    target_ned: Vec3
    tol_m: float
    speed_mps: float
    window_s: float = 1.0
    _track: collections.deque[tuple[float, Vec3]] = field(default_factory=collections.deque, repr=False)

    def update(self, t_s: float, pos_ned: Vec3, vel_ned: Vec3) -> bool:
        """One estimate sample (monotonic s, local NED): True when it is near and slow."""
        track = self._track
        track.append((t_s, pos_ned))
        while t_s - track[0][0] > self.window_s:
            track.popleft()
        speed = math.hypot(*vel_ned)
        span = t_s - track[0][0]
        if span >= 0.9 * self.window_s:  # a full window: the position's own rate counts too
            speed = min(speed, math.dist(pos_ned, track[0][1]) / span)
        return math.dist(pos_ned, self.target_ned) <= self.tol_m and speed <= self.speed_mps
