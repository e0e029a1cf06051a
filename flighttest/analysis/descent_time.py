"""The descent time of a flown descent, on the vertical axis: the one definition, live and after the flight.

A descent starts at the first setpoint of the planned descent (the ``stream_start`` event) and is
**reached** at the first instant from which, for ``hold_s``, the height is within ``height_tol_m`` of
the end point's height and the vertical speed within ``settled_vd_mps`` of zero — the estimate's
vertical velocity, or its height's own rate over the last ``hold_s`` where that is smaller: on PX4
SITL EKF2's vertical velocity read 0.2–0.4 m/s for seconds while its height (and the simulator's
truth) held, which would time the estimator's drift, not the descent. Only the vertical
axis counts: a multicopter holding position wanders sideways by decimetres (PX4 SIH: 0.3–0.8 m in
``../shared/px4_sih/vertical-3m-completed``), and a test that also waits for the horizontal error to
close times that wander, not the descent (it said 10.8 s for a 3 m descent flown in about 5 s). The
horizontal error at that instant is reported beside the time, so a descent that arrived far off to
the side still shows it.

The hold is judged only up to the end of the descent's own phases (``stream``, then the ``settle``
after it): a descent not settled before the landing, the hold or an abort has no time.

**The main descent** of a flight is this one segment, whatever phases it crosses: from the stream
start to the instant the rule was met (or, not met, to the end of the window it was judged in). Its
height is the fall of the same height samples between those instants, its mean rate that height over
its duration and its max rate the height's own fall over ``RATE_WINDOW_S`` (never below the mean: by
the mean value theorem the vehicle fell at least that fast somewhere). ``flighttest fly`` (live; no
max rate there: it times samples as they arrive, the log has the vehicle's clock), ``analyse``,
``compare``, ``report`` and the campaign all take it from here (:class:`FlownDescent`,
:func:`main_descent_record`), and the plan is timed by the same rule (:func:`planned_descent`), so a
vehicle flying its plan exactly shows the planned time.

- :class:`DescentTimer` is the rule fed one sample at a time; ``flighttest.flying.runner`` runs it on every
  telemetry sample and writes its result as the ``descent_reached`` event (and ``summary.json``).
- :func:`descent_reached` runs the same timer over arrays; :func:`from_log` over a log folder's
  state and events, so older folders (whose ``descent_reached`` used the 3D rest-to-rest test) can
  be timed again with this rule (``flighttest compare`` and the campaign report do).
"""

from __future__ import annotations

import collections
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flighttest.errors import FlighttestError

# the phases of a descent as the mission runner flies it: the stream, then the settle at its end
DESCENT_PHASES = ("stream", "settle")
# a trajectory that ends closer than this to its start (the probe comes back up) has no descent time
MIN_TRAVEL_M = 0.3
# the event the analysis adds to a loaded log's events with this rule's timing (:func:`timed_event`)
TIMED_EVENT = "descent_timed"
# the abort ladder's phases (``phase`` events the runner writes as it commands each rung)
ABORT_PHASES = ("abort_recover", "abort_hold", "abort_land")
# the max descent rate is the height's fall over this long: ten 50 Hz samples, so height noise does not
# read as rate, yet a sink of half a second shows whole (the segmenter's rate is smoothed over the same)
RATE_WINDOW_S = 0.2
# what the main descent's record says it is (``main_descent_record``'s ``basis``)
BASIS_PLANNED = "planned descent"  # flighttest's own log: stream start until the end height, settled
BASIS_SEGMENT = "log segment"  # any other log: the largest descent the segmentation found (compare.primary_descent)


def goes_somewhere(rel_end_m) -> bool:
    """A trajectory whose last point (relative to its start) is more than ``MIN_TRAVEL_M`` away: a descent to time."""
    return math.dist(tuple(float(x) for x in rel_end_m), (0.0, 0.0, 0.0)) > MIN_TRAVEL_M


def is_abort_phase(phase: Any) -> bool:
    """An abort ladder's phase (``abort_*``), or ``"abort"``: a descent after the abort began."""
    return isinstance(phase, str) and (phase == "abort" or phase.startswith("abort_"))


@dataclass(frozen=True)
class DescentRule:
    """When a descent counts as reached. The defaults: 0.2 m is 4 % of the 5 m test descent and
    within what PX4 holds its height to in a hover (its estimate moves 0.02–0.17 m about the end
    point in the reference flights); 0.2 m/s is above a hover's vertical-speed noise (PX4 SIH:
    up to 0.18 m/s) and a third of the 0.6 m/s the vertical baseline descends at; 0.5 s is 25
    telemetry samples at 50 Hz, long enough that an overshoot passing through the band does not count."""

    height_tol_m: float = 0.2
    settled_vd_mps: float = 0.2
    hold_s: float = 0.5
    # hover to hover (``HOVER_RULE``): also this close to the end point sideways and this slow across
    horizontal_tol_m: float | None = None
    settled_vh_mps: float | None = None

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if value is None and name in ("horizontal_tol_m", "settled_vh_mps"):
                continue
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise FlighttestError(f"descent rule {name} must be a finite number > 0 (got {value!r})")
        if (self.horizontal_tol_m is None) != (self.settled_vh_mps is None):
            raise FlighttestError("descent rule: horizontal_tol_m and settled_vh_mps go together")

    @property
    def horizontal(self) -> bool:
        return self.horizontal_tol_m is not None

    def describe(self) -> str:
        if self.horizontal:
            return (f"within {self.height_tol_m:g} m of the end point's height and {self.horizontal_tol_m:g} m of it "
                    f"sideways, vertical speed within {self.settled_vd_mps:g} m/s and horizontal within "
                    f"{self.settled_vh_mps:g} m/s, all for {self.hold_s:g} s")  # fmt: skip
        return (f"height within {self.height_tol_m:g} m of the end point's and vertical speed within "
                f"{self.settled_vd_mps:g} m/s, both for {self.hold_s:g} s")  # fmt: skip


# Hover to hover, the paper's problem and the efficiency figure's basis (``hover_to_hover_s``): the vertical
# rule and the end point sideways. 0.5 m and 0.3 m/s hold PX4 SITL's and ArduCopter SITL's hovers at the end
# point in every reference flight (bench/RESULTS.md, "Hover to hover"), yet a helix still turning is not home.
HOVER_RULE = DescentRule(horizontal_tol_m=0.5, settled_vh_mps=0.3)


@dataclass(frozen=True)
class DescentReached:
    """Where the rule was met: ``t_s`` on the caller's clock, ``descent_time_s`` from the stream start."""

    t_s: float
    descent_time_s: float
    height_error_m: float  # d − d_end at that instant (NED: > 0 below the end point)
    horizontal_error_m: float  # distance from the end point in the horizontal plane at that instant

    def fields(self) -> dict[str, float]:
        """The ``descent_reached`` event's fields (rounded to the millimetre / millisecond)."""
        return {"descent_time_s": round(self.descent_time_s, 3),
                "horizontal_error_m": round(self.horizontal_error_m, 3),
                "height_error_m": round(self.height_error_m, 3)}  # fmt: skip


@dataclass(frozen=True)
class FlownDescent:
    """The main descent as flown (module docstring): ``start_s`` the stream start, ``end_s`` where the
    rule was met (``reached``) or the window ended; heights NED-down of the timed height samples."""

    start_s: float
    end_s: float
    start_d_m: float
    end_d_m: float
    max_rate_mps: float
    reached: DescentReached | None
    horizontal_error_m: float | None  # off the end point sideways at ``end_s``

    @classmethod
    def of(cls, start_s, end_s, start_d_m, end_d_m, fastest_mps, reached, end_ned_m, at_ne) -> FlownDescent:
        duration = end_s - start_s
        mean = (end_d_m - start_d_m) / duration if duration > 0 else math.nan
        # a short descent can fall faster on average than any RATE_WINDOW_S window the samples show whole
        fastest = max(fastest_mps, mean) if math.isfinite(mean) else fastest_mps
        horiz = math.hypot(at_ne[0] - end_ned_m[0], at_ne[1] - end_ned_m[1])
        return cls(float(start_s), float(end_s), float(start_d_m), float(end_d_m),
                   float(fastest) if math.isfinite(fastest) else math.nan, reached, horiz)  # fmt: skip

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s

    @property
    def height_m(self) -> float:
        return self.end_d_m - self.start_d_m

    @property
    def mean_rate_mps(self) -> float:
        return self.height_m / self.duration_s if self.duration_s > 0 else math.nan

    @property
    def descent_time_s(self) -> float | None:
        return self.reached.descent_time_s if self.reached is not None else None


@dataclass(frozen=True)
class PlannedDescent:
    """A plan timed by this module's rule (its end point held after its last row, as the runner holds
    it): ``descent_time_s`` None when the plan never reaches its end (a probe returns to its start)."""

    descent_time_s: float | None
    height_m: float  # the plan's end below its start
    max_rate_mps: float  # the plan's fastest descent (its own vertical velocity)
    t_f_s: float  # the plan's last row


def planned_descent(t_s, n_m, e_m, d_m, vd_mps, rule: DescentRule | None = None, vn_mps=None,
                    ve_mps=None) -> PlannedDescent | None:  # fmt: skip
    """The plan (rows relative to its start, as ``trajectory.csv`` holds them) timed by the same rule as
    the flight, so a vehicle flying it exactly shows the same time. None for an empty or broken plan."""
    cols = [np.asarray(x, dtype=float) for x in (t_s, n_m, e_m, d_m, vd_mps)]
    if not len(cols[0]) or not all(np.isfinite(c).all() for c in cols):
        return None
    t, n, e, d, vd = cols
    vn, ve = (np.zeros_like(t) if v is None else np.asarray(v, dtype=float) for v in (vn_mps, ve_mps))
    rule = rule or DescentRule()
    t_f = float(t[-1])
    end = (float(n[-1]), float(e[-1]), float(d[-1]))
    height = float(d[-1] - d[0])
    fastest = float(np.max(vd)) if len(vd) else math.nan
    if not goes_somewhere((end[0] - n[0], end[1] - e[1], end[2] - d[0])):
        return PlannedDescent(None, height, fastest, t_f)
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.02
    hold = t_f + np.arange(1, math.ceil(rule.hold_s / max(step, 1e-3)) + 2) * step
    tt = np.concatenate([t, hold])
    pad = np.ones(len(hold))
    r = descent_reached(tt, np.concatenate([n, end[0] * pad]), np.concatenate([e, end[1] * pad]),
                        np.concatenate([d, end[2] * pad]), np.concatenate([vd, 0.0 * pad]), float(t[0]), end,
                        rule=rule, vn_mps=np.concatenate([vn, 0.0 * pad]),
                        ve_mps=np.concatenate([ve, 0.0 * pad]))  # fmt: skip
    return PlannedDescent(r.descent_time_s if r is not None else None, height, fastest, t_f)


class DescentTimer:
    """The rule of this module, one sample at a time. ``update`` returns the result once, on the
    sample that completes the hold (``hold_s`` after the instant it reports), and None otherwise."""

    def __init__(self, t_start_s: float, end_ned_m: tuple[float, float, float], rule: DescentRule | None = None):
        self.t_start_s = float(t_start_s)
        self.end_ned_m = tuple(float(x) for x in end_ned_m)
        self.rule = rule or DescentRule()
        self.result: DescentReached | None = None
        self._since: tuple[float, float, float, float, float] | None = None  # t, n, e, d of the hold's start
        self._heights: collections.deque[tuple[float, float, float, float]] = collections.deque()  # (t, n, e, d)
        self._start: tuple[float, float, float, float] | None = None  # t, n, e, d: the first sample
        self._last: tuple[float, float, float, float] | None = None  # t, n, e, d: the latest sample
        self._recent: collections.deque[tuple[float, float]] = collections.deque()  # (t, d) over RATE_WINDOW_S
        self._max_rate = -math.inf  # the height's fastest fall over RATE_WINDOW_S so far
        self._max_at_since = -math.inf  # ... up to the instant the hold began (the descent's end)

    def update(self, t_s: float, n_m: float, e_m: float, d_m: float, vd_mps: float,
               vn_mps: float = math.nan, ve_mps: float = math.nan) -> DescentReached | None:  # fmt: skip
        """One estimate sample; the horizontal velocity only counts for a rule with a horizontal part (NaN:
        the position's own rate alone)."""
        if self.result is not None or t_s < self.t_start_s:
            return None
        r, end = self.rule, self.end_ned_m
        values = (t_s, n_m, e_m, d_m, vd_mps)
        if not all(math.isfinite(v) for v in (t_s, d_m)):  # a gap breaks the hold and the height's rate
            self._heights.clear()
            self._recent.clear()
        else:
            self._heights.append((t_s, n_m, e_m, d_m))
            while t_s - self._heights[0][0] > r.hold_s:
                self._heights.popleft()
            self._track(t_s, n_m, e_m, d_m)
        vd = abs(vd_mps)
        vh = math.hypot(vn_mps, ve_mps) if math.isfinite(vn_mps) and math.isfinite(ve_mps) else math.inf
        t_old, n_old, e_old, d_old = self._heights[0] if self._heights else (t_s, n_m, e_m, d_m)
        if t_s - t_old >= 0.9 * r.hold_s:  # a full window: the height's own rate counts too
            vd = min(vd, abs(d_m - d_old) / (t_s - t_old))
            vh = min(vh, math.hypot(n_m - n_old, e_m - e_old) / (t_s - t_old))
        inside = all(math.isfinite(v) for v in values) and abs(d_m - end[2]) <= r.height_tol_m \
            and vd <= r.settled_vd_mps  # fmt: skip
        if inside and r.horizontal:
            inside = math.hypot(n_m - end[0], e_m - end[1]) <= r.horizontal_tol_m and vh <= r.settled_vh_mps
        if not inside:  # a gap in the data (NaN) breaks the hold like a sample outside it
            self._since = None
            return None
        if self._since is None:
            self._since = (t_s, n_m, e_m, d_m, vd_mps)
            self._max_at_since = self._max_rate
        t0, n0, e0, d0, _ = self._since
        if t_s - t0 < r.hold_s:
            return None
        self.result = DescentReached(t0, t0 - self.t_start_s, d0 - end[2], math.hypot(n0 - end[0], e0 - end[1]))
        return self.result

    def _track(self, t_s: float, n_m: float, e_m: float, d_m: float) -> None:
        """The start and latest samples and the height's fastest fall over ``RATE_WINDOW_S``."""
        if self._start is None:
            self._start = (t_s, n_m, e_m, d_m)
        self._last = (t_s, n_m, e_m, d_m)
        self._recent.append((t_s, d_m))
        while t_s - self._recent[0][0] > RATE_WINDOW_S:
            self._recent.popleft()
        t_old, d_old = self._recent[0]
        if t_s - t_old >= 0.9 * RATE_WINDOW_S:
            self._max_rate = max(self._max_rate, (d_m - d_old) / (t_s - t_old))

    def flown(self) -> FlownDescent | None:
        """The descent as flown so far: to the instant the rule was met, else to the latest sample fed
        (the caller stops feeding at the end of the descent's window). None before any sample."""
        if self._start is None or self._last is None:
            return None
        t0, n0, e0, d0 = self._start
        if self.result is not None:
            t1, n1, e1, d1, _ = self._since
            fastest = self._max_at_since
        else:
            t1, n1, e1, d1 = self._last
            fastest = self._max_rate
        return FlownDescent.of(self.t_start_s, t1, d0, d1, fastest, self.result, self.end_ned_m, (n1, e1))


def descent_reached(
    t_s, n_m, e_m, d_m, vd_mps, t_start_s: float, end_ned_m, t_stop_s: float | None = None,
    rule: DescentRule | None = None, vn_mps=None, ve_mps=None,
) -> DescentReached | None:  # fmt: skip
    """:class:`DescentTimer` over arrays (samples in time order), from ``t_start_s`` until ``t_stop_s``
    (the end of the descent's phases: the hold must be complete by then)."""
    return _timed(t_s, n_m, e_m, d_m, vd_mps, t_start_s, end_ned_m, t_stop_s, rule, vn_mps, ve_mps).result


def _timed(t_s, n_m, e_m, d_m, vd_mps, t_start_s, end_ned_m, t_stop_s, rule, vn_mps=None, ve_mps=None) -> DescentTimer:
    """A :class:`DescentTimer` fed the samples from ``t_start_s`` until it is met or ``t_stop_s``."""
    timer = DescentTimer(t_start_s, end_ned_m, rule)
    nan = np.full(len(np.asarray(t_s)), np.nan)
    cols = [np.asarray(x, dtype=float) for x in (t_s, n_m, e_m, d_m, vd_mps, nan if vn_mps is None else vn_mps,
                                                 nan if ve_mps is None else ve_mps)]  # fmt: skip
    t = cols[0]
    sel = (t >= t_start_s) & (t <= (math.inf if t_stop_s is None else t_stop_s))
    for t_k, n_k, e_k, d_k, vd_k, vn_k, ve_k in zip(*(c[sel] for c in cols)):
        if timer.update(float(t_k), float(n_k), float(e_k), float(d_k), float(vd_k), float(vn_k),
                        float(ve_k)) is not None:  # fmt: skip
            break
    return timer


@dataclass(frozen=True)
class LogDescent:
    """A log folder's descent timed by :func:`from_log`: ``reached`` None when it never met the rule
    (``why`` says why), ``end_s`` the end of the window it was judged in."""

    start_s: float
    end_s: float
    reached: DescentReached | None
    why: str | None = None
    flown: FlownDescent | None = None  # the main descent on the timed samples (None: no sample in the window)


def _first(events: list[dict], name: str) -> dict | None:
    return next((e for e in events if e.get("event") == name and isinstance(e.get("t_s"), int | float)), None)


def window(events: list[dict]) -> tuple[float, float, tuple[float, float, float] | None, str] | None:
    """(stream start, end of the descent's phases, origin NED or None, what ended them) from a log's
    events; None without a ``stream_start``. The phases end at the first abort, the first ``phase``
    event after the stream start that is not a descent phase, or the end of the log."""
    start = _first(events, "stream_start")
    if start is None:
        return None
    t0 = float(start["t_s"])
    origin = start.get("origin_ned")
    ok = isinstance(origin, list | tuple) and len(origin) == 3 and all(isinstance(x, int | float) for x in origin)
    stop, what = math.inf, "the end of the log"
    for e in events:
        t = e.get("t_s")
        if not isinstance(t, int | float) or t < t0 or t >= stop:
            continue
        if e.get("event") == "abort":
            stop, what = float(t), "the abort"
        elif e.get("event") == "phase" and e.get("phase") not in DESCENT_PHASES:
            stop, what = float(t), f"the {e.get('phase')} phase"
    return t0, stop, (tuple(float(x) for x in origin) if ok else None), what


def not_reached(rule: DescentRule | None, what: str) -> str:
    """Why a descent has no time: the rule was not met before ``what`` ended its window."""
    return f"not at the end height and settled ({(rule or DescentRule()).describe()}) before {what}"


def trajectory_end_m(folder: Path) -> tuple[float, float, float] | None:
    """The last point of the trajectory a log folder flew (``trajectory.csv``, relative to its start)."""
    path = Path(folder) / "trajectory.csv"
    if not path.is_file():
        return None
    import pandas as pd

    try:
        last = pd.read_csv(path, usecols=["n_m", "e_m", "d_m"]).iloc[-1]
    except (OSError, ValueError, IndexError, KeyError):
        return None
    end = tuple(float(last[k]) for k in ("n_m", "e_m", "d_m"))
    return end if all(math.isfinite(x) for x in end) else None


def from_log(log, rule: DescentRule | None = None) -> LogDescent | None:
    """The descent of a flighttest log folder (``flighttest.analysis.schema.FlightLog``) timed by
    this module's rule; None when it cannot be judged (no ``stream_start``, no end point, no state).

    The end point is the ``stream_start`` event's ``end_ned`` where the runner wrote it, else its
    ``origin_ned`` plus the last row of the folder's ``trajectory.csv``. Heights are the vehicle's own
    estimate (``d_est_m`` where the height arbitration replaced ``d_m``): the end point and the
    setpoints are in the estimator's frame, and the live timer saw the same numbers."""
    events = log.events or []
    win = window(events)
    if win is None:
        return None
    t0, stop, origin, _what = win
    start = _first(events, "stream_start") or {}
    end = start.get("end_ned")
    if isinstance(end, list | tuple) and len(end) == 3 and all(isinstance(x, int | float) for x in end):
        if origin is not None and not goes_somewhere(tuple(e - o for e, o in zip(end, origin))):
            return None
    else:
        rel = trajectory_end_m(log.path) if log.path is not None and Path(log.path).is_dir() else None
        if rel is None or origin is None or not goes_somewhere(rel):
            return None
        end = tuple(o + r for o, r in zip(origin, rel))
    s = log.state
    if s is None or not len(s) or not {"t_s", "n_m", "e_m", "d_m"} <= set(s.columns):
        return None
    d = s["d_est_m"] if "d_est_m" in s else s["d_m"]
    vd = s["vd_est_mps"] if "vd_est_mps" in s else s.get("vd_mps")
    if vd is None:
        return None
    timer = _timed(s["t_s"], s["n_m"], s["e_m"], d, vd, t0, end, stop, rule, s.get("vn_mps"), s.get("ve_mps"))
    reached = timer.result
    t_end = float(s["t_s"].iloc[-1]) if math.isinf(stop) else stop
    why = None if reached else not_reached(rule, _what)
    return LogDescent(t0, t_end, reached, why, timer.flown())


def timed_event(log, rule: DescentRule | None = None) -> dict | None:
    """:func:`from_log` as an event for the loaded log's event list (``TIMED_EVENT``; ``t_s`` the instant
    the descent was reached, else the end of the window judged), None where it cannot be judged. It
    is never written to a folder: ``events.jsonl`` keeps what the flight wrote."""
    timed = from_log(log, rule)
    return None if timed is None else event_of(timed, rule)


def event_of(timed: LogDescent, rule: DescentRule | None = None) -> dict:
    """:func:`timed_event` of a descent :func:`from_log` already timed."""
    r = timed.reached
    return {"event": TIMED_EVENT, "t_s": r.t_s if r else timed.end_s, "start_s": timed.start_s,
            **(r.fields() if r else dict.fromkeys(("descent_time_s", "horizontal_error_m", "height_error_m"))),
            "why": timed.why, "rule": (rule or DescentRule()).describe(), "by": __name__}  # fmt: skip


# The main descent as ``fly --json`` (``summary.json``), ``analyse --json`` and ``compare --json`` give it
MAIN_DESCENT_KEYS = (
    "basis", "start_s", "end_s", "start_unix_s", "duration_s", "descent_time_s", "planned_descent_s",
    "start_height_m", "height_m", "planned_height_m", "mean_rate_mps", "max_rate_mps", "planned_max_rate_mps",
    "horizontal_error_m", "reached", "note", "hover_to_hover_s", "optimum_s", "flown_over_optimum",
)  # fmt: skip


def _r(x, nd: int = 3) -> float | None:
    return round(float(x), nd) if isinstance(x, int | float) and math.isfinite(x) else None


def main_descent_record(
    flown: FlownDescent | None, planned: PlannedDescent | None, *, start_unix_s: float | None = None,
    ground_alt_m: float = 0.0, note: str | None = None,
) -> dict[str, Any]:  # fmt: skip
    """The main descent of a flighttest flight (``MAIN_DESCENT_KEYS``) from the timer's :class:`FlownDescent`
    and the plan's :class:`PlannedDescent`: times on the caller's clock (``start_unix_s`` the wall clock of
    ``start_s``), ``start_height_m`` above the ground seen at arming (``ground_alt_m``, up-positive, in
    the timed heights' datum). Without a flown descent the figures are None and ``note`` says why."""
    rec: dict[str, Any] = dict.fromkeys(MAIN_DESCENT_KEYS)
    rec["basis"] = BASIS_PLANNED
    if planned is not None:
        rec.update(planned_descent_s=_r(planned.descent_time_s), planned_height_m=_r(planned.height_m),
                   planned_max_rate_mps=_r(planned.max_rate_mps))  # fmt: skip
    rec["reached"] = bool(flown is not None and flown.reached is not None)
    rec["note"] = note
    if flown is None:
        return rec
    rec.update(start_s=_r(flown.start_s), end_s=_r(flown.end_s), start_unix_s=_r(start_unix_s),
               duration_s=_r(flown.duration_s), descent_time_s=_r(flown.descent_time_s),
               start_height_m=_r(-flown.start_d_m - ground_alt_m), height_m=_r(flown.height_m),
               mean_rate_mps=_r(flown.mean_rate_mps), max_rate_mps=_r(flown.max_rate_mps),
               horizontal_error_m=_r(flown.horizontal_error_m))  # fmt: skip
    return rec
