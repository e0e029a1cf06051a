"""The flight-safety review of the guard and the abort ladder (issue 24), each finding flown by the real
mission runner against the scripted autopilot in virtual time (``tests/virtual_flight.py``).

The scripted autopilot reports what MAVSDK reads from the heartbeat (armed, the mode) at 1 Hz, as PX4 and
ArduCopter send it, so an arm is acknowledged up to a second before the armed flag says so.
"""

from __future__ import annotations

import errno
import json
import math
from pathlib import Path

import numpy as np
import pytest

from flighttest.flying import guard as gd
from flighttest.flying import log_writer
from flighttest.flying.autopilot import ARDUPILOT
from flighttest.flying.mission_scripts import load_mission_module
from flighttest.flying.wind import WindEstimate, WindSources, autopilot_report, fuse
from flighttest.model.frames import quat_from_euler
from flighttest.model.trajectory import Trajectory
from sitl_fakes.scripted import ARDUPILOT_PARAMS as AP_DEFAULTS
from virtual_flight import DESCENT_M, START_M, X500, config, fly, in_phase

AP_READY = {**AP_DEFAULTS, "WP_ACC_Z": 1.5}


def heard(f, t_s: float) -> list[str]:
    return f.heard_after(t_s)


# -- 1. a pilot at any phase after arming -------------------------------------------------------------


@pytest.mark.parametrize("height_m", [1.0, 1.5, 1.65])
def test_a_pilot_taking_over_during_the_takeoff_gets_the_vehicle_and_nothing_more(tmp_path, height_m):
    # while PX4's takeoff climbs (the handover to offboard is at 1.7 m): the pilot's mode shows with the next
    # heartbeat, up to a second later; flighttest waits for a heartbeat after the handover height before it
    # starts offboard
    def script(ap, runner):
        ap.when(lambda: runner.phase == "takeoff" and -ap.p_ned[2] >= height_m, lambda: ap.pilot("POSCTL"))

    f = fly(tmp_path, script)
    assert f.outcome.outcome == "aborted" and f.outcome.abort_reason == "pilot took over (POSCTL) during the takeoff"
    assert f.ladder() == [("DONE", "pilot in control (POSCTL)")]
    assert f.heard_after(f.t_of("mode", new="POSCTL")) == []  # no offboard start, no Hold, no Land
    assert f.ap.mode == "POSCTL" and f.ap.armed and -f.ap.p_ned[2] == pytest.approx(height_m, abs=0.2)
    assert f.summary["abort_verdict"] == "pilot" and f.summary["final_mode"] == "POSCTL"


def test_a_pilot_switch_seen_as_the_ladder_starts_stops_what_it_queued(tmp_path):
    # a Ctrl-C queues Recover; the heartbeat that says POSCTL comes before the ladder sends anything
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, lambda: (runner.interrupt("SIGINT"), ap.pilot("POSCTL"),
                                                           ap.heartbeat_now()))  # fmt: skip

    f = fly(tmp_path, script)
    assert f.outcome.abort_reason == "SIGINT from the operator"
    assert f.ladder()[-1] == ("DONE", "pilot took over (POSCTL): sending nothing more")
    assert f.heard_after(f.t_of("abort")) == [] and f.ap.mode == "POSCTL" and f.ap.armed
    skipped = [e for e in f.events if e["event"] == "ladder_command_skipped"]
    assert skipped and skipped[0]["why"] == "pilot in control (POSCTL)"


def test_an_ardupilot_pilot_taking_over_during_the_takeoff_is_a_takeover_too(tmp_path):
    def script(ap, runner):
        ap.when(lambda: runner.phase == "takeoff" and -ap.p_ned[2] >= 1.0, lambda: ap.pilot("LOITER"))

    f = fly(tmp_path, script, autopilot=ARDUPILOT, params=dict(AP_READY))
    assert f.outcome.abort_reason == "pilot took over (LOITER) during the takeoff"
    assert f.heard_after(f.t_of("mode", new="LOITER")) == [] and f.ap.mode == "LOITER"


def test_a_vehicle_left_in_a_pilots_mode_is_refused_before_arming(tmp_path):
    # PX4 in Position on the ground, refusing every other mode: flighttest does not take it from the sticks
    def script(ap, runner):
        ap.mode = "POSCTL"

    f = fly(tmp_path, script, ignored={"hold"})
    assert f.outcome.outcome == "refused" and f.outcome.exit_code == 2
    assert f.outcome.abort_reason == ("preflight failed: mode before arming: POSCTL, a pilot's mode (needs not a "
                                      "pilot's mode, armable: switch it to HOLD)")  # fmt: skip
    assert "arm" not in [c for _, c in f.ap.commands]


# -- 2. on the ground only on evidence ----------------------------------------------------------------


@pytest.mark.parametrize("after_s", [0.25, 0.4, 0.6])
@pytest.mark.parametrize("spool_up_s", [1.0, 0.0])
def test_ctrl_c_just_after_the_takeoff_ends_landed_and_disarmed(tmp_path, after_s, spool_up_s):
    # the armed flag comes with the 1 Hz heartbeat: it still says "disarmed" while the vehicle spools up
    # (PX4 SITL: seconds before it lifts, and it disarms by itself only after a flight) or already climbs
    def script(ap, runner):
        ap.after(lambda: bool(ap.heard("takeoff")), after_s, lambda: runner.interrupt("SIGINT"))

    f = fly(tmp_path, script, spool_up_s=spool_up_s)
    rungs = f.ladder()
    assert rungs[-1] == ("DONE", "landed") and "vehicle on the ground" not in rungs[0][1]
    assert not f.ap.armed and f.ap.p_ned[2] == 0.0 and f.summary["final_armed"] is False
    heard = f.heard_after(f.t_of("abort"))
    assert "land" in heard
    if spool_up_s > after_s:  # it never lifted: on the ground and armed, the ladder disarms it
        assert not f.ap.took_off and heard[-1] == "disarm"
        assert ("LAND", "on the ground, still armed: disarming") in rungs
    else:
        assert f.ap.took_off and "disarm" not in heard  # it landed and disarmed by itself


def test_a_takeoff_refused_on_the_ground_still_lands_and_disarms(tmp_path):
    # armed, takeoff refused: on the ground but armed — not "landed" until it disarms
    f = fly(tmp_path, refused={"takeoff": "denied"})
    assert f.ladder()[-1] == ("DONE", "landed") and not f.ap.armed


# -- 3. a stale attitude ------------------------------------------------------------------------------


def test_a_stale_level_attitude_never_judges_a_flare(tmp_path):
    # the case: braking nose-up 15° at 2 m/s forward and 0.6 m/s down; a level attitude kept from
    # before says the state is clear, the true attitude says it is inside
    region = X500.guard_region()
    q_true = quat_from_euler(0.0, math.radians(15.0), 0.0)
    level = (1.0, 0.0, 0.0, 0.0)
    _, _, _, true_margin = region.check(2.0, 0.0, 0.6, *q_true)
    _, _, _, stale_margin = region.check(2.0, 0.0, 0.6, *level)
    assert true_margin < 0 < stale_margin
    guard = gd.Guard(gd.GuardLimits(region=region))
    d = guard.on_sample(gd.GuardSample(10.0, 2.0, 0.0, 0.6, *level, 5.0, att_age_s=0.3))
    assert d.verdict == gd.STALE and d.aborts and math.isnan(d.margin_mps) and "attitude 300 ms old" in d.reason
    assert guard.on_sample(gd.GuardSample(10.02, 2.0, 0.0, 0.6, *q_true, 5.0, att_age_s=0.02)).verdict != gd.STALE


def test_an_attitude_stream_that_stops_mid_descent_aborts_and_the_sink_is_not_called_arrested(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, ap.stop_attitude)

    f = fly(tmp_path, script)
    assert f.summary["abort_verdict"] == gd.STALE and "attitude" in f.outcome.abort_reason
    late_s = f.t_of("abort") - f.t_of("phase", phase="stream") - 1.0
    assert 0.0 < late_s <= 0.3
    # the region cannot be judged without an attitude: no "sink arrested" on a margin that is NaN
    assert f.ladder()[1] == ("HOLD", "recovery not confirmed within 2 s")
    assert f.ladder()[-1] == ("DONE", "landed") and not f.ap.armed


def test_a_steady_stream_that_falls_behind_is_stale(tmp_path):
    # every sample keeps coming at 50 Hz, but the link delivers ever older ones: 0.3 s more each second (the
    # vehicle's own timestamps say so; no gap in the arrivals shows it)
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, lambda: ap.delay_telemetry(0.3))

    f = fly(tmp_path, script)
    assert f.summary["abort_verdict"] == gd.STALE and "arrives" in f.outcome.abort_reason
    assert 0.8 <= f.t_of("abort") - f.t_of("phase", phase="stream") - 1.0 <= 1.0  # 0.25 s behind: 0.83 s


def test_a_simulator_that_stalls_and_resumes_is_not_late():
    # a starved simulator stops its own clock during the stall: after it, every sample is as fresh as ever,
    # arriving at its cadence with the offset the stall left (ArduCopter SITL: 0.36 s)
    guard = gd.Guard(gd.GuardLimits(region=X500.guard_region()))
    t, tv = 100.0, 5.0
    for _ in range(100):
        t, tv = t + 0.02, tv + 0.02
        guard.note_attitude(t, tv)
    t += 0.36  # the stall: nothing arrives, the vehicle's clock stands still
    for _ in range(100):
        t, tv = t + 0.02, tv + 0.02
        guard.note_attitude(t, tv)
        assert guard.lateness_s < 0.01
    for _ in range(50):  # then the link falls behind at its cadence: 10 ms more per sample
        t, tv = t + 0.03, tv + 0.02
        guard.note_attitude(t, tv)
    assert guard.lateness_s == pytest.approx(0.5, abs=0.01)


# -- 4. a log that cannot be written --------------------------------------------------------------------


def test_a_full_disk_mid_descent_stops_neither_the_guard_nor_the_ladder(tmp_path):
    def fill_disk(runner):
        for sink in runner.log._files:  # every open log file now writes to a full device
            sink.f = open("/dev/full", "w", buffering=1)  # noqa: SIM115 (closed with the log)

    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 0.5, lambda: fill_disk(runner))
        ap.after(in_phase(runner, "stream"), 1.0, lambda: ap.push((0.0, 0.0, 14.0), 0.4))

    f = fly(tmp_path, script)
    assert f.ap.listener_errors == []  # no telemetry listener raised
    assert f.outcome.outcome == "aborted" and f.summary["abort_verdict"] in (gd.MARGINAL, gd.PREDICTED, gd.VIOLATION)
    assert [r for r, _ in f.ladder()] == ["RECOVER", "HOLD", "LAND", "DONE"] and f.ladder()[-1][1] == "landed"
    assert [c for _, c in f.ap.commands][-2:] == ["stop_offboard", "land"] and not f.ap.armed
    assert f.summary["log_complete"] is False and f.summary["log_write_errors"] > 10
    assert f.summary["log_first_error"].startswith("No space left on device")


def test_a_summary_that_cannot_be_written_is_said_and_the_flight_still_ends_safely(tmp_path, monkeypatch):
    said: list[str] = []
    real = log_writer.write_json_atomic

    def full(path: Path, data) -> None:
        if path.name == "summary.json":
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        real(path, data)

    monkeypatch.setattr(log_writer, "write_json_atomic", full)
    f = fly(tmp_path, request={"print_fn": said.append}, summary_expected=False)
    assert f.outcome.outcome == "completed" and not f.ap.armed and f.ap.p_ned[2] == 0.0
    assert f.outcome.summary()["log_complete"] is False
    said = [x for x in said if isinstance(x, str) and "incomplete" in x]  # the progress lines aside
    assert len(said) == 1 and said[0].endswith("is incomplete: 1 write(s) failed (first: No space left on device: "
                                               "summary.json)")  # fmt: skip


# -- 5. the wind --------------------------------------------------------------------------------------


def _downwind(speed_mps: float, sink_mps: float, duration_s: float) -> Trajectory:
    """East at ``speed_mps`` sinking ``sink_mps``, from rest to rest in 1 s ramps."""
    t = np.arange(0.0, duration_s + 1e-9, 0.02)
    ramp = np.clip(np.minimum(t, duration_s - t), 0.0, 1.0)
    ve, vd = speed_mps * ramp, sink_mps * ramp
    e, d = np.cumsum(ve) * 0.02, np.cumsum(vd) * 0.02
    a = np.gradient(ramp, t)
    zero = np.zeros_like(t)
    meta = {"kind": "helix", "vehicle": "x500", "problem": {"name": "downwind"}, "status": "test"}
    return Trajectory.from_arrays(meta, t_s=t, n_m=zero, e_m=e, d_m=d, vn_mps=zero, ve_mps=ve, vd_mps=vd, an_mps2=zero,
                                  ae_mps2=speed_mps * a, ad_mps2=sink_mps * a, yaw_deg=zero)  # fmt: skip


def test_gusts_whose_updrafts_leave_no_clear_plan_stop_the_descent_before_it_starts(tmp_path):
    # in 3 m/s of wind, the operator's gusts of 0.4 m/s (1 σ): an updraft of 0.78 m/s allowed, more than the
    # vertical's room to the region where it slows at the bottom. The start hover refuses, says why, and lands
    def gusty(sd_mps):
        return lambda ap, runner: setattr(runner.wind, "stated_gust_sd_mps", sd_mps)

    windy = {"request": {"wind_ned_mps": (0.0, 3.0, 0.0), "wind_sd_mps": 0.1}, "wind_ned_mps": (0.0, 3.0, 0.0)}
    f = fly(tmp_path, gusty(0.4), **windy)
    assert f.outcome.outcome == "aborted" and f.summary["abort_verdict"] == "wind"
    assert f.outcome.abort_reason.startswith("no plan clears the guard region in the wind at the start, ")
    assert "updrafts to 0.78 m/s allowed for its gusts" in f.outcome.abort_reason
    assert "stream" not in [e["phase"] for e in f.events if e["event"] == "phase"]
    assert f.ladder()[-1] == ("DONE", "landed") and not f.ap.armed
    calm = fly(tmp_path / "calm", gusty(0.05), **windy)
    assert calm.outcome.outcome == "completed"  # 0.1 m/s of updraft: the vertical clears it


def test_a_zero_wind_report_does_not_replace_the_operators_tailwind(tmp_path):
    # downwind at 3 m/s in a 3 m/s tailwind, sinking 0.9 m/s: no air across the disk, straight down through
    # it. An autopilot that does not estimate the wind reports (0, 0, 0)
    def script(ap, runner):
        ap.report_wind((0.0, 0.0, 0.0), 0.0)

    f = fly(tmp_path, script, traj=_downwind(3.0, 0.9, 4.0), request={"wind_ned_mps": (0.0, 3.0, 0.0),
                                                                      "wind_sd_mps": 0.1},
            wind_ned_mps=(0.0, 3.0, 0.0))  # fmt: skip
    # the start hover judges the plan in that wind and refuses to descend (taking the report of zero for calm
    # it would have flown straight down through its own wake)
    assert f.outcome.outcome == "aborted" and f.summary["abort_verdict"] == "wind"
    assert f.outcome.abort_reason.startswith("no plan clears the guard region in the wind at the start, ")
    assert "stream" not in [e["phase"] for e in f.events if e["event"] == "phase"]
    # flighttest's own estimate, started from the operator's wind, never the autopilot's zero
    assert f.summary["wind_source"] == "flighttest" and f.summary["wind_ned_mps"][1] == pytest.approx(3.0, abs=0.3)


def test_the_wind_is_judged_with_its_age_and_accuracy():
    class St:
        wind_ned_mps, wind_accuracy_mps, t_wind = (1.0, 2.0, 0.0), 0.3, 10.0

    assert autopilot_report(St, 11.0) == WindEstimate((1.0, 2.0, 0.0), 0.3, "autopilot")
    assert autopilot_report(St, 12.5) is None  # older than WIND_REPORT_MAX_AGE_S
    St.wind_accuracy_mps = math.nan
    assert autopilot_report(St, 11.0).sd_mps == 1.0  # no accuracy given: not a precise one
    St.wind_ned_mps = (0.0, 0.0, 0.0)
    assert autopilot_report(St, 11.0) is None
    prior = WindEstimate((0.0, 3.0, 0.0), 0.5, "operator")
    assert WindSources(prior).current(St, 11.0) == prior
    # two sources that disagree: the fused wind is between them and less certain than either alone says
    fused = fuse([WindEstimate((0.0, 1.0, 0.0), 0.2, "autopilot"), prior])
    assert 1.0 < fused.ned_mps[1] < 3.0 and fused.sd_mps > 0.2 and fused.source == "autopilot+operator"
    agreeing = fuse([WindEstimate((0.0, 3.0, 0.0), 0.5, "autopilot"), prior])
    assert agreeing.sd_mps == pytest.approx(0.5 / math.sqrt(2.0))


def test_an_uncertain_wind_makes_the_guard_judge_the_worst_air():
    region = X500.guard_region()
    guard = gd.Guard(gd.GuardLimits(region=region))
    # level, 0.9 m/s down, 3 m/s east in calm air: the cone allows it; 1.5 m/s of doubt about the wind does not
    sure = guard.on_sample(gd.GuardSample(1.0, 0.0, 3.0, 0.9, 1.0, 0.0, 0.0, 0.0, 5.0))
    unsure = gd.Guard(gd.GuardLimits(region=region)).on_sample(
        gd.GuardSample(1.0, 0.0, 3.0, 0.9, 1.0, 0.0, 0.0, 0.0, 5.0, wind_radius_mps=1.5))
    assert sure.margin_mps > 0 > unsure.margin_mps and sure.u_mps == unsure.u_mps == pytest.approx(3.0)


# -- 6. the autopilot's own Land --------------------------------------------------------------------


@pytest.mark.parametrize("autopilot", ["PX4", ARDUPILOT])
def test_the_autopilots_own_land_mid_descent_is_followed_with_no_hold(tmp_path, autopilot):
    def script(ap, runner):
        def failsafe():
            ap.hold_ned = ap.p_ned.copy()
            ap.mode = "LAND"  # a battery or estimator failsafe, not flighttest's command

        ap.after(in_phase(runner, "stream"), 1.0, failsafe)

    extra = {"autopilot": ARDUPILOT, "params": dict(AP_READY)} if autopilot == ARDUPILOT else {}
    f = fly(tmp_path, script, **extra)
    assert f.outcome.outcome == "aborted"
    assert f.outcome.abort_reason == "the autopilot switched to LAND: following it"
    assert f.heard_after(f.t_of("mode", new="LAND")) == []  # no Hold, no Land re-sent
    assert f.ladder() == [("LAND", "the autopilot switched to LAND: following it"), ("DONE", "landed")]
    assert not f.ap.armed and f.ap.p_ned[2] == 0.0


# -- 7. heights from the ground ------------------------------------------------------------------------


def test_heights_count_from_the_ground_seen_at_arming(tmp_path):
    # the estimate reads 0.9 m on the ground: the start, the end and the floor are the mission's above it
    f = fly(tmp_path, height_offset_m=0.9)
    assert f.outcome.outcome == "completed"
    checks = {c["name"]: c for c in json.loads((Path(f.outcome.log_dir) / "preflight.json").read_text())["checks"]}
    assert checks["height on the ground"]["status"] == "warn" and "+0.90 m" in checks["height on the ground"]["value"]
    assert next(e for e in f.events if e["event"] == "ground")["alt_m"] == pytest.approx(0.9)
    start = next(e for e in f.events if e["event"] == "stream_start")["origin_ned"]
    assert start[2] == pytest.approx(-(START_M + 0.9))  # in the estimate's frame
    guard = [row.split(",") for row in (Path(f.outcome.log_dir) / "guard.csv").read_text().splitlines()]
    alt = guard[0].index("alt_m")
    # the guard's height is above the ground: the floor (1 m) is 1 m above it, not 0.1 m
    t0, t1 = f.t_of("phase", phase="stream"), f.t_of("phase", phase="land")
    lowest = min(float(r[alt]) for r in guard[1:] if r[alt] and t0 < float(r[0]) < t1)
    assert lowest == pytest.approx(START_M - DESCENT_M, abs=0.25)


def test_the_floor_acts_at_its_height_above_the_ground(tmp_path):
    # the estimate reads 0.9 m high on the ground; pressed gently down at the end of the descent (2 m), the
    # vehicle meets the 1.6 m floor at 1.6 m above the ground, not at 0.7 m
    at_abort: list[float] = []

    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), runner.traj.duration_s - 0.3, lambda: ap.push((0.0, 0.0, 3.0), 4.0))
        ap.when(lambda: runner.ladder.active, lambda: at_abort.append(-float(ap.p_ned[2])))

    f = fly(tmp_path, script, height_offset_m=0.9, flight={"min_alt_m": 1.6})
    assert f.summary["abort_verdict"] == gd.FLOOR and f.outcome.abort_reason.endswith("below floor 1.6 m")
    assert at_abort[0] == pytest.approx(1.6, abs=0.1)
    assert f.ap.p_ned[2] == 0.0 and not f.ap.armed


def test_the_climb_turns_the_heading_no_faster_than_its_rate():
    from flighttest.flying.runner import LOOK_AROUND_DEG, LOOK_AROUND_RATE_DPS, LOOK_AROUND_SHARE, look_around_deg

    assert look_around_deg(10.0) == LOOK_AROUND_DEG
    # the mission's 2 m → 7 m climb at 1 m/s, its swing in the first LOOK_AROUND_SHARE of it: over 130°
    assert 130.0 < look_around_deg(LOOK_AROUND_SHARE * 5.0) <= LOOK_AROUND_DEG
    short = look_around_deg(1.0)
    assert short * math.pi / 1.0 == pytest.approx(LOOK_AROUND_RATE_DPS)  # the raised cosine's peak rate
    assert look_around_deg(0.0) == 0.0


def _climb_yaw_deg(f) -> np.ndarray:
    rows = [r.split(",") for r in (Path(f.outcome.log_dir) / "setpoints.csv").read_text().splitlines()]
    yaw, phase = rows[0].index("yaw_deg"), rows[0].index("phase")
    return np.array([float(r[yaw]) for r in rows[1:] if r[phase] == "climb"])


def test_a_descent_swings_its_heading_in_the_climb_and_a_probe_holds_it(tmp_path):
    from flighttest.flying.runner import LOOK_AROUND_DEG, LOOK_AROUND_RATE_DPS

    # a trajectory that returns to its start (a probe): the heading held, as identify's hover reference needs
    t = np.arange(0.0, 4.0 + 1e-9, 0.02)
    z = np.zeros_like(t)
    d = 0.25 * (1.0 - np.cos(np.pi * t / 2.0))  # down 0.5 m and back up, at most 0.39 m/s
    vd = 0.125 * np.pi * np.sin(np.pi * t / 2.0)
    ad = 0.0625 * np.pi**2 * np.cos(np.pi * t / 2.0)
    there_and_back = Trajectory.from_arrays(
        {"kind": "vertical", "vehicle": "x500", "problem": {"height_m": 0.5}, "status": "closed_form"},
        t_s=t, n_m=z, e_m=z, d_m=d, vn_mps=z, ve_mps=z, vd_mps=vd, an_mps2=z, ae_mps2=z, ad_mps2=ad, yaw_deg=z,
    )  # fmt: skip
    probe = fly(tmp_path / "probe", traj=there_and_back)
    assert probe.outcome.outcome == "completed"
    held = _climb_yaw_deg(probe)
    assert held.size > 50 and np.ptp(held) == 0.0
    # a descent (the vertical, no plans for the wind: a trajectory file's climb is the same) and a flight that
    # chooses among plans for the wind: the climb's swing, out and back to the plan's heading before the hover
    plan = load_mission_module("vertical").plan(X500, config(True))
    for name, request in (("file", {}), ("for_wind", {"wind_plans": [plan]})):
        swung = fly(tmp_path / name, request=request)
        assert swung.outcome.outcome == "completed"
        yaw = _climb_yaw_deg(swung)
        # this short climb (to START_M) swings as far as the rate allows, and ends at the heading it left
        assert 20.0 < np.ptp(yaw) <= LOOK_AROUND_DEG and yaw[-1] == pytest.approx(yaw[0], abs=1e-6), name
        assert np.abs(np.diff(yaw)).max() * 50.0 <= LOOK_AROUND_RATE_DPS * 1.01  # setpoints at 50 Hz
