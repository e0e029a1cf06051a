"""flighttest flying the fake's ArduCopter personality (issue 15), in real time over UDP with real MAVSDK:
what ArduCopter SITL showed (../shared/ardupilot_sitl, bench/RESULTS.md) as CI can check it without
ArduPilot. The profile is ArduCopter SITL's own quad, whose ``[autopilot]`` limits the plans fit.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from build_up_checks import assert_build_up
from test_fly_missions import (
    CI_STALE_PERIODS,
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


@pytest.mark.parametrize("mode", ["LOITER", "ALT_HOLD"])
def test_a_pilot_switching_to_a_manual_mode_mid_descent_is_a_takeover(fake_vehicle_factory, tmp_path, mode):
    fake = ap_fake(fake_vehicle_factory)
    proc = start_fly("vertical", fake.url, tmp_path, "--config", str(ci_config(tmp_path, "vertical")))
    wait_for_event(tmp_path, "stream_start", proc, timeout_s=120.0)
    time.sleep(1.0)
    with fake.pilot() as pilot:
        pilot.switch(mode)
        rc, s, err = finish(proc)
        assert rc == 1 and s["abort_reason"] == f"pilot took over ({mode})", err
        assert s["ladder"][-1]["why"] == f"pilot in control ({mode})"
        # MAVSDK would have called LOITER HOLD, flighttest's hold rung: read from the heartbeat it is the pilot's
        assert modes(s["log_dir"])[-1] == mode and s["final_mode"] == mode and s["final_armed"] is True
        ev = events(s["log_dir"])
        t_pilot = next(e["t_s"] for e in ev if e["event"] == "mode" and e["new"] == mode)
        assert not [e for e in ev if e["event"] == "ladder_command" and e["t_s"] > t_pilot]
    assert_complete_log(s["log_dir"])


# ArduCopter SITL has no vortex ring: its probe sweeps to the top (1.17 m/s) and identify keeps the prior
# (bench/RESULTS.md). The fake's onset above the sweep does the same.
NO_VRS_ONSET_MPS = 1.6


@pytest.mark.timeout(900)  # the EKF's 42 s, a 2-minute probe, up to four flights and the plans: about 8 minutes
def test_campaign_on_the_arducopter_fake_runs_all_six_steps_as_on_its_sitl(tmp_path):
    # default ArduCopter parameters: the plans fit its GUIDED limits (the profile's [autopilot]), the
    # preflight passes, the guard stays silent and the helix is faster; the fake's EKF takes its real 42 s
    out = tmp_path / "campaign"
    env = {**os.environ, "FLIGHTTEST_VEHICLES": str(tmp_path / "my_vehicles")}
    cmd = [sys.executable, "-m", "flighttest", "campaign", "--sim", "--sim-autopilot", "ardupilot", "--vehicle",
           VEHICLE, "--truth-onset", str(NO_VRS_ONSET_MPS), "--yes", "-o", str(out), "--json",
           "--stale-periods", str(CI_STALE_PERIODS), "--build-up", "2"]  # fmt: skip
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=1000, env=env)
    assert r.returncode == 0, r.stderr[-3000:]
    s = json.loads(r.stdout)
    steps = json.loads((out / "campaign.json").read_text())["steps"]
    # the build-up (issue 22): EKF3's estimate is close to the truth (the fake's SCALED_PRESSURE says so), so the
    # margins narrow from the config's; the fastest clean flight is kept, the truth never in its VRS region
    rows = assert_build_up(out, s, most=2)
    assert all(r["estimate_mps"] is not None for m in rows for r in rows[m])
    assert all(step["status"] == "done" for step in steps.values()), steps
    assert s["vehicle"] == VEHICLE and s["onset_found"] is False
    # like for like, the first flights (the config's margins): the helix descends faster (15.8-15.9 s against
    # 16.8). The kept flights need not say so: the helix's next plan may not converge while the vertical narrows
    # to 10.9 s (bench/RESULTS.md, "A flaky assertion found in the same review")
    first = {m: json.loads((out / "build_up" / f"{m}.json").read_text())["flights"][0]["record"]["descent_time_s"]
             for m in ("vertical", "helix")}  # fmt: skip
    assert first["helix"] < first["vertical"], first
    assert s["speedup_helix_vs_vertical"] == pytest.approx(s["vertical_descent_s"] / s["helix_descent_s"])
    assert [f["step"] for f in s["flights"]] == ["vertical", "helix"]
    assert all(f["outcome"] == "completed" and f["guard_aborts"] == 0 for f in s["flights"])
