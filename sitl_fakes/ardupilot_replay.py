"""Fly GUIDED setpoints through the ArduCopter personality in-process, faster than real time.

The same vehicle code as the UDP fake (``FakeArduCopter``: the setpoint handler, ``AC_PosControl``'s shaping,
the cascade with ArduCopter's gains, the physics), without a link or a clock: setpoints go in as
SET_POSITION_TARGET_LOCAL_NED messages at their times, the vehicle hovers in GUIDED from the start. The
disturbance model is off (ArduCopter SITL has none) and the estimate is the truth unless an
``EstimateError`` is given. Used by ``tests/test_fake_ardupilot.py`` to compare the fake's GUIDED response
with the reference DataFlash logs (``../shared/ardupilot_sitl``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from flighttest.model.profiles import VehicleProfile
from sitl_fakes.ardupilot import CopterMode
from sitl_fakes.ardupilot_vehicle import FakeArduCopter
from sitl_fakes.disturbance import VrsTruth
from sitl_fakes.estimator import EstimateError
from sitl_fakes.fast import PHYSICS_DT_S, FastCopter, Silent, advance
from sitl_fakes.link import mavlink
from sitl_fakes.truthlog import TruthLog
from sitl_fakes.vehicle import FakeConfig

GUIDED_POSVELACCEL = 3  # ModeGuided::SubMode numbers, as the DataFlash GUIP records log them
GUIDED_VELACCEL = 4
# SET_POSITION_TARGET_LOCAL_NED type masks of MAVSDK's set_position_velocity_acceleration_ned and
# set_velocity_ned (yaw given, yaw rate ignored)
MASK_POSVELACCEL = 1 << 11
MASK_VELACCEL = 0b111 | (0b111 << 6) | (1 << 11)


@dataclass(frozen=True)
class GuidedSetpoints:
    """Setpoints as received (NED, absolute): times in s from the replay's start; ``kind`` 3 pos+vel+acc, 4 vel."""

    t_s: np.ndarray
    kind: np.ndarray
    pos_ned: np.ndarray
    vel_ned: np.ndarray
    acc_ned: np.ndarray


@dataclass(frozen=True)
class GuidedResponse:
    t_s: np.ndarray
    pos_ned: np.ndarray  # truth
    vel_ned: np.ndarray  # truth
    est_vel_ned: np.ndarray  # the estimate ArduCopter would report (PSC*.V*)
    desired_pos_ned: np.ndarray  # AC_PosControl's desired state (PSC*.DP*, DV*, DA*)
    desired_vel_ned: np.ndarray
    desired_acc_ned: np.ndarray

    def at(self, t_s: float) -> int:
        return int(min(np.searchsorted(self.t_s, t_s), self.t_s.size - 1))


def copter(profile: VehicleProfile, params: Mapping[str, float] | None = None,
           estimate_error: EstimateError | None = None, seed: int = 0) -> FakeArduCopter:  # fmt: skip
    """An in-process ArduCopter-personality vehicle on the ground at home, EKF ready, on a clock that
    ``advance`` moves (messages go in with ``vehicle.handle(msg, ("test", 0))``; nothing is sent anywhere)."""
    error = estimate_error if estimate_error is not None else EstimateError().scaled(0.0)
    cfg = FakeConfig(profile=profile, truth=VrsTruth(1.0, 20.0, 0.0, seed, profile.v_h_mps), seed=seed,
                     estimate_error=error, telemetry_gap_rate_hz=0.0)  # fmt: skip
    v = FastCopter(cfg, Silent(), TruthLog(None, 0.0), 0.0, ekf_delay_s=0.0)  # type: ignore[arg-type]
    for name, value in (params or {}).items():
        v.params[name].value = value
    return v


def hovering(v: FakeArduCopter, pos_ned: tuple[float, float, float]) -> FakeArduCopter:
    """Put ``v`` armed and airborne at ``pos_ned``, at hover thrust, in GUIDED."""
    s = v.body.state
    s.n_m, s.e_m, s.d_m = pos_ned
    s.on_ground = False
    s.thrust_n = [v.p("MOT_THST_HOVER") * v.profile.max_thrust_per_rotor_n] * 4
    v.collective_filtered = v.p("MOT_THST_HOVER")
    v.est = v.estimator.estimate(s)
    v.armed = True
    v.arm_time = v.now
    v.land_complete = False
    v.ever_flown_since_arm = True
    v.ekf_ready = True
    v.set_mode(CopterMode.GUIDED, "test")
    return v


def replay_guided(
    profile: VehicleProfile,
    setpoints: GuidedSetpoints,
    start_pos_ned: tuple[float, float, float],
    duration_s: float,
    params: Mapping[str, float] | None = None,
    settle_s: float = 3.0,
    estimate_error: EstimateError | None = None,
    seed: int = 0,
    dt_s: float = PHYSICS_DT_S,
) -> GuidedResponse:
    """Hover at ``start_pos_ned`` in GUIDED for ``settle_s`` (holding it with 50 Hz setpoints, as flighttest
    does before a descent), then fly ``setpoints`` for ``duration_s``; times in the response are from the
    end of the settling."""
    v = hovering(copter(profile, params, estimate_error, seed), start_pos_ned)
    s = v.body.state
    hold = mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, MASK_POSVELACCEL, *start_pos_ned, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    addr = ("replay", 0)
    n_settle = math.ceil(settle_s / dt_s)
    n = math.ceil(duration_s / dt_s)
    out = {k: np.empty((n, 3)) for k in ("p", "v", "ev", "dp", "dv", "da")}
    out_t = np.empty(n)
    k = -1
    for i in range(n_settle + n):
        now = i * dt_s
        if i < n_settle:
            if i % 5 == 0:  # 50 Hz
                v.now = now
                v.handle(hold, addr)
        else:
            t = now - n_settle * dt_s
            while k + 1 < setpoints.t_s.size and setpoints.t_s[k + 1] <= t:
                k += 1
                v.now = now
                v.handle(_message(setpoints, k), addr)
        v.step(dt_s, now)
        if i >= n_settle:
            j = i - n_settle
            out_t[j] = (j + 1) * dt_s
            out["p"][j] = (s.n_m, s.e_m, s.d_m)
            out["v"][j] = (s.vn_mps, s.ve_mps, s.vd_mps)
            e = v.est
            out["ev"][j] = (e.vn_mps, e.ve_mps, e.vd_mps)
            out["dp"][j] = v.pc.pos_ned
            out["dv"][j] = v.pc.vel_ned
            out["da"][j] = v.pc.acc_ned
    return GuidedResponse(out_t, out["p"], out["v"], out["ev"], out["dp"], out["dv"], out["da"])


def _message(sp: GuidedSetpoints, k: int):
    pos, vel, acc = (tuple(float(x) for x in a[k]) for a in (sp.pos_ned, sp.vel_ned, sp.acc_ned))
    mask = MASK_VELACCEL if int(sp.kind[k]) == GUIDED_VELACCEL else MASK_POSVELACCEL
    return mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, mask, *pos, *vel, *acc, 0.0, 0.0)


__all__ = ["GuidedResponse", "GuidedSetpoints", "advance", "copter", "hovering", "replay_guided"]
