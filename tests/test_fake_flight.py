"""The fake PX4 flown through real MAVSDK 4 (and pymavlink where MAVSDK would refuse locally).

Every Mavsdk is destroyed explicitly (``async with``) after all its calls have returned; telemetry
is polled with getters rather than left-open subscriptions.
"""

from __future__ import annotations

import asyncio
import math
import os
import time

os.environ.setdefault("MAVLINK20", "1")

import pandas as pd
import pytest
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
from mavsdk.asyncio.plugins.offboard import (
    AccelerationNed,
    OffboardAsync,
    PositionNedYaw,
    VelocityNedYaw,
)
from mavsdk.asyncio.plugins.param import ParamAsync, ParamError
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync
from pymavlink import mavutil

from flighttest.model.profiles import load_profile
from sitl_fakes.disturbance import default_onset_mps
from sitl_fakes.drag import truth_drag_for

pytestmark = pytest.mark.flight

TAKEOFF_ALT_M = 1.5


class Session:
    """One MAVSDK ground station connected to a fake, with the plugins the tests use."""

    def __init__(self, mavsdk: Mavsdk, system):
        self.mavsdk = mavsdk
        self.system = system
        self.tel = TelemetryAsync(system)
        self.action = ActionAsync(system)
        self.offboard = OffboardAsync(system)
        self.param = ParamAsync(system)

    async def wait(self, getter, predicate, timeout_s: float, what: str):
        end = time.monotonic() + timeout_s
        value = None
        while time.monotonic() < end:
            value = await getter()
            if predicate(value):
                return value
            await asyncio.sleep(0.05)
        raise AssertionError(f"timed out after {timeout_s} s waiting for {what}; last value {value!r}")

    async def healthy(self):
        await self.wait(self.tel.health_all_ok, bool, 10.0, "health_all_ok")

    async def position(self):
        return (await self.tel.position_velocity_ned()).position

    async def takeoff(self, alt_m: float = TAKEOFF_ALT_M):
        await self.action.set_takeoff_altitude(alt_m)
        await self.action.arm()
        await self.action.takeoff()
        # the mode was Hold before takeoff too: wait for the climb, then for Hold
        await self.wait(self.position, lambda p: -p.down_m > alt_m - 0.1, 15.0, "takeoff climb")
        await self.wait(self.tel.flight_mode, lambda m: m == FlightMode.HOLD, 5.0, "Hold after takeoff")


async def connect(fake) -> tuple[Mavsdk, Session]:
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        await mavsdk.add_any_connection(fake.url)
        system = await mavsdk.first_autopilot(10.0)
        assert system is not None, "no autopilot discovered"
    except BaseException:
        mavsdk.destroy()
        raise
    return mavsdk, Session(mavsdk, system)


def truth(fake) -> pd.DataFrame:
    """The complete truth log: stop the fake first (it flushes and writes its ``stop`` row)."""
    assert fake.stop() == 0
    return pd.read_csv(fake.truth_log, low_memory=False)


def states(df: pd.DataFrame) -> pd.DataFrame:
    return df[df.kind == "state"].astype({"d_m": float, "vd_mps": float})


def pymav(fake):
    """A pymavlink ground station on the fake's port (a second, independent MAVLink peer)."""
    conn = mavutil.mavlink_connection(fake.url.replace("udpout://", "udpout:"), source_system=200)
    conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    assert conn.wait_heartbeat(timeout=5) is not None
    return conn


def command_ack(conn, command: int, *params, timeout_s: float = 3.0) -> int:
    p = [*params, *[0.0] * (7 - len(params))]
    conn.mav.command_long_send(1, 1, command, 0, *p)
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        ack = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.2)
        if ack is not None and ack.command == command:
            assert (ack.target_system, ack.target_component) == (200, conn.mav.srcComponent)
            return ack.result
    raise AssertionError(f"no COMMAND_ACK for {command}")


def test_discover_health_arm_takeoff_hold_land_disarm(fake_vehicle_factory):
    fake = fake_vehicle_factory(estimate_error=0)  # holds to 0.1 m: the controller, not PX4's estimate

    async def fly():
        mavsdk, s = await connect(fake)
        async with mavsdk:
            assert (await s.system.autopilot_type()).name == "PX4"
            await s.healthy()
            assert not await s.tel.armed()
            await s.takeoff()
            await asyncio.sleep(0.5)  # settle on the takeoff altitude
            pos = await s.position()
            assert pos.down_m == pytest.approx(-TAKEOFF_ALT_M, abs=0.1)
            start = pos
            await asyncio.sleep(2.0)  # hold
            pos = await s.position()
            assert math.dist((pos.north_m, pos.east_m, pos.down_m), (start.north_m, start.east_m, start.down_m)) < 0.1
            await s.action.hold()  # as the abort ladder's Hold rung asks, before its Land
            await s.action.land()
            await s.wait(s.tel.armed, lambda a: not a, 15.0, "disarm after landing")
            assert (await s.position()).down_m == pytest.approx(0.0, abs=0.01)
            # PX4 leaves Land for the last mode asked for that it arms in (UserModeIntention::onDisarm) …
            await s.wait(s.tel.flight_mode, lambda m: m == FlightMode.HOLD, 3.0, "Hold after the disarm")
            # … takes Land while disarmed, and will not arm there (PX4 SITL after an abort: "armable not ok"
            # for 30 s, the next flight refused; mode_req_prevent_arming)
            await s.action.land()
            await s.wait(s.tel.flight_mode, lambda m: m == FlightMode.LAND, 3.0, "Land, disarmed")
            await s.wait(s.tel.health, lambda h: not h.is_armable, 3.0, "not armable in Land")
            with pytest.raises(ActionError):
                await s.action.arm()
            await s.action.hold()
            await s.wait(s.tel.health, lambda h: h.is_armable, 3.0, "armable again in Hold")

    asyncio.run(fly())
    df = truth(fake)
    details = " | ".join(df[df.kind == "mode"].detail.astype(str))
    for expected in ("armed", "HOLD->TAKEOFF", "TAKEOFF->HOLD (takeoff complete)", "HOLD->LAND", "disarmed (landed)",
                     "LAND->HOLD (landed: back to the mode last asked for)"):  # fmt: skip
        assert expected in details
    assert not (df.kind == "crash").any()
    assert -states(df).d_m.min() == pytest.approx(TAKEOFF_ALT_M, abs=0.25)


def test_offboard_position_velocity_acceleration_tracking(fake_vehicle_factory):
    fake = fake_vehicle_factory(estimate_error=0)  # the cascade's tracking, not the estimate's wander

    async def fly():
        mavsdk, s = await connect(fake)
        async with mavsdk:
            await s.healthy()
            await s.takeoff()
            # position: within 0.15 m after 6 s
            await s.offboard.set_position_ned(PositionNedYaw(1.5, -1.0, -2.0, 30.0))
            await s.offboard.start()
            assert await s.tel.flight_mode() == FlightMode.OFFBOARD or await s.wait(
                s.tel.flight_mode, lambda m: m == FlightMode.OFFBOARD, 2.0, "Offboard"
            )
            await asyncio.sleep(6.0)
            pos = await s.position()
            assert math.dist((pos.north_m, pos.east_m, pos.down_m), (1.5, -1.0, -2.0)) < 0.15
            yaw = (await s.tel.attitude_euler()).yaw_deg
            assert yaw == pytest.approx(30.0, abs=2.0)
            # velocity: within 0.1 m/s after 2 s
            await s.offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.8, 0.0, 30.0))
            await asyncio.sleep(2.5)
            vel = (await s.tel.position_velocity_ned()).velocity
            assert vel.east_m_s == pytest.approx(0.8, abs=0.1)
            assert abs(vel.north_m_s) < 0.1 and abs(vel.down_m_s) < 0.1
            # acceleration (feed-forward only): 0.6 m/s² north for 1.5 s
            t_acc = time.monotonic()
            await s.offboard.set_acceleration_ned(AccelerationNed(0.6, 0.0, 0.0))
            await asyncio.sleep(1.5)
            await s.offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 30.0))
            await asyncio.sleep(1.5)
            await s.offboard.stop()
            await s.wait(s.tel.flight_mode, lambda m: m == FlightMode.HOLD, 2.0, "Hold after offboard stop")
            return t_acc

    asyncio.run(fly())
    df = truth(fake)
    sp = df[df.kind == "setpoint"]
    masks = set(sp.sp_type_mask.dropna().astype(int))
    # MAVSDK's masks: position+yaw, velocity+yaw, acceleration only
    assert {0b100111111000, 0b100111000111, 0b110000111111} <= masks
    st = states(df)
    acc = st[(st.sp_type_mask == 0b110000111111) & (st["mode"] == "OFFBOARD")].astype({"vn_mps": float, "t_s": float})
    assert len(acc) > 200
    # skip the first 0.3 s (motor lag and attitude change), then fit dv/dt
    acc = acc[acc.t_s > acc.t_s.iloc[0] + 0.3]
    slope = (acc.vn_mps.iloc[-1] - acc.vn_mps.iloc[0]) / (acc.t_s.iloc[-1] - acc.t_s.iloc[0])
    # PX4 turns the feed-forward into thrust as if nothing but gravity acted: the airframe's drag (the fake's
    # truth, sitl_fakes.drag) takes its share of the 0.6 m/s²
    prof = load_profile("x500")
    drag, v = truth_drag_for(prof), acc.vn_mps.mean()
    drag_mps2 = (drag.linear_n_per_mps[0] * v + drag.quadratic_n_per_mps2[0] * v * v) / prof.mass_kg
    assert slope == pytest.approx(0.6 - drag_mps2, abs=0.15)


def test_offboard_refused_without_setpoint_stream(fake_vehicle_factory):
    fake = fake_vehicle_factory()
    conn = pymav(fake)
    try:
        offboard = mavutil.mavlink.MAV_CMD_DO_SET_MODE
        custom = mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        assert command_ack(conn, offboard, custom, 6, 0) == mavutil.mavlink.MAV_RESULT_TEMPORARILY_REJECTED
        # one stale setpoint is not a stream
        conn.mav.set_position_target_local_ned_send(0, 1, 1, 1, 0b110111111000, 0, 0, -1, 0, 0, 0, 0, 0, 0, 0, 0)
        time.sleep(0.8)
        assert command_ack(conn, offboard, custom, 6, 0) == mavutil.mavlink.MAV_RESULT_TEMPORARILY_REJECTED
        for _ in range(5):  # a 10 Hz stream
            conn.mav.set_position_target_local_ned_send(0, 1, 1, 1, 0b110111111000, 0, 0, -1, 0, 0, 0, 0, 0, 0, 0, 0)
            time.sleep(0.1)
        assert command_ack(conn, offboard, custom, 6, 0) == mavutil.mavlink.MAV_RESULT_ACCEPTED
        hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=2)
        assert hb is not None and (hb.custom_mode >> 16) & 0xFF == 6
    finally:
        conn.close()
    df = truth(fake)
    results = df[(df.kind == "command") & df.detail.str.startswith("cmd=176")].detail.tolist()
    assert [r.split("result=")[1][0] for r in results] == ["1", "1", "0"]


def test_offboard_loss_failsafe_after_com_of_loss_t(fake_vehicle_factory):
    fake = fake_vehicle_factory(param={"COM_OF_LOSS_T": 0.6}, estimate_error=0)

    async def observe(s: Session, t_stop: list[float]):
        await s.healthy()
        await s.wait(s.tel.flight_mode, lambda m: m == FlightMode.OFFBOARD, 10.0, "Offboard (set by pymavlink)")
        await s.wait(s.tel.flight_mode, lambda m: m == FlightMode.HOLD, 10.0, "failsafe Hold")
        assert await s.tel.armed()
        assert t_stop, "failsafe before the stream stopped"

    async def main():
        mavsdk, s = await connect(fake)
        async with mavsdk:
            t_stop: list[float] = []
            watcher = asyncio.create_task(observe(s, t_stop))
            conn = await asyncio.to_thread(pymav, fake)
            try:
                await asyncio.to_thread(stream_then_stop, conn, t_stop)
                await watcher
            finally:
                watcher.cancel()
                await asyncio.gather(watcher, return_exceptions=True)
                conn.close()

    def stream_then_stop(conn, t_stop):
        mask = 0b110111111000  # position + yaw
        for _ in range(5):
            conn.mav.set_position_target_local_ned_send(0, 1, 1, 1, mask, 0, 0, -1.0, 0, 0, 0, 0, 0, 0, 0, 0)
            time.sleep(0.1)
        custom = mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        assert command_ack(conn, mavutil.mavlink.MAV_CMD_DO_SET_MODE, custom, 6, 0) == 0
        assert command_ack(conn, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
        end = time.monotonic() + 3.0
        while time.monotonic() < end:
            conn.mav.set_position_target_local_ned_send(0, 1, 1, 1, mask, 0, 0, -1.0, 0, 0, 0, 0, 0, 0, 0, 0)
            time.sleep(0.1)
        t_stop.append(time.monotonic())

    asyncio.run(main())
    df = truth(fake)
    last_sp = df[df.kind == "setpoint"].t_s.astype(float).max()
    failsafe = df[df.kind == "failsafe"]
    assert len(failsafe) == 1
    delay = float(failsafe.t_s.iloc[0]) - last_sp
    # checked every 4 ms step; allow scheduling jitter. The lower bound to a rounding: the truth log's times
    # are sums of steps, 0.5999999999999996 s in a new user's clone of 61204eb
    assert 0.6 - 1e-9 <= delay < 0.6 + 0.1
    assert "OFFBOARD->HOLD" in " ".join(df[df.kind == "mode"].detail.astype(str))
    st = states(df)
    assert -st.d_m.min() == pytest.approx(1.0, abs=0.3)  # it flew the setpoint before the loss


def test_params_read_and_set(fake_vehicle_factory):
    fake = fake_vehicle_factory()

    async def main():
        mavsdk, s = await connect(fake)
        async with mavsdk:
            assert await s.param.get_param_float("COM_OF_LOSS_T") == pytest.approx(1.0)
            assert await s.param.get_param_float("MIS_TAKEOFF_ALT") == pytest.approx(2.5)
            assert await s.param.get_param_float("MPC_Z_VEL_MAX_DN") == pytest.approx(1.5)
            assert await s.param.get_param_float("MPC_TILTMAX_AIR") == pytest.approx(45.0)
            assert await s.param.get_param_int("COM_OBL_RC_ACT") == 0
            assert await s.param.get_param_int("COM_RC_OVERRIDE") == 1
            await s.param.set_param_float("MPC_Z_VEL_MAX_DN", 2.5)
            await s.param.set_param_int("COM_OBL_RC_ACT", 4)
            assert await s.param.get_param_float("MPC_Z_VEL_MAX_DN") == pytest.approx(2.5)
            assert await s.param.get_param_int("COM_OBL_RC_ACT") == 4
            with pytest.raises(ParamError):
                await s.param.get_param_float("NO_SUCH_PARAM")

    asyncio.run(main())
    params = truth(fake).query("kind == 'param'").detail.tolist()
    assert "MPC_Z_VEL_MAX_DN=2.5" in params and "COM_OBL_RC_ACT=4" in params


def test_two_mavsdk_clients_and_a_pymavlink_peer_at_once(fake_vehicle_factory):
    fake = fake_vehicle_factory()

    async def main():
        m1, s1 = await connect(fake)
        async with m1:
            m2, s2 = await connect(fake)
            async with m2:
                conn = await asyncio.to_thread(pymav, fake)
                try:
                    await asyncio.gather(s1.healthy(), s2.healthy())
                    await s1.action.arm()
                    await s2.wait(s2.tel.armed, bool, 3.0, "second client sees armed")
                    hb = await asyncio.to_thread(
                        lambda: conn.recv_match(type="HEARTBEAT", blocking=True, timeout=2)
                    )
                    assert hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
                    await s2.action.disarm()
                    await s1.wait(s1.tel.armed, lambda a: not a, 3.0, "first client sees disarmed")
                    p1, p2 = await s1.tel.position(), await s2.tel.position()
                    assert p1.latitude_deg == pytest.approx(p2.latitude_deg, abs=1e-7)
                finally:
                    conn.close()

    asyncio.run(main())
    peers = {d.split("@")[1].split(" ")[0] for d in truth(fake).query("kind == 'command'").detail}
    assert len(peers) >= 2


def _descend(fake, w_mps: float, top_m: float, bottom_m: float):
    async def main():
        mavsdk, s = await connect(fake)
        async with mavsdk:
            await s.healthy()
            await s.action.arm()
            await s.offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, -3.0, 0.0))
            await s.offboard.start()
            await s.wait(s.position, lambda p: -p.down_m > top_m, 10.0, "climb")
            await s.offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, w_mps, 0.0))
            await s.wait(s.position, lambda p: -p.down_m < bottom_m, 20.0, "descent")
            await s.offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -bottom_m, 0.0))
            await asyncio.sleep(0.5)
            await s.offboard.stop()

    asyncio.run(main())
    st = states(truth(fake)).astype({"dT_T": float, "region": int})
    return st[(st.sp_type_mask == 0b100111000111) & (st.sp_vd_mps.astype(float) > 0)]


def test_vertical_descent_fluctuates_at_twice_w_allow_not_at_half(fake_vehicle_factory):
    w_allow = default_onset_mps(load_profile("x500").v_h_mps)
    fast = fake_vehicle_factory(param={"MPC_Z_VEL_MAX_DN": 3.0}, seed=3)
    slow = fake_vehicle_factory(param={"MPC_Z_VEL_MAX_DN": 3.0}, seed=3)
    d_fast = _descend(fast, 2.0 * w_allow, 6.0, 1.5)
    d_slow = _descend(slow, 0.5 * w_allow, 3.0, 2.0)
    steady = d_fast[d_fast.vd_mps > 1.5 * w_allow]
    assert len(steady) > 250
    assert steady.dT_T.std() > 0.03
    assert (steady.region > 0).mean() > 0.9
    assert steady.dT_T.mean() < -0.02  # thrust lost, not only shaken
    assert len(d_slow) > 500
    assert (d_slow.dT_T == 0).all() and (d_slow.region == 0).all()
    assert d_slow.vd_mps.max() < w_allow


def test_crash_is_reported_and_arming_refused_after(fake_vehicle_factory):
    fake = fake_vehicle_factory()

    async def main():
        mavsdk, s = await connect(fake)
        async with mavsdk:
            await s.healthy()
            texts: list[str] = []

            async def collect():
                async for st in s.tel.subscribe_status_text():
                    texts.append(st.text)

            collector = asyncio.create_task(collect())
            try:
                await s.takeoff(2.0)
                await s.action.kill()  # forced disarm in the air: it falls 2 m
                end = time.monotonic() + 3.0
                while not any("crash" in t for t in texts) and time.monotonic() < end:
                    await asyncio.sleep(0.05)
            finally:
                collector.cancel()  # ends the subscription (its finally unsubscribes)
                await asyncio.gather(collector, return_exceptions=True)
            assert any(t.startswith("crash: touchdown at") for t in texts), texts
            await asyncio.sleep(0.5)
            with pytest.raises(ActionError):
                await s.action.arm()
            with pytest.raises(ActionError):
                await s.action.arm()

    asyncio.run(main())
    df = truth(fake)
    crash = df[df.kind == "crash"]
    assert len(crash) == 1
    speed = float(crash.detail.iloc[0].split("touchdown at ")[1].split(" ")[0])
    assert speed > 2.5
    st = states(df)
    after = st[st.t_s.astype(float) > float(crash.t_s.iloc[0])]
    assert len(after) > 50
    assert (after.armed == 0).all() and (after.d_m == 0).all()
    assert (after[["t1_n", "t2_n", "t3_n", "t4_n"]].astype(float) == 0).all().all()


def test_peer_option_reaches_a_listening_mavsdk(fake_vehicle_factory):
    """PX4 SITL style: the fake sends to MAVSDK's ``udpin`` port, MAVSDK answers the sender."""
    import socket

    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()

    async def main():
        mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        async with mavsdk:
            await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
            fake_vehicle_factory(peer=[f"127.0.0.1:{port}"])
            system = await mavsdk.first_autopilot(10.0)
            assert system is not None
            s = Session(mavsdk, system)
            await s.healthy()
            await s.action.arm()  # the command travels back over the same link
            await s.wait(s.tel.armed, bool, 3.0, "armed")
            await s.action.disarm()

    asyncio.run(main())
