"""Mission configs: validated on load; bad files and fields are one error line, exit code 2."""

from __future__ import annotations

import subprocess
import sys

import pytest

from flighttest.errors import FlighttestError
from flighttest.flying.mission_scripts import MISSIONS, MISSIONS_DIR
from flighttest.flying.missions_config import load_mission_config, mission_config_from_dict
from flighttest.model.profiles import load_profile
from flighttest.planner.tracking import TrackingMargin, helix_problem_for_flight


@pytest.mark.parametrize("mission", sorted(MISSIONS))
def test_the_shipped_mission_configs_load(mission):
    cfg = load_mission_config(MISSIONS_DIR / f"{MISSIONS[mission]}.toml")
    assert cfg.mission == mission
    assert cfg.flight.start_height_m > cfg.flight.min_alt_m
    # the field default (flighttest.flying.guard.STALE_AFTER_S), not the older 3 periods = 60 ms
    assert cfg.to_dict()["guard"]["stale_after_s"] == 0.25 and cfg.guard.stale_periods is None


def test_defaults_and_types():
    cfg = mission_config_from_dict({"mission": "vertical", "guard": {"debounce_samples": 2, "horizon_s": 0}})
    assert cfg.guard.debounce_samples == 2 and cfg.guard.horizon_s == 0.0
    assert cfg.flight.rate_hz == 50.0 and cfg.abort.recovery_lateral_mps == 1.0
    assert isinstance(cfg.flight.start_height_m, float)
    cfg = cfg.with_flight(start_height_m=8, land=False)
    assert cfg.flight.start_height_m == 8.0 and cfg.flight.land is False


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"mission": "loop"}, "'mission' must be one of"),
        ({}, "'mission' must be one of"),
        ({"mission": "vertical", "extra": 1}, "unknown section or key 'extra'"),
        ({"mission": "vertical", "flight": {"hieght_m": 5}}, "[flight]: unknown key 'hieght_m'"),
        ({"mission": "vertical", "flight": {"start_height_m": "5"}}, "'start_height_m' must be a finite number"),
        ({"mission": "vertical", "flight": {"start_height_m": float("nan")}}, "must be a finite number"),
        ({"mission": "vertical", "flight": {"rate_hz": 0}}, "'rate_hz' must be > 0"),
        ({"mission": "vertical", "flight": {"rate_hz": 500}}, "rate_hz must lie in [1, 200]"),
        ({"mission": "vertical", "flight": {"land": 1}}, "'land' must be true or false"),
        ({"mission": "vertical", "flight": {"start_height_m": 1, "min_alt_m": 2}}, "must exceed min_alt_m"),
        ({"mission": "vertical", "guard": {"debounce_samples": 0}}, "integer ≥ 1"),
        ({"mission": "vertical", "guard": {"debounce_samples": 1.5}}, "integer ≥ 1"),
        ({"mission": "vertical", "guard": {"stale_periods": -1}}, "'stale_periods' must be > 0"),
        ({"mission": "vertical", "guard": {"horizon_s": -0.1}}, "'horizon_s' must be ≥ 0"),
        ({"mission": "vertical", "guard": {"observe_region": "yes"}}, "must be true or false"),
        ({"mission": "vertical", "abort": []}, "[abort] must be a table"),
        ({"mission": "vertical", "plan": {"descent_m": {"a": 1}}}, "'descent_m' must be a finite number"),
    ],
)
def test_bad_fields_are_one_line_naming_file_and_key(data, message):
    with pytest.raises(FlighttestError) as exc:
        mission_config_from_dict(data, "m.toml")
    text = str(exc.value)
    assert message in text and text.startswith("m.toml") and "\n" not in text


def test_malformed_and_missing_files(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('mission = "vertical"\n[flight\nstart_height_m = 5\n')
    with pytest.raises(FlighttestError, match="malformed TOML"):
        load_mission_config(bad)
    with pytest.raises(FlighttestError, match="cannot read mission config"):
        load_mission_config(tmp_path / "missing.toml")


@pytest.mark.parametrize(
    ("toml", "message"),
    [
        ('mission = "vertical"\n[flight\n', "malformed TOML"),
        ('mission = "vertical"\n[guard]\nstale_periods = "many"\n', "'stale_periods' must be a finite number"),
        ('mission = "helix"\n[plan]\nthrust_min_fraction = 0.9\nthrust_max_fraction = 0.8\n', "thrust_min_fraction"),
        ('mission = "helix"\n[plan]\ntilt_margin_deg = "ten"\n', "'tilt_margin_deg' must be a finite number"),
    ],
)
def test_the_cli_reports_a_bad_config_in_one_line_with_exit_2(tmp_path, toml, message):
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(toml)
    target = "helix" if "helix" in toml else "vertical"
    p = subprocess.run([sys.executable, "-m", "flighttest", "fly", target, "--connect", "udpout://127.0.0.1:9",
                        "--vehicle", "x500", "--config", str(cfg), "--yes"],
                       capture_output=True, text=True, timeout=60)  # fmt: skip
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in p.stderr


def test_tracking_margin_from_a_plan_table_and_its_problem():
    prof = load_profile("x500")
    m = TrackingMargin.from_plan({"descent_m": 5.0, "tilt_margin_deg": 15, "rate_fraction": 0.5})
    assert (m.tilt_margin_deg, m.rate_fraction, m.descent_max_mps) == (15.0, 0.5, 1.3)
    p = helix_problem_for_flight(prof, 5.0, 3.0, m)
    assert p.tilt_max_rad == pytest.approx(0.5235987756)  # 45° − 15°
    assert p.rate_max_rps[0] == pytest.approx(0.9599310886)  # the x500's own 0.25 (below the plan's 0.5) × 220 °/s
    sih = helix_problem_for_flight(load_profile("sih_quadx"), 5.0, 3.0, m)
    assert sih.rate_max_rps[0] == pytest.approx(1.9198621772)  # a vehicle that says nothing: the plan's 0.5
    n_thrust = 4 * prof.max_thrust_per_rotor_n / prof.mass_kg
    assert p.f_min_mps2 == pytest.approx(0.2 * n_thrust) and p.f_max_mps2 == pytest.approx(0.75 * n_thrust)
    assert p.descent_max_mps == 1.3
    assert p.thrust_rate_max_mps3 == 8.0
    assert helix_problem_for_flight(prof, 5.0, 3.0, TrackingMargin(thrust_rate_max_mps3=5)).thrust_rate_max_mps3 == 5
    assert p.constraint.w_allow_mps == prof.w_allow_mps
    # the x500's own tracking margin (0.6) above the mission's 0.4; a larger mission margin wins
    assert p.constraint.margin_mps == pytest.approx(prof.vrs.margin_mps + 0.6)
    wide = helix_problem_for_flight(prof, 5.0, 3.0, TrackingMargin(guard_margin_mps=0.7))
    assert wide.constraint.margin_mps == pytest.approx(prof.vrs.margin_mps + 0.7)
    sih = load_profile("sih_quadx")
    assert helix_problem_for_flight(sih, 5.0, 3.0, m).constraint.margin_mps == pytest.approx(sih.vrs.margin_mps + 0.4)
    with pytest.raises(FlighttestError, match="leaves no tilt"):
        helix_problem_for_flight(prof, 5.0, 3.0, TrackingMargin(tilt_margin_deg=42))
    with pytest.raises(FlighttestError, match="rate_fraction"):
        TrackingMargin(rate_fraction=0.0)
    with pytest.raises(FlighttestError, match="thrust_rate_max_mps3"):
        TrackingMargin(thrust_rate_max_mps3=0.0)
