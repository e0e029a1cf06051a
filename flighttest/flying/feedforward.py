"""The acceleration feed-forward an autopilot needs to fly a plan as planned.

A plan gives position, velocity and the *net* acceleration of the vehicle. PX4's position controller
(``PositionControl``, the firmware of ``../shared/px4_sih``; reproduced in ``sitl_fakes.control``)
does apply the acceleration flighttest sends as feed-forward, but turns it into a thrust vector its
own way, and its attitude follows that vector late. Three corrections make the vehicle fly the plan's
thrust vector when the plan needs it (measured on PX4 SITL and on the fake calibrated against it:
``bench/RESULTS.md``, "Flying the plan PX4 flies: helix and vertical on PX4 SITL and on the fake (issue 11)"):

1. **Lead** (``lead_s``): PX4 has no tilt feed-forward; its tilt trails a new thrust direction by
   ``1/MC_ROLL_P`` (0.25 s on SIH) plus the rate loop and motors. The *horizontal* acceleration sent
   at ``t`` is the plan's at ``t + lead_s``, so the tilt arrives when the plan needs it. Not the
   vertical one: collective thrust follows within the motors' 50 ms, and a led plunge sinks faster
   than planned while the tilt still lags. Position and velocity are not led (the position loop would
   pull ahead).
2. **Drag** (``drag_per_s``): PX4 assumes thrust and gravity are all that act; a vehicle with linear
   drag (SIH: ``SIH_KDV`` N per m/s) needs ``drag/m · v_air`` more. Without it the velocity loop
   makes up the loss late, at the helix's speeds by tenths of a m/s.
3. **Decoupling** (``decoupled``, PX4's ``MPC_ACC_DECOUPLE`` = 1, its default): PX4 tilts for the
   horizontal acceleration *against gravity alone* and sets the vertical thrust separately, so in a
   plunge (vertical acceleration ``a_d`` > 0) it tilts less than the plan — by ``(g − a_d)/g`` in
   tan(tilt). Scaling the horizontal feed-forward by ``g/(g − a_d)`` makes PX4's tilt the plan's.

And one bound on the position setpoint while streaming: the catch-up limit (``limit_catch_up_down``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from flighttest.model.aero import G_MPS2
from flighttest.model.trajectory import Trajectory

# the fraction of g below which the vertical thrust would vanish: no tilt can be matched there
MIN_SPECIFIC_THRUST_MPS2 = 0.1 * G_MPS2


@dataclass(frozen=True)
class Feedforward:
    lead_s: float = 0.2
    drag_per_s: float = 0.0  # linear drag / mass
    decoupled: bool = True

    def describe(self) -> dict[str, float | bool]:
        return {"lead_s": self.lead_s, "drag_per_s": self.drag_per_s, "decoupled": self.decoupled}


def feedforward_accel_ned(
    t_s: np.ndarray, vel_ned: np.ndarray, acc_ned: np.ndarray, ff: Feedforward, wind_ned=(0.0, 0.0, 0.0)
) -> np.ndarray:
    """The acceleration to send at each row (n, 3) for a plan's velocity and net acceleration."""
    t = np.asarray(t_s, float)
    acc = np.asarray(acc_ned, float)
    v_air = np.asarray(vel_ned, float) - np.asarray(wind_ned, float)
    if ff.lead_s > 0 and t.size > 1:
        led = t + ff.lead_s
        acc = np.stack([np.interp(led, t, acc[:, 0], right=0.0), np.interp(led, t, acc[:, 1], right=0.0),
                        acc[:, 2]], axis=1)  # fmt: skip
        # the drag's share of the tilt trails as the rest does: led too (bench/RESULTS.md, "The climb looks
        # around": sih_quadx's drag-aware helix on the fake)
        end = v_air[-1]
        v_air = np.stack([np.interp(led, t, v_air[:, 0], right=end[0]), np.interp(led, t, v_air[:, 1], right=end[1]),
                          v_air[:, 2]], axis=1)  # fmt: skip
    acc = acc + ff.drag_per_s * v_air
    if ff.decoupled:
        scale = G_MPS2 / np.maximum(G_MPS2 - acc[:, 2], MIN_SPECIFIC_THRUST_MPS2)
        acc = acc * np.stack([scale, scale, np.ones_like(scale)], axis=1)
    return acc


# a plan whose horizontal path stays within this of its start flies over one point (the vertical, the probe)
STATIONARY_M = 0.5


def wind_share_ned(traj: Trajectory, wind_ned) -> tuple[float, float, float]:
    """The wind whose drag the feed-forward adds for ``traj``. Zero for a plan that stays over one point: the
    autopilot's velocity integrator already holds that drag from the hover before it, and sent again it
    doubles. In 3 m/s on PX4 SIH the vertical lurched 1.38 m upwind at its start with it, 0.48 m without,
    and the probe's fluctuation detector stopped its sweep 0.09 s in; without, it swept to the end. The helix
    keeps it: without, its plunge outran its tilt and the guard stopped it (bench/RESULTS.md, "The drag
    feed-forward counts the wind twice")."""
    df = traj.df
    reach = float(np.hypot(df["n_m"] - df["n_m"].iloc[0], df["e_m"] - df["e_m"].iloc[0]).max()) if len(df) else 0.0
    return (0.0, 0.0, 0.0) if reach <= STATIONARY_M else tuple(float(x) for x in wind_ned)


def hold_accel_ned(traj: Trajectory, ff: Feedforward, wind_ned=(0.0, 0.0, 0.0)) -> tuple[float, float, float]:
    """The acceleration a hold at the end of ``traj`` is sent with: the drag of the wind the stream's feed-forward
    carried (``wind_share_ned``), at rest. The autopilot's velocity integrator does not hold that drag after a
    stream that sent it, so a hold without it drifts downwind: on PX4 SITL in 3 m/s (SIH) 1.7 m, and it took
    7 s to come back within 0.5 m (bench/RESULTS.md, "The hold after a helix in wind")."""
    acc = feedforward_accel_ned(np.zeros(1), np.zeros((1, 3)), np.zeros((1, 3)), ff, wind_share_ned(traj, wind_ned))
    return float(acc[0, 0]), float(acc[0, 1]), 0.0


def for_autopilot(traj: Trajectory, ff: Feedforward, wind_ned=(0.0, 0.0, 0.0)) -> Trajectory:
    """``traj`` with its acceleration columns replaced by what the autopilot should be sent, in the wind
    ``wind_ned`` (its drag's share: ``wind_share_ned``)."""
    df = traj.df.copy()
    acc = feedforward_accel_ned(
        df["t_s"].to_numpy(float),
        df[["vn_mps", "ve_mps", "vd_mps"]].to_numpy(float),
        df[["an_mps2", "ae_mps2", "ad_mps2"]].to_numpy(float),
        ff,
        wind_share_ned(traj, wind_ned),
    )
    df["an_mps2"], df["ae_mps2"], df["ad_mps2"] = acc[:, 0], acc[:, 1], acc[:, 2]
    return Trajectory(df, dict(traj.meta))


# the autopilot's vertical position gain (velocity per metre of position error), by autopilot, newest name
# first: ArduPilot master (2026, ../shared/ardupilot_sitl) calls it PSC_D_POS_P, 4.x PSC_POSZ_P
Z_POSITION_GAIN_PARAMS = {"PX4": ("MPC_Z_P",), "ArduPilot": ("PSC_D_POS_P", "PSC_POSZ_P")}
DEFAULT_Z_POSITION_GAIN_PER_S = 1.0  # both autopilots' default


def z_position_gain_per_s(params: dict | None, autopilot: str | None) -> float:
    """The vertical position gain the autopilot uses, from its parameters (else both defaults' 1/s)."""
    names = Z_POSITION_GAIN_PARAMS.get(autopilot or "", ("MPC_Z_P",))
    name = next((n for n in names if n in (params or {})), names[0])
    try:
        gain = float((params or {})[name])
    except (KeyError, TypeError, ValueError):
        return DEFAULT_Z_POSITION_GAIN_PER_S
    return gain if math.isfinite(gain) and gain > 0 else DEFAULT_Z_POSITION_GAIN_PER_S


@dataclass(frozen=True)
class CatchUpLimit:
    """How far below the vehicle a down position setpoint may be sent (PX4 and ArduPilot both add
    their vertical position gain × the position error to the plan's descent rate).

    An EKF whose vertical velocity runs ahead of the truth falls behind a slow descent, and the
    autopilot turns that position error into a descent faster than planned, by the estimate the guard
    judges (PX4 SITL: bench/RESULTS.md, "This change: the catch-up limit, the helix's thrust-rate
    bound, settling on the position's rate."). So the commanded descent rate, plan plus catch-up, stays
    within ``max(plan + excess_mps, floor_mps)``: a little over the plan where it descends fast, and up
    to ``floor_mps`` (a rate far inside the cone at rest) where it holds or barely descends, so an end
    hold is still reached promptly. Climbing back to the plan is never limited.
    """

    excess_mps: float = 0.1
    floor_mps: float = 0.3
    gain_per_s: float = DEFAULT_Z_POSITION_GAIN_PER_S

    def limit(self, d_setpoint_m: float, d_estimate_m: float, vd_plan_mps: float) -> float:
        """The down position setpoint (NED, m) to send for the plan's ``d_setpoint_m``."""
        below_m = max(self.excess_mps, self.floor_mps - vd_plan_mps) / self.gain_per_s
        return min(d_setpoint_m, d_estimate_m + below_m)

    def describe(self) -> dict[str, float]:
        return {"catch_up_excess_mps": self.excess_mps, "catch_up_floor_mps": self.floor_mps,
                "z_position_gain_per_s": self.gain_per_s}  # fmt: skip
