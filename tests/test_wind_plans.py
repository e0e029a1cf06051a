"""The helices planned ahead for wind (``flighttest.planner.wind_plans``): a ladder of speeds, a cache keyed by
what they depend on, one process planning a key at a time, a speed the planner cannot serve left out."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from flighttest.errors import FlighttestError
from flighttest.flying.plan_config import HelixPlanConfig
from flighttest.model.profiles import load_profile
from flighttest.planner.export import vertical_trajectory
from flighttest.planner.helix import solve_helix
from flighttest.planner.tracking import TrackingMargin, helix_problem_for_flight
from flighttest.planner.vertical import plan_vertical
from flighttest.planner.wind_plans import helix_plans_for_winds, wind_speeds

PLAN = {"descent_m": 2.0}


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FLIGHTTEST_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache" / "plans"


class CountingSolver:
    """A stand-in for IPOPT that takes its time: a vertical plan, tagged with the wind it was asked for."""

    def __init__(self, profile, fail_at: float | None = None, delay_s: float = 0.0):
        self.profile, self.fail_at, self.delay_s, self.calls = profile, fail_at, delay_s, []
        self.error = "the planner did not converge (Infeasible_Problem_Detected)"
        self.lock = threading.Lock()

    def __call__(self, speed_mps: float, radius_mps: float):
        with self.lock:
            self.calls.append(speed_mps)
        time.sleep(self.delay_s)
        if speed_mps == self.fail_at:
            raise FlighttestError(self.error)
        tr = vertical_trajectory(plan_vertical(self.profile, height_m=2.0), self.profile.name, self.profile.mass_kg)
        tr.meta["problem"] = {"wind_ned_mps": [0.0, speed_mps, 0.0], "wind_radius_mps": radius_mps}
        return tr


def test_the_ladder_of_speeds():
    assert wind_speeds(6.0, 1.0) == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert wind_speeds(5.0, 2.0) == [2.0, 4.0]
    assert wind_speeds(6.0, 0.0) == [] and wind_speeds(0.0, 1.0) == []
    # every wind between two steps is within a plan's radius of one (the hover judges its uncertainty)
    hp = HelixPlanConfig()
    assert hp.wind_radius_mps >= hp.wind_step_mps / 2


def test_a_solve_that_runs_out_of_time_is_no_plan():
    prof = load_profile("x500")
    problem = helix_problem_for_flight(prof, height_m=3.0, radius_m=2.0, margin=TrackingMargin(),
                                       wind_ned_mps=(0.0, 2.0, 0.0), wind_radius_mps=0.5)  # fmt: skip
    sol = solve_helix(problem, max_solve_s=0.01)
    assert not sol.success and "WallTime" in sol.result.status


def test_plans_are_cached_by_what_they_depend_on(cache):
    prof = load_profile("x500")
    solver = CountingSolver(prof)
    first = helix_plans_for_winds(prof, PLAN, [1.0, 2.0], 1.25, solver)
    assert solver.calls == [1.0, 2.0]
    again = helix_plans_for_winds(prof, PLAN, [1.0, 2.0], 1.25, solver)
    assert solver.calls == [1.0, 2.0]  # loaded, not planned again
    assert [t.meta["problem"]["wind_ned_mps"][1] for t in again] == [1.0, 2.0]
    assert [t.duration_s for t in again] == pytest.approx([t.duration_s for t in first])
    # another radius, another plan table: planned again
    helix_plans_for_winds(prof, PLAN, [1.0], 1.0, solver)
    helix_plans_for_winds(prof, {"descent_m": 3.0}, [1.0], 1.25, solver)
    assert solver.calls == [1.0, 2.0, 1.0, 1.0]


def test_a_speed_the_planner_cannot_serve_is_left_out_and_said(cache):
    prof = load_profile("x500")
    said: list[str] = []
    plans = helix_plans_for_winds(prof, PLAN, [1.0, 2.0, 3.0], 1.25, CountingSolver(prof, fail_at=2.0), said.append)
    assert [t.meta["problem"]["wind_ned_mps"][1] for t in plans] == [1.0, 3.0]
    assert any(s.startswith("no helix for 2 m/s of wind: the planner did not converge") for s in said)
    # the next flight does not spend the planner's time on it again, and says why it has no plan for it
    solver, said = CountingSolver(prof, fail_at=2.0), []
    again = helix_plans_for_winds(prof, PLAN, [1.0, 2.0, 3.0], 1.25, solver, said.append)
    assert solver.calls == [] and [t.meta["problem"]["wind_ned_mps"][1] for t in again] == [1.0, 3.0]
    assert any(s.startswith("no helix for 2 m/s of wind: the planner did not converge") and "planned before" in s
               for s in said)  # fmt: skip


def test_a_speed_the_planner_ran_out_of_time_for_is_tried_again(cache):
    # SOLVE_MAX_S stopped it: a busier machine may have, so the next flight plans it again
    prof = load_profile("x500")
    timed_out = CountingSolver(prof, fail_at=2.0)
    timed_out.error = "the planner did not converge (Maximum_WallTime_Exceeded)"
    helix_plans_for_winds(prof, PLAN, [1.0, 2.0], 1.25, timed_out)
    solver = CountingSolver(prof)
    again = helix_plans_for_winds(prof, PLAN, [1.0, 2.0], 1.25, solver)
    assert solver.calls == [2.0] and [t.meta["problem"]["wind_ned_mps"][1] for t in again] == [1.0, 2.0]


def test_a_speed_the_planner_ran_out_of_time_for_twice_is_left_out_until_its_file_is_deleted(cache):
    # arducopter_sitl's 5 m/s runs out of time even on an idle machine: tried at every flight, it cost each 28 s
    prof = load_profile("x500")
    timed_out = CountingSolver(prof, fail_at=2.0)
    timed_out.error = "the planner did not converge (Maximum_WallTime_Exceeded)"
    for _ in range(3):
        said: list[str] = []
        plans = helix_plans_for_winds(prof, PLAN, [1.0, 2.0], 1.25, timed_out, said.append)
        assert [t.meta["problem"]["wind_ned_mps"][1] for t in plans] == [1.0]
    assert timed_out.calls == [1.0, 2.0, 2.0]  # the third flight plans nothing
    left_out = next(s for s in said if s.startswith("no helix for 2 m/s of wind"))
    assert "Maximum_WallTime_Exceeded" in left_out and "twice" in left_out and "planned before" in left_out
    failed = Path(left_out.split("delete ")[1].split(" to plan")[0])
    failed.unlink()  # the operator's "plan it again": two tries again
    helix_plans_for_winds(prof, PLAN, [1.0, 2.0], 1.25, timed_out)
    assert timed_out.calls[3:] == [2.0] and not failed.exists()
    solver = CountingSolver(prof)
    again = helix_plans_for_winds(prof, PLAN, [1.0, 2.0], 1.25, solver)
    assert solver.calls == [2.0] and [t.meta["problem"]["wind_ned_mps"][1] for t in again] == [1.0, 2.0]


def test_two_flights_planning_the_same_winds_at_once_plan_each_only_once(cache):
    prof = load_profile("x500")
    solver = CountingSolver(prof, delay_s=0.3)
    got: list[list] = [[], []]

    def run(k: int) -> None:
        got[k] = helix_plans_for_winds(prof, PLAN, [1.0, 2.0], 1.25, solver)

    threads = [threading.Thread(target=run, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=30.0)
    assert sorted(solver.calls) == [1.0, 2.0]
    assert [len(g) for g in got] == [2, 2]


def test_a_cache_that_cannot_be_written_still_gives_the_plans(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("FLIGHTTEST_CACHE", str(blocker))
    prof = load_profile("x500")
    solver = CountingSolver(prof)
    assert len(helix_plans_for_winds(prof, PLAN, [1.0], 1.25, solver)) == 1
    assert len(helix_plans_for_winds(prof, PLAN, [1.0], 1.25, solver)) == 1
    assert solver.calls == [1.0, 1.0]


def test_the_vehicles_tracking_margin_as_far_as_its_boundary_leaves_the_hover_room():
    import dataclasses

    from flighttest.planner.tracking import HOVER_ROOM_MPS, guard_margin_for

    x500 = load_profile("x500")
    assert x500.tracking_margin_mps == 0.6 and guard_margin_for(x500, TrackingMargin()) == 0.6

    def with_w_allow(w_mps: float):
        return dataclasses.replace(x500, vrs=dataclasses.replace(x500.vrs, w_allow_mps=w_mps))

    low = with_w_allow(0.59)  # an onset identified low: room for 0.41 above the mission's 0.4
    assert guard_margin_for(low, TrackingMargin()) == pytest.approx(0.59 - x500.vrs.margin_mps - HOVER_ROOM_MPS)
    assert guard_margin_for(with_w_allow(0.5), TrackingMargin()) == 0.4  # never below the mission's
    assert guard_margin_for(load_profile("arducopter_sitl"), TrackingMargin()) == 0.4  # no tracking margin of its own
