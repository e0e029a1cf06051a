"""Flying from Python without argparse (issue 23): ``flighttest.fly_mission`` / ``prepare_flight``, the
library under ``flighttest fly`` and the mission scripts, and ``missions/fly_from_python.py`` that uses it."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
import tomli_w

import flighttest
from flighttest.errors import FlighttestError
from flighttest.flying.mission_scripts import MISSIONS, MISSIONS_DIR
from sitl_fakes.scripted import ScriptedAutopilot
from sitl_fakes.virtual_time import run_virtual

URL = "udpin://0.0.0.0:14540"


def test_a_named_mission_flies_from_keyword_arguments(tmp_path):
    ap = ScriptedAutopilot()
    said: list[object] = []
    out = run_virtual(flighttest.fly_mission_async(
        "vertical", open_link=lambda _tlog, _event: ap, connect=URL, vehicle="x500", height_m=4.0, descent_m=2.0,
        yes=True, log_dir=tmp_path, print_fn=said.append))  # fmt: skip
    assert out.outcome == "completed" and out.exit_code == 0 and out.descent_time_s is not None
    assert Path(out.log_dir).parent == tmp_path and (Path(out.log_dir) / "summary.json").is_file()
    assert out.summary()["mission"] == "vertical" and not ap.armed and ap.p_ned[2] == 0.0
    assert any(getattr(x, "title", "") for x in said)  # the preflight table went to print_fn


@pytest.mark.parametrize(("kwargs", "says"), [
    ({"height_m": -1.0}, "height_m"),
    ({"descent_m": 30.0, "height_m": 5.0}, "(set descent_m, height_m or min_alt_m)"),
    ({"wind_ned_mps": (0.0, 1.0)}, "wind_ned_mps: three numbers"),
    ({"max_descent_mps": 1.0}, "max_descent_mps applies to the probe mission only"),
])  # fmt: skip
def test_bad_keywords_are_one_line_naming_the_keyword(tmp_path, kwargs, says):
    args = {"connect": URL, "vehicle": "x500", "log_dir": tmp_path, **kwargs}
    with pytest.raises(FlighttestError) as exc:
        flighttest.prepare_flight("vertical", **args)
    assert says in str(exc.value) and "\n" not in str(exc.value)
    assert not any(tmp_path.iterdir())  # nothing written


def test_the_command_line_names_its_options_in_the_same_checks(tmp_path):
    p = subprocess.run([sys.executable, "-m", "flighttest", "fly", "vertical", "--connect", URL, "--vehicle", "x500",
                        "--height", "-1", "--log-dir", str(tmp_path)], capture_output=True, text=True)  # fmt: skip
    assert p.returncode == 2 and "--height" in p.stderr and "height_m" not in p.stderr


@pytest.mark.flight
def test_the_example_script_flies_the_helix_through_the_library(fake_vehicle_factory, tmp_path):
    # the user's own mission folder (FLIGHTTEST_MISSIONS) holds the helix with the CI stale allowance
    # (tests/test_fly_missions.py: CI_STALE_PERIODS)
    user = tmp_path / "missions"
    user.mkdir()
    shutil.copy(MISSIONS_DIR / f"{MISSIONS['helix']}.py", user)
    cfg = tomllib.loads((MISSIONS_DIR / f"{MISSIONS['helix']}.toml").read_text())
    cfg["guard"]["stale_periods"] = 15.0
    (user / f"{MISSIONS['helix']}.toml").write_text(tomli_w.dumps(cfg))
    fake = fake_vehicle_factory("x500")
    env = {**__import__("os").environ, "FLIGHTTEST_MISSIONS": str(user), "FLIGHTTEST_LOG_DIR": str(tmp_path / "logs")}
    p = subprocess.run([sys.executable, str(MISSIONS_DIR / "fly_from_python.py"), fake.url], capture_output=True,
                       text=True, timeout=150, env=env, stdin=subprocess.DEVNULL)  # fmt: skip
    assert p.returncode == 0, p.stdout + p.stderr
    outcome, *_, log_dir = p.stdout.strip().splitlines()[-1].split()
    assert outcome == "completed" and (Path(log_dir) / "summary.json").is_file()
    assert Path(log_dir).parent == tmp_path / "logs"
