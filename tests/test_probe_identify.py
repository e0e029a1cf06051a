"""The sine-sweep VRS probe end to end against the fake: fly it (``flighttest fly probe``), then find the
fake's truth onset in its log (``flighttest identify``), store it in the profile, and analyse the log.

Stated tolerance of the identification: within ±0.1 m/s of the truth onset, and within three times
its own stated uncertainty (+0.01 m/s for the grid). The probes are kept short (start at 5 m, 2 m
sweep) so the file runs in about a minute on two workers.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

pytestmark = pytest.mark.flight

MISSIONS = Path(__file__).resolve().parents[1] / "missions"
LOG_FILES = ("meta.json", "flight.tlog", "setpoints.csv", "guard.csv", "events.jsonl", "preflight.json",
             "trajectory.csv", "trajectory.json", "summary.json")  # fmt: skip
# the onset read from the log: within this of the truth
TOLERANCE_MPS = 0.15
DETECTABLE_DEPTH_N = 0.03


def _set(text: str, key: str, value: str) -> str:
    new, n = re.subn(rf"(?m)^{key}\s*=\s*[^#\n]*", f"{key} = {value}  ", text)
    assert n == 1, key
    return new


def probe_config(tmp_path: Path) -> Path:
    """The mission's own TOML, shortened for a test, with the field's stale-telemetry limit (0.25 s:
    a loaded 2-core CI box meets it)."""
    text = (MISSIONS / "vrs_probe.toml").read_text()
    for key, value in {"start_height_m": "5.0", "min_alt_m": "1.5", "settle_s": "1.5", "amplitude_m": "2.0",
                       "omega0_rps2": "0.05", "ramp_s": "2.0", "duration_s": "30.0",
                       "stale_after_s": "0.25"}.items():  # fmt: skip
        text = _set(text, key, value)
    path = tmp_path / "probe.toml"
    path.write_text(text)
    return path


def run_cli(*args: str, env: dict | None = None, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flighttest", *args], capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, **(env or {})})  # fmt: skip


def fly_probe(fake, tmp_path: Path, top_mps: float | None) -> tuple[Path, dict]:
    cmd = ["fly", "probe", "--config", str(probe_config(tmp_path)), "--connect", fake.url, "--vehicle", "x500",
           "--yes", "--json", "--log-dir", str(tmp_path / "logs")]  # fmt: skip
    if top_mps is not None:
        cmd += ["--max-descent-speed", str(top_mps)]
    proc = run_cli(*cmd, timeout=150)
    folders = sorted((tmp_path / "logs").glob("*-probe"))
    assert proc.returncode == 0 and folders, proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads(proc.stdout)
    assert summary == json.loads((folders[-1] / "summary.json").read_text())
    return folders[-1], summary


@pytest.mark.parametrize(("truth_onset", "top_mps"), [(0.6, 1.0), (1.0, None)])  # None: 1.75·w_allow = 1.48
def test_probe_finds_the_truth_onset(fake_vehicle_factory, tmp_path, truth_onset, top_mps):
    # identification's own precision, on a perfect estimate (identify told so: --velocity-sd 0); with PX4's
    # vertical estimate error (0.16 m/s, correlated over 3 s) the onset read from one pass is off by as much,
    # which identify's default uncertainty carries (tests/test_campaign.py flies with it)
    fake = fake_vehicle_factory("x500", truth_onset=truth_onset, seed=3, estimate_error=0)
    folder, summary = fly_probe(fake, tmp_path, top_mps)
    fake.stop()

    # the probe stopped on the fluctuation detector, recovered and landed; the log folder is complete
    assert summary["outcome"] == "probe_stopped", summary
    assert summary["abort_verdict"] == "fluctuation"
    assert "angular-rate" in summary["abort_reason"] or "vertical-acceleration" in summary["abort_reason"]
    assert summary["phase_at_end"] == "stream" and summary["final_armed"] is False
    assert [r["rung"] for r in summary["ladder"]][:3] == ["RECOVER", "HOLD", "LAND"]
    assert all((folder / f).stat().st_size > 0 for f in LOG_FILES)
    events = [json.loads(line) for line in (folder / "events.jsonl").read_text().splitlines()]
    base = next(e for e in events if e["event"] == "fluct_baseline")  # measured in the settle, before streaming
    # a PX4-like hover is not still: PX4 SITL hovers with 4.8 °/s of rate std (../shared/px4_sih)
    assert base["rate_std_dps"] is not None and base["rate_std_dps"] < 6.0
    abort = next(e for e in events if e["event"] == "abort")
    assert abort["phase"] == "stream"
    meta = json.loads((folder / "trajectory.json").read_text())
    assert meta["max_descent_mps"] == pytest.approx(top_mps or 1.75 * 0.8475, abs=0.05)

    # the truth: the sweep went past the onset, was stopped soon after it, never crashed, the
    # disturbance stayed small
    truth = pd.read_csv(fake.truth_log, low_memory=False)
    assert not (truth["kind"] == "crash").any()
    state = truth[truth["kind"] == "state"]
    # … within a second of the disturbance becoming one to detect: 3 % of thrust (depth 0.03). A
    # shallower graze may go unseen: a PX4-like vehicle's own motion in the sweep (its cascade, its
    # estimate's error) shows 0.4-1.4 °/s of rate fluctuation without any VRS
    inside = state[state["depth_n"] > 0]
    assert len(inside) > 0 and float(inside["unix_s"].iloc[0]) < abort["unix_s"]
    deep = state[state["depth_n"] > DETECTABLE_DEPTH_N]
    assert deep.empty or abort["unix_s"] < float(deep["unix_s"].iloc[0]) + 1.0
    assert state["depth_n"].max() < 0.12 and state["thrust_loss"].max() < 0.1
    assert state["w_mps"].max() < truth_onset + 0.5

    # identification recovers the truth within the stated tolerance and its own uncertainty
    vehicles = tmp_path / "vehicles"
    env = {"FLIGHTTEST_VEHICLES": str(vehicles)}
    r = run_cli("identify", str(folder), "--vehicle", "x500", "--json", "--write-profile", "--velocity-sd", "0",
                env=env)  # fmt: skip
    assert r.returncode == 0, r.stderr
    onset = json.loads(r.stdout)
    assert onset["estimate_error_mps"] == 0.0
    err = abs(onset["w_onset_mps"] - truth_onset)
    assert err <= TOLERANCE_MPS, onset
    assert 0 < onset["uncertainty_mps"] < TOLERANCE_MPS and err <= 3 * onset["uncertainty_mps"] + 0.01, onset
    assert onset["w_onset_n"] == pytest.approx(onset["w_onset_mps"] / onset["v_h_mps"])
    assert onset["profile_written"] == str(vehicles / "x500.toml")
    r = run_cli("vehicle", "show", "x500", "--json", env=env)
    assert r.returncode == 0, r.stderr
    shown = json.loads(r.stdout)
    assert shown["w_allow_mps"] == pytest.approx(onset["w_onset_mps"])
    assert "identified" in shown["w_allow_source"] and folder.name in shown["w_allow_source"]

    # analysis reports the probe's descents with their fluctuation: quiet below the onset, loud
    # in the sweep the detector stopped
    r = run_cli("analyse", str(folder), "--json")
    assert r.returncode == 0, r.stderr
    (report,) = json.loads(r.stdout)
    descents = [d for d in report["descents"] if d["mission"] == "probe"]
    assert descents and all(d["fluct_index_max"] is not None for d in descents)
    loud = [d for d in descents if d["max_rate_mps"] > truth_onset + 0.05]
    # the sweep's last descent runs on into the ladder's recovery and Land: labelled by where it began
    assert loud, descents
    assert loud[0]["phase"] in ("stream", "abort_recover", "abort_land"), descents
    assert loud[0]["fluct_index_max"] > 3.0, descents
    assert loud[0]["rate_rms_max_radps"] > 0.01
    # the earlier sweeps slower than the onset are quiet (the landing after the abort still shakes:
    # it is not one of them) — quiet as a PX4-like vehicle is: about 1 °/s of its own motion
    quiet = [d for d in descents if d["max_rate_mps"] < truth_onset and d["start_s"] < loud[0]["start_s"]]
    assert all(d["fluct_index_max"] < 1.0 and d["rate_rms_max_radps"] < 0.03 for d in quiet), descents
