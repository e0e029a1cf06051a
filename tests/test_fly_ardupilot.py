"""flighttest flying the fake's ArduCopter personality (issue 15), in real time over UDP with real MAVSDK:
what ArduCopter SITL showed (../shared/ardupilot_sitl, bench/RESULTS.md) as CI can check it without
ArduPilot. The profile is ArduCopter SITL's own quad, whose ``[autopilot]`` limits the plans fit.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_fly_missions import (
    assert_complete_log,
    ci_config,
    events,
    finish,
    truth,
    wait_for_event,
)

pytestmark = pytest.mark.flight

VEHICLE = "arducopter_sitl"
EKF_DELAY_S = 2.0  # the fake's EKF start-up (ArduCopter SITL's 42 s, shortened for CI)
FLY_TIMEOUT_S = 180


def ap_fake(factory):
    return factory(VEHICLE, autopilot="ardupilot", ekf_delay_s=EKF_DELAY_S)


def fly_cmd(target: str, url: str, log_dir: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "flighttest", "fly", target, "--connect", url, "--vehicle", VEHICLE,
            "--log-dir", str(log_dir), "--json", "--yes", *extra]  # fmt: skip


def start_fly(*args: str) -> subprocess.Popen:
    return subprocess.Popen(fly_cmd(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL)  # fmt: skip


def modes(log_dir: str) -> list[str]:
    return [e["new"] for e in events(log_dir) if e["event"] == "mode"]


def test_ctrl_c_mid_helix_brakes_then_lands_with_the_log_complete(fake_vehicle_factory, tmp_path):
    fake = ap_fake(fake_vehicle_factory)
    proc = start_fly("helix", fake.url, tmp_path, "--config", str(ci_config(tmp_path, "helix")))
    log = wait_for_event(tmp_path, "stream_start", proc, timeout_s=120.0)
    assert log["rows"] > 100
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    rc, s, err = finish(proc)
    assert rc == 1 and s["abort_reason"] == "SIGINT from the operator", err
    assert_complete_log(s["log_dir"])
    autopilot = next(e for e in events(s["log_dir"]) if e["event"] == "autopilot")
    assert autopilot["autopilot"] == "ArduPilot" and autopilot["hold_mode"] == "BRAKE"
    # ArduCopter's own names, from its heartbeat: took off and flew in GUIDED, held in BRAKE, then LAND
    assert modes(s["log_dir"])[-3:] == ["GUIDED", "BRAKE", "LAND"]
    assert [r["rung"] for r in s["ladder"]] == ["RECOVER", "HOLD", "LAND", "DONE"]
    assert s["ladder"][-1]["why"] == "landed" and s["final_armed"] is False
    tr = truth(fake)
    st = tr[tr["kind"] == "state"]
    assert st.iloc[-1]["armed"] == 0 and not (tr["kind"] == "crash").any()
