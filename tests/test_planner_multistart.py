"""The planners' shared skeleton (flighttest.planner.multistart) on a fake solver: no IPOPT, instant.

Each fake start names the time its solve "finds" (None: it fails, with a dynamics defect). The
refinement shaves 0.1 s per round and records what it was asked to solve from.
"""

from __future__ import annotations

import numpy as np
import pytest

from flighttest.planner.multistart import (
    attempt_record,
    families_agree,
    multistart,
    multistart_refined,
    refine,
    round_label,
)
from flighttest.planner.ocp import OcpResult


def _result(guess: str, t_f_s: float, success: bool = True, defect: float = 0.0) -> OcpResult:
    return OcpResult(status="Solve_Succeeded" if success else "Infeasible_Problem_Detected", success=success,
                     t_f_s=t_f_s, t_s=np.linspace(0.0, t_f_s, 3), x=np.zeros((3, 1)), u=np.zeros((3, 1)),
                     solve_s=0.0, iterations=7, max_defect=defect, mesh=np.full(2, 0.5), guess=guess)  # fmt: skip


class FakeSolve:
    """``solve_start`` over starts ``(name, t_f or None, defect)``, logging the order it was called in."""

    def __init__(self):
        self.called: list[str] = []

    def __call__(self, start: tuple[str, float | None, float]) -> OcpResult:
        name, t_f, defect = start
        self.called.append(name)
        return _result(name, 60.0, False, defect) if t_f is None else _result(name, t_f)


class FakeRefinement:
    """Each round is 0.1 s faster; ``again`` asks for more rounds ``wanted`` times; round ``fail_at`` fails."""

    word = "refine"

    def __init__(self, wanted: int = 1, fail_at: int | None = None):
        self.wanted = wanted
        self.fail_at = fail_at
        self.solved_from: list[OcpResult] = []
        self.labels: list[str] = []

    def solve(self, current: OcpResult, label: str, round_: int) -> OcpResult:
        self.solved_from.append(current)
        self.labels.append(label)
        ok = round_ != self.fail_at
        return _result(label, current.t_f_s - 0.1, ok, 0.0 if ok else 1.0)

    def record(self, r: OcpResult) -> dict:
        return {**attempt_record(r), "fake": True}

    def again(self, r: OcpResult) -> bool:
        self.wanted -= 1
        return self.wanted >= 0


STARTS = [("slow", 5.0, 0.0), ("broken", None, 0.3), ("fast", 3.0, 0.0), ("closest", None, 0.1), ("mid", 4.0, 0.0)]


def test_failed_starts_are_recorded_and_the_fastest_converged_one_is_refined():
    solve = FakeSolve()
    refinements: list[tuple] = []

    def refinement_for(start):
        refinements.append(start)
        return fine

    fine = FakeRefinement(wanted=1)
    attempts: list[dict] = []
    out = multistart_refined(STARTS, solve, refinement_for, 3, attempts)
    assert solve.called == ["slow", "broken", "fast", "closest", "mid"]  # every start, in order
    # the fine NLP is built once, for the start that won, and its first solve starts from that result
    assert refinements == [("fast", 3.0, 0.0)]
    assert fine.solved_from[0].guess == "fast" and fine.solved_from[0].t_f_s == 3.0
    # one refinement round was asked for: fine solve + refine1, each from the last converged solve
    assert fine.labels == ["fast fine", "fast fine refine1"]
    assert fine.solved_from[1].guess == "fast fine"
    assert out.guess == "fast fine refine1" and out.t_f_s == pytest.approx(2.8)
    assert [a["guess"] for a in attempts] == [s[0] for s in STARTS] + ["fast fine", "fast fine refine1"]
    assert [a["status"] for a in attempts[:2]] == ["Solve_Succeeded", "Infeasible_Problem_Detected"]
    assert "fake" not in attempts[0] and attempts[-1]["fake"]  # starts: default record; fine: the refinement's


def test_no_converged_start_returns_the_closest_failure_unrefined():
    attempts: list[dict] = []

    def refinement_for(start):
        raise AssertionError("no fine NLP when nothing converged")

    starts = [s for s in STARTS if s[1] is None]
    out = multistart_refined(starts, FakeSolve(), refinement_for, 3, attempts)
    assert out.guess == "closest" and not out.success
    assert len(attempts) == 2
    with pytest.raises(ValueError, match="no starts"):
        multistart_refined([], FakeSolve(), refinement_for, 3, [])


def test_refinement_rounds_are_capped_and_a_failed_round_keeps_the_last_converged():
    attempts: list[dict] = []
    start = _result("fast", 3.0)
    greedy = FakeRefinement(wanted=99)
    out = refine(start, greedy, 2, attempts)
    assert greedy.labels == ["fast fine", "fast fine refine1", "fast fine refine2"]  # rounds + 1 solves
    assert out.t_f_s == pytest.approx(2.7)
    failing = FakeRefinement(wanted=99, fail_at=2)
    out = refine(start, failing, 3, attempts)
    assert failing.labels[-1] == "fast fine refine2"  # tried, failed, stopped there
    assert out.guess == "fast fine refine1" and out.success


def test_a_warm_start_that_is_only_a_guess_gives_way_to_the_failed_solve():
    guess = _result("steady", 10.0, success=False, defect=np.inf)
    out = refine(guess, FakeRefinement(fail_at=0), 3, [])
    assert out.guess == "steady fine" and not out.success  # reported, not the unsolved guess
    out = refine(guess, FakeRefinement(wanted=0), 3, [])
    assert out.guess == "steady fine" and out.success


def test_families_agree_stops_when_two_families_reach_the_same_best_time():
    solve = FakeSolve()
    starts = [("oblique+1", 3.0, 0.0), ("oblique-1", 3.0, 0.0),  # twins: one family, no stop
              ("zigzag1", 4.0, 0.0), ("zigzag2", 3.0 * (1 + 1e-9), 0.0),  # a second family agrees: stop
              ("zigzag3", 1.0, 0.0)]  # fmt: skip
    found = multistart(starts, solve, [], stop=families_agree(lambda g: g.rstrip("+-0123456789"), 1e-6))
    assert solve.called == ["oblique+1", "oblique-1", "zigzag1", "zigzag2"]  # zigzag3 never solved
    assert found.best is not None and found.best.guess == "oblique+1"  # the first of equals
    # a faster start resets the agreement: the search goes on
    solve = FakeSolve()
    starts = [("a1", 3.0, 0.0), ("b1", 2.0, 0.0), ("c1", 3.0, 0.0), ("d1", 2.0, 0.0), ("e1", 1.0, 0.0)]
    found = multistart(starts, solve, [], stop=families_agree(lambda g: g[0], 1e-6))
    assert solve.called == ["a1", "b1", "c1", "d1"] and found.best_start == ("b1", 2.0, 0.0)


def test_round_labels_name_the_start_and_the_round():
    assert round_label("helix1", "tighten", 0) == "helix1 fine"
    assert round_label("helix1", "tighten", 2) == "helix1 fine tighten2"
