"""When a hover counts as settled (flighttest.flying.settling), in virtual time."""

from __future__ import annotations

import numpy as np

from flighttest.flying.settling import SettleCheck


def _run(check: SettleCheck, pos, vel, seconds: float = 3.0, rate_hz: float = 50.0) -> list[bool]:
    return [check.update(t, pos(t), vel(t)) for t in np.arange(0.0, seconds, 1.0 / rate_hz)]


def test_settles_near_the_point_at_rest():
    out = _run(SettleCheck((0, 0, -7), 0.6, 0.25), lambda t: (0.1, 0.0, -6.8), lambda t: (0.0, 0.0, 0.05))
    assert all(out)


def test_a_biased_velocity_with_a_still_position_settles_after_one_window():
    # PX4 SITL: EKF2's vertical velocity −0.25..−0.3 m/s for 10 s while its height held
    check = SettleCheck((0, 0, -7), 0.6, 0.25, window_s=1.0)
    out = _run(check, lambda t: (0.0, 0.0, -6.75), lambda t: (0.0, 0.0, -0.3))
    first = out.index(True)
    assert 0.85 <= first / 50.0 <= 1.0 and all(out[first:])


def test_a_vehicle_really_moving_does_not_settle():
    # within the tolerance but drifting at 0.3 m/s (position and velocity agree): not settled
    out = _run(SettleCheck((0, 0, -7), 0.6, 0.25), lambda t: (-0.45 + 0.3 * t, 0.0, -7.0),
               lambda t: (0.3, 0.0, 0.0), seconds=3.0)  # fmt: skip
    assert not any(out)


def test_far_from_the_point_never_settles():
    out = _run(SettleCheck((0, 0, -7), 0.6, 0.25), lambda t: (0.0, 0.0, -6.2), lambda t: (0.0, 0.0, 0.0))
    assert not any(out)
