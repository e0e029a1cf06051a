"""The live panel, as an operator sees it: ``flighttest fly`` under a pseudo-terminal against the
fake, answering the go/no-go prompt like a person, the screen captured and read back."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import struct
import sys
import termios
import time
import tomllib
from pathlib import Path

import pytest
import tomli_w

from flighttest.flying.mission_scripts import MISSIONS_DIR

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


def _run_in_pty(argv: list[str], answer: bytes, timeout_s: float = 120.0) -> tuple[int, str]:
    pid, fd = pty.fork()
    if pid == 0:  # the child: a terminal 120 columns wide
        fcntl.ioctl(0, termios.TIOCSWINSZ, struct.pack("HHHH", 50, 120, 0, 0))
        os.environ.update(TERM="xterm-256color", COLUMNS="120", LINES="50")
        os.environ.pop("NO_COLOR", None)
        os.execvp(argv[0], argv)
    out = b""
    answered = False
    deadline = time.monotonic() + timeout_s
    try:
        while time.monotonic() < deadline:
            r, _, _ = select.select([fd], [], [], 0.2)
            if not r:
                continue
            try:
                data = os.read(fd, 65536)
            except OSError:  # the child closed the terminal
                break
            if not data:
                break
            out += data
            if not answered and b"arm and fly?" in out:
                os.write(fd, answer)
                answered = True
    finally:
        if time.monotonic() >= deadline:
            os.kill(pid, 9)
        _, status = os.waitpid(pid, 0)
        os.close(fd)
    return os.waitstatus_to_exitcode(status), ANSI.sub("", out.decode("utf-8", "replace"))


@pytest.mark.flight
def test_the_live_panel_shows_the_flight_and_the_prompt_is_answered(fake_vehicle_factory, tmp_path):
    cfg = tomllib.loads((MISSIONS_DIR / "vertical_descent.toml").read_text())
    cfg["guard"]["stale_periods"] = 15.0  # a busy CI machine (see test_fly_missions.py)
    cfg_path = tmp_path / "vertical.toml"
    cfg_path.write_text(tomli_w.dumps(cfg))
    fake = fake_vehicle_factory("x500")
    rc, screen = _run_in_pty(
        [sys.executable, "-m", "flighttest", "fly", "vertical", "--connect", fake.url, "--vehicle", "x500",
         "--height", "5", "--config", str(cfg_path), "--log-dir", str(tmp_path / "logs")],
        answer=b"y\n",
    )  # fmt: skip
    assert rc == 0, screen[-3000:]
    # the preflight table, then the prompt, answered
    assert "Preflight — vertical on 'x500'" in screen and "GO: arm and fly?" in screen
    # every field of the panel, with live values while it descended
    assert "flighttest fly — vertical" in screen
    rows = {
        "phase": r"phase\s+│ stream\b",
        "mode": r"mode / armed\s+│ OFFBOARD / True",
        "altitude": r"altitude\s+│ [1-4]\.\d\d m",
        "descent rate": r"descent rate\s+│ \+0\.[3-9]\d m/s",
        "w / u": r"w / u\s+│ 0\.[3-9]\d / 0\.\d\d m/s",
        "guard margin": r"guard margin\s+│ 0\.\d\d m/s \(predicted -?\d\.\d\d\)",
        "verdict": r"guard verdict\s+│ ok",
        "jitter": r"setpoint jitter\s+│ p99 \d+\.\d ms, [45]\d\.\d Hz",
        "link": r"link\s+│ up, posvel [45]\d Hz, last \d+ ms",
        "wind": r"wind\s+│ 0\.\d ± 0\.\d\d m/s( from \d{3}°)? \(flighttest\)",  # still air, its own estimate
        "updraft": r"updraft allowed\s+│ 0\.\d\d m/s \(gusts 1 σ 0\.\d\d m/s\)",
    }
    missing = [name for name, pattern in rows.items() if not re.search(pattern, screen)]
    assert not missing, f"panel rows not seen: {missing}\n{screen[-2500:]}"
    assert "completed" in screen and "log: " in screen
    assert list((tmp_path / "logs").glob("*/summary.json"))
    events = next((tmp_path / "logs").glob("*/events.jsonl")).read_text()
    assert '"event": "go", "by": "operator"' in events
    assert Path(fake.truth_log).is_file()
