"""Keeping pauses out of the flying process's event loop: the garbage collector during a flight.

One asyncio loop runs everything that flies: telemetry listeners, the guard, the 50 Hz setpoint
streamer and the stale-telemetry ticker. Whatever stops that loop stops all of them, and what
stopped it in the reference flights on PX4 was CPython's cyclic garbage collector. By the time a
flight arms, the process holds about 85 000 objects the collector tracks (pandas, numpy, MAVSDK,
CasADi, the plan, the profile); a *full* collection walks them all and takes tens to hundreds of
milliseconds (``bench/RESULTS.md``, "The flying process's own pauses"), and CPython starts one on its own
whenever enough objects have survived the younger collections — at a moment nobody chose, a
descent included. Young collections only walk the objects made since the last one: well under a
millisecond.

``FlightCollector``, a context manager the runner opens before it connects and closes on every
exit of the flight:

- on entry (nothing connected yet, so the pause harms nothing): one full collection, then
  ``gc.freeze()``. Every object alive then — imports, the plan, the profile, MAVSDK — moves to the
  collector's permanent generation, which no collection walks again: from here even a full
  collection only walks what was made since;
- ``hold_off()``, once the preflight is done and before arming: the same again for what connecting
  and the preflight made (a few milliseconds), and the collector's automatic runs are off
  (``gc.disable()``): no collection starts by itself during the flight, however the allocations
  fall. Reference counting still frees everything that is not in a cycle (nearly all a flight
  allocates); cyclic garbage waits for the next ``safe_point()``, which the runner calls where a
  pause of a few milliseconds costs nothing (the settles, where PX4 holds the position). A flight
  that streams for long between safe points collects anyway once ``young_limit`` objects are
  pending (``maybe_collect()``, from the stale ticker): a young collection of that size is about
  a millisecond;
- on exit, any exit (an exception, a cancelled task), the collector is as it was: enabled or not,
  its thresholds, and its permanent generation emptied again if it was empty before (a process
  that froze objects itself keeps them frozen: ``gc.unfreeze`` cannot tell whose they are).

``stats`` records every collection while the context is open (``gc.callbacks``): how many of
each generation and the longest, for the flight log. ``bench/bench_telemetry.py`` measures the
loop's worst pause with and without this.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

# young objects pending (gc.get_count()[0]) above which maybe_collect() runs a young collection:
# 10 000 are walked in well under a millisecond; CPython's own threshold is 700
YOUNG_LIMIT = 10_000


@dataclass
class CollectorStats:
    """Collections seen while a ``FlightCollector`` was open."""

    collections: dict[int, int] = field(default_factory=lambda: {0: 0, 1: 0, 2: 0})
    max_ms: dict[int, float] = field(default_factory=lambda: {0: 0.0, 1: 0.0, 2: 0.0})
    collected: int = 0  # unreachable objects freed
    frozen: int = 0  # objects moved to the permanent generation on entry
    entry_ms: float = 0.0  # the full collection on entry (before connecting)
    hold_off_ms: float = 0.0  # the collection before arming (what connecting and the preflight made)
    safe_points: int = 0

    @property
    def worst_ms(self) -> float:
        return max(self.max_ms.values())

    def to_dict(self) -> dict[str, Any]:
        return {
            "collections": {f"gen{g}": n for g, n in self.collections.items()},
            "max_ms": {f"gen{g}": round(ms, 3) for g, ms in self.max_ms.items()},
            "worst_ms": round(self.worst_ms, 3),
            "collected": self.collected,
            "frozen": self.frozen,
            "entry_ms": round(self.entry_ms, 3),
            "hold_off_ms": round(self.hold_off_ms, 3),
            "safe_points": self.safe_points,
        }


class FlightCollector:
    """``with FlightCollector() as gcx: ... gcx.hold_off() ... gcx.safe_point() ...`` — see the module docstring.

    ``enabled=False`` changes nothing about the collector (it still records ``stats``): the
    measurement baseline of the bench."""

    def __init__(self, enabled: bool = True, young_limit: int = YOUNG_LIMIT) -> None:
        self.enabled = enabled
        self.young_limit = young_limit
        self.stats = CollectorStats()
        self._was_enabled: bool | None = None
        self._thresholds: tuple[int, int, int] | None = None
        self._froze = False
        self._t_start: float | None = None
        self._open = False

    # -- the context -------------------------------------------------------------------------------
    def __enter__(self) -> FlightCollector:
        if self._open:
            raise RuntimeError("FlightCollector is not re-entrant")
        self._was_enabled = gc.isenabled()
        self._thresholds = gc.get_threshold()
        gc.callbacks.append(self._on_gc)
        self._open = True
        if self.enabled:
            try:
                self._froze = gc.get_freeze_count() == 0
                self.stats.entry_ms = self._collect_and_freeze()
            except BaseException:
                self._restore()
                raise
        return self

    def _collect_and_freeze(self) -> float:
        """A full collection (recorded apart from the flight's: ``entry_ms``, ``hold_off_ms``), then freeze."""
        self._quiet = True
        try:
            t0 = time.perf_counter()
            gc.collect()
            ms = (time.perf_counter() - t0) * 1000.0
        finally:
            self._quiet = False
        gc.freeze()
        self.stats.frozen = gc.get_freeze_count()
        return ms

    def __exit__(self, *exc: object) -> None:
        self._restore()

    def _restore(self) -> None:
        if not self._open:
            return
        self._open = False
        if self._on_gc in gc.callbacks:
            gc.callbacks.remove(self._on_gc)
        if self._froze:
            gc.unfreeze()  # back into the oldest generation: collected as before the flight
            self._froze = False
        if self._thresholds is not None:
            gc.set_threshold(*self._thresholds)
        if self._was_enabled:
            gc.enable()
        else:
            gc.disable()

    # -- during the flight -------------------------------------------------------------------------
    def hold_off(self) -> float:
        """Before arming: collect and freeze what was made since entry, then no automatic runs; ms."""
        if not (self._open and self.enabled):
            return 0.0
        self.stats.hold_off_ms = self._collect_and_freeze()
        gc.disable()
        return self.stats.hold_off_ms

    def safe_point(self) -> float:
        """A full collection now (only what the flight made: the rest is frozen); its duration in ms."""
        if not (self._open and self.enabled):
            return 0.0
        t0 = time.perf_counter()
        gc.collect()
        self.stats.safe_points += 1
        return (time.perf_counter() - t0) * 1000.0

    def maybe_collect(self) -> None:
        """A young collection if more than ``young_limit`` objects are pending (a long stream)."""
        if self._open and self.enabled and gc.get_count()[0] > self.young_limit:
            gc.collect(0)

    _quiet = False

    def _on_gc(self, phase: str, info: dict[str, int]) -> None:
        if self._quiet:
            return
        if phase == "start":
            self._t_start = time.perf_counter()
            return
        if self._t_start is None:
            return
        ms = (time.perf_counter() - self._t_start) * 1000.0
        self._t_start = None
        g = int(info.get("generation", 2))
        st = self.stats
        st.collections[g] = st.collections.get(g, 0) + 1
        st.max_ms[g] = max(st.max_ms.get(g, 0.0), ms)
        st.collected += int(info.get("collected", 0))


class FlightPauses:
    """The collector through one flight, each step logged as a ``gc`` event (``event(name, **fields)``):
    ``freeze`` once connected, ``hold_off`` before arming, ``safe_point`` where PX4 holds the vehicle,
    ``tick`` at every stale-ticker period, ``restore`` on every exit."""

    def __init__(self, event: Callable[..., None]) -> None:
        self._event = event
        self._collector: FlightCollector | None = None

    def freeze(self) -> None:
        """Connected, before the preflight: one full collection (a full one of this heap pauses the process
        for up to a few hundred ms) and everything alive frozen, out of every later collection."""
        if self._collector is None:
            self._collector = FlightCollector().__enter__()
            st = self._collector.stats
            self._event("gc", what="heap frozen", ms=round(st.entry_ms, 1), frozen=st.frozen)

    def hold_off(self) -> None:
        """Preflight done, arming next: what it made frozen too, and no automatic collections until the
        flight is over (only at the safe points)."""
        if self._collector is not None:
            ms = self._collector.hold_off()
            self._event("gc", what="held off", ms=round(ms, 1), frozen=self._collector.stats.frozen)

    def safe_point(self) -> None:
        """Collect what the flight made so far (the rest is frozen: a few ms)."""
        if self._collector is not None:
            self._event("gc", what="safe point", ms=round(self._collector.safe_point(), 2))

    def tick(self) -> None:
        if self._collector is not None:
            self._collector.maybe_collect()

    def restore(self) -> None:
        """Every exit of a flight: the collector as it was before, and what it did meanwhile."""
        if self._collector is not None:
            gcx, self._collector = self._collector, None
            gcx.__exit__(None, None, None)
            self._event("gc", what="restored", **gcx.stats.to_dict())
