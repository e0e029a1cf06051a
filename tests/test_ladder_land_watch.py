"""The abort ladder keeps watching in Land (issue 12): stale telemetry or a lost link re-send Land and
are noted, a link gone for good ends the ladder with the reason, a pilot's mode ends it at once.

The decisions are the pure ``AbortLadder`` in virtual time (no clock, no vehicle); one flight on the
fake checks the runner acts on them: an abort, then a telemetry pause while the ladder lands."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path

import pandas as pd
import pytest
import tomli_w

from flighttest.flying import guard as g
from flighttest.flying.mission_scripts import MISSIONS, MISSIONS_DIR


def ob(t: float, **kw) -> g.LadderObservation:
    return g.LadderObservation(t_s=t, **kw)


def ladder_in_land(**timing) -> g.AbortLadder:
    lad = g.AbortLadder(g.LadderTiming(**timing))
    assert lad.trigger(0.0, "SIGINT from the operator", first=g.Rung.LAND) == g.CMD_LAND
    return lad


def whys(lad: g.AbortLadder) -> list[str]:
    return [w for _, _, w in lad.history]


# -- the decisions, in virtual time ------------------------------------------------------------------


def test_a_disarm_not_yet_confirmed_gets_no_land_re_sent():
    """PX4 leaves Land for Hold as it disarms (UserModeIntention::onDisarm); the evidence of the disarm takes a
    second (ground.DISARM_HELD_S). A Land re-sent in it left PX4 SITL disarmed in Land, where it will not arm,
    and the campaign's next flight was refused (bench/RESULTS.md)."""
    lad = ladder_in_land(land_retry_s=3.0)
    assert lad.step(ob(10.0, mode="HOLD", armed=False)) is None
    assert lad.step(ob(10.5, mode="HOLD", armed=False)) is None
    assert lad.step(ob(11.0, mode="HOLD", armed=False, landed=True)) is None
    assert lad.done and lad.history[-1][1:] == ("DONE", "landed")
    # armed in Hold: a Land that did not take, re-sent
    lad = ladder_in_land(land_retry_s=3.0)
    assert lad.step(ob(10.0, mode="HOLD")) == g.CMD_LAND
    # and while the telemetry is stale the disarm cannot be trusted either: Land goes on being sent
    lad = ladder_in_land(land_retry_s=3.0, land_min_resend_s=0.5)
    assert lad.step(ob(10.0, mode="HOLD", armed=False, telemetry_fresh=False)) == g.CMD_LAND


def test_stale_telemetry_in_land_re_sends_land_and_notes_it_until_landed():
    lad = ladder_in_land(land_retry_s=3.0, land_min_resend_s=0.5)
    assert lad.step(ob(0.2, mode="LAND")) is None
    assert lad.step(ob(1.0, mode="LAND", telemetry_fresh=False)) == g.CMD_LAND  # at once when it starts
    assert "telemetry stale during Land: re-sending Land" in whys(lad)
    assert lad.step(ob(2.0, mode="LAND", telemetry_fresh=False)) is None
    # the mode cannot be trusted while stale: Land goes on being re-sent though the mode says LAND
    assert lad.step(ob(4.0, mode="LAND", telemetry_fresh=False)) == g.CMD_LAND
    assert whys(lad)[-1] == "re-sending Land (telemetry stale)"
    assert lad.step(ob(4.5, mode="LAND")) is None  # back: noted, nothing sent
    assert whys(lad)[-1].startswith("telemetry stale during Land is over")
    assert lad.step(ob(9.0, mode="LAND")) is None  # fresh and landing: nothing to do
    assert lad.step(ob(10.0, mode="LAND", landed=True)) is None
    assert lad.done and lad.history[-1][1:] == ("DONE", "landed")
    assert lad.reason == "SIGINT from the operator"  # the abort reason stays the first trigger's


def test_stale_right_after_land_was_sent_waits_for_the_retry():
    lad = ladder_in_land(land_retry_s=3.0, land_min_resend_s=0.5)
    assert lad.step(ob(0.1, mode="LAND", telemetry_fresh=False)) is None
    assert "Land was just sent" in whys(lad)[-1]
    assert lad.step(ob(3.0, mode="LAND", telemetry_fresh=False)) == g.CMD_LAND


def test_link_lost_in_land_re_sends_then_gives_up_with_the_reason():
    lad = ladder_in_land(land_retry_s=3.0, link_give_up_s=5.0)
    assert lad.step(ob(1.0, mode="LAND", link_ok=False, telemetry_fresh=False, heard_age_s=1.0)) == g.CMD_LAND
    assert "link lost during Land: re-sending Land" in whys(lad)
    assert lad.step(ob(4.0, mode="LAND", link_ok=False, telemetry_fresh=False, heard_age_s=4.0)) == g.CMD_LAND
    assert lad.step(ob(5.5, mode="LAND", link_ok=False, telemetry_fresh=False, heard_age_s=5.5)) is None
    assert lad.done
    why = lad.history[-1][2]
    assert why.startswith("link lost and nothing heard for 5.5 s") and "failsafe" in why


def test_link_flagged_lost_while_telemetry_still_arrives_does_not_give_up():
    lad = ladder_in_land(link_give_up_s=5.0)
    for t in (1.0, 6.0, 11.0):
        lad.step(ob(t, mode="LAND", link_ok=False, heard_age_s=0.02))
    assert not lad.done


@pytest.mark.parametrize("mode", sorted(g.PILOT_MODES))
def test_a_pilot_mode_in_land_ends_the_ladder_and_sends_nothing(mode):
    lad = ladder_in_land()
    assert lad.step(ob(1.0, mode=mode)) is None
    assert lad.done and lad.history[-1][2].startswith(f"pilot took over ({mode})")
    assert lad.step(ob(9.0, mode=mode)) is None  # and nothing after


@pytest.mark.parametrize("first", [g.Rung.RECOVER, g.Rung.HOLD])
def test_a_pilot_mode_on_the_other_rungs_ends_the_ladder_too(first):
    lad = g.AbortLadder()
    lad.trigger(0.0, "in guard region", first=first)
    assert lad.step(ob(4.0, mode="POSCTL")) is None  # no Land after the Hold timeout: the pilot flies
    assert lad.done and "pilot took over (POSCTL)" in lad.history[-1][2]


def test_without_trouble_land_behaves_as_before():
    lad = ladder_in_land(land_retry_s=3.0)
    assert lad.step(ob(1.0, mode="HOLD")) is None
    assert lad.step(ob(3.1, mode="HOLD")) == g.CMD_LAND  # re-sent: the mode does not show Land
    assert lad.step(ob(3.2, mode="LAND")) is None
    assert lad.step(ob(8.0, mode="LAND", landed=True)) is None and lad.done


# -- on the fake: an abort, then stale telemetry during the ladder's Land ----------------------------

LOCAL_POSITION_NED, ATTITUDE_QUATERNION, ODOMETRY = 32, 31, 331
STATE_MESSAGES = {LOCAL_POSITION_NED, ATTITUDE_QUATERNION, ODOMETRY}


def _msgid(frame: bytes) -> int:
    if frame[:1] == b"\xfd" and len(frame) >= 10:
        return int.from_bytes(frame[7:10], "little")
    if frame[:1] == b"\xfe" and len(frame) >= 6:
        return frame[5]
    return -1


class StateDropRelay:
    """flighttest ⇄ relay ⇄ fake over UDP; with ``drop`` set, the vehicle's state messages (position-
    velocity, attitude, odometry) do not reach flighttest while heartbeats still do: stale telemetry
    on a live link."""

    def __init__(self, fake_port: int) -> None:
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind(("127.0.0.1", 0))
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.bind(("127.0.0.1", 0))
        for s in (self.front, self.back):
            s.settimeout(0.1)
        self.fake = ("127.0.0.1", fake_port)
        self.gcs: tuple[str, int] | None = None
        self.drop = False
        self.dropped = 0
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=f, daemon=True) for f in (self._up, self._down)]
        for t in self._threads:
            t.start()

    @property
    def url(self) -> str:
        return f"udpout://127.0.0.1:{self.front.getsockname()[1]}"

    def _up(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self.front.recvfrom(65535)
            except (TimeoutError, OSError):
                continue
            self.gcs = addr
            self.back.sendto(data, self.fake)

    def _down(self) -> None:
        while not self._stop.is_set():
            try:
                data, _ = self.back.recvfrom(65535)
            except (TimeoutError, OSError):
                continue
            if self.gcs is None:
                continue
            if self.drop and _msgid(data) in STATE_MESSAGES:
                self.dropped += 1
                continue
            self.front.sendto(data, self.gcs)

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(1.0)
        self.front.close()
        self.back.close()


def _events(log_root: Path) -> list[dict]:
    out = []
    for f in log_root.glob("*/events.jsonl"):
        out += [json.loads(line) for line in f.read_text().splitlines() if line.strip()]
    return out


def _wait(log_root: Path, proc: subprocess.Popen, pred, what: str, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if any(pred(e) for e in _events(log_root)):
            return
        if proc.poll() is not None:
            raise AssertionError(f"flighttest ended before {what}: {proc.stderr.read()}")
        time.sleep(0.05)
    raise AssertionError(f"no {what} within {timeout_s} s")


def _short_config(tmp_path: Path) -> Path:
    """The vertical mission made short: start at 2.5 m (the fake's take-off height), 1 m down, quick
    settles and ladder; the CI stale allowance (15 periods = 0.3 s) so only the injected pause is stale."""
    cfg = tomllib.loads((MISSIONS_DIR / f"{MISSIONS['vertical']}.toml").read_text())
    cfg["flight"].update(start_height_m=2.5, min_alt_m=1.0, settle_s=0.5)
    cfg["plan"]["descent_m"] = 1.0
    cfg["guard"]["stale_periods"] = 15.0
    cfg["abort"].update(recover_max_s=1.0, hold_dwell_s=0.5)
    path = tmp_path / "vertical-short.toml"
    path.write_text(tomli_w.dumps(cfg))
    return path


@pytest.mark.flight
def test_on_the_fake_stale_telemetry_during_the_ladders_land_is_noted_and_it_still_lands(
    fake_vehicle_factory, tmp_path
):
    fake = fake_vehicle_factory("x500", param={"MPC_LAND_SPEED": 1.0, "COM_DISARM_LAND": 0.5})
    relay = StateDropRelay(fake.port)
    logs = tmp_path / "logs"
    cmd = [sys.executable, "-m", "flighttest", "fly", "vertical", "--connect", relay.url, "--vehicle", "x500",
           "--config", str(_short_config(tmp_path)), "--log-dir", str(logs), "--json", "--yes"]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        _wait(logs, proc, lambda e: e["event"] == "stream_start", "the descent")
        proc.send_signal(signal.SIGINT)  # the abort: the ladder runs Recover → Hold → Land
        _wait(logs, proc, lambda e: e["event"] == "ladder" and e.get("rung") == "LAND", "the ladder's Land")
        relay.drop = True  # the telemetry pause, while the ladder lands
        time.sleep(1.0)
        relay.drop = False
        out, err = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            proc.kill()
        relay.close()
    assert relay.dropped > 0
    assert proc.returncode == 1, err
    s = json.loads(out)
    assert s["outcome"] == "aborted" and "SIGINT" in s["abort_reason"]
    ladder = [(e["rung"], e["why"]) for e in _events(logs) if e["event"] == "ladder"]
    assert ("LAND", "telemetry stale during Land: re-sending Land") in ladder or any(
        r == "LAND" and "telemetry stale during Land" in w for r, w in ladder
    ), ladder
    assert any("during Land is over: telemetry back" in w for _, w in ladder), ladder
    assert ladder[-1] == ("DONE", "landed"), ladder
    summary = json.loads((Path(s["log_dir"]) / "summary.json").read_text())
    assert summary["outcome"] == "aborted" and summary["ladder"][-1]["rung"] == "DONE"
    assert summary["final_armed"] is False
    fake.stop()
    tr = pd.read_csv(fake.truth_log, low_memory=False)
    assert not (tr["kind"] == "crash").any()
    last = tr[tr["kind"] == "state"].iloc[-1]
    assert last["armed"] == 0 and last["landed"] == 1
