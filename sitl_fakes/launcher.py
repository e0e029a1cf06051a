"""Start the fake vehicle as a subprocess from Python or pytest: ``FakeVehicle``.

The fake binds a free UDP port itself (``--port 0``: the kernel picks one, so parallel test workers
never race for a port) and announces it on its first line, ``connect: udpout://127.0.0.1:P``.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from flighttest.errors import FlighttestError

CONNECT_PREFIX = "connect: "
START_TIMEOUT_S = 20.0
STOP_TIMEOUT_S = 5.0


def _option(name: str, value: Any) -> list[str]:
    """``truth_onset=1.2`` → ``--truth-onset 1.2``; tuples join with commas (``--wind-ned=-2,1,0``); dict/list
    repeat."""
    flag = "--" + name.replace("_", "-")
    if isinstance(value, dict):
        return [x for k, v in value.items() for x in (flag, f"{k}={v}")]
    if isinstance(value, list):
        return [x for v in value for x in (flag, str(v))]
    if isinstance(value, tuple):  # one "--flag=a,b,c": a leading minus would read as another option
        return [f"{flag}={','.join(str(v) for v in value)}"]
    return [flag, str(value)]


class FakeVehicle:
    """A running ``python -m sitl_fakes``. Context manager; ``stop()`` is idempotent.

    Keyword options map onto the command line: ``FakeVehicle(truth_onset=1.0, wind_ned=(2, 0, 0),
    param={"MIS_TAKEOFF_ALT": 1.5}, peer=["127.0.0.1:14540"])``; ``autopilot="ardupilot", ekf_delay_s=2``
    for the ArduCopter personality (``--autopilot ardupilot --ekf-delay-s 2``).
    """

    def __init__(
        self,
        vehicle: str = "x500",
        port: int | None = None,
        truth_log: str | Path | None = None,
        extra_args: Iterable[str] = (),
        **options: Any,
    ):
        self.vehicle = vehicle
        self.requested_port = 0 if port is None else int(port)
        self._tmpdir = None
        if truth_log is None:
            self._tmpdir = tempfile.mkdtemp(prefix="sitl_fake_")
            truth_log = Path(self._tmpdir) / "truth.csv"
        self.truth_log = Path(truth_log)
        self.stderr_path = self.truth_log.with_name(self.truth_log.stem + ".stderr.txt")
        self.args = ["--vehicle", vehicle, "--port", str(self.requested_port), "--truth-log", str(self.truth_log)]
        for name, value in options.items():
            self.args += _option(name, value)
        self.args += list(extra_args)
        self.proc: subprocess.Popen | None = None
        self.port: int | None = None
        self.url: str | None = None
        self._drain: threading.Thread | None = None

    def start(self, timeout_s: float = START_TIMEOUT_S) -> FakeVehicle:
        if self.proc is not None:
            return self
        self.truth_log.parent.mkdir(parents=True, exist_ok=True)
        # the fake stops when this process dies: told our pid, it sees a parent that died before its loop began
        env = dict(os.environ, MAVLINK20="1", PYTHONUNBUFFERED="1", SITL_FAKES_PARENT_PID=str(os.getpid()))
        with open(self.stderr_path, "wb") as err:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "sitl_fakes", *self.args],
                stdout=subprocess.PIPE,
                stderr=err,
                stdin=subprocess.DEVNULL,
                env=env,
            )
        line = self._first_line(timeout_s)
        if not line.startswith(CONNECT_PREFIX):
            self.stop()
            detail = self.stderr_path.read_text(errors="replace").strip().splitlines()
            raise FlighttestError(
                f"fake vehicle did not start: {detail[-1] if detail else line.strip() or 'no output'}"
            )
        self.url = line[len(CONNECT_PREFIX):].strip()
        self.port = int(self.url.rsplit(":", 1)[1])
        # keep reading stdout so the fake can never block on a full pipe
        self._drain = threading.Thread(target=self._drain_stdout, daemon=True)
        self._drain.start()
        return self

    def _first_line(self, timeout_s: float) -> str:
        result: list[str] = []
        reader = threading.Thread(target=lambda: result.append(self.proc.stdout.readline().decode()), daemon=True)
        reader.start()
        reader.join(timeout_s)
        return result[0] if result else ""

    def _drain_stdout(self) -> None:
        try:
            for _ in self.proc.stdout:
                pass
        except (ValueError, OSError):
            pass

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> int | None:
        """SIGTERM, then SIGKILL after ``timeout_s``. Returns the exit code."""
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        return self.proc.returncode

    def pilot(self, **kwargs):
        """A pilot at the transmitter of an ArduCopter-personality fake (``sitl_fakes.pilot.Pilot``: RC
        overrides from the ground station's sysid; ``switch("LOITER")``, ``sticks(throttle=…)``)."""
        from sitl_fakes.pilot import Pilot

        if self.url is None:
            raise FlighttestError("the fake vehicle is not running")
        return Pilot(self.url, **kwargs)

    def read_truth(self):
        """The truth log as a pandas DataFrame (state and event rows; see README)."""
        import pandas as pd

        return pd.read_csv(self.truth_log, low_memory=False)

    def __enter__(self) -> FakeVehicle:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def __repr__(self) -> str:
        return f"FakeVehicle({self.vehicle!r}, url={self.url!r}, truth_log={str(self.truth_log)!r})"


def wait_for(predicate, timeout_s: float, period_s: float = 0.05) -> bool:
    """Poll ``predicate()`` until true or timeout; for tests reading the truth log."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(period_s)
    return bool(predicate())
