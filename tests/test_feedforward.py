"""The feed-forward flighttest sends PX4 (flighttest.flying.feedforward), pure, and what PX4's cascade makes of it."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from flighttest.flying.feedforward import (
    CatchUpLimit,
    Feedforward,
    feedforward_accel_ned,
    for_autopilot,
    hold_accel_ned,
    wind_share_ned,
    z_position_gain_per_s,
)
from flighttest.model.aero import G_MPS2
from flighttest.model.profiles import load_profile
from flighttest.model.trajectory import Trajectory
from sitl_fakes.control import Controller, Limits, Target
from sitl_fakes.fast import advance, hover_at, vehicle
from sitl_fakes.physics import RigidBodyState
from sitl_fakes.px4 import Mode

T = np.arange(0.0, 2.0, 0.02)


def test_lead_sends_the_acceleration_due_later():
    acc = np.zeros((T.size, 3))
    acc[T >= 1.0, 0] = 2.0  # a step at 1 s
    out = feedforward_accel_ned(T, np.zeros_like(acc), acc, Feedforward(lead_s=0.2, decoupled=False))
    assert out[np.isclose(T, 0.78), 0] == 0.0 and out[np.isclose(T, 0.8), 0] == pytest.approx(2.0)
    assert out[-1, 0] == 0.0  # past the plan's end the plan is at rest


def test_drag_is_added_along_the_air_relative_velocity():
    vel = np.tile([2.0, -1.0, 0.5], (T.size, 1))
    ff = Feedforward(lead_s=0.0, drag_per_s=0.5, decoupled=False)
    out = feedforward_accel_ned(T, vel, np.zeros_like(vel), ff, wind_ned=(1.0, 0.0, 0.0))
    assert out[0] == pytest.approx([0.5 * 1.0, -0.5, 0.25])


def test_a_plan_over_one_point_sends_no_wind_drag_and_one_that_travels_does():
    """The vertical and the probe start from a hover whose integrator holds the wind's drag already."""
    n = 50
    t = np.arange(n) * 0.1
    still = pd.DataFrame({"t_s": t, "n_m": 0.0, "e_m": 0.0, "d_m": -7.0 + 0.3 * t, "vn_mps": 0.0, "ve_mps": 0.0,
                          "vd_mps": 0.3, "an_mps2": 0.0, "ae_mps2": 0.0, "ad_mps2": 0.0, "yaw_deg": 0.0})  # fmt: skip
    travels = still.assign(e_m=0.4 * t, ve_mps=0.4)
    wind = (0.0, -3.0, 0.0)
    ff = Feedforward(lead_s=0.0, drag_per_s=1.0, decoupled=False)
    assert wind_share_ned(Trajectory(still, {}), wind) == (0.0, 0.0, 0.0)
    assert wind_share_ned(Trajectory(travels, {}), wind) == wind
    sent_still = for_autopilot(Trajectory(still, {}), ff, wind).df
    sent_travels = for_autopilot(Trajectory(travels, {}), ff, wind).df
    assert sent_still["ae_mps2"].to_numpy() == pytest.approx(0.0)  # the plan's own velocity's drag only
    assert sent_travels["ae_mps2"].to_numpy() == pytest.approx(0.4 + 3.0)


@pytest.mark.parametrize("a_down", [-3.0, 0.0, 4.0])
def test_decoupling_makes_px4s_tilt_the_plans(a_down):
    # the plan tilts for (a_n, g − a_d); PX4 with MPC_ACC_DECOUPLE for (a_n', g): scaled, they agree,
    # and PX4's vertical thrust (from a_d alone) gives the plan's collective
    plan = np.array([[2.0, 0.0, a_down]])
    sent = feedforward_accel_ned(np.array([0.0]), np.zeros((1, 3)), plan, Feedforward(lead_s=0.0))
    plan_tilt = math.atan2(2.0, G_MPS2 - a_down)
    prof = load_profile("sih_quadx")
    hover = prof.mass_kg * G_MPS2 / (4 * prof.max_thrust_per_rotor_n)
    ctrl = Controller(prof)
    target = Target(acc=[float(x) for x in sent[0]])
    bz, collective = ctrl.thrust_setpoint(0.004, RigidBodyState(), target, Limits(thr_hover=hover))
    assert math.acos(bz[2]) == pytest.approx(plan_tilt, abs=1e-6)
    thrust_n = collective * 4 * prof.max_thrust_per_rotor_n
    assert thrust_n == pytest.approx(prof.mass_kg * math.hypot(2.0, G_MPS2 - a_down), rel=1e-6)


def test_catch_up_limit_bounds_the_descent_the_position_error_adds():
    limit = CatchUpLimit(excess_mps=0.1, floor_mps=0.3, gain_per_s=1.0)
    # the plan descends at 0.3 m/s, the vehicle is 0.35 m above it: sent 0.1 m below the vehicle, so
    # PX4 commands 0.3 + 0.1 m/s, not 0.3 + 0.35
    assert limit.limit(-3.0, -3.35, 0.3) == pytest.approx(-3.25)
    # within the limit the plan's own setpoint goes out
    assert limit.limit(-3.3, -3.35, 0.3) == -3.3
    # below the plan (climbing back to it) nothing is limited
    assert limit.limit(-3.0, -2.5, 0.3) == -3.0
    # holding (plan at rest) or climbing, the catch-up may still descend at the floor rate
    assert limit.limit(-2.0, -3.0, 0.0) == pytest.approx(-2.7)
    assert limit.limit(-2.0, -3.0, -0.4) == pytest.approx(-2.3)  # plan climbs 0.4: descend ≤ 0.3 net
    # in metres through the autopilot's gain: twice the gain, half the distance
    assert CatchUpLimit(0.1, 0.3, 2.0).limit(-3.0, -3.35, 0.3) == pytest.approx(-3.30)


@pytest.mark.parametrize(
    ("params", "autopilot", "gain"),
    [({"MPC_Z_P": 1.5}, "PX4", 1.5), ({"PSC_POSZ_P": 0.8}, "ArduPilot", 0.8), ({"PSC_D_POS_P": 0.7}, "ArduPilot", 0.7),
     ({"PSC_D_POS_P": 0.7, "PSC_POSZ_P": 0.8}, "ArduPilot", 0.7), ({}, "PX4", 1.0), (None, None, 1.0),
     ({"MPC_Z_P": "x"}, "PX4", 1.0), ({"MPC_Z_P": 0.0}, "PX4", 1.0), ({"MPC_Z_P": float("nan")}, "PX4", 1.0)],
)
def test_z_position_gain_from_the_autopilots_parameters(params, autopilot, gain):
    assert z_position_gain_per_s(params, autopilot) == gain


def _x500_ff() -> Feedforward:
    prof = load_profile("x500")
    return Feedforward(lead_s=0.2, drag_per_s=prof.drag_n_per_mps / prof.mass_kg)


def _travels() -> pd.DataFrame:
    """A plan that goes 3 m east and ends at rest."""
    n = 50
    return pd.DataFrame({"t_s": np.arange(n) * 0.1, "n_m": 0.0, "e_m": np.linspace(0.0, 3.0, n), "d_m": 0.0,
                         "vn_mps": 0.0, "ve_mps": 0.0, "vd_mps": 0.0, "an_mps2": 0.0, "ae_mps2": 0.0, "ad_mps2": 0.0,
                         "yaw_deg": 0.0})  # fmt: skip


def _hold_after_a_windy_stream(hold_acc_ne: tuple[float, float]) -> float:
    """The fake's PX4 (x500) in 3 m/s of wind: held in Hold (its integrator takes the wind's drag), then in
    offboard at the same point with the wind's drag sent as feed-forward, as a helix's stream ends (the
    integrator lets its share go), then held with ``hold_acc_ne``. How far downwind it drifts in that hold (m)."""
    wind = (0.0, 3.0, 0.0)
    v = hover_at(vehicle("x500", wind_ned=wind), (0.0, 0.0, -7.0))
    advance(v, 15.0)
    ff, travels = _x500_ff(), _travels()
    stream_acc = for_autopilot(Trajectory(travels, {}), ff, wind).df[["an_mps2", "ae_mps2", "ad_mps2"]].iloc[-1]

    def keep_fresh(veh):
        veh.last_sp_time = veh.now

    v.offboard_sp = Target(pos=[0.0, 0.0, -7.0], vel=[0.0, 0.0, 0.0], acc=[float(a) for a in stream_acc])
    keep_fresh(v)
    v.set_mode(Mode.OFFBOARD, "test")
    assert v.mode is Mode.OFFBOARD
    advance(v, 6.0, each=keep_fresh)
    v.offboard_sp = Target(pos=[0.0, 0.0, -7.0], vel=[0.0, 0.0, 0.0], acc=[hold_acc_ne[0], hold_acc_ne[1], 0.0])
    drift = [0.0]
    advance(v, 6.0, each=lambda veh: (keep_fresh(veh), drift.append(veh.body.state.e_m)))
    return max(drift)


def test_the_hold_after_a_stream_that_carried_the_winds_drag_keeps_it():
    """PX4's integrator lets go of the wind's drag while a helix's stream sends it: a hold at the end without it
    drifted 1.7 m downwind on PX4 SITL (SIH) in 3 m/s and took 7 s to come back within 0.5 m."""
    ff, travels = _x500_ff(), _travels()
    still = travels.assign(e_m=0.0)
    wind = (0.0, 3.0, 0.0)
    an, ae, ad = hold_accel_ned(Trajectory(travels, {}), ff, wind)
    assert (an, ad) == (0.0, 0.0) and ae == pytest.approx(-3.0 * ff.drag_per_s)
    assert hold_accel_ned(Trajectory(still, {}), ff, wind) == (0.0, 0.0, 0.0)  # its hover's integrator holds it
    assert _hold_after_a_windy_stream((an, ae)) < 0.05
    assert _hold_after_a_windy_stream((0.0, 0.0)) > 0.3  # without: downwind, as before
