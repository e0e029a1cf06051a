"""Issue 22, item 2: ``flighttest params save|apply|restore`` — QGroundControl parameter files, against the fake's
PX4 and ArduCopter parameters over real UDP MAVLink (connects, never flies). What the fake holds is read back
with pymavlink's own PARAM_REQUEST_READ, not through flighttest."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import time

import pytest
from pymavlink import mavutil

from flighttest.analysis.params import same_value
from flighttest.errors import FlighttestError
from flighttest.flying.params_file import changes, file_text, read_params, write_params


def _cli(*argv: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flighttest", "params", *argv], capture_output=True, text=True,
                          timeout=timeout)  # fmt: skip


def _held(port: int, names: list[str], int_bytewise: bool = False) -> dict[str, float]:
    """The fake's values, as its PARAM_VALUE answers say (PX4 sends an integer's bytes in the float)."""
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=254, source_component=190)
    out: dict[str, float] = {}
    try:
        deadline = time.monotonic() + 10.0
        for name in names:
            while name not in out and time.monotonic() < deadline:
                conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                conn.mav.param_request_read_send(1, 1, name.encode(), -1)
                msg = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
                if msg is not None and msg.param_id == name:
                    v = msg.param_value
                    if int_bytewise and msg.param_type <= 6:
                        v = struct.unpack("<i", struct.pack("<f", v))[0]
                    out[name] = v
    finally:
        conn.close()
    assert set(out) == set(names), out
    return out


# -- the file format ---------------------------------------------------------------------------------


def test_a_saved_file_reads_back_as_it_was_written(tmp_path):
    params = {"MPC_Z_VEL_MAX_DN": 1.2, "COM_OBL_RC_ACT": 5, "MC_ROLL_P": 6.5, "EKF2_TAU_VEL": 0.25}
    path = write_params(tmp_path / "v.params", params, sysid=3, autopilot="PX4")
    text = path.read_text()
    assert "# Vehicle-Id Component-Id Name Value Type" in text and "3\t1\tMPC_Z_VEL_MAX_DN\t1.2\t9" in text
    assert "3\t1\tCOM_OBL_RC_ACT\t5\t6" in text
    back = read_params(path)
    assert back == params and isinstance(back["COM_OBL_RC_ACT"], int)
    # Mission Planner's NAME,value lines load too
    (tmp_path / "mp.param").write_text("WP_ACC_Z,2.0\nFS_GCS_ENABLE,1\n# a comment\n\nPSC_JERK_D 10\n")
    assert read_params(tmp_path / "mp.param") == {"WP_ACC_Z": 2.0, "FS_GCS_ENABLE": 1, "PSC_JERK_D": 10}
    assert file_text(1.2000000476837158) == "1.2" and file_text(94502.83) == "94502.83"
    assert same_value(0.1, 0.10000000149011612)


@pytest.mark.parametrize("line, message", [
    ("1\t1\tMPC_Z_VEL_MAX_DN\tnan\t9", "not a finite number"),
    ("1\t1\tMPC_Z_VEL_MAX_DN\tfast\t9", "is not a number"),
    ("1\t1\tCOM_OBL_RC_ACT\t2.5\t6", "integer parameter"),
    ("1\t1\tMPC_Z\t1", "not a parameter line"),
    ("1\t1\tMPC Z\t1\t9", "not a parameter name"),
    ("1\t1\tA_NAME_LONGER_THAN_16\t1\t9", "not a parameter name"),
    ("1\t1\tMPC_Z_VEL_MAX_DN\t1\tfloat", "MAV_PARAM_TYPE"),
])  # fmt: skip
def test_a_damaged_file_is_one_line_naming_where(tmp_path, line, message):
    path = tmp_path / "bad.params"
    path.write_text(f"# header\n1\t1\tMC_ROLL_P\t6.5\t9\n{line}\n")
    with pytest.raises(FlighttestError, match=message) as exc:
        read_params(path)
    assert f"{path}:3" in str(exc.value) and "\n" not in str(exc.value)


def test_what_a_file_would_change_is_refused_whole_for_a_name_the_vehicle_lacks():
    now = {"WP_ACC_Z": 1.0, "FS_GCS_ENABLE": 0, "WP_ACC": 2.5}
    todo, own = changes({**now, "STAT_RUNTIME": 61}, {"WP_ACC_Z": 2.0, "FS_GCS_ENABLE": 1, "WP_ACC": 2.5000000001,
                                                      "STAT_RUNTIME": 0})  # fmt: skip
    assert own == ["STAT_RUNTIME"]  # the autopilot keeps it itself: a saved file does not turn it back
    assert [(c.name, c.now, c.new) for c in todo] == [("WP_ACC_Z", 1.0, 2.0), ("FS_GCS_ENABLE", 0, 1)]
    with pytest.raises(FlighttestError, match="no parameter WPNAV_ACCEL_Z: nothing applied"):
        changes(now, {"WP_ACC_Z": 2.0, "WPNAV_ACCEL_Z": 200})
    with pytest.raises(FlighttestError, match="integer parameter"):
        changes(now, {"FS_GCS_ENABLE": 1.5})


# -- against the fake ---------------------------------------------------------------------------------


@pytest.mark.parametrize("autopilot, changes_, int_bytewise", [
    ("px4", {"MPC_Z_VEL_MAX_DN": (1.5, 1.2), "MPC_TILTMAX_AIR": (45.0, 35.0)}, True),
    ("ardupilot", {"WP_ACC_Z": (1.0, 2.0), "PSC_JERK_D": (5.0, 10.0), "FS_GCS_ENABLE": (0, 1)}, False),
])  # fmt: skip
def test_save_apply_restore_on_the_fake(tmp_path, fake_vehicle_factory, autopilot, changes_, int_bytewise):
    vehicle = "x500" if autopilot == "px4" else "arducopter_sitl"
    fake = fake_vehicle_factory(vehicle, autopilot=autopilot)
    names = list(changes_)
    assert _held(fake.port, names, int_bytewise) == pytest.approx({n: v[0] for n, v in changes_.items()})
    saved = tmp_path / "before.params"
    r = _cli("save", "--connect", fake.url, "-o", str(saved), "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["action"] == "save" and doc["count"] > 50 and doc["autopilot"] == ("PX4" if autopilot == "px4" else
                                                                                 "ArduPilot")  # fmt: skip
    held = read_params(saved)
    assert all(same_value(held[n], v[0]) for n, v in changes_.items())

    test_day = tmp_path / "test-day.params"
    test_day.write_text("".join(f"{n},{v[1]}\n" for n, v in changes_.items()))
    backup = tmp_path / "backup.params"
    r = _cli("apply", str(test_day), "--connect", fake.url, "--yes", "--backup", str(backup))
    assert r.returncode == 0, r.stderr
    assert all(n in r.stdout for n in names) and f"set {len(names)} of {len(names)}" in r.stdout
    assert _held(fake.port, names, int_bytewise) == pytest.approx({n: v[1] for n, v in changes_.items()})
    assert read_params(backup) == pytest.approx({n: v[0] for n, v in changes_.items()})  # what it changed, before

    r = _cli("apply", str(test_day), "--connect", fake.url, "--yes", "--json")  # again: nothing left to change
    assert r.returncode == 0 and json.loads(r.stdout)["changes"] == []
    r = _cli("restore", str(saved), "--connect", fake.url, "--yes", "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert sorted(doc["applied"]) == sorted(names) and doc["failed"] == [] and doc["backup"] is None
    assert _held(fake.port, names, int_bytewise) == pytest.approx({n: v[0] for n, v in changes_.items()})


def test_apply_refuses_names_the_vehicle_lacks_and_an_armed_vehicle(tmp_path, fake_vehicle_factory):
    fake = fake_vehicle_factory("x500")
    bad = tmp_path / "typo.params"
    bad.write_text("MPC_Z_VEL_MAX_DN,1.2\nMPC_Z_VEL_MAX_DX,1.2\n")
    r = _cli("apply", str(bad), "--connect", fake.url, "--yes")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "no parameter MPC_Z_VEL_MAX_DX" in r.stderr
    r = _cli("apply", str(bad), "--connect", fake.url, "--yes", "--json")
    assert r.returncode == 2 and "no parameter" in json.loads(r.stdout)["error"]
    assert _held(fake.port, ["MPC_Z_VEL_MAX_DN"]) == {"MPC_Z_VEL_MAX_DN": 1.5}
    # no terminal to ask and no --yes: refused before connecting
    r = _cli("apply", str(bad), "--connect", fake.url)
    assert r.returncode == 2 and "--yes" in r.stderr

    # armed (pymavlink's arm command, not flighttest's): nothing changes
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{fake.port}", source_system=255, source_component=190)
    try:
        for _ in range(20):
            conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            conn.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            hb = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.3)
            if hb is not None and hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED:
                break
        else:
            pytest.fail("the fake did not arm")
        good = tmp_path / "good.params"
        good.write_text("MPC_Z_VEL_MAX_DN,1.2\n")
        r = _cli("apply", str(good), "--connect", fake.url, "--yes")
        assert r.returncode == 2 and "armed" in r.stderr, r.stderr
        assert _held(fake.port, ["MPC_Z_VEL_MAX_DN"]) == {"MPC_Z_VEL_MAX_DN": 1.5}
    finally:
        conn.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0)
        conn.close()
