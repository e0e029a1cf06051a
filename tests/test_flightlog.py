"""Flight log folders: written as the vehicle flies, complete lines only, readable after SIGKILL."""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest

from flighttest.errors import FlighttestError
from flighttest.flying.guard import OK, Decision, GuardSample
from flighttest.flying.log_writer import GUARD_COLUMNS, SETPOINT_COLUMNS, FlightLogWriter


def _rows(path: Path) -> list[str]:
    """What another process sees on disk right now (no help from our file objects)."""
    return path.read_text(encoding="utf-8").splitlines()


def test_folder_layout_and_rows_reach_the_disk_as_they_are_written(tmp_path):
    log = FlightLogWriter(tmp_path, "helix descent/1", t0_mono=100.0)
    assert log.dir.parent == tmp_path and log.dir.name.endswith("-helix_descent_1")
    assert _rows(log.dir / "setpoints.csv") == [",".join(SETPOINT_COLUMNS)]
    assert _rows(log.dir / "guard.csv") == [",".join(GUARD_COLUMNS)]
    log.setpoint(101.5, "stream", 1.0, 2.0, -5.0, 0.1, 0.2, 0.3, 0.0, 0.0, 0.5, 90.0)
    sample = GuardSample(101.52, 0.1, 0.2, 0.3, 1.0, 0.0, 0.0, 0.0, 5.0)
    log.guard(Decision(101.52, OK, "none", "", 0.3, 0.22, 0.45, 0.4, sample))
    log.event(101.6, "phase", phase="stream")
    # no close, no explicit flush: the rows are already in the files
    sp = _rows(log.dir / "setpoints.csv")
    assert len(sp) == 2 and sp[1].startswith("1.5,") and sp[1].endswith(",90,stream")
    g = _rows(log.dir / "guard.csv")
    assert len(g) == 2 and ",ok,0.3,0.22,0.45,0.4,none," in g[1]
    ev = json.loads(_rows(log.dir / "events.jsonl")[0])
    assert ev["event"] == "phase" and ev["phase"] == "stream" and ev["t_s"] == pytest.approx(1.6)
    assert ev["unix_s"] == pytest.approx(log.unix0 + 1.6)
    log.write_summary({"outcome": "completed"})
    summary = json.loads((log.dir / "summary.json").read_text())
    assert summary == {"outcome": "completed", "log_dir": str(log.dir)}
    log.close()
    log.setpoint(102.0, "late", *([0.0] * 10))  # after close: ignored, no error
    assert len(_rows(log.dir / "setpoints.csv")) == 2


def test_non_finite_values_are_empty_cells_and_stale_decisions_log_without_a_sample(tmp_path):
    log = FlightLogWriter(tmp_path, "m", t0_mono=0.0)
    log.guard(Decision(1.0, "stale", "abort", "no telemetry for 70 ms (> 60 ms)"))
    log.setpoint(1.0, "p", math.nan, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    log.close()
    g = pd.read_csv(log.dir / "guard.csv")
    assert g["verdict"].tolist() == ["stale"] and g["reason"].iloc[0].startswith("no telemetry")
    assert g[["w_mps", "vn_mps", "alt_m"]].isna().all(axis=None)
    sp = pd.read_csv(log.dir / "setpoints.csv")
    assert math.isnan(sp["n_m"].iloc[0]) and sp["e_m"].iloc[0] == 0.0


def test_two_flights_in_the_same_second_get_two_folders(tmp_path):
    a, b = FlightLogWriter(tmp_path, "m"), FlightLogWriter(tmp_path, "m")
    assert a.dir != b.dir and a.dir.is_dir() and b.dir.is_dir()
    a.close()
    b.close()


def test_an_unwritable_log_root_is_one_error_line(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(FlighttestError, match="cannot create log folder"):
        FlightLogWriter(blocker / "logs", "m")


WRITER = textwrap.dedent(
    """
    import sys, time
    from flighttest.flying.log_writer import FlightLogWriter
    from flighttest.flying.guard import Decision, GuardSample
    log = FlightLogWriter(sys.argv[1], "killed", t0_mono=time.monotonic())
    print(log.dir, flush=True)
    k = 0
    while True:
        t = time.monotonic()
        log.setpoint(t, "stream", 0.0, 0.0, -5.0 + 0.001 * k, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, float(k))
        s = GuardSample(t, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 5.0)
        log.guard(Decision(t, "ok", "none", f"row {k}", 0.5, 0.0, 0.2, 0.2, s))
        if k % 20 == 0:
            log.event(t, "tick", k=k)
        print(k, flush=True)
        k += 1
        time.sleep(0.002)
    """
)


def test_a_log_written_by_a_process_killed_with_sigkill_is_complete_up_to_the_kill(tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    log_dir = Path(proc.stdout.readline().strip())
    last = -1
    deadline = time.monotonic() + 30
    while last < 300 and time.monotonic() < deadline:  # a second or so of rows
        last = int(proc.stdout.readline())
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    assert last >= 300
    sp = pd.read_csv(log_dir / "setpoints.csv")
    g = pd.read_csv(log_dir / "guard.csv")
    # every row the writer finished before it reported it is there, and every row is whole
    assert len(sp) >= last + 1 and sp["yaw_deg"].tolist() == list(range(len(sp)))
    assert sp.notna().all(axis=None)
    assert len(g) >= last + 1 and g["reason"].tolist() == [f"row {k}" for k in range(len(g))]
    assert g[["verdict", "w_mps", "alt_m"]].notna().all(axis=None)
    events = [json.loads(x) for x in (log_dir / "events.jsonl").read_text().splitlines()]
    assert [e["k"] for e in events] == list(range(0, 20 * len(events), 20)) and events[-1]["k"] >= last - 20
    assert not (log_dir / "summary.json").exists()  # the mark of a flight that did not end cleanly


@pytest.mark.flight
def test_a_flight_killed_mid_descent_leaves_a_folder_the_analysis_opens(fake_vehicle_factory, tmp_path):
    import tomllib

    import tomli_w

    from flighttest.analysis.loaders.folder import load_folder
    from flighttest.flying.mission_scripts import MISSIONS_DIR

    cfg = tomllib.loads((MISSIONS_DIR / "vertical_descent.toml").read_text())
    cfg["guard"]["stale_periods"] = 15.0  # a busy CI machine; this test is about the log
    cfg_path = tmp_path / "vertical.toml"
    cfg_path.write_text(tomli_w.dumps(cfg))
    fake = fake_vehicle_factory("x500")
    logs = tmp_path / "logs"
    proc = subprocess.Popen(
        [sys.executable, "-m", "flighttest", "fly", "vertical", "--connect", fake.url, "--vehicle", "x500",
         "--height", "5", "--config", str(cfg_path), "--log-dir", str(logs), "--yes", "--json"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
    )  # fmt: skip
    deadline = time.monotonic() + 90
    started = None
    while started is None and time.monotonic() < deadline and proc.poll() is None:
        for f in logs.glob("*/events.jsonl"):
            started = next((json.loads(x) for x in f.read_text().splitlines() if '"stream_start"' in x), None)
        time.sleep(0.05)
    assert started is not None, proc.stderr.read() if proc.poll() is not None else "no stream_start"
    time.sleep(1.0)
    t_kill = time.time()
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    (log_dir,) = logs.iterdir()
    assert not (log_dir / "summary.json").exists()
    flight = load_folder(log_dir)
    assert flight.source == "flighttest-folder" and not flight.notes
    assert flight.meta["mission"] == "vertical" and flight.meta["trajectory_meta"]["kind"] == "vertical"
    assert len(flight.state) > 100 and flight.state["unix_s"].iloc[-1] > t_kill - 1.0
    stream = flight.setpoints[flight.setpoints["phase"] == "stream"]
    assert len(stream) >= 40 and flight.setpoints["unix_s"].iloc[-1] > t_kill - 1.0
    assert len(flight.guard) > 100 and flight.guard["unix_s"].iloc[-1] > t_kill - 1.0
    assert any(e["event"] == "stream_start" for e in flight.events)
    # the vehicle was left to its own offboard-loss failsafe (COM_OF_LOSS_T = 1 s), which held it
    time.sleep(max(0.0, t_kill + 2.0 - time.time()))
    fake.stop()
    tr = pd.read_csv(fake.truth_log, low_memory=False)
    assert (tr["kind"] == "failsafe").any() and not (tr["kind"] == "crash").any()
    assert tr[tr["kind"] == "state"].iloc[-1]["mode"] == "HOLD"
