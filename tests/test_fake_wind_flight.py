"""The fake's wind report over MAVLink, as the autopilots send it: PX4 no WIND_COV unless EKF2_DRAG_CTRL (then its
lagging estimate), ArduCopter no WIND unless asked (then EKF3's wind states: zero without drag fusion). The
physics behind it is tested in fast time (``tests/test_fake_wind.py``)."""

from __future__ import annotations

import math
import os
import time

os.environ.setdefault("MAVLINK20", "1")

import pandas as pd
import pytest
from pymavlink import mavutil

pytestmark = pytest.mark.flight
M = mavutil.mavlink
WIND_ID = 168  # ardupilotmega WIND


def gcs(fake, sysid: int = 200):
    conn = mavutil.mavlink_connection(fake.url.replace("udpout://", "udpout:"), source_system=sysid)
    conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    assert conn.wait_heartbeat(timeout=5) is not None
    return conn


def ack(conn, command: int, *params: float) -> int:
    conn.mav.command_long_send(1, 1, command, 0, *params, *[0.0] * (7 - len(params)))
    end = time.monotonic() + 3.0
    while time.monotonic() < end:
        msg = conn.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.2)
        if msg is not None and msg.command == command:
            return msg.result
    raise AssertionError(f"no COMMAND_ACK for {command}")


def listen(conn, seconds: float) -> dict[str, list]:
    seen: dict[str, list] = {}
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        msg = conn.recv_match(blocking=True, timeout=0.1)
        if msg is not None:
            seen.setdefault(msg.get_type(), []).append(msg)
    return seen


def test_px4_sends_wind_cov_only_with_drag_fusion_and_then_a_lagging_estimate(fake_vehicle_factory):
    takeoff = {"MIS_TAKEOFF_ALT": 3.0}
    plain = fake_vehicle_factory("sih_quadx", wind_ned=(0, 3, 0), param=takeoff)
    fused = fake_vehicle_factory("sih_quadx", wind_ned=(0, 3, 0), param={
        **takeoff, "EKF2_DRAG_CTRL": 1, "EKF2_MCOEF": 1.0, "EKF2_BCOEF_X": 0.0, "EKF2_BCOEF_Y": 0.0})  # fmt: skip
    conns = [gcs(plain), gcs(fused)]
    try:
        for conn in conns:
            assert ack(conn, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_HIGHRES_IMU, 20_000) == 0
            assert ack(conn, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
            assert ack(conn, M.MAV_CMD_NAV_TAKEOFF, *[math.nan] * 7) == M.MAV_RESULT_ACCEPTED
        t_takeoff = time.monotonic()
        seen_plain = listen(conns[0], 8.0)
        seen_fused = listen(conns[1], 3.0)
        airborne_s = time.monotonic() - t_takeoff
    finally:
        for conn in conns:
            conn.close()
    # by default PX4 estimates no wind on a multicopter: not a single WIND_COV in wind, in flight
    assert "WIND_COV" not in seen_plain and len(seen_plain.get("HIGHRES_IMU", [])) > 200
    # the IMU feels the 3 N of drag across the thrust axis (leaning west: along body +y)
    imu = seen_plain["HIGHRES_IMU"][-50:]
    assert sum(m.yacc for m in imu) / len(imu) == pytest.approx(2.87, abs=0.4)
    # with EKF2_DRAG_CTRL: WIND_COV at 2 Hz, its estimate still short of the 3 m/s after ~10 s, honest about it
    covs = seen_fused.get("WIND_COV", [])
    assert len(covs) >= 4, airborne_s
    last = covs[-1]
    assert 0.5 < last.wind_y < 2.9 and abs(last.wind_x) < 1.0 and last.wind_z == 0.0
    assert last.var_horiz > 0.1 and last.horiz_accuracy == 0.0  # PX4's fields: variances in var_horiz
    assert last.wind_alt == pytest.approx(488.0 + 3.0, abs=1.0)
    # the truth log has the truth and the estimate side by side
    assert fused.stop() == 0 and plain.stop() == 0
    df = fused.read_truth()
    st = df[(df.kind == "state") & df.est_wind_e_mps.notna()]
    assert len(st) > 100 and (st.wind_e_mps == 3.0).all()
    assert st.est_wind_e_mps.iloc[-1] == pytest.approx(last.wind_y, abs=0.5)
    assert pd.read_csv(plain.truth_log, low_memory=False).est_wind_e_mps.isna().all()


def test_ardupilot_sends_wind_only_when_asked_and_zero_without_drag_fusion(fake_vehicle_factory):
    fake = fake_vehicle_factory(autopilot="ardupilot", ekf_delay_s=0.5, wind_ned=(0, 3, 0))
    conn = gcs(fake)
    try:
        seen = listen(conn, 1.5)
        assert "WIND" not in seen
        assert ack(conn, M.MAV_CMD_SET_MESSAGE_INTERVAL, WIND_ID, 200_000) == M.MAV_RESULT_ACCEPTED
        winds = listen(conn, 1.5).get("WIND", [])
    finally:
        conn.close()
    # ArduCopter's EKF3 keeps its wind states inhibited without EK3_DRAG_*: WIND says 0 (and -180°, atan2(-0, -0))
    assert len(winds) >= 5 and all(m.speed == 0.0 and m.speed_z == 0.0 for m in winds)
