"""Fly setpoints through the fake's PX4 cascade and physics in-process, faster than real time.

No link, no modes: the vehicle is in offboard from the first step and holds each setpoint until the
next one arrives (what PX4 does with a 50 Hz ``trajectory_setpoint`` stream). Used to calibrate the
fake against PX4's reference flights (``tests/test_px4_calibration.py``: the same setpoints, the same
start, the response compared) and to check a plan against the autopilot's response before flying it.
The disturbance model is off (PX4's SIH has none); the estimate is the truth unless an
``EstimateError`` is given (then PX4's controller flies the estimate, and ``Response.est_vel_ned`` is what
its telemetry would report).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from flighttest.model.aero import G_MPS2
from flighttest.model.profiles import VehicleProfile
from sitl_fakes import px4
from sitl_fakes.control import NAN, Controller, Limits, Target
from sitl_fakes.estimator import EstimateError, Estimator
from sitl_fakes.physics import QuadBody, RigidBodyState

PHYSICS_DT_S = 0.004


@dataclass(frozen=True)
class SetpointStream:
    """Setpoints as sent (NED, absolute): times in s from the replay's start; NaN = not controlled."""

    t_s: np.ndarray  # (n,)
    pos_ned: np.ndarray  # (n, 3)
    vel_ned: np.ndarray  # (n, 3)
    acc_ned: np.ndarray  # (n, 3)
    yaw_rad: np.ndarray  # (n,)


@dataclass(frozen=True)
class Response:
    """The vehicle's true state at each physics step (arrays over time)."""

    t_s: np.ndarray
    pos_ned: np.ndarray
    vel_ned: np.ndarray
    quat: np.ndarray  # (n, 4) w, x, y, z body → NED
    motors: np.ndarray  # (n, 4) commands 0..1
    est_vel_ned: np.ndarray  # (n, 3) the estimate's velocity (= vel_ned without an estimate error)
    est_pos_ned: np.ndarray  # (n, 3) the estimate's position

    @property
    def tilt_deg(self) -> np.ndarray:
        q = self.quat
        return np.degrees(np.arccos(np.clip(1.0 - 2.0 * (q[:, 1] ** 2 + q[:, 2] ** 2), -1.0, 1.0)))

    def at(self, t_s: float) -> int:
        return int(min(np.searchsorted(self.t_s, t_s), self.t_s.size - 1))


def px4_params(overrides: Mapping[str, float] | None = None, profile: VehicleProfile | None = None) -> dict:
    """The fake's PX4 parameter values (defaults, the vehicle's hover thrust, then ``overrides``)."""
    values = {name: float(p.value) for name, p in px4.default_params().items()}
    if profile is not None:
        values["MPC_THR_HOVER"] = profile.mass_kg * G_MPS2 / (profile.n_rotors * profile.max_thrust_per_rotor_n)
    values.update(overrides or {})
    return values


def replay(
    profile: VehicleProfile,
    stream: SetpointStream,
    start: RigidBodyState,
    duration_s: float,
    params: Mapping[str, float] | None = None,
    dt_s: float = PHYSICS_DT_S,
    estimate_error: EstimateError | None = None,
    seed: int = 0,
    catch_up_down: Callable[[int, float, float], float] | None = None,
) -> Response:
    """Fly ``stream`` from ``start`` (airborne, in offboard) for ``duration_s``.

    ``catch_up_down(k, d_setpoint_m, d_estimate_m)``: the down position setpoint actually sent for row
    ``k`` (flighttest's streamer limits how far below the vehicle it may be)."""
    values = px4_params(params, profile)
    lim = Limits.from_params(values.__getitem__, profile)
    body = QuadBody(profile)
    body.state = RigidBodyState(**{k: getattr(start, k) for k in RigidBodyState.__dataclass_fields__})
    body.state.on_ground = False
    hover_n = values["MPC_THR_HOVER"] * profile.max_thrust_per_rotor_n
    body.state.thrust_n = [hover_n] * 4
    ctrl = Controller(profile)
    ctrl.reset(body.state)
    ctrl.vel_int[2] = 0.0
    n = math.ceil(duration_s / dt_s)
    out_t = np.empty(n)
    out_p = np.empty((n, 3))
    out_v = np.empty((n, 3))
    out_q = np.empty((n, 4))
    out_u = np.empty((n, 4))
    out_ev = np.empty((n, 3))
    out_ep = np.empty((n, 3))
    estimator = Estimator(estimate_error, seed) if estimate_error is not None else None
    k = -1
    no_wind = (0.0, 0.0, 0.0)
    ones = (1.0, 1.0, 1.0, 1.0)
    for i in range(n):
        t = i * dt_s
        while k + 1 < stream.t_s.size and stream.t_s[k + 1] <= t:
            k += 1
        s = body.state
        if estimator is not None:
            estimator.step(dt_s)
            s = estimator.estimate(s)
        if k < 0:
            target = Target(pos=[s.n_m, s.e_m, s.d_m], yaw_rad=s.yaw_rad())
        else:
            pos = [float(x) for x in stream.pos_ned[k]]
            if catch_up_down is not None:
                pos[2] = catch_up_down(k, pos[2], s.d_m)
            target = Target(
                pos=pos,
                vel=[float(x) for x in stream.vel_ned[k]],
                acc=[float(x) for x in stream.acc_ned[k]],
                yaw_rad=float(stream.yaw_rad[k]),
            )
        bz, collective = ctrl.thrust_setpoint(dt_s, s, target, lim)
        yaw = target.yaw_rad if target.yaw_rad == target.yaw_rad else ctrl.yaw_hold_rad
        thrusts = ctrl.rotor_thrusts(dt_s, s, bz, collective, yaw, lim)
        body.step(dt_s, thrusts, ones, no_wind)
        out_ev[i] = (s.vn_mps, s.ve_mps, s.vd_mps)
        out_ep[i] = (s.n_m, s.e_m, s.d_m)
        s = body.state
        out_t[i] = t + dt_s
        out_p[i] = (s.n_m, s.e_m, s.d_m)
        out_v[i] = (s.vn_mps, s.ve_mps, s.vd_mps)
        out_q[i] = (s.qw, s.qx, s.qy, s.qz)
        out_u[i] = ctrl.last_u
    if estimator is None:
        out_ev, out_ep = out_v.copy(), out_p.copy()
    return Response(out_t, out_p, out_v, out_q, out_u, out_ev, out_ep)


__all__ = ["NAN", "Response", "SetpointStream", "px4_params", "replay"]
