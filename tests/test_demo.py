"""The README's main job: ``flighttest demo`` flies the whole campaign against the fake, end to end."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from flighttest.profiles import load_profile


@pytest.mark.flight
def test_demo_runs_the_whole_campaign(tmp_path):
    env = {**os.environ, "FLIGHTTEST_VEHICLES": str(tmp_path / "my_vehicles")}
    # the busy CI machine runs other flights in parallel: relax the stale-telemetry allowance only
    proc = subprocess.run(
        [sys.executable, "-m", "flighttest", "demo", "--json", "--log-dir", str(tmp_path), "--stale-periods", "15"],
        capture_output=True, text=True, timeout=420, env=env,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    s = json.loads(proc.stdout)
    assert [f["mission"] for f in s["flights"]] == ["probe", "vertical", "helix"]
    assert [f["outcome"] for f in s["flights"]] == ["probe_stopped", "completed", "completed"]
    # the probe found the fake's true onset (its default: Onera's boundary for the x500's v_h)
    truth = load_profile("x500").w_allow_mps
    assert s["identified_w_allow_mps"] == pytest.approx(truth, abs=0.1)
    # ... stored in the demo's own profile folder, never the user's
    assert Path(s["identified_profile"]).parent == Path(s["out_dir"]) / "vehicles"
    assert not (tmp_path / "my_vehicles").exists()
    # the helix beats the vertical baseline over the same height
    assert s["speedup_helix_vs_vertical"] > 1.2
    assert (Path(s["report"]) / "report.md").is_file()
    assert Path(s["chart"]).stat().st_size > 10_000
    # the fake never crashed, and only the probe touched its true VRS region, briefly and shallowly
    truth_log = pd.read_csv(Path(s["out_dir"]) / "fake_truth.csv", low_memory=False)
    assert not (truth_log["kind"] == "crash").any()
    state = truth_log[truth_log["kind"] == "state"]
    assert pd.to_numeric(state["depth_n"]).max() < 0.1
