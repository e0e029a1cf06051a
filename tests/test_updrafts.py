"""The updraft the guard allows (issue 21): no autopilot reports vertical air, and an updraft moves ``w`` one
for one. Pure, in virtual time: the worst air with an updraft, the gust meter, the operator's figure, the
guard's verdict and the analysis's worst-air margin."""

from __future__ import annotations

import json
import math
import random
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

import flighttest
from flighttest.analysis.exposure import velocity_track
from flighttest.analysis.wind import LogWind
from flighttest.errors import FlighttestError
from flighttest.flying import guard as g
from flighttest.flying.missions_config import load_mission_config
from flighttest.flying.wind import (
    GUST_FLOOR_MPS,
    GUST_MIN_SAMPLES,
    GUST_WINDOW_S,
    UPDRAFT_SIGMAS,
    GustMeter,
    WindSources,
)
from flighttest.model.frames import GuardRegion, disk_tilt_sin, quat_from_euler, worst_blade_velocity_mps
from flighttest.model.profiles import load_profile

REGION = GuardRegion(w_allow_mps=0.8, v_h_mps=6.0, cone_deg=20.0, margin_mps=0.1)
NO_REPORT = SimpleNamespace(wind_ned_mps=None, wind_accuracy_mps=math.nan, t_wind=None)


def test_an_updraft_raises_w_one_for_one_and_takes_u_by_the_tilt():
    assert worst_blade_velocity_mps(0.3, 2.0, 0.0, 0.0, 0.4) == pytest.approx((0.7, 2.0))
    tilt = math.sin(math.radians(30.0))
    w, u = worst_blade_velocity_mps(0.3, 2.0, tilt, 0.2, 0.4)
    assert w == pytest.approx(0.3 + tilt * 0.2 + 0.4) and u == pytest.approx(2.0 - 0.2 - tilt * 0.4)
    assert worst_blade_velocity_mps(0.0, 0.1, 1.0, 0.0, 0.4)[1] == 0.0  # never below zero


def feed(meter: GustMeter, sd_mps: float, seconds: float, t0: float = 0.0, seed: int = 1) -> float:
    rng = random.Random(seed)
    t = t0
    while t < t0 + seconds:
        meter.add(t, 3.0 + rng.gauss(0.0, sd_mps), rng.gauss(0.0, sd_mps))
        t += 0.02
    return t


def test_the_gust_meter_reads_the_spread_above_steady_airs():
    steady = GustMeter()
    feed(steady, 0.02, 8.0)  # the estimate's own wander in steady air
    assert steady.sd_mps == 0.0
    gusty = GustMeter()
    feed(gusty, 0.25, 8.0)
    assert gusty.sd_mps == pytest.approx(0.25 - GUST_FLOOR_MPS, abs=0.03)
    few = GustMeter()
    for k in range(GUST_MIN_SAMPLES - 1):
        few.add(0.02 * k, 3.0 * (k % 2), 0.0)
    assert few.sd_mps == 0.0  # not yet held still long enough to say


def test_the_gust_meter_forgets_beyond_its_window():
    m = GustMeter()
    t = feed(m, 0.4, 3.0)
    assert m.sd_mps > 0.2
    feed(m, 0.01, GUST_WINDOW_S + 0.1, t0=t)
    assert m.sd_mps == 0.0
    assert m.samples[0][0] >= m.samples[-1][0] - GUST_WINDOW_S


def test_the_wind_carries_the_larger_of_the_operators_gusts_and_the_measured():
    src = WindSources(stated_gust_sd_mps=0.2)
    w = src.current(NO_REPORT, 0.0)
    assert w.gust_sd_mps == 0.2 and w.updraft_mps == pytest.approx(UPDRAFT_SIGMAS * 0.2)
    assert w.describe()["gust_sd_mps"] == 0.2
    feed(src.gusts, 0.5, 5.0)
    measured = src.gusts.sd_mps
    assert measured > 0.2 and src.current(NO_REPORT, 0.0).gust_sd_mps == measured
    assert WindSources().current(NO_REPORT, 0.0).updraft_mps == 0.0  # still air: nothing allowed


def test_the_wind_sources_measure_gusts_only_when_asked():
    x500 = load_profile("x500")
    src = WindSources.for_flight(x500.drag, x500.mass_kg, None, gust_sd_mps=0.0)
    f_body = (0.0, 0.0, -9.80665)
    for k in range(400):  # 8 s of a still hover: the filter settles
        st = SimpleNamespace(vn_mps=0.0, ve_mps=0.0, vd_mps=0.0, t_posvel=0.02 * k, q=(1.0, 0.0, 0.0, 0.0),
                             t_att=0.02 * k, accel_frd_mps2=f_body)  # fmt: skip
        src.on_imu(0.02 * k, st, measure_gusts=k >= 200)
    assert src.estimator is not None and src.estimator.sd_mps < 0.3
    assert 0 < len(src.gusts.samples) <= 200  # only the samples it was asked to measure, once settled
    assert src.current(NO_REPORT, 8.0).gust_sd_mps == 0.0  # a still estimate: no gusts


def test_the_guard_judges_the_updraft_it_allows():
    limits = g.GuardLimits(region=REGION, horizon_s=0.0, debounce_samples=1, clear_violation_mps=0.05)
    calm = g.GuardSample(0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 10.0)
    d = g.Guard(limits).on_sample(calm)
    assert d.verdict == g.OK and d.margin_mps == pytest.approx(0.8 - 0.1 - 0.5)
    gusty = g.GuardSample(0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 10.0, updraft_mps=0.4)
    d = g.Guard(limits).on_sample(gusty)
    assert d.margin_mps == pytest.approx(0.8 - 0.1 - 0.9) and d.verdict == g.VIOLATION and d.aborts
    assert d.w_mps == pytest.approx(0.5)  # logged as estimated; judged with the updraft


def test_the_analysis_judges_the_worst_air_with_the_logged_gusts():
    n = 5
    q = quat_from_euler(math.radians(20.0), 0.0, 0.0)
    state = pd.DataFrame({"t_s": np.arange(n) * 0.1, "vn_mps": 1.0, "ve_mps": 0.0, "vd_mps": 0.4,
                          "qw": q[0], "qx": q[1], "qy": q[2], "qz": q[3],
                          "wn_mps": 0.0, "we_mps": 0.0, "wd_mps": 0.0})  # fmt: skip
    prof = load_profile("x500")
    ned, sd = np.zeros((n, 3)), np.full(n, 0.1)
    calm = velocity_track(state, prof, LogWind("logged: flighttest", "", ned, sd))
    gusty = velocity_track(state, prof, LogWind("logged: flighttest", "", ned, sd, gust_sd_mps=np.full(n, 0.2)))
    assert np.allclose(gusty["margin_mps"], calm["margin_mps"])  # at the estimate: as flown
    tilt = float(disk_tilt_sin(*q))
    drop = calm["margin_worst_mps"] - gusty["margin_worst_mps"]
    assert np.all(drop >= UPDRAFT_SIGMAS * 0.2 - 1e-9) and np.all(drop <= UPDRAFT_SIGMAS * 0.2 * (1 + tilt) + 1e-9)


def test_the_operators_gusts_are_a_checked_config_value(tmp_path):
    src = tmp_path / "m.toml"
    src.write_text('mission = "vertical"\n[guard]\ngust_sd_mps = -0.1\n', encoding="utf-8")
    with pytest.raises(FlighttestError, match="gust_sd_mps"):
        load_mission_config(src)
    src.write_text('mission = "vertical"\n[guard]\ngust_sd_mps = 0.3\n', encoding="utf-8")
    assert load_mission_config(src).guard.gust_sd_mps == 0.3


def test_gusts_whose_updraft_puts_a_hover_in_the_region_are_refused_before_anything_connects(tmp_path):
    # x500: w_allow 0.85 − margin 0.10; 0.4 m/s of gusts allow an updraft of 0.78 m/s, which the guard held
    # against the vehicle on the ground and aborted at arming ("marginal ... w=0.00")
    x500 = load_profile("x500")
    limit = (x500.w_allow_mps - x500.vrs.margin_mps) / UPDRAFT_SIGMAS
    src = tmp_path / "m.toml"
    logs = tmp_path / "logs"
    args = {"connect": "udpin://0.0.0.0:14540", "vehicle": "x500", "config": src, "log_dir": logs}
    src.write_text(f'mission = "vertical"\n[guard]\ngust_sd_mps = {limit - 0.01:.2f}\n', encoding="utf-8")
    assert flighttest.prepare_flight("vertical", **args).config.guard.gust_sd_mps == round(limit - 0.01, 2)
    src.write_text(f'mission = "vertical"\n[guard]\ngust_sd_mps = {limit + 0.01:.2f}\n', encoding="utf-8")
    with pytest.raises(FlighttestError, match=r"gust_sd_mps .* put even a hover .* inside x500's guard region"):
        flighttest.prepare_flight("vertical", **args)
    p = subprocess.run([sys.executable, "-m", "flighttest", "fly", "vertical", "--connect", "udpin://0.0.0.0:14540",
                        "--vehicle", "x500", "--config", str(src), "--log-dir", str(logs), "--json"],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    out = json.loads(p.stdout)
    assert p.returncode == 2 and out["outcome"] == "refused" and "gust_sd_mps" in out["error"]
    assert "Traceback" not in p.stderr and not logs.exists()
