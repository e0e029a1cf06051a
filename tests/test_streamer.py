"""The setpoint streamer: deadline pacing, its jitter measurement, and the safe setpoint it leaves in
MAVSDK's resend. Real MAVSDK (``VehicleLink``) to the fake over UDP; the fake's truth log shows what
the vehicle received."""

from __future__ import annotations

import asyncio
import math
import time

import numpy as np
import pandas as pd
import pytest

from flighttest.flying.feedforward import CatchUpLimit
from flighttest.flying.link import VehicleLink
from flighttest.flying.streamer import Setpoint, SetpointStreamer, jitter_stats_ms

HERE = (1.0, 2.0, -3.0)  # where the test says the vehicle is


def test_jitter_stats_of_known_intervals():
    iv = np.array([0.020] * 97 + [0.021, 0.030, 0.010])
    j = jitter_stats_ms(iv, 0.020)
    assert j["n"] == 100
    assert j["p50_ms"] == pytest.approx(0.0)
    assert j["max_ms"] == pytest.approx(10.0)
    assert 1.0 <= j["p99_ms"] <= 10.0
    assert j["rate_hz"] == pytest.approx(1.0 / iv.mean())
    empty = jitter_stats_ms(np.array([]), 0.02)
    assert empty["n"] == 0 and math.isnan(empty["p99_ms"])


def _received(fake) -> pd.DataFrame:
    fake.stop()
    tr = pd.read_csv(fake.truth_log, low_memory=False)
    sp = tr[(tr["kind"] == "setpoint") & tr["sp_n_m"].notna()].copy()
    for c in ("sp_n_m", "sp_e_m", "sp_d_m", "sp_vn_mps", "sp_ve_mps", "sp_vd_mps", "sp_ad_mps2"):
        sp[c] = pd.to_numeric(sp[c], errors="coerce")
    return sp


def _descending(k: int) -> Setpoint:
    return Setpoint(0.0, 0.0, -5.0 + 0.02 * k, vd_mps=1.0, ad_mps2=0.5)


async def _with_streamer(url: str, body, **kw):
    async with VehicleLink(url, telemetry_hz=10.0, discover_s=0.3) as link:
        streamer = SetpointStreamer(link.offboard_setters(), None, 50.0, here=lambda: HERE, **kw)
        try:
            return await body(streamer)
        finally:
            streamer.stop_watchdog()


@pytest.mark.flight
def test_deadline_pacing_locks_ticks_to_the_clock_and_measures_a_stall(fake_vehicle_factory):
    fake = fake_vehicle_factory("x500")
    sent: list[tuple[int, float]] = []

    async def body(streamer: SetpointStreamer):
        loop = asyncio.get_running_loop()
        t0 = loop.time()

        def at(k: int) -> Setpoint | None:
            if k >= 50:
                return None
            sent.append((k, loop.time() - t0))
            if k == 10:
                time.sleep(0.1)  # the loop is stuck for 5 ticks
            return Setpoint(0.0, 0.0, -5.0, yaw_deg=float(k))

        result = await streamer.stream(at, "test")
        return result, streamer.jitter(), streamer.sent

    result, jitter, n_sent = asyncio.run(_with_streamer(fake.url, body))
    assert result == "done"
    ks = [k for k, _ in sent]
    assert ks == sorted(set(ks)) and ks[-1] == 49
    # no backlog burst after the stall: the tick that belongs to now, not ticks 11, 12, ...
    after = ks[ks.index(10) + 1]
    assert after >= 15
    assert len(ks) <= 50 - (after - 11)
    # every tick went out at or after its deadline (trajectory time follows the clock)
    assert all(t >= k * 0.02 - 0.002 for k, t in sent)
    assert jitter["n"] == len(ks) - 1 and jitter["max_ms"] >= 80.0
    # the vehicle got them, in order
    rx = _received(fake)
    got = pd.to_numeric(rx["sp_yaw_deg"], errors="coerce").round().astype(int).tolist()
    ours = [g for g in got if g in set(ks)]
    assert len(set(ours)) >= len(ks) - 2
    assert n_sent == len(ks)


@pytest.mark.flight
@pytest.mark.parametrize("how", ["stopped", "exception"])
def test_a_stopped_stream_leaves_a_hold_at_the_vehicle_in_mavsdks_resend(fake_vehicle_factory, how):
    fake = fake_vehicle_factory("x500")

    async def body(streamer: SetpointStreamer):
        def at(k: int) -> Setpoint:
            if how == "exception" and k == 10:
                raise RuntimeError("planner blew up")
            return _descending(k)

        try:
            result = await streamer.stream(at, "stream", should_stop=lambda: how == "stopped" and streamer.sent >= 10)
        except RuntimeError:
            result = "raised"
        t_stop = time.time()
        await asyncio.sleep(0.6)  # MAVSDK keeps re-sending the last setpoint at 20 Hz
        return result, streamer.last, t_stop

    result, last, t_stop = asyncio.run(_with_streamer(fake.url, body))
    assert result == ("stopped" if how == "stopped" else "raised")
    assert last == Setpoint(*HERE, yaw_deg=0.0)
    rx = _received(fake)
    assert (rx["sp_vd_mps"] > 0.9).sum() >= 9  # the descent was streamed
    resent = rx[rx["unix_s"] > t_stop + 0.05]
    assert len(resent) >= 5  # re-sent by MAVSDK after we stopped …
    # … and every one of them is the hold at the vehicle: zero velocity and acceleration
    assert (resent[["sp_n_m", "sp_e_m", "sp_d_m"]].to_numpy() == np.array(HERE)).all()
    assert (resent[["sp_vn_mps", "sp_ve_mps", "sp_vd_mps"]].to_numpy() == 0).all()
    assert (resent["sp_ad_mps2"].fillna(0) == 0).all()


@pytest.mark.flight
def test_a_stream_that_runs_out_at_rest_sends_nothing_more(fake_vehicle_factory):
    fake = fake_vehicle_factory("x500")

    async def body(streamer: SetpointStreamer):
        rows = [_descending(k) for k in range(5)] + [Setpoint(0.0, 0.0, -4.9)]
        result = await streamer.stream(lambda k: rows[k] if k < len(rows) else None, "stream")
        return result, streamer.sent, streamer.last

    result, n_sent, last = asyncio.run(_with_streamer(fake.url, body))
    assert (result, n_sent) == ("done", 6)
    assert last == Setpoint(0.0, 0.0, -4.9)  # the plan's own end point, not "here"


@pytest.mark.flight
def test_watchdog_leaves_a_hold_when_the_loop_is_stuck(fake_vehicle_factory):
    fake = fake_vehicle_factory("x500")

    async def body(streamer: SetpointStreamer):
        streamer.start_watchdog()
        streamer.send(_descending(0), "stream")
        t_block = time.time()
        time.sleep(0.5)  # the event loop is stuck: no setpoint from us
        return streamer.watchdog_fired, streamer.last, t_block

    fired, last, t_block = asyncio.run(_with_streamer(fake.url, body, stuck_after_s=0.15))
    assert fired == 1
    assert last == _descending(0).hold()
    rx = _received(fake)
    hold = rx[(rx["sp_vd_mps"] == 0) & (rx["unix_s"] > t_block)]
    assert len(hold) >= 1
    # it reached the vehicle while the loop was still stuck
    assert hold["unix_s"].iloc[0] - t_block < 0.4


@pytest.mark.flight
def test_catch_up_limit_sends_position_setpoints_near_the_vehicle_and_keeps_the_planned_end(fake_vehicle_factory):
    # the vehicle (7 m up) is 2 m above a plan descending at 1 m/s from 5 m: each setpoint goes out
    # 0.1 m below the vehicle (excess 0.1 m/s at gain 1); the plan's end (at rest) 0.3 m below it; the
    # streamer still knows the planned end, where the mission's settle holds
    fake = fake_vehicle_factory("x500")
    above = (1.0, 2.0, -7.0)

    async def body(streamer: SetpointStreamer):
        streamer.here = lambda: above
        streamer.catch_up = CatchUpLimit(excess_mps=0.1, floor_mps=0.3, gain_per_s=1.0)
        rows = [_descending(k) for k in range(5)] + [Setpoint(0.0, 0.0, -4.9)]
        result = await streamer.stream(lambda k: rows[k] if k < len(rows) else None, "stream")
        return result, streamer.last, streamer.last_planned

    result, last, planned = asyncio.run(_with_streamer(fake.url, body))
    assert result == "done"
    assert last.d_m == pytest.approx(-6.7) and last == last.hold()
    assert planned == Setpoint(0.0, 0.0, -4.9)
    rx = _received(fake)
    descending = rx[rx["sp_vd_mps"] > 0.9]
    assert len(descending) >= 5 and np.allclose(descending["sp_d_m"], -6.9, atol=1e-4)  # (MAVSDK may resend one)
