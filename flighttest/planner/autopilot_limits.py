"""The autopilot's setpoint-shaping limits as the planners plan against them.

ArduCopter's GUIDED mode shapes what it is sent with its position controller's limits (vertical and
horizontal acceleration, descent and climb speed; ``VehicleProfile.autopilot``, a profile's
``[autopilot]`` table). A plan that asks for more is flown late and then overshoots, into the guard on
a descent that rides its bound, and the preflight (``ardupilot_param_checks``) refuses it. Every planner
that plans for a profile with such a table keeps ``AUTOPILOT_LIMIT_FRACTION`` of each limit: the
preflight compares the plan's largest value with the parameter (``≥``), and the helix's between-node
path and the 100 Hz file may pass a bound that holds at the mesh's nodes by a little.

PX4's table is of another kind: its offboard control shapes nothing but clips the vertical velocity
setpoint to ``MPC_Z_VEL_MAX_DN``/``UP``. It bounds the planner's optimum (the yardstick flies no faster
than the vehicle can) and not the flown plans: their configs keep below PX4's defaults, and a plan asked
to go faster is refused by the preflight naming the parameter, not flown slower than asked.
"""

from __future__ import annotations

from dataclasses import dataclass

from flighttest.errors import FlighttestError
from flighttest.model.profiles import VehicleProfile

AUTOPILOT_LIMIT_FRACTION = 0.9


@dataclass(frozen=True)
class PlanLimits:
    """What a plan may ask of the autopilot (None: unlimited): accelerations in m/s², speeds in m/s."""

    accel_z_max_mps2: float | None = None
    accel_h_max_mps2: float | None = None
    descent_max_mps: float | None = None
    climb_max_mps: float | None = None
    jerk_h_max_mps3: float | None = None  # m/s³: bounds the tilt rate (a_h ≈ g tan θ: jerk ≈ g θ̇)
    jerk_z_max_mps3: float | None = None  # m/s³: bounds the collective thrust's rate

    def summary(self) -> dict[str, float | None]:
        return {"autopilot_accel_z_max_mps2": self.accel_z_max_mps2,
                "autopilot_accel_h_max_mps2": self.accel_h_max_mps2,
                "autopilot_descent_max_mps": self.descent_max_mps,
                "autopilot_climb_max_mps": self.climb_max_mps,
                "autopilot_jerk_h_max_mps3": self.jerk_h_max_mps3,
                "autopilot_jerk_z_max_mps3": self.jerk_z_max_mps3}  # fmt: skip


NO_LIMITS = PlanLimits()


def plan_limits(profile: VehicleProfile, fraction: float = AUTOPILOT_LIMIT_FRACTION) -> PlanLimits:
    """``fraction`` of each limit the profile's autopilot shapes setpoints with; ``NO_LIMITS`` for a
    profile without an ``[autopilot]`` table, and for PX4's below the full limits (module docstring)."""
    if not 0 < fraction <= 1:
        raise FlighttestError(f"autopilot limit fraction must lie in (0, 1] (got {fraction!r})")
    ap = profile.autopilot
    if ap is None or (ap.name == "PX4" and fraction < 1.0):  # a flown plan: PX4 clips, the preflight checks
        return NO_LIMITS

    def derated(v: float | None) -> float | None:
        return None if v is None else fraction * v

    return PlanLimits(accel_z_max_mps2=derated(ap.accel_z_max_mps2), accel_h_max_mps2=derated(ap.accel_h_max_mps2),
                      descent_max_mps=derated(ap.descent_max_mps), climb_max_mps=derated(ap.climb_max_mps),
                      jerk_h_max_mps3=derated(ap.jerk_h_max_mps3),
                      jerk_z_max_mps3=derated(ap.jerk_z_max_mps3))  # fmt: skip


def capped(value: float, cap: float | None) -> float:
    """``value``, or ``cap`` where that is lower (None: no cap)."""
    return value if cap is None else min(value, cap)
