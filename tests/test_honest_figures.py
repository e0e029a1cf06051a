"""Honest figures (issue 11 item 6): the descent time on the vertical axis with the horizontal error
beside it, descents after an abort labelled so and never a flight's main descent, the final mode as
it was when the vehicle disarmed; and the ``sih_quadx`` profile (item 7). No flying: pure functions,
the PX4 reference folders in ``../shared/px4_sih`` and the mission runner's telemetry hook fed by hand.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from flighttest.analysis import descent_time as dt
from flighttest.analysis.compare import compare_row, flown_descent, primary_descent
from flighttest.analysis.loaders import load_log
from flighttest.analysis.pipeline import analyse
from flighttest.model.profiles import load_profile

PX4_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "px4_sih"
needs_px4 = pytest.mark.skipif(not (PX4_DIR / "vertical-3m-completed").is_dir(), reason="no PX4 reference flights")


# -- the rule on synthetic traces -----------------------------------------------------------------------


def _descent_trace(wander_m: float = 0.5, rate_hz: float = 50.0, height_m: float = 3.0, t_f_s: float = 5.0):
    """A smooth 3 m descent (minimum-jerk, rest to rest in ``t_f_s``) from d = −5 m, then a hover,
    with a slow horizontal wander of ``wander_m`` that never comes within 0.3 m of the end point."""
    t = np.arange(0.0, 15.0, 1.0 / rate_hz)
    s = np.clip(t / t_f_s, 0.0, 1.0)
    d = -5.0 + height_m * (10 * s**3 - 15 * s**4 + 6 * s**5)
    vd = height_m / t_f_s * (30 * s**2 - 60 * s**3 + 30 * s**4) * (t <= t_f_s)
    n = 0.3 + wander_m * (1 + np.sin(2 * np.pi * 0.1 * t))
    e = 0.3 + wander_m * np.cos(2 * np.pi * 0.07 * t)
    return t, n, e, d, vd


def test_the_vertical_rule_ignores_horizontal_wander():
    t, n, e, d, vd = _descent_trace()
    end = (0.0, 0.0, -2.0)
    r = dt.descent_reached(t, n, e, d, vd, 0.0, end)
    # the minimum-jerk profile is within 0.2 m and 0.2 m/s of the end from t ≈ 4.46 s (where the
    # speed falls below 0.2 m/s; the height is 0.03 m off then): the rule finds that sample
    first = t[np.flatnonzero((np.abs(d - end[2]) <= 0.2) & (np.abs(vd) <= 0.2))[0]]
    assert r is not None and r.descent_time_s == pytest.approx(first, abs=1e-9) and 4.3 < first < 4.6
    assert r.horizontal_error_m == pytest.approx(math.hypot(n[t == first][0], e[t == first][0]), abs=1e-9)
    assert r.horizontal_error_m > 0.3 and r.height_error_m == pytest.approx(d[t == first][0] + 2.0)
    # the old rule (3D distance ≤ 0.2 m and 3D speed ≤ 0.3 m/s) never fires on this trace
    dist = np.sqrt(n**2 + e**2 + (d - end[2]) ** 2)
    assert not (dist <= 0.2).any()


def test_a_biased_vertical_velocity_with_a_still_height_is_reached():
    # PX4 SITL: EKF2's vertical velocity read 0.3 m/s off for seconds while its height held at the end
    t, n, e, d, vd = _descent_trace(wander_m=0.0)
    end = (0.0, 0.0, -2.0)
    base = dt.descent_reached(t, n, e, d, vd, 0.0, end)
    biased = np.where(t > 4.0, vd + 0.3, vd)
    assert not (np.abs(biased[t > 4.0]) <= 0.2).any()  # on the velocity alone: never reached
    r = dt.descent_reached(t, n, e, d, biased, 0.0, end)
    # reached once a whole hold window of the height shows it still (not never, as on velocity alone)
    assert r is not None and base.t_s <= r.t_s <= base.t_s + 0.5
    # a vehicle really moving through the band at 0.3 m/s (height and velocity agree) is not reached
    creep = np.where(t > 4.0, -2.15 + 0.3 * (t - 4.0), d)
    assert dt.descent_reached(t, n, e, creep, np.where(t > 4.0, 0.3, vd), 0.0, end, t_stop_s=5.0) is None


def test_the_hold_a_gap_and_the_stop_time():
    t, n, e, d, vd = _descent_trace(wander_m=0.0)
    end = (0.0, 0.0, -2.0)
    base = dt.descent_reached(t, n, e, d, vd, 0.0, end)
    # an overshoot through the band is not "reached": 0.3 s of the hold pushed out of the band
    d2 = d.copy()
    kick = (t > base.t_s + 0.2) & (t < base.t_s + 0.4)
    d2[kick] += 0.5
    again = dt.descent_reached(t, n, e, d2, vd, 0.0, end)
    assert again.t_s > base.t_s + 0.39
    # a NaN sample breaks the hold like a sample outside it
    d3 = d.copy()
    d3[np.argmin(np.abs(t - (base.t_s + 0.25)))] = np.nan
    assert dt.descent_reached(t, n, e, d3, vd, 0.0, end).t_s > base.t_s + 0.25
    # the hold must be complete before the descent's phases end (settle → land, an abort)
    assert dt.descent_reached(t, n, e, d, vd, 0.0, end, t_stop_s=base.t_s + 0.3) is None
    # one sample at a time, as the runner feeds it, gives the same answer, once
    timer = dt.DescentTimer(0.0, end)
    hits = [timer.update(*x) for x in zip(t, n, e, d, vd)]
    assert [h for h in hits if h is not None] == [base] and timer.result == base
    with pytest.raises(Exception, match="height_tol_m"):
        dt.DescentRule(height_tol_m=0.0)


def _events(stream_t: float, extra: list[dict] = ()) -> list[dict]:
    return [{"event": "phase", "phase": "stream", "t_s": stream_t},
            {"event": "stream_start", "t_s": stream_t, "origin_ned": [0.0, 0.0, -5.0], "end_ned": [0.0, 0.0, -2.0]},
            *extra]  # fmt: skip


def test_a_log_is_timed_from_its_state_and_events(tmp_path):
    t, n, e, d, vd = _descent_trace()
    state = pd.DataFrame({"t_s": t + 10.0, "n_m": n, "e_m": e, "d_m": d, "vd_mps": vd})
    log = SimpleNamespace(events=_events(10.0, [{"event": "phase", "phase": "settle", "t_s": 15.0},
                                                {"event": "phase", "phase": "land", "t_s": 20.0}]),
                          state=state, path=tmp_path)  # fmt: skip
    got = dt.from_log(log)
    assert got.reached.descent_time_s == pytest.approx(dt.descent_reached(t, n, e, d, vd, 0.0, (0, 0, -2)).t_s)
    assert got.end_s == 20.0 and got.why is None
    # aborted before the end: no time, and why
    log.events = _events(10.0, [{"event": "abort", "t_s": 12.0, "reason": "test"}])
    got = dt.from_log(log)
    assert got.reached is None and got.end_s == 12.0 and "before the abort" in got.why
    # a trajectory that comes back to its start (the probe) has no descent to time
    log.events = [{**e, "end_ned": [0.1, 0.0, -5.0]} if e["event"] == "stream_start" else e for e in _events(10.0)]
    assert dt.from_log(log) is None


# -- the PX4 reference flights ----------------------------------------------------------------------------


@needs_px4
def test_px4_vertical_is_timed_on_the_vertical_axis():
    """``vertical-3m-completed``: the folder's own ``descent_reached`` (the 3D rest-to-rest test) says
    10.8 s, held open by 0.3–0.8 m of PX4's horizontal wander. On the vertical axis the descent took
    5.18 s from the stream start: the plan itself is 5.16 s rest to rest and PX4 flew its timing (it is
    within 0.2 m of the end height and at 0.09 m/s 5.18 s after the first setpoint). Checked: within
    0.15 s of the plan's t_f — the telemetry sample spacing (20–40 ms) plus the 0.1 s PX4 took to
    start moving — and the horizontal error beside it, 0.3–0.8 m, is the wander the README names.
    (The ~4.8 s quoted in the issue is the log segment, 4.75 s: from 0.05 m below the start height,
    0.25 s after the stream start, to 0.1 m above the end height, before the vertical speed settled.)"""
    folder = PX4_DIR / "vertical-3m-completed"
    t_f = json.loads((folder / "trajectory.json").read_text())["t_f_s"]
    old = next(json.loads(x) for x in (folder / "events.jsonl").read_text().splitlines() if "descent_reached" in x)
    assert old["descent_time_s"] == pytest.approx(10.8)
    a = analyse(load_log(folder), "x500")
    flown = flown_descent(a.log.events)
    assert flown["timed_by"] == "analysis"
    assert flown["duration_s"] == pytest.approx(t_f, abs=0.15)
    assert 0.3 <= flown["horizontal_error_m"] <= 0.8
    row = compare_row(str(folder), a.descents, a.log.events, a.log.meta)
    assert row["descent_time_s"] == flown["duration_s"] and row["outcome"] == "completed"
    assert row["main_descent_note"] is None and row["height_m"] == pytest.approx(3.0, abs=0.05)


@needs_px4
@pytest.mark.parametrize("name", ["helix-5m-guard-abort-1", "helix-5m-guard-abort-2"])
def test_px4_aborted_helix_has_no_main_descent(name):
    """The ladder's Land after the abort (labelled ``stream`` in these older folders, whose ladder
    logged no phase) is an abort descent, not the helix: compare showed 0.53× and 0.66× from it."""
    a = analyse(load_log(PX4_DIR / name), "x500")
    t_abort = next(e["t_s"] for e in a.log.events if e["event"] == "abort")
    assert len(a.descents) and (a.descents["start_s"] >= t_abort).all()
    assert set(a.descents["phase"]) == {"abort"}
    assert primary_descent(a.descents, a.log.events) is None
    row = compare_row(str(PX4_DIR / name), a.descents, a.log.events, a.log.meta)
    assert row["outcome"] == "aborted" and row["descent_time_s"] is None and row.get("duration_s") is None
    assert "after the abort" in row["main_descent_note"] and row["mission"] == "helix"


@needs_px4
def test_px4_vertical_abort_keeps_the_interrupted_descent_and_labels_the_land():
    a = analyse(load_log(PX4_DIR / "vertical-5m-guard-abort"), "x500")
    t_abort = next(e["t_s"] for e in a.log.events if e["event"] == "abort")
    phases = dict(zip(a.descents["start_s"] < t_abort, a.descents["phase"]))
    assert phases == {True: "stream", False: "abort"}
    main = primary_descent(a.descents, a.log.events)
    assert main["start_s"] < t_abort and main["phase"] == "stream"
    row = compare_row("v", a.descents, a.log.events, a.log.meta)
    assert row["outcome"] == "aborted" and row["descent_time_s"] is None  # never reached before the abort


def test_ladder_phases_are_never_the_main_descent():
    d = pd.DataFrame({"start_s": [10.0, 30.0, 50.0], "end_s": [15.0, 40.0, 60.0], "height_m": [3.0, 6.0, 1.0],
                      "phase": ["stream", "abort_land", "abort"], "glitch": [False] * 3})  # fmt: skip
    assert primary_descent(d)["start_s"] == 10.0
    assert primary_descent(d.iloc[1:]) is None
    # a descent starting after the abort is out even where its phase says otherwise
    d2 = d.assign(phase=["stream", "stream", "land"])
    assert primary_descent(d2, [{"event": "abort", "t_s": 20.0}])["start_s"] == 10.0
    assert primary_descent(d2.iloc[1:], [{"event": "abort", "t_s": 20.0}]) is None


# -- the runner: the live rule, the ladder's phases, the final mode -----------------------------------------


def _runner(tmp_path):
    from flighttest.flying.link import TelemetryState
    from flighttest.flying.log_writer import FlightLogWriter
    from flighttest.flying.mission_scripts import load_mission_module, mission_config_path
    from flighttest.flying.missions_config import load_mission_config
    from flighttest.flying.runner import FlyRequest, MissionRunner

    prof = load_profile("x500")
    cfg = load_mission_config(mission_config_path("vertical"))
    traj = load_mission_module("vertical").plan(prof, cfg)
    runner = MissionRunner(FlyRequest("udpin://0.0.0.0:14540", prof, cfg, traj, "vertical", log_root=tmp_path))
    runner.log = FlightLogWriter(tmp_path, "vertical")
    runner.link = SimpleNamespace(state=TelemetryState(q=(1.0, 0.0, 0.0, 0.0), armed=True, flight_mode="OFFBOARD"))
    return runner


def _events_of(runner) -> list[dict]:
    runner.log.close()
    return [json.loads(x) for x in (runner.log.dir / "events.jsonl").read_text().splitlines()]


def test_the_runner_times_the_descent_with_the_same_rule(tmp_path):
    runner = _runner(tmp_path)
    t, n, e, d, vd = _descent_trace()
    end = (0.0, 0.0, -2.0)
    runner.phase, runner.t_stream_start = "stream", 100.0
    runner.watch.descent_timer = dt.DescentTimer(100.0, end)
    st = runner.link.state
    for k in range(len(t)):
        st.n_m, st.e_m, st.d_m, st.vd_mps, st.vn_mps, st.ve_mps = n[k], e[k], d[k], vd[k], 0.0, 0.0
        runner.watch.on_posvel(100.0 + t[k])
    want = dt.descent_reached(t, n, e, d, vd, 0.0, end)
    assert runner.descent_time_s == pytest.approx(want.descent_time_s)
    assert runner.watch.horizontal_error_m == pytest.approx(want.horizontal_error_m)
    s = runner._outcome("completed", None).summary()
    assert s["descent_time_s"] == runner.descent_time_s and s["horizontal_error_m"] == runner.watch.horizontal_error_m
    # the main descent as the analysis gives it: the same rule's figures, the plan timed alike beside them
    m = s["main_descent"]
    assert m["basis"] == "planned descent" and m["reached"] and m["descent_time_s"] == round(want.descent_time_s, 3)
    assert m["height_m"] == pytest.approx(3.0, abs=0.2) and m["mean_rate_mps"] == pytest.approx(
        m["height_m"] / m["descent_time_s"], abs=1e-3)  # fmt: skip
    assert m["max_rate_mps"] is None  # arrival times jitter: the analysis gives it on the vehicle's clock
    df = runner.traj.df
    plan = dt.planned_descent(df["t_s"], df["n_m"], df["e_m"], df["d_m"], df["vd_mps"])
    assert s["planned_descent_s"] == m["planned_descent_s"] == round(plan.descent_time_s, 3)
    assert m["planned_height_m"] == pytest.approx(3.0)
    ev = [x for x in _events_of(runner) if x["event"] == "descent_reached"]
    assert len(ev) == 1 and ev[0]["horizontal_error_m"] == round(want.horizontal_error_m, 3)


def test_the_ladder_labels_its_phases_once_per_rung(tmp_path):
    runner = _runner(tmp_path)
    runner.phase = "stream"
    for phase in ("abort_recover", "abort_hold", "abort_land", "abort_land"):  # Land is re-sent
        runner.ladder_run.log_phase(phase)
    assert runner.phase == "stream"  # the nominal flow's phase: where it aborted (phase_at_end)
    phases = [(x["phase"], x["nominal_phase"]) for x in _events_of(runner) if x["event"] == "phase"]
    assert phases == [("abort_recover", "stream"), ("abort_hold", "stream"), ("abort_land", "stream")]


def test_final_mode_is_the_mode_at_disarm(tmp_path):
    from flighttest.flying.outcome import final_mode
    from flighttest.flying.watch import MODE_SETTLE_S

    assert final_mode("OFFBOARD", False, "LAND") == {
        "final_mode": "LAND", "final_mode_note": "at disarm; OFFBOARD reported after disarming"}  # fmt: skip
    assert final_mode("HOLD", True, "HOLD") == {"final_mode": "HOLD", "final_mode_note": None}
    assert final_mode("LAND", False, "LAND")["final_mode_note"] == "at disarm"
    assert final_mode("HOLD", False, None) == {"final_mode": "HOLD", "final_mode_note": None}  # never armed
    # the runner: LAND while armed, then PX4's disarming heartbeat (mode back to OFFBOARD, disarmed)
    runner = _runner(tmp_path)
    st = runner.link.state
    st.n_m = st.e_m = st.vn_mps = st.ve_mps = st.vd_mps = 0.0
    st.d_m = -1.0
    runner.watch.on_mode("OFFBOARD", "LAND")
    st.flight_mode = "LAND"
    time.sleep(MODE_SETTLE_S + 0.02)
    runner.watch.on_posvel(time.monotonic())
    runner.watch.on_mode("LAND", "OFFBOARD")
    st.flight_mode = "OFFBOARD"
    runner.watch.on_posvel(time.monotonic())  # the mode arrived before the armed flag: not counted
    st.armed = False
    runner.watch.on_posvel(time.monotonic())
    s = runner._outcome("completed", None).summary()
    assert s["final_mode"] == "LAND" and s["final_armed"] is False and "OFFBOARD" in s["final_mode_note"]


# -- the sih_quadx profile -----------------------------------------------------------------------------------


def test_sih_quadx_profile():
    p = load_profile("sih_quadx")
    assert (p.mass_kg, p.n_rotors, p.max_thrust_per_rotor_n, p.max_tilt_deg) == (1.0, 4, 5.0, 45.0)
    assert p.inertia_kgm2 == (0.025, 0.025, 0.03) and p.max_rate_dps[:2] == (220.0, 220.0)
    assert p.rotor_diameter_m == pytest.approx(0.2032) and "assumed" in p.description
    # SIH's roll/pitch lever SIH_L_ROLL 0.2 m = arm / √2 of an X frame
    assert p.arm_length_m / math.sqrt(2) == pytest.approx(0.2, abs=1e-3)
    assert p.yaw_moment_per_thrust_m == pytest.approx(0.1 / 5.0)
    assert p.min_thrust_per_rotor_n == pytest.approx(0.12 * 5.0)
    # v_h = sqrt(T_h / (2 ρ A)), T_h = m g / 4, A = π (0.1016 m)²
    assert p.v_h_mps == pytest.approx(math.sqrt(1.0 * 9.80665 / 4 / (2 * 1.225 * math.pi * 0.1016**2)), rel=1e-9)
    assert p.v_h_mps == pytest.approx(5.555, abs=0.001)
    assert p.thrust_to_weight == pytest.approx(2.04, abs=0.005)
    assert p.max_accel_down_mps2 == pytest.approx(9.80665 - 4 * 0.6 / 1.0)


def test_the_fake_starts_as_sih_quadx(fake_vehicle_factory):
    fake = fake_vehicle_factory("sih_quadx")
    assert fake.alive() and fake.url.startswith("udpout://127.0.0.1:")
    fake.stop()
    assert "sih_quadx v_h=5.555" in fake.stderr_path.read_text()
