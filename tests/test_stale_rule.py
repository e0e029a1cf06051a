"""The stale-telemetry rule against the telemetry real links deliver, and the garbage collector held
off during a flight (issue 11 item 4). No flights: virtual time throughout.

The reference flights on PX4 SITL (``../shared/px4_sih``, skipped where absent) are replayed through
the guard's stale logic: healthy links never trip it, although their gaps reach 173 ms (one flight
aborted on the old 60 ms rule, and the replay reproduces that abort). A dead link trips it within
0.3 s wherever flighttest flies offboard; where PX4 flies itself a short gap is only logged.
"""

from __future__ import annotations

import asyncio
import gc
import itertools
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from flighttest.analysis.loaders.mavlink_frames import decode, read_frames
from flighttest.flying import guard as g
from flighttest.flying import runner as ms
from flighttest.flying.log_writer import FlightLogWriter
from flighttest.flying.missions_config import MissionConfig, load_mission_config, mission_config_from_dict
from flighttest.flying.pauses import FlightCollector
from flighttest.model.profiles import load_profile
from sitl_fakes.virtual_time import run_virtual

X500 = load_profile("x500")
PX4_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "px4_sih"
PX4_FLIGHTS = ["helix-5m-guard-abort-1", "helix-5m-guard-abort-2", "probe-full-sweep", "probe-stale-abort",
               "vertical-3m-completed", "vertical-5m-guard-abort"]  # fmt: skip
TICK_S = 0.02  # the runner's stale ticker: one telemetry period at 50 Hz
DEAD_LINK_BUDGET_S = 0.3  # issue 11: a dead link is acted on within this while flying offboard
WORST_HEALTHY_GAP_S = 0.173  # the longest the reference links went quiet, both state streams merged


def _limits(**kw) -> g.GuardLimits:
    return g.GuardLimits(region=X500.guard_region(), telemetry_period_s=TICK_S, **kw)


def replay(limits: g.GuardLimits, state_t, posvel_t, phase_at, t_end: float, offset_s: float = 0.0):
    """Every decision ``Guard.on_tick`` makes on ticks every TICK_S (first at ``offset_s`` after the
    first sample) while samples arrive at ``state_t`` (any stream) and ``posvel_t`` (position-
    velocity). ``phase_at(t)``: the runner's phase, or "" where it does not judge staleness (before
    connecting, after landing, the ladder in charge). Returns [(t, phase, decision)]."""
    guard = g.Guard(limits)
    arrivals = sorted([(t, False) for t in state_t] + [(t, True) for t in posvel_t])
    out, i = [], 0
    now = arrivals[0][0] + offset_s
    while now <= t_end:
        while i < len(arrivals) and arrivals[i][0] <= now:
            t, is_posvel = arrivals[i]
            guard.note_state_sample(t)
            if is_posvel:
                guard.last_velocity_t = t
            i += 1
        phase = phase_at(now)
        if phase:
            guard.armed = phase not in ("land", "preflight", "connect")  # as the runner sets it
            d = guard.on_tick(now, phase)
            if d is not None:
                out.append((now, phase, d))
        now += TICK_S
    return out


# -- the reference flights on PX4 -------------------------------------------------------------------


def _reference(name: str):
    folder = PX4_DIR / name
    if not (folder / "flight.tlog").is_file():
        pytest.skip(f"reference flight not available: {folder} (needs ../shared next to the checkout)")
    frames = read_frames(folder / "flight.tlog")
    pos = decode(frames, "LOCAL_POSITION_NED", sysid=1).recv_us / 1e6
    att = decode(frames, "ATTITUDE_QUATERNION", sysid=1).recv_us / 1e6
    events = [json.loads(line) for line in (folder / "events.jsonl").read_text().splitlines() if line.strip()]
    spans, t_abort = [], math.inf
    for e in events:
        if e["event"] == "phase" and e["unix_s"] < t_abort:
            spans.append((e["unix_s"], e["phase"]))
        if e["event"] == "abort":
            t_abort = min(t_abort, e["unix_s"])
            spans.append((e["unix_s"], ""))  # the ladder watches the telemetry itself from here
    starts = np.array([t for t, _ in spans])
    names = [""] + [p if p not in ("landed", "dry_run") else "" for _, p in spans]

    def phase_at(t: float) -> str:
        return names[int(np.searchsorted(starts, t, side="right"))]

    state = np.sort(np.concatenate([pos, att]))
    return state, np.sort(pos), phase_at, events


@pytest.mark.parametrize("name", PX4_FLIGHTS)
def test_healthy_px4_links_never_trip_the_stale_rule(name):
    state, pos, phase_at, _ = _reference(name)
    limits = _limits()
    for offset in (0.0, 0.005, 0.01, 0.015):  # every alignment of the ticker to the samples
        decisions = replay(limits, state, pos, phase_at, state[-1], offset)
        assert not [d for _, _, d in decisions if d.aborts], name
    # and not by luck of the ticks: every gap is shorter than the limit of the phases it spans
    for stream in (state, pos):
        limit_of = {True: limits.autopilot_stale_s, False: limits.stale_after_s}
        factor = 1.0 if stream is state else g.VELOCITY_STALE_FACTOR
        for a, b in itertools.pairwise(stream):
            pa, pb = phase_at(a), phase_at(b)
            if not (pa or pb):
                continue
            lim = min(limit_of[p in g.AUTOPILOT_PHASES] for p in (pa, pb) if p) * factor
            assert b - a < lim, (name, pa, pb, b - a)


def test_the_replay_reproduces_the_abort_the_old_rule_gave_on_px4():
    """probe-stale-abort aborted in the hover before the sweep on "no telemetry for 69 ms (> 60 ms)":
    the replay with the old rule (3 periods everywhere the guard was armed) finds it too."""
    state, pos, phase_at, events = _reference("probe-stale-abort")
    old = _limits(stale_periods=3.0)

    def old_phase(t: float) -> str:  # the old runner judged every armed phase alike, land excepted
        p = phase_at(t)
        return "stream" if p in ("arm", "takeoff", "climb", "settle", "stream") else ""

    aborts = [(t, d) for t, _, d in replay(old, state, pos, old_phase, state[-1]) if d.aborts]
    t_real = next(e["unix_s"] for e in events if e["event"] == "abort")
    assert aborts and abs(aborts[0][0] - t_real) < 0.1
    assert phase_at(aborts[0][0]) == "settle"
    assert re.match(r"no telemetry for 6\d ms \(> 60 ms\)", aborts[0][1].reason)


# -- synthetic links: what CI always checks -----------------------------------------------------------


def _link(t0: float, t1: float, gaps: dict[float, float] = {}, period_s: float = 0.02):  # noqa: B006
    """Position-velocity and attitude at 50 Hz, 10 ms apart, from t0 to t1; ``gaps``: start → length,
    nothing arrives in them (then, as on PX4, what was held back arrives at once)."""
    pos = np.arange(t0, t1, period_s)
    att = pos + period_s / 2
    for start, length in gaps.items():
        pos = np.where((pos > start) & (pos < start + length), start + length, pos)
        att = np.where((att > start) & (att < start + length), start + length, att)
    return np.sort(np.concatenate([pos, att])), np.sort(pos)


def test_the_worst_gaps_measured_on_px4_do_not_trip_in_offboard():
    # the longest quiet spell of a healthy link (173 ms), a process pause (56 ms), PX4 SITL's 85 ms gaps
    state, pos = _link(0.0, 10.0, {2.0: WORST_HEALTHY_GAP_S, 4.0: 0.056, 6.0: 0.085, 6.3: 0.085})
    for phase in sorted(g.OFFBOARD_PHASES):
        for offset in np.arange(0.0, TICK_S, 0.002):
            decisions = replay(_limits(), state, pos, lambda t, p=phase: p, 10.0, offset)
            assert decisions == [], (phase, offset)


@pytest.mark.parametrize("phase", sorted(g.OFFBOARD_PHASES))
def test_a_dead_link_trips_within_0_3_s_while_flying_offboard(phase):
    t_dead = 5.0
    state, pos = _link(0.0, t_dead)
    last = state[-1]
    for offset in np.arange(0.0, TICK_S, 0.001):
        decisions = replay(_limits(), state, pos, lambda t: phase, t_dead + 2.0, offset)
        first = decisions[0]
        t, _, d = first
        assert d.verdict == g.STALE and d.aborts, (offset, d)
        assert g.STALE_AFTER_S < t - last <= g.STALE_AFTER_S + TICK_S + 1e-9 < DEAD_LINK_BUDGET_S
        assert d.reason.startswith("no telemetry for") and "(> 250 ms)" in d.reason
    assert g.stale_rung(phase) == g.Rung.RECOVER


def test_position_velocity_alone_lost_trips_at_twice_the_limit():
    """Attitude still arriving but no position-velocity: the region cannot be judged; stale at 0.5 s."""
    state, pos = _link(0.0, 10.0)
    pos = pos[pos < 5.0]
    decisions = replay(_limits(), state, pos, lambda t: "stream", 10.0)
    t, _, d = decisions[0]
    assert d.aborts and d.reason.startswith("no position-velocity telemetry")
    assert 2 * g.STALE_AFTER_S < t - pos[-1] <= 2 * g.STALE_AFTER_S + TICK_S + 1e-9


def test_a_150_ms_gap_during_takeoff_is_logged_not_an_abort():
    state, pos = _link(0.0, 4.0, {2.0: 0.150})
    for phase in ("arm", "takeoff", "land", "hold"):
        decisions = replay(_limits(), state, pos, lambda t, p=phase: p, 4.0)
        assert not any(d.aborts for _, _, d in decisions), phase
        assert decisions == [] or all(d.action == g.OBSERVE for _, _, d in decisions)
    # on a gap longer than the tolerance (0.25 s) it does show, as observed only
    state, pos = _link(0.0, 4.0, {2.0: 0.6})
    decisions = replay(_limits(), state, pos, lambda t: "takeoff", 4.0)
    assert decisions and all(d.action == g.OBSERVE for _, _, d in decisions)
    assert "in takeoff: the autopilot flies itself" in decisions[0][2].reason


def test_a_long_gap_where_px4_flies_itself_starts_the_ladder():
    state, pos = _link(0.0, 3.0)
    for phase, rung in (("takeoff", g.Rung.HOLD), ("arm", g.Rung.HOLD), ("hold", g.Rung.HOLD),
                        ("land", g.Rung.LAND)):  # fmt: skip
        decisions = replay(_limits(), state, pos, lambda t, p=phase: p, 6.0)
        t, _, d = next((t, p, d) for t, p, d in decisions if d.aborts)
        assert g.AUTOPILOT_STALE_S < t - state[-1] <= g.AUTOPILOT_STALE_S + TICK_S + 1e-9, phase
        assert "(> 1000 ms)" in d.reason and g.stale_rung(phase) == rung


def test_before_arming_nothing_acts_and_before_the_first_sample_nothing_is_stale():
    guard = g.Guard(_limits())
    assert guard.on_tick(100.0, "stream") is None
    guard.note_state_sample(0.0)
    guard.armed = False
    d = guard.on_tick(1.0, "preflight")
    assert d.verdict == g.STALE and d.action == g.NONE


def test_the_guard_keeps_the_longest_gap_for_the_log():
    guard = g.Guard(_limits())
    for t in (0.0, 0.02, 0.04, 0.21, 0.23, 0.1):  # an old sample arriving late is no gap
        guard.note_state_sample(t)
    assert guard.max_gap_s == pytest.approx(0.17)


# -- the limit's two spellings ----------------------------------------------------------------------------


def test_stale_periods_still_works_and_defines_the_limit_in_one_place():
    assert _limits().stale_after_s == g.STALE_AFTER_S == 0.25
    assert _limits(stale_periods=15.0).stale_after_s == pytest.approx(0.3)  # what the CI tests pass
    assert _limits(stale_after_s=0.1, stale_periods=3.0).stale_after_s == pytest.approx(0.06)  # periods win
    assert g.GuardLimits(region=X500.guard_region(), telemetry_period_s=0.1, stale_periods=3).stale_after_s == (
        pytest.approx(0.3))  # fmt: skip
    # where PX4 flies itself never stricter than offboard
    assert _limits(stale_periods=75.0).autopilot_stale_s == pytest.approx(1.5)
    cfg = mission_config_from_dict({"mission": "vertical", "guard": {"stale_periods": 15}})
    assert cfg.guard.stale_periods == 15.0 and cfg.guard.stale_after_s == g.STALE_AFTER_S
    cfg = mission_config_from_dict({"mission": "vertical", "guard": {"stale_after_s": 0.4}})
    assert cfg.guard.stale_after_s == 0.4 and cfg.guard.stale_periods is None


@pytest.mark.parametrize("value", [0, -1, 1.5, "x", True])
def test_stale_after_s_out_of_range_is_one_line(value):
    from flighttest.errors import FlighttestError

    with pytest.raises(FlighttestError, match=r"^cfg \[guard\]: 'stale_after_s' must be"):
        mission_config_from_dict({"mission": "vertical", "guard": {"stale_after_s": value}}, "cfg")


def test_the_shipped_missions_fly_the_new_rule():
    from flighttest.flying.mission_scripts import MISSIONS, MISSIONS_DIR

    for stem in MISSIONS.values():
        cfg = load_mission_config(MISSIONS_DIR / f"{stem}.toml")
        assert cfg.guard.stale_after_s == g.STALE_AFTER_S and cfg.guard.stale_periods is None, stem


# -- the runner's stale ticker, in virtual time ---------------------------------------------------------


def _runner(tmp_path: Path, **guard) -> ms.MissionRunner:
    from flighttest.planner.export import vertical_trajectory
    from flighttest.planner.vertical import plan_vertical

    traj = vertical_trajectory(plan_vertical(X500, height_m=3.0), "x500", X500.mass_kg)
    cfg = mission_config_from_dict({"mission": "vertical", "guard": guard}) if guard else MissionConfig("vertical")
    req = ms.FlyRequest(connect="udpout://127.0.0.1:14580", profile=X500, config=cfg, trajectory=traj,
                        mission_name="vertical")  # fmt: skip
    runner = ms.MissionRunner(req)
    runner.log = FlightLogWriter(tmp_path, "vertical", t0_mono=0.0)
    return runner


def _tick(runner: ms.MissionRunner, state, pos, phases: dict[float, str], until: float) -> list[dict]:
    """Run the runner's ``_stale_ticker`` on a virtual clock (``sitl_fakes.virtual_time``, from 0):
    samples (``state``, ``pos``) reach the guard at their times, ``phases`` (time → phase) are set at
    theirs. The events it logged, in order."""

    def arrive(t: float, is_posvel: bool) -> None:
        runner.guard.note_state_sample(t)
        if is_posvel:
            runner.guard.last_velocity_t = t

    def enter(phase: str) -> None:
        runner.phase = phase
        runner.guard.armed = phase not in ("land", "preflight")

    async def main() -> None:
        loop = asyncio.get_running_loop()
        for t in state:
            loop.call_at(t, arrive, t, t in pos_set)
        for t, phase in phases.items():
            loop.call_at(t, enter, phase)
        task = loop.create_task(runner.watch.stale_ticker())
        loop.call_at(until, task.cancel)
        await asyncio.gather(task, return_exceptions=True)

    pos_set = set(pos.tolist())
    run_virtual(main(), start_s=0.0)
    runner.log.close()
    return [json.loads(line) for line in (runner.log.dir / "events.jsonl").read_text().splitlines()]


def test_the_ticker_aborts_a_dead_link_mid_stream_at_recover(tmp_path):
    runner = _runner(tmp_path)
    state, pos = _link(0.0, 3.0)
    events = _tick(runner, state, pos, {0.0: "settle", 1.0: "stream"}, 4.0)
    aborts = [e for e in events if e["event"] == "abort"]
    assert len(aborts) == 1 and aborts[0]["phase"] == "stream" and aborts[0]["rung"] == "RECOVER"
    assert runner.abort_verdict == g.STALE
    t_abort = runner.ladder.history[0][0]
    assert t_abort - state[-1] <= DEAD_LINK_BUDGET_S
    rule = next(e for e in events if e["event"] == "stale_rule")
    assert rule["offboard_s"] == 0.25 and rule["autopilot_s"] == 1.0
    gaps = {e["phase"]: e["max_gap_ms"] for e in events if e["event"] == "telemetry_gaps"}
    assert gaps["settle"] == pytest.approx(10.0, abs=0.5)


def test_the_ticker_logs_a_gap_in_takeoff_once_and_flies_on(tmp_path):
    runner = _runner(tmp_path)
    state, pos = _link(0.0, 6.0, {2.0: 0.3, 2.6: 0.4, 4.0: 0.150})
    events = _tick(runner, state, pos, {0.0: "takeoff", 5.0: "climb"}, 6.0)
    assert not runner.ladder.active and not [e for e in events if e["event"] == "abort"]
    noted = [e for e in events if e["event"] == "stale_while_takeoff"]
    assert len(noted) == 2  # one per gap over 0.25 s; the 150 ms one is below even that
    assert noted[0]["reason"].endswith("in takeoff: the autopilot flies itself")
    gaps = {e["phase"]: e["max_gap_ms"] for e in events if e["event"] == "telemetry_gaps"}
    assert gaps["takeoff"] == pytest.approx(400.0, abs=11.0)


def test_the_ticker_hands_a_long_gap_while_landing_to_the_ladders_land(tmp_path):
    runner = _runner(tmp_path)
    state, pos = _link(0.0, 2.0)
    events = _tick(runner, state, pos, {0.0: "land"}, 4.0)
    assert [e["event"] for e in events].count("stale_while_landing") == 1
    aborts = [e for e in events if e["event"] == "abort"]
    assert len(aborts) == 1 and aborts[0]["rung"] == "LAND" and "(> 1000 ms)" in aborts[0]["reason"]


def test_the_ticker_leaves_staleness_to_the_ladder_once_it_runs(tmp_path):
    runner = _runner(tmp_path)
    runner.ladder.trigger(0.0, "an earlier abort")
    state, pos = _link(0.0, 1.0)
    events = _tick(runner, state, pos, {0.0: "stream"}, 3.0)
    assert not [e for e in events if e["event"] in ("abort", "stale_while_stream")]
    assert runner.ladder.reason == "an earlier abort"


def test_a_config_in_periods_flies_its_periods(tmp_path):
    runner = _runner(tmp_path, stale_periods=15.0)  # the CI allowance: 0.3 s
    assert runner.limits.stale_after_s == pytest.approx(0.3)
    state, pos = _link(0.0, 2.0, {1.0: 0.28})
    events = _tick(runner, state, pos, {0.0: "stream"}, 3.0)
    aborts = [e for e in events if e["event"] == "abort"]
    assert len(aborts) == 1 and "(> 300 ms)" in aborts[0]["reason"]  # the dead link at 2 s, not the gap


# -- the garbage collector during a flight ------------------------------------------------------------


@pytest.fixture
def collector_state():
    """The collector as the test found it, put back whatever happens."""
    before = gc.isenabled(), gc.get_threshold(), gc.get_freeze_count()
    yield before
    gc.unfreeze()
    gc.set_threshold(*before[1])
    gc.enable() if before[0] else gc.disable()


def test_the_collector_is_held_off_in_flight_and_restored_after(collector_state):
    gc.enable()
    gc.set_threshold(700, 10, 10)
    with FlightCollector() as gcx:
        assert gc.isenabled()  # connected, preflight: still collecting, the heap frozen
        assert gc.get_freeze_count() > 1000 and abs(gcx.stats.frozen - gc.get_freeze_count()) < 100
        assert gcx.hold_off() >= 0.0
        assert not gc.isenabled()
        junk = [[] for _ in range(100)]
        for a, b in itertools.pairwise(junk):
            a.append(b)
            b.append(a)  # cycles: only a collection frees them
        del junk, a, b
        ms_ = gcx.safe_point()
        assert ms_ >= 0.0 and gcx.stats.safe_points == 1 and gcx.stats.collected >= 100
        assert not gc.isenabled()
    assert gc.isenabled() and gc.get_threshold() == (700, 10, 10) and gc.get_freeze_count() == 0
    d = gcx.stats.to_dict()
    assert d["collections"]["gen2"] >= 1 and d["entry_ms"] > 0 and d["safe_points"] == 1


def test_the_collector_is_restored_on_an_exception_and_a_cancelled_task(collector_state):
    gc.enable()
    gc.set_threshold(500, 5, 5)
    with pytest.raises(RuntimeError), FlightCollector() as gcx:
        gcx.hold_off()
        raise RuntimeError("boom")
    assert gc.isenabled() and gc.get_threshold() == (500, 5, 5) and gc.get_freeze_count() == 0

    async def flight() -> None:
        with FlightCollector() as gcx:
            gcx.hold_off()
            await asyncio.sleep(10)

    async def main() -> None:
        task = asyncio.create_task(flight())
        await asyncio.sleep(0.01)
        assert not gc.isenabled()
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)

    asyncio.run(main())
    assert gc.isenabled() and gc.get_threshold() == (500, 5, 5) and gc.get_freeze_count() == 0


def test_a_collector_disabled_or_frozen_before_stays_so(collector_state):
    gc.disable()
    with FlightCollector() as gcx:
        gcx.hold_off()
    assert not gc.isenabled()
    gc.enable()
    gc.freeze()  # someone else's frozen objects: unfreeze cannot tell them apart, so they stay frozen
    n = gc.get_freeze_count()
    with FlightCollector():
        pass
    assert gc.isenabled() and gc.get_freeze_count() >= n


def test_a_disabled_collector_changes_nothing_but_counts(collector_state):
    gc.enable()
    with FlightCollector(enabled=False) as gcx:
        assert gcx.hold_off() == 0.0 and gcx.safe_point() == 0.0
        assert gc.isenabled() and gc.get_freeze_count() == 0
        gc.collect()
    assert gcx.stats.collections[2] >= 1


def test_maybe_collect_runs_a_young_collection_past_the_limit(collector_state):
    with FlightCollector(young_limit=50) as gcx:
        gcx.hold_off()
        keep = [[] for _ in range(200)]
        assert gc.get_count()[0] > 50
        before = gcx.stats.collections[0]
        gcx.maybe_collect()
        assert gcx.stats.collections[0] == before + 1 and gc.get_count()[0] < 50
        del keep


def test_the_runner_freezes_holds_off_and_restores_with_its_log(tmp_path, collector_state):
    gc.enable()
    runner = _runner(tmp_path)
    runner.pauses.freeze()
    assert gc.isenabled() and gc.get_freeze_count() > 0
    runner.pauses.hold_off()
    assert not gc.isenabled()
    runner.pauses.safe_point()
    runner.pauses.restore()
    runner.pauses.restore()  # every exit calls it: twice is harmless
    assert gc.isenabled() and gc.get_freeze_count() == 0
    runner.log.close()
    events = [json.loads(line) for line in (runner.log.dir / "events.jsonl").read_text().splitlines()]
    whats = [e["what"] for e in events if e["event"] == "gc"]
    assert whats == ["heap frozen", "held off", "safe point", "restored"]
