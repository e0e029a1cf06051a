"""The build-up: a descent flown again and again, each flight's margin narrowed by what the last ones proved.

Flight testers expand an envelope step by step. ``flighttest campaign --build-up N`` flies each of the
vertical baseline and the helix up to N times. The first flight keeps the mission config's margin (a
vehicle with no history flies today's conservative margins); each next one plans with the margin of a
:class:`MarginBudget` made of the evidence of every flight so far
(:mod:`flighttest.analysis.margin_evidence`):

- **tracking**: the most margin a flight used, its plan's own least margin to the guard's bound (the
  preflight's) less how close the guard came to acting: its least margin, or its prediction's beyond the
  clear-violation band where lower (the guard's margin takes in the wind's uncertainty, so a windier flight
  proves less); scaled by how much more tracking room the next flight is given than that flight had
  (:func:`room_growth`), as a plan that asks more of the autopilot tracks it worse;
- **estimate**: the estimator's error against the barometer over the time in the air (the most any of
  the vehicle's flights measured), else ``estimate_default_mps``: the guard judges the estimate, the truth
  may be this far beyond it. Only what the guard's own margin (the profile's ``[vrs] margin_mps``) does not
  already cover: the plan's margin sits on top of it, and the vehicle flies its estimate, so the estimate's
  error moves the truth, not what the guard sees (PX4 and ArduCopter SITL: the truth's least margin never more
  than 0.01 m/s nearer the bound than the guard's, bench/RESULTS.md "The build-up's evidence, judged against the
  simulators' truth");
- **reserve**: a constant on top.

The next margin is their sum, never below ``floor_mps`` and never more than ``max_narrow_fraction``
narrower than the last. The tracking room the plan leaves the autopilot (``EXPAND_KEYS``: the helix's rate
fraction, thrust rate and descent speed, the vertical's acceleration fraction; :func:`expand_caps`) widens by
``expand_fraction`` after a flight
that completed with the guard silent and whose least margin kept the estimate's error and the reserve.
Where the planner finds no plan for the next margins, that flight plans halfway from the last one's
(:func:`halfway_budget`), once. The build-up stops at the first of: a flight that did not complete, a guard
that said anything over the descent, a flight not ``min_gain_fraction`` faster hover to hover than the one
before, N flights, no plan even halfway, or nothing left to change (the margin at the floor or the evidence's,
no more room earned). The campaign keeps the fastest flight that completed with the guard silent.

Which ``[plan]`` key the margin is: :data:`BUILD_UP_KEYS`. Pure logic: the flying is the campaign's
(``flighttest.campaign.steps``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from flighttest.analysis.margin_evidence import MarginEvidence
from flighttest.flying.missions_config import BuildUpConfig
from flighttest.model.profiles import VehicleProfile

# the [plan] key each descent's margin inside the guard's bound is, on top of the guard's own margin
BUILD_UP_KEYS = {"vertical": "extra_margin_mps", "helix": "guard_margin_mps"}
# the tracking room each descent's plan leaves the autopilot, widened after a clean flight that kept its
# reserve: [plan] key → the most it grows to. The helix's time is set by these, not by its guard margin
# (on the fake's x500 a guard margin of 0.27 m/s instead of 0.4 planned the same 7.77 s helix: bench/RESULTS.md,
# "The build-up")
EXPAND_KEYS = {"vertical": {"accel_fraction": 1.0},
               "helix": {"rate_fraction": 1.0, "thrust_rate_max_mps3": 100.0, "descent_max_mps": math.inf}}  # fmt: skip
# the helix's descent speed widens up to this share of the vehicle's own descent limit (PX4's MPC_Z_VEL_MAX_DN
# clips the setpoint and its correction together): once the helix plans within the clip's margins its time is set
# by its own 1.3 m/s (sih_quadx: 5.03 s hover to hover at 1.3, 4.71 s at 1.43; bench/RESULTS.md, "PX4's vertical
# speed clip in the yardstick"). A vehicle whose limit is not known keeps the config's.
DESCENT_ROOM_FRACTION = 0.95
SAME_MPS = 0.005  # margins closer than this are the same margin: a flight with it proves nothing new


def expand_caps(mission: str, profile: VehicleProfile) -> dict[str, float]:
    """The tracking room each ``EXPAND_KEYS`` key of ``mission`` may widen to on ``profile``: the descent speed
    up to ``DESCENT_ROOM_FRACTION`` of the vehicle's own limit (left out where the profile knows none)."""
    caps = dict(EXPAND_KEYS[mission])
    if "descent_max_mps" in caps:
        limit = profile.autopilot.descent_max_mps if profile.autopilot is not None else None
        if limit is None:
            del caps["descent_max_mps"]
        else:
            caps["descent_max_mps"] = min(caps["descent_max_mps"], DESCENT_ROOM_FRACTION * limit)
    return caps


@dataclass(frozen=True)
class MarginTerm:
    name: str  # "config", "tracking", "estimate", "reserve"
    value_mps: float
    source: str  # where it came from, in words


@dataclass(frozen=True)
class MarginBudget:
    """The margin a plan keeps inside the guard's bound (``key``), the terms it is made of, and the tracking
    room the plan leaves (``expanded``: the ``EXPAND_KEYS`` it flies with, when not the config's)."""

    key: str
    margin_mps: float
    terms: tuple[MarginTerm, ...] = ()
    note: str = ""  # what set the margin when not the terms' sum (the floor, the narrowing step)
    expanded: tuple[tuple[str, float], ...] = ()  # (plan key, value) of the tracking room, widened

    def plan_changes(self) -> dict[str, float]:
        """The ``[plan]`` keys this budget sets."""
        return {self.key: self.margin_mps, **dict(self.expanded)}

    @property
    def evidence_mps(self) -> float:
        return sum(t.value_mps for t in self.terms)

    def to_dict(self) -> dict[str, Any]:
        return {"key": self.key, "margin_mps": round(self.margin_mps, 4),
                "terms": [{"name": t.name, "value_mps": round(t.value_mps, 4), "source": t.source} for t in self.terms],
                "note": self.note, "expanded": {k: round(v, 4) for k, v in self.expanded}}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> MarginBudget:
        terms = tuple(MarginTerm(str(t["name"]), float(t["value_mps"]), str(t["source"])) for t in d.get("terms", ()))
        expanded = tuple((str(k), float(v)) for k, v in (d.get("expanded") or {}).items())
        return cls(str(d["key"]), float(d["margin_mps"]), terms, str(d.get("note", "")), expanded)


def first_budget(key: str, margin_mps: float, room: dict[str, float] | None = None) -> MarginBudget:
    """A vehicle with no history: the mission config's margin and tracking room (``room``), as they are."""
    term = MarginTerm("config", margin_mps, f"the mission config's {key}: no flight has proved anything yet")
    return MarginBudget(key, margin_mps, (term,), "no history: the mission config's margin",
                        tuple(sorted((room or {}).items())))  # fmt: skip


@dataclass(frozen=True)
class BuildUpFlight:
    """One flight of a build-up: the margin it was planned with, the budget behind it, what it proved."""

    k: int  # 1, 2, …
    budget: MarginBudget
    evidence: MarginEvidence
    plan: str  # the plan file flown
    record: dict[str, Any] = field(default_factory=dict)  # the campaign's flight record (outcome, log_dir, …)

    @property
    def margin_mps(self) -> float:
        return self.budget.margin_mps

    @property
    def planned_least_mps(self) -> float:
        """The plan's own least margin to the guard's bound: the preflight's, else the margin it was planned
        with (a helix's guard margin need not bind: its rates and thrust may keep it further off)."""
        p = self.evidence.plan_min_margin_mps
        return self.margin_mps if p is None else p

    @property
    def least_mps(self) -> float | None:
        """How close the guard came to acting: its least margin, its prediction included where the log has it."""
        e = self.evidence
        return e.min_margin_mps if e.min_acting_margin_mps is None else e.min_acting_margin_mps

    @property
    def used_mps(self) -> float | None:
        """The margin this flight used: the plan's least less the guard's least (None without a guard log)."""
        least = self.least_mps
        return None if least is None else self.planned_least_mps - least

    def row(self) -> dict[str, Any]:
        """What the report's build-up table shows of it."""
        e = self.evidence
        return {"flight": self.k, "margin_mps": round(self.margin_mps, 4), "outcome": e.outcome,
                "hover_to_hover_s": e.hover_to_hover_s, "flown_over_optimum": e.flown_over_optimum,
                "plan_min_margin_mps": self.planned_least_mps, "min_margin_mps": e.min_margin_mps,
                "min_acting_margin_mps": e.min_acting_margin_mps, "used_mps": self.used_mps,
                "tracking_mps": e.tracking_mps,
                "estimate_mps": e.estimate_mps, "guard_silent": e.guard_silent, "log_dir": e.log_dir,
                "plan": self.plan}  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        return {"k": self.k, "budget": self.budget.to_dict(), "evidence": self.evidence.to_dict(), "plan": self.plan,
                "record": self.record}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> BuildUpFlight:
        ev = {k: v for k, v in d["evidence"].items() if k != "guard_silent"}
        return cls(int(d["k"]), MarginBudget.from_dict(d["budget"]), MarginEvidence(**ev), str(d["plan"]),
                   dict(d.get("record") or {}))  # fmt: skip


def next_budget(key: str, flights: list[BuildUpFlight], cfg: BuildUpConfig, caps: dict[str, float] | None = None,
                estimates: tuple[tuple[float, str], ...] = (),
                guard_margin_mps: float = 0.0) -> MarginBudget:  # fmt: skip
    """The margin the next flight plans with, from every flight so far (the last one's margin when none of
    them has a guard log to judge by), and its tracking room: the last flight's, each key of ``caps`` widened by
    ``expand_fraction`` (up to its cap) when that flight completed with the guard silent and its least margin
    kept the estimate's error and the reserve. ``estimates``: the estimate's error the vehicle's other flights
    measured (value, where), which the estimate term takes too: the estimator is the vehicle's, not the
    descent's (PX4 SITL's helix read 0.000 m/s where its verticals just before read 0.049 and 0.073).
    ``guard_margin_mps``: the guard's own margin, which covers that much of the estimate's error."""
    last = flights[-1]
    used = [(f, f.used_mps) for f in flights if f.used_mps is not None]
    if not used:
        return MarginBudget(key, last.margin_mps, last.budget.terms, "no guard log: nothing proved",
                            last.budget.expanded)  # fmt: skip
    measured = [(float(f.evidence.estimate_mps), f"flight {f.k}: {f.evidence.estimate_source}")
                for f in flights if f.evidence.estimate_mps is not None] + list(estimates)  # fmt: skip
    if measured:
        error, source = max(measured, key=lambda m: m[0])
    else:
        error = cfg.estimate_default_mps
        source = f"not measured ({last.evidence.estimate_source}): [build_up] estimate_default_mps"
    beyond = max(0.0, error - guard_margin_mps)
    if guard_margin_mps > 0:
        source = (f"{error:.3f} m/s ({source}) less the guard's own margin, {guard_margin_mps:.3f} m/s, which "
                  f"covers {error - beyond:.3f} of it")  # fmt: skip
    estimate = MarginTerm("estimate", beyond, source)
    reserve = MarginTerm("reserve", cfg.reserve_mps, "[build_up] reserve_mps")
    room = dict(last.budget.expanded)
    e = last.evidence
    least = last.least_mps
    kept = least is not None and least >= beyond + cfg.reserve_mps
    if e.outcome == "completed" and e.guard_silent and kept:
        room = {k: min(cap, room[k] * (1.0 + cfg.expand_fraction)) for k, cap in (caps or {}).items() if k in room}
        room = {**dict(last.budget.expanded), **room}
    f_t, tracking = max(used, key=lambda fu: fu[1])
    tracking = max(0.0, tracking)
    # the margin used was measured with that flight's tracking room; a plan given more of it tracks worse in
    # proportion (PX4 SITL: a helix planned 0.274 m/s in with its rates and thrust rate widened by 1.25 from the
    # flight whose 0.224 it was given stopped on the guard's prediction: bench/RESULTS.md, "One change at a time")
    growth, widened = room_growth(dict(f_t.budget.expanded), room)
    scaled = f" × {growth:.2f} for its room widened since ({', '.join(widened)})" if widened else ""
    terms = [MarginTerm("tracking", tracking * growth, f"flight {f_t.k}'s plan kept {f_t.planned_least_mps:.3f} m/s "
                        f"from the guard's bound, the guard came within {f_t.least_mps:.3f} m/s of acting (its least "
                        f"margin {f_t.evidence.min_margin_mps:.3f} m/s; {f_t.evidence.log_dir}){scaled}"),
             estimate, reserve]  # fmt: skip
    evidence = sum(t.value_mps for t in terms)
    step = last.margin_mps * (1.0 - cfg.max_narrow_fraction)
    margin = max(cfg.floor_mps, evidence, step)
    if cfg.floor_mps > max(evidence, step):
        note = "the floor ([build_up] floor_mps)"
    elif step > evidence:
        note = f"at most {cfg.max_narrow_fraction:.0%} narrower than flight {last.k}"
    else:
        note = "the evidence"
    return MarginBudget(key, margin, tuple(terms), note, tuple(sorted(room.items())))


def room_growth(before: dict[str, float], after: dict[str, float]) -> tuple[float, list[str]]:
    """How much more tracking room ``after`` gives than ``before``: the largest ratio of a key's value (at least 1),
    and the keys that grew."""
    ratios = {k: v / before[k] for k, v in after.items() if before.get(k, 0.0) > 0 and math.isfinite(v / before[k])}
    widened = sorted(k for k, r in ratios.items() if r > 1.0 + 1e-6)
    return max([1.0, *ratios.values()]), widened


def halfway_budget(budget: MarginBudget, last: BuildUpFlight, why: str) -> MarginBudget | None:
    """Halfway from ``last``'s margin and tracking room to ``budget``'s: the next flight's plan when the planner
    found none for ``budget`` (IPOPT out of iterations on the ArduCopter fake's helix, bench/RESULTS.md "The
    build-up"). None when halfway is ``last``'s own: nothing new to fly."""
    before = dict(last.budget.expanded)
    margin = 0.5 * (last.margin_mps + budget.margin_mps)
    room = tuple((k, 0.5 * (before.get(k, v) + v)) for k, v in budget.expanded)
    wider_room = any(v > before.get(k, v) * (1 + 1e-6) for k, v in room)
    if margin >= last.margin_mps - SAME_MPS and not wider_room:
        return None
    return MarginBudget(budget.key, margin, budget.terms, f"halfway from flight {last.k}'s: no plan for "
                        f"{budget.margin_mps:.3f} m/s ({why})", room)  # fmt: skip


def stop_reason(flights: list[BuildUpFlight], upcoming: MarginBudget, most: int, cfg: BuildUpConfig) -> str | None:
    """Why the build-up ends after its last flight, None to fly ``upcoming`` next."""
    last = flights[-1]
    e = last.evidence
    if e.outcome != "completed":
        return f"flight {last.k} ended {e.outcome or 'without a summary'}"
    if not e.guard_silent:
        return (f"the guard was not silent on flight {last.k} ({e.guard_flags} verdicts not ok over the descent, "
                f"{e.guard_aborts} aborts)")  # fmt: skip
    if len(flights) >= 2:
        t, before = e.hover_to_hover_s, flights[-2].evidence.hover_to_hover_s
        if not _finite(t) or not _finite(before):
            return f"flight {last.k} or the one before has no hover-to-hover time"
        if t > before * (1.0 - cfg.min_gain_fraction):
            return (f"the time stopped improving: flight {last.k} took {t:.2f} s hover to hover, flight {last.k - 1} "
                    f"{before:.2f} s")  # fmt: skip
    if len(flights) >= most:
        return f"{most} flights, the most asked for (--build-up {most})"
    narrower = upcoming.margin_mps < last.margin_mps - SAME_MPS
    wider_room = any(v > dict(last.budget.expanded).get(k, v) * (1 + 1e-6) for k, v in upcoming.expanded)
    if narrower or wider_room:
        return None
    if last.margin_mps <= cfg.floor_mps + SAME_MPS:
        return f"flight {last.k} flew at the floor, {cfg.floor_mps:g} m/s, with all the tracking room allowed"
    return (f"nothing to change: the evidence asks for {upcoming.evidence_mps:.3f} m/s against flight {last.k}'s "
            f"{last.margin_mps:.3f} m/s, and no more tracking room is earned")  # fmt: skip


def best_flight(flights: list[BuildUpFlight]) -> BuildUpFlight | None:
    """The flight the campaign keeps: the fastest hover to hover that completed with the guard silent, else the
    first that completed, else None."""
    clean = [f for f in flights if f.evidence.outcome == "completed" and f.evidence.guard_silent]
    if clean:
        return min(clean, key=lambda f: _time_or_inf(f.evidence.hover_to_hover_s))
    return next((f for f in flights if f.evidence.outcome == "completed"), None)


def _time_or_inf(x: Any) -> float:
    return float(x) if _finite(x) else math.inf


def _finite(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
