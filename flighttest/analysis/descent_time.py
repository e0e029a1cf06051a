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

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise FlighttestError(f"descent rule {name} must be a finite number > 0 (got {value!r})")

    def describe(self) -> str:
        return (f"height within {self.height_tol_m:g} m of the end point's and vertical speed within "
                f"{self.settled_vd_mps:g} m/s, both for {self.hold_s:g} s")  # fmt: skip


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


class DescentTimer:
    """The rule of this module, one sample at a time. ``update`` returns the result once, on the
    sample that completes the hold (``hold_s`` after the instant it reports), and None otherwise."""

    def __init__(self, t_start_s: float, end_ned_m: tuple[float, float, float], rule: DescentRule | None = None):
        self.t_start_s = float(t_start_s)
        self.end_ned_m = tuple(float(x) for x in end_ned_m)
        self.rule = rule or DescentRule()
        self.result: DescentReached | None = None
        self._since: tuple[float, float, float, float, float] | None = None  # t, n, e, d of the hold's start
        self._heights: collections.deque[tuple[float, float]] = collections.deque()  # (t, d) over hold_s

    def update(self, t_s: float, n_m: float, e_m: float, d_m: float, vd_mps: float) -> DescentReached | None:
        if self.result is not None or t_s < self.t_start_s:
            return None
        r, end = self.rule, self.end_ned_m
        values = (t_s, n_m, e_m, d_m, vd_mps)
        if not all(math.isfinite(v) for v in (t_s, d_m)):  # a gap breaks the hold and the height's rate
            self._heights.clear()
        else:
            self._heights.append((t_s, d_m))
            while t_s - self._heights[0][0] > r.hold_s:
                self._heights.popleft()
        vd = abs(vd_mps)
        t_old, d_old = self._heights[0] if self._heights else (t_s, d_m)
        if t_s - t_old >= 0.9 * r.hold_s:  # a full window: the height's own rate counts too
            vd = min(vd, abs(d_m - d_old) / (t_s - t_old))
        inside = all(math.isfinite(v) for v in values) and abs(d_m - end[2]) <= r.height_tol_m \
            and vd <= r.settled_vd_mps  # fmt: skip
        if not inside:  # a gap in the data (NaN) breaks the hold like a sample outside it
            self._since = None
            return None
        if self._since is None:
            self._since = (t_s, n_m, e_m, d_m, vd_mps)
        t0, n0, e0, d0, _ = self._since
        if t_s - t0 < r.hold_s:
            return None
        self.result = DescentReached(t0, t0 - self.t_start_s, d0 - end[2], math.hypot(n0 - end[0], e0 - end[1]))
        return self.result


def descent_reached(
    t_s, n_m, e_m, d_m, vd_mps, t_start_s: float, end_ned_m, t_stop_s: float | None = None,
    rule: DescentRule | None = None,
) -> DescentReached | None:  # fmt: skip
    """:class:`DescentTimer` over arrays (samples in time order), from ``t_start_s`` until ``t_stop_s``
    (the end of the descent's phases: the hold must be complete by then)."""
    timer = DescentTimer(t_start_s, end_ned_m, rule)
    cols = [np.asarray(x, dtype=float) for x in (t_s, n_m, e_m, d_m, vd_mps)]
    t = cols[0]
    sel = (t >= t_start_s) & (t <= (math.inf if t_stop_s is None else t_stop_s))
    for t_k, n_k, e_k, d_k, vd_k in zip(*(c[sel] for c in cols)):
        if timer.update(float(t_k), float(n_k), float(e_k), float(d_k), float(vd_k)) is not None:
            return timer.result
    return None


@dataclass(frozen=True)
class LogDescent:
    """A log folder's descent timed by :func:`from_log`: ``reached`` None when it never met the rule
    (``why`` says why), ``end_s`` the end of the window it was judged in."""

    start_s: float
    end_s: float
    reached: DescentReached | None
    why: str | None = None


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
    reached = descent_reached(s["t_s"], s["n_m"], s["e_m"], d, vd, t0, end, stop, rule)
    t_end = float(s["t_s"].iloc[-1]) if math.isinf(stop) else stop
    rule_text = (rule or DescentRule()).describe()
    why = None if reached else f"not at the end height and settled ({rule_text}) before {_what}"
    return LogDescent(t0, t_end, reached, why)


def timed_event(log, rule: DescentRule | None = None) -> dict | None:
    """:func:`from_log` as an event for the loaded log's event list (``TIMED_EVENT``; ``t_s`` the instant
    the descent was reached, else the end of the window judged), None where it cannot be judged. It
    is never written to a folder: ``events.jsonl`` keeps what the flight wrote."""
    timed = from_log(log, rule)
    if timed is None:
        return None
    r = timed.reached
    return {"event": TIMED_EVENT, "t_s": r.t_s if r else timed.end_s, "start_s": timed.start_s,
            **(r.fields() if r else dict.fromkeys(("descent_time_s", "horizontal_error_m", "height_error_m"))),
            "why": timed.why, "rule": (rule or DescentRule()).describe(), "by": __name__}  # fmt: skip
