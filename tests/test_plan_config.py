"""Each mission's [plan] defaults live in one place (flighttest.flying.plan_config): the shipped TOMLs agree
with them, the mission scripts use them, and `flighttest plan probe|vertical` plans what `fly` flies."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from flighttest.errors import FlighttestError
from flighttest.flying.mission_scripts import load_mission_module, mission_config_path
from flighttest.flying.missions_config import load_mission_config
from flighttest.flying.plan_config import HelixPlanConfig, ProbePlanConfig, VerticalPlanConfig
from flighttest.model.profiles import load_profile
from flighttest.model.trajectory import Trajectory
from flighttest.planner.tracking import TrackingMargin

CONFIGS = {"probe": ProbePlanConfig, "vertical": VerticalPlanConfig, "helix": HelixPlanConfig}


@pytest.mark.parametrize("mission", sorted(CONFIGS))
def test_the_shipped_toml_writes_out_the_defaults(mission):
    table = load_mission_config(mission_config_path(mission)).plan
    cls = CONFIGS[mission]
    defaults = cls()
    for f in dataclasses.fields(cls):
        if f.name in table:
            assert table[f.name] == getattr(defaults, f.name), (mission, f.name)
    if mission == "helix":  # its tracking margins: TrackingMargin's defaults
        margin = TrackingMargin()
        for f in dataclasses.fields(TrackingMargin):
            assert table[f.name] == getattr(margin, f.name), f.name
    # and a table that leaves every key out plans the same (the defaults apply)
    assert cls.from_table({}) == cls.from_table(table)


def test_a_missing_key_takes_the_default_not_another_value():
    assert ProbePlanConfig.from_table({"amplitude_m": 2}) == ProbePlanConfig(amplitude_m=2.0)
    assert ProbePlanConfig().top_speed_mps(0.8) == pytest.approx(1.4)
    assert ProbePlanConfig(max_descent_mps=1.1).top_speed_mps(0.8) == 1.1
    with pytest.raises(FlighttestError, match="accel_fraction"):
        ProbePlanConfig.from_table({"accel_fraction": 0.0})
    with pytest.raises(FlighttestError, match="must be a number"):
        VerticalPlanConfig.from_table({"descent_m": "3"})


@pytest.mark.parametrize("mission", ["probe", "vertical"])
def test_flighttest_plan_plans_what_fly_flies(tmp_path, mission):
    prof = load_profile("x500")
    flown = load_mission_module(mission).plan(prof, load_mission_config(mission_config_path(mission)))
    r = subprocess.run([sys.executable, "-m", "flighttest", "plan", mission, "--vehicle", "x500", "--json", "-o",
                        str(tmp_path / "p")], capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr
    planned = Trajectory.load(tmp_path / "p", profile=prof)
    assert planned.meta["t_f_s"] == pytest.approx(flown.meta["t_f_s"], rel=1e-6)
    a = planned.resample(50.0).df
    b = flown.resample(50.0).df
    assert len(a) == len(b) and np.allclose(a["d_m"], b["d_m"], atol=1e-6)
    json.loads(r.stdout)  # JSON only
