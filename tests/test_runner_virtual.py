"""Every way a flight ends, flown by the real mission runner against a scriptable in-process autopilot
(``sitl_fakes.scripted``) on a virtual clock (``sitl_fakes.virtual_time``): a whole flight takes a
fraction of a second of CPU and the same script gives the same flight on a busy machine.

Each test checks what the runner did (its outcome, the abort ladder's rungs and reasons), what the
vehicle heard (commands and when) and where it was left, and that the flight's log is complete on
disk. The real-time flights against the UDP fake (``-m flight``) stay: they cover MAVSDK and MAVLink.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from flighttest.flying import guard as gd
from flighttest.flying.autopilot import ARDUPILOT
from flighttest.flying.mission_scripts import load_mission_module
from flighttest.flying.runner import LADDER_TIMEOUT_S, LINK_GIVE_UP_S, FlyRequest, MissionRunner
from flighttest.planner.optimum import vertical_optimum
from sitl_fakes.scripted import ARDUPILOT_PARAMS as AP_DEFAULTS
from sitl_fakes.scripted import PX4_PARAMS as PX4_DEFAULTS
from sitl_fakes.scripted import ScriptedAutopilot
from sitl_fakes.virtual_time import run_virtual
from virtual_flight import DESCENT_M, START_M, X500, Flight, config, fly, in_phase, leaning_descent

# -- the nominal flight --------------------------------------------------------------------------------


def test_a_nominal_flight_descends_times_its_descent_and_lands(tmp_path):
    f = fly(tmp_path)
    assert f.outcome.outcome == "completed" and f.outcome.exit_code == 0 and f.outcome.abort_reason is None
    assert [c for _, c in f.ap.commands] == ["arm", "set_takeoff_altitude", "takeoff", "start_offboard", "land"]
    plan_s = f.runner.traj.duration_s
    assert 0.9 * plan_s <= f.outcome.descent_time_s <= 1.3 * plan_s
    reached = next(e for e in f.events if e["event"] == "descent_reached")
    assert reached["descent_time_s"] == pytest.approx(f.outcome.descent_time_s, abs=0.01)
    assert reached["height_error_m"] <= 0.2
    # hover to hover (issue 22): no sooner than the vertical axis, against the planner's optimum for the plan
    hover = next(e for e in f.events if e["event"] == "hover_reached")
    assert f.summary["hover_to_hover_s"] == hover["hover_to_hover_s"] >= round(f.outcome.descent_time_s, 3)
    assert f.summary["optimum_s"] == vertical_optimum(X500, DESCENT_M).optimum_s < plan_s
    assert f.summary["flown_over_optimum"] == pytest.approx(f.summary["hover_to_hover_s"] / f.summary["optimum_s"],
                                                            abs=1e-3)  # fmt: skip
    assert f.summary["main_descent"]["flown_over_optimum"] == f.summary["flown_over_optimum"] > 1.0
    assert f.summary["final_armed"] is False and f.summary["final_mode"] == "LAND"
    assert f.ap.p_ned[2] == 0.0 and not f.ap.armed
    assert f.ap.takeoff_alt_m == START_M  # PX4's takeoff is asked for the start height, as ever
    assert "ladder" not in f.summary
    phases = [e["phase"] for e in f.events if e["event"] == "phase"]
    assert phases == ["connect", "preflight", "arm", "takeoff", "climb", "settle", "stream", "settle", "land",
                      "landed"]  # fmt: skip


def test_no_land_leaves_the_vehicle_holding_at_the_end_point(tmp_path):
    f = fly(tmp_path, land=False)
    assert f.outcome.outcome == "completed"
    assert [c for _, c in f.ap.commands][-1] == "stop_offboard" and "land" not in [c for _, c in f.ap.commands]
    assert f.ap.mode == "HOLD" and f.ap.armed
    assert f.ap.p_ned[2] == pytest.approx(-(START_M - DESCENT_M), abs=0.2)
    assert f.summary["final_mode"] == "HOLD" and f.summary["final_armed"] is True


def test_no_land_with_a_hold_that_never_comes_is_an_abort_that_says_so(tmp_path):
    f = fly(tmp_path, land=False, ignored={"stop_offboard", "hold"}, offboard_loss_failsafe=False)
    assert f.outcome.outcome == "aborted" and f.outcome.exit_code == 1
    assert f.outcome.abort_reason == "error: Hold not confirmed after the flight (--no-land)"
    rungs = f.ladder()
    # Recover is only for offboard flight phases: straight to Hold, which does not come either; --no-land ends there
    assert [r for r, _ in rungs] == ["RECOVER", "HOLD", "DONE"]
    assert rungs[-1][1].startswith("Hold not confirmed within 3 s (mode OFFBOARD)")
    assert "land" not in [c for _, c in f.ap.commands]


# -- the pilot --------------------------------------------------------------------------------------


def test_a_pilot_switching_to_position_mode_mid_descent_gets_the_vehicle_and_nothing_more(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, lambda: ap.pilot("POSCTL"))

    f = fly(tmp_path, script)
    assert f.outcome.outcome == "aborted" and f.outcome.abort_reason == "pilot took over (POSCTL)"
    assert f.ladder()[-1] == ("DONE", "pilot in control (POSCTL)")
    assert f.heard_after(f.t_of("mode", new="POSCTL")) == []
    assert f.ap.mode == "POSCTL" and f.ap.armed and f.ap.p_ned[2] < -1.0  # flying, the pilot's
    assert f.summary["final_mode"] == "POSCTL" and f.outcome.descent_time_s is None


def test_a_pilot_taking_over_the_landing_gets_it_and_nothing_more(tmp_path):
    def script(ap, runner):
        ap.after(lambda: runner.phase == "land", 0.5, lambda: ap.pilot("ALTCTL"))

    f = fly(tmp_path, script)
    assert f.outcome.abort_reason == "pilot took over (ALTCTL) while landing"
    assert f.ladder()[-1] == ("DONE", "pilot in control (ALTCTL)")
    assert f.heard_after(f.t_of("mode", new="ALTCTL")) == []
    assert f.ap.mode == "ALTCTL" and f.ap.armed
    assert f.outcome.descent_time_s is not None  # the descent was flown before the landing


# -- the operator ------------------------------------------------------------------------------------


def test_each_further_ctrl_c_skips_to_the_next_rung(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, lambda: runner.interrupt("SIGINT"))
        ap.after(lambda: runner.ladder.active, 0.1, lambda: runner.interrupt("SIGINT"))
        ap.after(lambda: runner.ladder.rung == gd.Rung.HOLD, 0.1, lambda: runner.interrupt("SIGINT"))

    f = fly(tmp_path, script)
    assert f.outcome.abort_reason == "SIGINT from the operator"
    assert f.ladder() == [("RECOVER", "SIGINT from the operator"), ("HOLD", "SIGINT again"), ("LAND", "SIGINT again"),
                          ("DONE", "landed")]  # fmt: skip
    t = [x["t_s"] for x in f.summary["ladder"]]
    assert t[1] - t[0] == pytest.approx(0.1, abs=0.03) and t[2] - t[1] == pytest.approx(0.1, abs=0.03)
    assert f.summary["abort_verdict"] == "signal" and not f.ap.armed and f.ap.p_ned[2] == 0.0
    assert [e["count"] for e in f.events if e["event"] == "signal"] == [1, 2, 3]


def test_ctrl_c_during_the_preflight_never_arms(tmp_path):
    def script(ap, runner):
        ap.after(lambda: runner.phase == "preflight", 0.3, lambda: runner.interrupt("SIGTERM"))

    f = fly(tmp_path, script)
    assert f.outcome.outcome == "aborted" and f.outcome.abort_reason == "SIGTERM from the operator"
    assert "arm" not in [c for _, c in f.ap.commands] and not f.ap.armed


# -- the vehicle and the link -----------------------------------------------------------------------


def test_a_guard_abort_mid_descent_recovers_holds_and_lands(tmp_path):
    def script(ap, runner):
        # a sink the position loop cannot hold (10 m/s² of authority against 14 down), as in the VRS
        ap.after(in_phase(runner, "stream"), 1.0, lambda: ap.push((0.0, 0.0, 14.0), 0.4))

    f = fly(tmp_path, script)
    assert f.outcome.outcome == "aborted" and f.summary["abort_verdict"] in (gd.MARGINAL, gd.PREDICTED, gd.VIOLATION)
    assert [r for r, _ in f.ladder()] == ["RECOVER", "HOLD", "LAND", "DONE"]
    assert f.ladder()[1][1] == "sink arrested" and f.ladder()[-1][1] == "landed"
    t_abort = f.t_of("abort")
    # nothing after the Land: PX4 leaves Land for Hold as it disarms, and a Land re-sent then (before the disarm
    # was a second old) left PX4 SITL disarmed in Land, where it will not arm (bench/RESULTS.md)
    assert f.heard_after(t_abort) == ["stop_offboard", "land"]
    assert f.outcome.descent_time_s is None and not f.ap.armed and f.ap.mode == "HOLD"
    phases = [e["phase"] for e in f.events if e["event"] == "phase" and e["t_s"] >= t_abort]
    assert phases == ["abort_recover", "abort_hold", "abort_land"]


def test_stale_telemetry_mid_descent_recovers_then_holds_and_lands_blind(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, ap.stop_telemetry)

    f = fly(tmp_path, script)
    assert f.summary["abort_verdict"] == gd.STALE and f.ladder()[0][0] == "RECOVER"
    stale_s = f.t_of("abort") - f.t_of("phase", phase="stream") - 1.0
    assert 0.0 < stale_s <= 0.3  # issue 11: a dead link acted on within 0.3 s offboard
    assert [r for r, _ in f.ladder()][:3] == ["RECOVER", "HOLD", "LAND"]
    assert f.ladder()[1][1] == "recovery not confirmed within 2 s"  # nothing to confirm it with
    assert f.ladder()[-1] == ("DONE", "landed")  # the heartbeat's armed flag still comes
    assert not f.ap.armed and f.ap.p_ned[2] == 0.0


def test_a_link_lost_for_good_is_left_to_the_vehicles_failsafe_after_link_give_up(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, ap.lose_link)

    f = fly(tmp_path, script)
    t_lost = f.t_of("phase", phase="stream") + 1.0
    assert f.summary["abort_verdict"] == gd.STALE  # telemetry stops before MAVSDK says disconnected
    last_rung, why = f.ladder()[-1]
    assert last_rung == "DONE" and why.endswith("the vehicle's own failsafe is in charge")
    t_done = f.summary["ladder"][-1]["t_s"]
    # the ladder keeps judging while its Hold goes unanswered: it gives up LINK_GIVE_UP_S after it started
    # (the stale rule's 0.25 s after the loss), not after the command's 5 s timeout on top
    assert LINK_GIVE_UP_S <= t_done - t_lost <= LINK_GIVE_UP_S + 0.4
    assert f.ap.mode == "HOLD" and f.ap.armed  # PX4's offboard-loss failsafe holds it in the air
    assert f.heard_after(t_lost) == []


def test_a_link_reported_lost_at_once_starts_the_ladder_at_hold(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, ap.lose_link)

    f = fly(tmp_path, script, disconnect_report_s=0.0)
    assert f.outcome.abort_reason == "link lost" and f.ladder()[0][0] == "HOLD"
    assert "failsafe is in charge" in f.ladder()[-1][1]


def test_a_link_back_within_give_up_lets_the_ladder_finish_on_the_ground(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, ap.lose_link)
        ap.after(lambda: not ap.link_up, 2.0, ap.restore_link)

    f = fly(tmp_path, script)
    assert f.summary["abort_verdict"] == gd.STALE
    assert f.ladder()[-1] == ("DONE", "landed") and not f.ap.armed
    assert "land" in f.heard_after(f.t_of("abort"))


def test_a_hold_that_never_comes_in_the_ladder_goes_on_to_land(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, lambda: runner.interrupt("SIGINT"))

    f = fly(tmp_path, script, ignored={"stop_offboard", "hold"}, offboard_loss_failsafe=False)
    rungs = f.ladder()
    hold = next(i for i, (r, _) in enumerate(rungs) if r == "LAND")
    assert rungs[hold][1] == "Hold not confirmed within 3 s (mode OFFBOARD)"
    assert rungs[-1] == ("DONE", "landed") and not f.ap.armed


def test_a_vehicle_that_never_lands_ends_the_ladder_at_its_timeout(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, lambda: runner.interrupt("SIGINT"))

    f = fly(tmp_path, script, ignored={"land"})
    rungs = f.ladder()
    assert rungs[-1] == ("DONE", "ladder timed out")
    t = [x["t_s"] for x in f.summary["ladder"]]
    assert t[-1] - t[0] == pytest.approx(LADDER_TIMEOUT_S, abs=0.2)
    assert len(f.ap.heard("land")) >= LADDER_TIMEOUT_S / 3.0 - 3  # re-sent every land_retry_s (3 s)
    assert f.ap.armed and f.ap.mode == "HOLD"  # what the runner could not change, reported as it is
    assert f.summary["final_mode"] == "HOLD" and f.summary["final_armed"] is True


def test_stale_telemetry_while_landing_hands_the_landing_to_the_ladders_land(tmp_path):
    def script(ap, runner):
        ap.after(lambda: runner.phase == "land", 0.5, ap.stop_telemetry)
        ap.after(lambda: not ap.telemetry_on, 2.0, ap.resume_telemetry)

    f = fly(tmp_path, script)
    assert f.outcome.descent_time_s is not None
    assert [e for e in f.events if e["event"] == "stale_while_landing"]
    assert f.ladder()[0][0] == "LAND" and f.ladder()[-1] == ("DONE", "landed")
    assert any("during Land" in why for _, why in f.ladder())
    assert len(f.ap.heard("land")) >= 2 and not f.ap.armed  # the ladder asked again


def test_an_exception_in_the_flow_still_lands_and_writes_the_log(tmp_path):
    f = fly(tmp_path, refused={"takeoff": "denied"})
    assert f.outcome.outcome == "aborted" and f.outcome.abort_reason == "error: takeoff: denied"
    assert f.summary["abort_verdict"] == "exception"
    assert any(e["event"] == "exception" and "denied" in e["error"] for e in f.events)
    assert f.ladder()[-1] == ("DONE", "landed") and not f.ap.armed


# -- ArduCopter: its modes, its hold, its pilots, its preflight (issue 15) ---------------------------------

# what the preflight tells the user to set for this plan (the vertical's 1.47 m/s²), and nothing more
AP_READY = {**AP_DEFAULTS, "WP_ACC_Z": 1.5}


def fly_ap(tmp_path: Path, script=None, land: bool = True, **autopilot: Any) -> Flight:
    autopilot.setdefault("params", dict(AP_READY))
    return fly(tmp_path, script, land, autopilot=ARDUPILOT, **autopilot)


def test_ardupilot_defaults_are_refused_before_arming_with_the_value_to_set(tmp_path):
    f = fly(tmp_path, autopilot=ARDUPILOT)
    assert f.outcome.outcome == "refused" and f.outcome.exit_code == 2
    assert f.outcome.abort_reason.startswith("preflight failed: WP_ACC_Z: 1 m/s²")
    assert "set WP_ACC_Z to 1.3" in f.outcome.abort_reason  # the vertical's peak, ramped at its jerk
    assert "arm" not in [c for _, c in f.ap.commands]
    checks = {c["name"]: c for c in f.summary["preflight"]["checks"]}
    assert checks["FS_GCS_ENABLE"]["status"] == "warn" and checks["MAV_GCS_SYSID"]["status"] == "warn"
    assert "set MAV_GCS_SYSID to 245" in checks["MAV_GCS_SYSID"]["requirement"]
    assert "COM_OF_LOSS_T" not in checks  # PX4's table is not asked of ArduPilot


def test_older_ardupilot_names_are_refused_with_the_value_to_set_in_their_own_unit(tmp_path):
    params = {k: v for k, v in AP_DEFAULTS.items() if k not in ("WP_ACC_Z", "WP_SPD_DN")}
    f = fly(tmp_path, autopilot=ARDUPILOT, params={**params, "WPNAV_ACCEL_Z": 100.0, "WPNAV_SPEED_DN": 150.0})
    assert f.outcome.outcome == "refused"  # a trajectory file (no replan): judged as it is
    assert f.outcome.abort_reason.startswith("preflight failed: WPNAV_ACCEL_Z: 1 m/s²")
    assert "set WPNAV_ACCEL_Z to 130" in f.outcome.abort_reason  # cm/s², as that firmware holds it
    checks = {c["name"]: c for c in f.summary["preflight"]["checks"]}
    assert checks["WPNAV_SPEED_DN"]["status"] == "pass" and checks["WPNAV_SPEED_DN"]["value"] == "1.5 m/s"


def test_px4s_own_vertical_speeds_keep_the_plan_and_make_its_optimum_within_them(tmp_path):
    # issue 22: PX4 clips offboard descents to MPC_Z_VEL_MAX_DN. Raised for the test day (as the rehearsal does), the
    # plan stays as it is (its config keeps it below PX4's default) and the yardstick is made for the vehicle's own
    def replan(_profile):
        raise AssertionError("a PX4 speed limit planned the mission again")

    raised = {**PX4_DEFAULTS, "MPC_Z_VEL_MAX_DN": 3.0}
    f = fly(tmp_path, params=raised, request={"replan": replan})
    assert f.outcome.outcome == "completed", f.outcome.abort_reason
    live = next(e for e in f.events if e["event"] == "live_limits")
    assert live["changed"] == ["MPC_Z_VEL_MAX_DN 3 (the profile's 1.5)"] and live["replanned"] is False
    assert f.runner.req.profile.autopilot.descent_max_mps == 3.0
    assert f.runner.traj.duration_s == load_mission_module("vertical").plan(X500, config()).duration_s
    assert f.summary["optimum_s"] == vertical_optimum(f.runner.req.profile, DESCENT_M).optimum_s
    # lowered below the plan: flown slower than asked? No: refused before arming, the parameter named
    (tmp_path / "low").mkdir()
    g = fly(tmp_path / "low", params={**PX4_DEFAULTS, "MPC_Z_VEL_MAX_DN": 0.2}, request={"replan": replan})
    assert g.outcome.outcome == "refused" and "MPC_Z_VEL_MAX_DN" in g.outcome.abort_reason
    assert "arm" not in [c for _, c in g.ap.commands]


def _replan(cfg):
    return lambda profile: (load_mission_module("vertical").plan(profile, cfg), [])


@pytest.mark.parametrize("names", ["newer", "older"])
def test_ardupilot_limits_read_at_the_preflight_are_planned_within(tmp_path, names):
    # issue 22: the plan made within the vehicle's own GUIDED limits, not a profile's copy (x500 has none): the
    # vertical's 1.47 m/s² within 90 % of WP_ACC_Z 1, where the profile's plan was refused. Older firmware
    # names it WPNAV_ACCEL_Z, in cm/s² (ArduCopter SITL 90700977)
    params = dict(AP_DEFAULTS)
    if names == "older":
        for new, old in (("WP_ACC_Z", "WPNAV_ACCEL_Z"), ("WP_ACC", "WPNAV_ACCEL"), ("WP_SPD_DN", "WPNAV_SPEED_DN"),
                         ("WP_SPD_UP", "WPNAV_SPEED_UP")):  # fmt: skip
            params[old] = 100.0 * params.pop(new)
        params["PSC_JERK_Z"] = params.pop("PSC_JERK_D")
    f = fly(tmp_path, autopilot=ARDUPILOT, params=params, request={"replan": _replan(config())})
    assert f.outcome.outcome == "completed", f.outcome.abort_reason
    name = "WP_ACC_Z" if names == "newer" else "WPNAV_ACCEL_Z"
    live = next(e for e in f.events if e["event"] == "live_limits")["changed"]
    assert any(x.startswith(f"{name} {1 if names == 'newer' else 100} ") for x in live), live
    flown = pd.read_csv(Path(f.outcome.log_dir) / "trajectory.csv")
    assert flown["ad_mps2"].abs().max() <= 0.9 * 1.0 + 1e-6  # what the vehicle was told: within its 90 %
    assert f.runner.traj.duration_s > load_mission_module("vertical").plan(X500, config()).duration_s
    checks = {c["name"]: c for c in f.summary["preflight"]["checks"]}
    assert checks[name]["status"] == "pass" and checks[name]["value"] == "1 m/s²"
    assert "rides it" in checks[name]["requirement"]  # the limit bounds the plan: raising it would pay


def test_no_plan_within_the_vehicles_own_limits_is_refused_before_arming(tmp_path):
    def replan(_profile):
        raise ValueError("IPOPT: restoration failed")  # what a planner may raise, not only FlighttestError

    f = fly(tmp_path, autopilot=ARDUPILOT, request={"replan": replan})
    assert f.outcome.outcome == "refused" and f.outcome.exit_code == 2
    assert f.outcome.abort_reason.startswith("no plan within the vehicle's own limits (WP_ACC_Z 1 ")
    assert "restoration failed" in f.outcome.abort_reason and "arm" not in [c for _, c in f.ap.commands]


def test_ardupilot_flies_the_descent_in_guided_and_lands(tmp_path):
    f = fly_ap(tmp_path)
    assert f.outcome.outcome == "completed" and f.outcome.descent_time_s is not None
    # it boots in STABILIZE, a pilot's mode: the flight starts from GUIDED (from the arm on, a pilot's mode is a
    # takeover)
    assert [c for _, c in f.ap.commands] == ["set_mode", "arm", "set_takeoff_altitude", "takeoff", "start_offboard",
                                             "land"]  # fmt: skip
    autopilot = next(e for e in f.events if e["event"] == "autopilot")
    assert autopilot["offboard_mode"] == "GUIDED" and autopilot["hold_mode"] == "BRAKE"
    assert {e["new"] for e in f.events if e["event"] == "mode"} == {"GUIDED", "LAND"}
    assert f.summary["final_mode"] == "LAND" and not f.ap.armed
    assert f.ap.takeoff_alt_m == 2.0  # its takeoff stops at the handover, at rest, not on its way to START_M


def test_ardupilot_abort_brakes_then_lands(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, lambda: ap.push((0.0, 0.0, 14.0), 0.4))

    f = fly_ap(tmp_path, script)
    assert [r for r, _ in f.ladder()] == ["RECOVER", "HOLD", "LAND", "DONE"]
    # its hold rung is BRAKE, asked for as such: "offboard stop" would leave it in a pilot's mode
    assert f.heard_after(f.t_of("abort")) == ["hold", "land"]
    assert [e["new"] for e in f.events if e["event"] == "mode" and e["t_s"] > f.t_of("abort")] == ["BRAKE", "LAND"]
    assert f.ladder()[-1] == ("DONE", "landed") and not f.ap.armed


@pytest.mark.parametrize("mode", ["LOITER", "ALT_HOLD", "POSHOLD", "STABILIZE"])
def test_ardupilot_pilot_modes_mid_descent_are_a_takeover(tmp_path, mode):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, lambda: ap.pilot(mode))

    f = fly_ap(tmp_path, script)
    assert f.outcome.abort_reason == f"pilot took over ({mode})"
    assert f.ladder()[-1] == ("DONE", f"pilot in control ({mode})")
    assert f.heard_after(f.t_of("mode", new=mode)) == [] and f.ap.mode == mode and f.ap.armed


def test_ardupilot_no_land_ends_braking_in_the_air(tmp_path):
    f = fly_ap(tmp_path, land=False)
    assert f.outcome.outcome == "completed" and f.ap.mode == "BRAKE" and f.ap.armed
    assert [c for _, c in f.ap.commands][-1] == "hold"


def test_ardupilot_link_lost_stays_in_guided_braking_after_guid_timeout(tmp_path):
    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, ap.lose_link)

    f = fly_ap(tmp_path, script)
    assert "the vehicle's own failsafe is in charge" in f.ladder()[-1][1]
    # no offboard-loss mode change on ArduPilot: GUID_TIMEOUT zeroes the targets, it holds in GUIDED
    assert f.ap.mode == "GUIDED" and f.ap.armed and f.ap.setpoint is None and f.ap.speed_mps < 0.05


def test_ardupilot_second_flight_on_the_same_vehicle_arms_from_guided(tmp_path):
    # the campaign flies several times without a reboot: ArduCopter is left disarmed in LAND, and MAVSDK's
    # arm would turn that into BRAKE, where it refuses to arm; the preflight sets GUIDED first
    cfg = config()
    traj = load_mission_module("vertical").plan(X500, cfg)
    ap = ScriptedAutopilot(autopilot=ARDUPILOT, params=dict(AP_READY))
    outcomes = []
    for k in range(2):
        req = FlyRequest("udpin://0.0.0.0:14540", X500, cfg, traj, "vertical", yes=True, log_root=tmp_path / str(k),
                         print_fn=lambda _: None)  # fmt: skip
        outcomes.append(run_virtual(MissionRunner(req, open_link=lambda _t, _e: ap).run()))
        assert ap.mode == "LAND" and not ap.armed
    assert [o.outcome for o in outcomes] == ["completed", "completed"]
    heard = [c for _, c in ap.commands]
    assert heard.count("arm") == 2 and heard[heard.index("land") + 1] == "set_mode"
    events = [json.loads(x) for x in (Path(outcomes[1].log_dir) / "events.jsonl").read_text().splitlines()]
    reset = next(e for e in events if e["event"] == "mode_reset")
    assert (reset["old"], reset["new"]) == ("LAND", "GUIDED")


def test_without_a_terminal_a_flight_says_what_it_does(tmp_path):
    said: list[object] = []
    f = fly(tmp_path, request={"print_fn": said.append})
    lines = [x.split("] ", 1)[1] for x in said if isinstance(x, str)]
    assert lines[5].startswith("wind 0.") and lines[5].endswith("(flighttest): flying the plan for 0 m/s of wind")
    assert lines[:5] + lines[6:] == ["connected: preflight checks", "arming", "taking off",
                                     f"took off: climbing to {START_M:g} m in OFFBOARD", "settling at the start point",
                                     "descent started", "descent flown: settling at the end point", "landing",
                                     "landed and disarmed"]  # fmt: skip
    assert f.outcome.outcome == "completed"


def test_an_abort_is_said_with_its_rungs(tmp_path):
    said: list[object] = []

    def script(ap, runner):
        ap.after(in_phase(runner, "stream"), 1.0, lambda: runner.interrupt("SIGINT"))

    fly(tmp_path, script, request={"print_fn": said.append})
    lines = [x.split("] ", 1)[1] for x in said if isinstance(x, str)]
    i = lines.index("ABORT in stream: SIGINT from the operator")
    assert lines[i + 1:] == ["abort ladder: recover", "abort ladder: hold", "abort ladder: land"]


def test_a_run_refused_for_want_of_a_terminal_leaves_no_flight_folder(tmp_path):
    f = fly(tmp_path, request={"yes": False})  # pytest's stdin is no terminal
    assert f.outcome.outcome == "refused" and f.outcome.abort_reason.startswith("no terminal to confirm arming")
    assert f.outcome.log_dir is None and list(tmp_path.iterdir()) == []
    assert f.summary["preflight"]["ok"] is True and "arm" not in [c for _, c in f.ap.commands]


def test_a_trajectory_is_judged_against_the_tilt_the_vehicle_allows(tmp_path):
    # issue 22: MPC_TILTMAX_AIR (ATC_ANGLE_MAX on ArduCopter) read at the preflight; a file is flown as it is, so
    # one leaning 17.9° is refused before arming on a vehicle that allows 15, where the level vertical flies
    lean = leaning_descent()
    for d in ("low", "ok"):
        (tmp_path / d).mkdir()
    low = fly(tmp_path / "low", traj=lean, params={**PX4_DEFAULTS, "MPC_TILTMAX_AIR": 15.0})
    checks = {c["name"]: c for c in low.summary["preflight"]["checks"]}
    assert low.outcome.outcome == "refused" and low.outcome.exit_code == 2
    assert "arm" not in [c for _, c in low.ap.commands]
    assert checks["tilt"]["status"] == "fail" and checks["tilt"]["value"] == "max 17.9°"
    assert "≤ 15°" in checks["tilt"]["requirement"]
    ok = fly(tmp_path / "ok", params={**PX4_DEFAULTS, "MPC_TILTMAX_AIR": 15.0})  # the level vertical
    assert ok.outcome.outcome == "completed", ok.outcome.abort_reason
    live = next(e for e in ok.events if e["event"] == "live_limits")
    assert live["changed"] == ["MPC_TILTMAX_AIR 15 (the profile's 45)"] and live["replanned"] is False
    assert {c["name"]: c for c in ok.summary["preflight"]["checks"]}["tilt"]["status"] == "pass"
