"""The six planar cases of the paper's Table II, with Table I's bounds.

Table I: V_Y, V_Z ∈ [−10, 10] m/s, Z ∈ [−15, 15] m, f_coll ∈ [−20, 20] m/s², ω ∈ [−1, 1] rad/s,
φ ∈ [−π/3, π/3]; hover to hover (f_coll = g, ω = 0 at both ends), 5 m descent.

**The ω bound of the flip cases.** ±1 rad/s cannot be what the paper used for cases 5 and 6: a
flip that starts and ends level turns through 2π, which at 1 rad/s alone takes 6.3 s, against the
table's 2.27 s and 2.08 s. The minimum time falls as the bound on ω rises, and a local optimum
(GPOPS-II's) can only be slower than the global one, so the paper's bound must be at least the
ω for which the *best* solution reaches the table's time. Our multi-start optimum gives (fine mesh):
case 6 takes 2.17 s at 4.5 rad/s and 2.07 s at 5 rad/s, case 5 2.27 s at about 4.5 rad/s and
2.14 s at 5 rad/s. Case 6 (2.08 s) therefore needs ω_max ≥ ≈5 rad/s; 5 rad/s is the smallest
round bound consistent with both rows, and we use it (``OMEGA_FLIP_RPS``): case 6 then matches the
table and case 5 beats it (GPOPS-II stopped in a local optimum). ``bench/bench_planner.py`` prints
the sweep. The flip solutions use negative collective thrust (Table I allows it) — not flyable
with fixed-pitch rotors on one-way ESCs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from flighttest.errors import FlighttestError
from flighttest.planner.planar import PlanarProblem

OMEGA_FLIP_RPS = 5.0


@dataclass(frozen=True)
class TableCase:
    number: int
    problem: PlanarProblem
    paper_t_f_s: float
    paper_class: frozenset[str]  # subset of {"oblique", "zigzag", "flips"}
    description: str


def _case(n, y_bound, y_final, phi_free, paper_t, classes, desc):
    p = PlanarProblem(
        height_m=5.0,
        y_bound_m=y_bound,
        y_final=y_final,
        phi_bound_rad=None if phi_free else math.pi / 3,
        omega_max_rps=OMEGA_FLIP_RPS if phi_free else 1.0,
    )
    return TableCase(n, p, paper_t, frozenset(classes), desc)


TABLE_II: dict[int, TableCase] = {
    c.number: c
    for c in (
        _case(1, 15, "fixed", False, 5.33, {"zigzag"}, "Y ∈ [−15, 15], φ ∈ [−π/3, π/3], final Y fixed (0)"),
        _case(2, 2, "free", False, 6.80, {"zigzag"}, "Y ∈ [−2, 2], φ ∈ [−π/3, π/3], final Y bounded"),
        _case(3, 5, "free", False, 4.60, {"zigzag"}, "Y ∈ [−5, 5], φ ∈ [−π/3, π/3], final Y bounded"),
        _case(4, 10, "free", False, 3.39, {"oblique"}, "Y ∈ [−10, 10], φ ∈ [−π/3, π/3], final Y free"),
        _case(5, 15, "fixed", True, 2.27, {"flips"}, "Y ∈ [−15, 15], φ free, final Y fixed (0)"),
        _case(6, 15, "free", True, 2.08, {"oblique", "flips"}, "Y ∈ [−15, 15], φ free, final Y free"),
    )
}


def table_case(number: int, **overrides) -> TableCase:
    if number not in TABLE_II:
        raise FlighttestError(f"unknown Table II case {number} (cases are 1-6)")
    c = TABLE_II[number]
    return replace(c, problem=replace(c.problem, **overrides)) if overrides else c


def detected_classes(label_flags: dict) -> frozenset[str]:
    return frozenset(k for k in ("oblique", "zigzag", "flips") if label_flags.get(k))
