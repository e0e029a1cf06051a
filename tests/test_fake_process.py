"""The fake vehicle as a process (CLI, port, signals, parent death) and its physics in fast time."""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time

import pandas as pd
import pytest

from flighttest.model.aero import G_MPS2
from flighttest.model.profiles import load_profile
from sitl_fakes.control import NAN, Target
from sitl_fakes.disturbance import Disturbance, VrsTruth, default_onset_mps
from sitl_fakes.estimator import EstimateError
from sitl_fakes.launcher import FakeVehicle, wait_for
from sitl_fakes.link import Link
from sitl_fakes.px4 import Mode
from sitl_fakes.telemetry import Telemetry
from sitl_fakes.truthlog import TruthLog
from sitl_fakes.vehicle import FakeConfig, FakePx4


def run_fake(*args: str, timeout: float = 20.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sitl_fakes", *args], capture_output=True, text=True, timeout=timeout
    )


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--vehicle", "nope"], "unknown vehicle 'nope'"),
        (["--wind-ned", "1,2"], "--wind-ned"),
        (["--truth-cone-deg", "95"], "cone"),
        (["--truth-onset", "-1"], "onset_mps"),
        (["--param", "NOPE=1"], "--param"),
        (["--peer", "localhost"], "--peer"),
        (["--physics-hz", "0"], "--physics-hz"),
        (["--truth-drag", "1,x"], "--truth-drag"),
        (["--truth-drag=-1,0"], "--truth-drag"),
        (["--gust-tau-s", "-2"], "--gust-tau-s"),
        (["--truth-log", "/proc/nope/truth.csv"], "--truth-log"),
    ],
)
def test_bad_input_is_one_error_line_and_exit_2(args, message):
    proc = run_fake("--port", "0", "--duration-s", "0.5", *args)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("sitl_fakes: error:") and message in lines[0]
    assert "Traceback" not in proc.stderr


def test_flighttest_sim_is_the_same_program():
    proc = subprocess.run(
        [sys.executable, "-m", "flighttest", "sim", "--port", "0", "--duration-s", "0.5"],
        capture_output=True, text=True, timeout=20,
    )  # fmt: skip
    assert proc.returncode == 0
    assert proc.stdout.splitlines()[0].startswith("connect: udpout://127.0.0.1:")
    bad = subprocess.run(
        [sys.executable, "-m", "flighttest", "sim", "--vehicle", "nope"], capture_output=True, text=True
    )
    assert bad.returncode == 2 and bad.stderr.startswith("flighttest: error: unknown vehicle")


def test_port_is_bound_exclusively(fake_vehicle_factory):
    fake = fake_vehicle_factory()
    second = run_fake("--port", str(fake.port), "--duration-s", "0.5")
    assert second.returncode == 2 and "cannot bind UDP port" in second.stderr
    # a MAVSDK-style listener (SO_REUSEADDR) cannot share it either
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        with pytest.raises(OSError):
            sock.bind(("127.0.0.1", fake.port))
    finally:
        sock.close()
    assert fake.alive()


def test_sigterm_stops_cleanly_with_complete_log(tmp_path):
    fake = FakeVehicle(truth_log=tmp_path / "t.csv").start()
    time.sleep(0.5)
    assert fake.stop() == 0
    df = pd.read_csv(fake.truth_log)
    assert df.kind.iloc[0] == "event" and df.detail.iloc[0].startswith("start")
    assert df.detail.iloc[-1] == "stop (SIGTERM)"
    assert (df.kind == "state").sum() > 50


def test_the_fake_says_on_stderr_when_and_why_it_stops(tmp_path):
    # a shell that closes sends SIGHUP: the fake used to vanish without a word
    fake = FakeVehicle(truth_log=tmp_path / "t.csv").start()
    time.sleep(0.5)
    fake.proc.send_signal(signal.SIGHUP)
    assert fake.proc.wait(5) == 0
    last = fake.stderr_path.read_text().strip().splitlines()[-1]
    assert last.startswith("sitl_fakes: stopped after ") and "SIGHUP (the terminal or shell" in last
    assert pd.read_csv(fake.truth_log).detail.iloc[-1] == "stop (SIGHUP)"
    fake.stop()


def test_exits_when_its_parent_dies(tmp_path):
    script = textwrap.dedent(
        f"""
        import os, sys
        sys.path.insert(0, {os.getcwd()!r})
        from sitl_fakes.launcher import FakeVehicle
        fake = FakeVehicle(truth_log={str(tmp_path / "t.csv")!r}).start()
        print(fake.proc.pid, flush=True)
        os._exit(0)  # die without stopping the fake
        """
    )
    parent = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=30)
    pid = int(parent.stdout.strip())

    def gone() -> bool:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        # a zombie reparented to us/init counts as gone once it has exited
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split(")")[1].split()[0] == "Z"

    try:
        # it polls its parent every 0.5 s; the rest is room for a busy machine (CI's two cores run two lanes)
        assert wait_for(gone, 20.0)
    finally:
        if not gone():
            os.kill(pid, signal.SIGKILL)
    assert "stop (parent died)" in (tmp_path / "t.csv").read_text()


# -- fast-time physics: the same FakePx4 the process runs, stepped without the clock -------------------


def make_vehicle(vehicle="x500", onset=None, severity=1.0, seed=1, **cfg):
    """The fake in fast time; its estimate is the truth unless ``estimate_error`` is given (these tests
    judge the controller's tracking, which a PX4-like estimate error would hide)."""
    cfg.setdefault("estimate_error", EstimateError().scaled(0.0))
    profile = load_profile(vehicle)
    onset = default_onset_mps(profile.v_h_mps) if onset is None else onset
    config = FakeConfig(profile=profile, truth=VrsTruth(onset, 20.0, severity, seed, profile.v_h_mps), **cfg)
    link = Link(0, "127.0.0.1")
    v = FakePx4(config, link, TruthLog(None, 0.0), 0.0)
    v.telemetry = Telemetry(v, 50.0, 250.0)
    return v, link


def fly(v: FakePx4, target: Target, seconds: float, t0: float, dt: float = 0.004):
    """Offboard on ``target`` for ``seconds`` of simulated time; returns samples and the end time."""
    v.offboard_sp = target
    v.mode = Mode.OFFBOARD
    out = []
    t = t0
    for _ in range(round(seconds / dt)):
        t += dt
        v.last_sp_time = t
        v.step(dt, t)
        s = v.body.state
        out.append((t, s.n_m, s.e_m, s.d_m, s.vd_mps, math.degrees(s.tilt_rad()), list(v.thrust_cmd), v.dist.dT_T))
    return out, t


def test_hover_thrust_balances_weight_and_limits_hold_in_a_hard_step():
    v, link = make_vehicle()
    try:
        prof = v.profile
        v.arm("test")
        out, t = fly(v, Target(pos=[0.0, 0.0, -5.0]), 10.0, 0.0)
        assert out[-1][3] == pytest.approx(-5.0, abs=0.05)
        assert sum(out[-1][6]) == pytest.approx(prof.mass_kg * G_MPS2, rel=0.02)
        # a 30 m step sideways: tilt and thrust stay within the profile
        out, t = fly(v, Target(pos=[30.0, 0.0, -5.0]), 12.0, t)
        assert max(o[5] for o in out) <= prof.max_tilt_deg + 3.0
        assert max(max(o[6]) for o in out) <= prof.max_thrust_per_rotor_n + 1e-9
        assert min(min(o[6]) for o in out) >= prof.min_thrust_per_rotor_n - 1e-9
        assert abs(max(o[3] for o in out) - (-5.0)) < 1.0  # altitude kept while manoeuvring
        assert out[-1][1] == pytest.approx(30.0, abs=0.5)
    finally:
        link.close()


def test_steady_wind_is_held_against_by_leaning_into_it():
    v, link = make_vehicle(wind_ned=(4.0, 0.0, 0.0), gust_mps=0.5)
    try:
        v.arm("test")
        out, _ = fly(v, Target(pos=[0.0, 0.0, -3.0], yaw_rad=0.0), 15.0, 0.0)
        tail = out[-500:]
        assert max(abs(o[1]) for o in tail) < 0.5 and max(abs(o[3] + 3.0) for o in tail) < 0.3
        s = v.body.state
        pitch = math.asin(max(-1.0, min(1.0, 2 * (s.qw * s.qy - s.qz * s.qx))))
        assert pitch > math.radians(1.0)  # nose up: thrust tilted back against a wind blowing north
    finally:
        link.close()


def test_disturbance_is_zero_outside_and_fluctuates_inside():
    prof = load_profile("x500")
    onset = default_onset_mps(prof.v_h_mps)
    d = Disturbance(VrsTruth(onset, 20.0, 1.0, 5, prof.v_h_mps))
    # level, straight down just below the onset: nothing
    for _ in range(500):
        assert d.step(0.004, 0.0, 0.0, 0.9 * onset, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) == [1.0] * 4
    # fast forward flight with the same sink rate stays outside the cone
    d.step(0.004, 5.0, 0.0, 1.5 * onset, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert d.region == 0 and d.dT_T == 0.0
    # straight down at 2 w_allow: thrust lost on average and fluctuating
    samples = [d.step(0.004, 0.0, 0.0, 2 * onset, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0) and d.dT_T for _ in range(2500)]
    mean = sum(samples) / len(samples)
    std = math.sqrt(sum((x - mean) ** 2 for x in samples) / len(samples))
    assert d.region in (1, 2) and -0.2 < mean < -0.05 and std > 0.03
    # a head wind of the same speed cancels the air-relative descent
    d.step(0.004, 0.0, 0.0, 2 * onset, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2 * onset)
    assert d.dT_T == 0.0
    # the truth onset, not flighttest's belief, decides
    d2 = Disturbance(VrsTruth(3 * onset, 20.0, 1.0, 5, prof.v_h_mps))
    d2.step(0.004, 0.0, 0.0, 2 * onset, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert d2.dT_T == 0.0


def test_deep_vrs_descent_departs_and_crashes_but_not_without_the_disturbance():
    """A 3·w_allow descent that stops 4 m up: with the truth disturbance the vehicle departs."""
    outcomes = {}
    for severity in (0.0, 1.0):
        v, link = make_vehicle(severity=severity, seed=2)
        try:
            v.params["MPC_Z_VEL_MAX_DN"].value = 10.0
            v.arm("test")
            _, t = fly(v, Target(pos=[0.0, 0.0, -20.0]), 12.0, 0.0)
            w = 3.0 * default_onset_mps(v.profile.v_h_mps)
            t_end = t + 15.0
            while t < t_end and not v.crashed:
                target = Target(pos=[0.0, 0.0, NAN], vel=[0.0, 0.0, w]) if v.body.state.d_m < -4.0 else Target(
                    pos=[0.0, 0.0, -4.0]
                )
                _, t = fly(v, target, 0.1, t)
            outcomes[severity] = v.crashed
        finally:
            link.close()
    assert outcomes == {0.0: False, 1.0: True}
