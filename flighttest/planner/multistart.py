"""Multi-start → fine solve → refinement: the skeleton of every minimum-time planner's solve.

A minimum-time descent is non-convex, and one IPOPT run finds one local optimum. So a planner
(``planar``, ``helix``) solves a cheap coarse NLP from several initial guesses (``multistart``),
solves the fastest that converged again on the fine mesh, and then runs a few refinement rounds
(``refine``) wherever the dense re-simulation still finds a constraint broken between mesh nodes.
``multistart_refined`` chains the two; a planner with a good warm start of its own (the helix's
long descents) calls ``refine`` alone.

What differs between planners comes in as parameters: the starts and how one is solved
(``solve_start``), when more starts are not worth it (a ``StopRule``, e.g. ``families_agree``),
and a ``Refinement``: how the fine NLP is solved from the previous solution, what a round changes
(mesh nodes, tightened bounds) and what each solve adds to the solution's ``attempts`` table.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

from flighttest.planner.ocp import OcpResult

S = TypeVar("S")

# Called with every converged start and the best result before it; True: stop starting.
StopRule = Callable[[OcpResult, OcpResult | None], bool]


def attempt_record(r: OcpResult) -> dict:
    """One row of a solution's ``attempts`` table: the guess, IPOPT's status, the time found, the effort."""
    return {"guess": r.guess, "status": r.status, "t_f_s": r.t_f_s, "solve_s": r.solve_s, "iterations": r.iterations}


@dataclass
class MultistartOutcome(Generic[S]):
    """What a multi-start found."""

    best: OcpResult | None  # the fastest start that converged (the first of equals)
    best_start: S | None  # the start it was solved from
    # when no start converged: the one closest to feasible (smallest dynamics defect), to report
    fallback: OcpResult | None


def multistart(
    starts: Iterable[S],
    solve_start: Callable[[S], OcpResult],
    attempts: list[dict],
    *,
    record: Callable[[OcpResult], dict] = attempt_record,
    stop: StopRule | None = None,
) -> MultistartOutcome[S]:
    """Solve from every start in order (``solve_start``), each solve appended to ``attempts`` as
    ``record`` says; keep the fastest that converged. ``stop`` may end the search early: it sees each
    converged result with the best before it."""
    best: OcpResult | None = None
    best_start: S | None = None
    fallback: OcpResult | None = None
    for start in starts:
        r = solve_start(start)
        attempts.append(record(r))
        if not r.success:
            if fallback is None or r.max_defect < fallback.max_defect:
                fallback = r
            continue
        done = stop is not None and stop(r, best)
        if best is None or r.t_f_s < best.t_f_s:
            best, best_start = r, start
        if done:
            break
    return MultistartOutcome(best=best, best_start=best_start, fallback=fallback)


def families_agree(family: Callable[[str], str], rel: float, n: int = 2) -> StopRule:
    """A ``StopRule``: stop once starts of ``n`` different guess families (``family`` of the guess
    name) reached the same best time, within ``rel``. Agreement between unrelated basins is the
    evidence that the remaining starts rarely beat that time; a family (e.g. mirrored twins) is
    counted once because its members agree by symmetry, not by search. Keeps state: make one per
    multi-start."""
    agreeing: set[str] = set()

    def stop(r: OcpResult, best: OcpResult | None) -> bool:
        nonlocal agreeing
        fam = family(r.guess)
        if best is not None and abs(r.t_f_s - best.t_f_s) <= rel * best.t_f_s:
            agreeing.add(fam)
        elif best is None or r.t_f_s < best.t_f_s:
            agreeing = {fam}
        return len(agreeing) >= n

    return stop


class Refinement(Protocol):
    """A planner's fine solve and what its refinement rounds change between solves."""

    # names the rounds after the first fine solve in the attempts table ("refine", "tighten")
    word: str

    def solve(self, current: OcpResult, label: str, round_: int) -> OcpResult:
        """The fine NLP solved from ``current``: the coarse best or a warm start in round 0, the
        last converged fine solution after; ``label`` names the solve (``OcpResult.guess``)."""
        ...

    def record(self, r: OcpResult) -> dict:
        """The attempts row of a fine solve, taken right after it (before ``again``)."""
        ...

    def again(self, r: OcpResult) -> bool:
        """After a converged round that is not the last: check ``r`` and change the next round's
        problem; False when ``r`` needs no other round or nothing is left to change."""
        ...


def round_label(guess: str, word: str, round_: int) -> str:
    """``"helix1 fine"`` for the first fine solve, ``"helix1 fine tighten2"`` for the rounds after."""
    return f"{guess} fine" + (f" {word}{round_}" if round_ else "")


def refine(start: OcpResult, refinement: Refinement, rounds: int, attempts: list[dict]) -> OcpResult:
    """The fine solve from ``start`` and up to ``rounds`` refinement rounds; every solve appended to
    ``attempts``. Returns the last converged solve; when a round fails the solution before it stands
    (a start that is only a guess, not a solution, gives way to the failed solve, which the planner's
    check then reports)."""
    current = start
    for round_ in range(rounds + 1):
        r = refinement.solve(current, round_label(start.guess, refinement.word, round_), round_)
        attempts.append(refinement.record(r))
        if not r.success:
            if not current.success:
                current = r
            break
        current = r
        if round_ == rounds or not refinement.again(r):
            break
    return current


def multistart_refined(
    starts: Iterable[S],
    solve_start: Callable[[S], OcpResult],
    refinement_for: Callable[[S], Refinement],
    rounds: int,
    attempts: list[dict],
    *,
    record: Callable[[OcpResult], dict] = attempt_record,
    stop: StopRule | None = None,
) -> OcpResult:
    """``multistart`` on the coarse NLP, then ``refine`` the best with ``refinement_for(its start)``
    (built only then: a planner compiles its fine NLP only when a start converged). When no start
    converged, the fallback is returned unrefined (the planner reports it as a failure)."""
    found = multistart(starts, solve_start, attempts, record=record, stop=stop)
    if found.best is None:
        if found.fallback is None:
            raise ValueError("multistart_refined: no starts to solve from")
        return found.fallback
    return refine(found.best, refinement_for(found.best_start), rounds, attempts)
