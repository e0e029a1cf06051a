"""An asyncio event loop on a virtual clock, for flying the runner against ``sitl_fakes.scripted``.

The loop's ``time()`` stands still while anything is ready to run and, when every task waits on a
timer, jumps straight to the earliest one: ``asyncio.sleep``, ``asyncio.wait_for`` and
``loop.call_at`` all keep their meaning, a minute of flight takes the CPU time its callbacks need,
and the same script gives the same flight on a busy machine as on an idle one.

Only what runs on the loop is virtual. A thread (an executor, a watchdog) is not waited for while the
clock jumps, so code flown on this loop must not depend on one; with nothing scheduled at all the
loop blocks on its selector as usual (a thread's ``call_soon_threadsafe`` still wakes it).
"""

from __future__ import annotations

import asyncio
import selectors
from collections.abc import Coroutine
from typing import Any, TypeVar

T = TypeVar("T")

START_S = 1000.0  # far from 0, so "no time yet" (0.0 / None) never looks like a moment of the flight


class _JumpingSelector(selectors.DefaultSelector):  # type: ignore[misc,valid-type]
    """Polls for I/O without waiting; where the loop would have waited ``timeout``, moves its clock."""

    def __init__(self) -> None:
        super().__init__()
        self.loop: VirtualTimeLoop | None = None

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        ready = super().select(0)
        if ready or timeout == 0 or self.loop is None:
            return ready
        if timeout is None:  # no timer at all: only another thread can wake the loop
            return super().select(None)
        self.loop.advance(timeout)
        return []


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """``asyncio.SelectorEventLoop`` whose clock only moves when the loop would otherwise sleep."""

    def __init__(self, start_s: float = START_S) -> None:
        selector = _JumpingSelector()
        super().__init__(selector)
        selector.loop = self
        self._now_s = start_s
        self.jumps = 0  # how often the clock moved: a measure of the work one virtual second costs

    def time(self) -> float:
        return self._now_s

    def advance(self, dt_s: float) -> None:
        if dt_s > 0:
            self._now_s += dt_s
            self.jumps += 1


def run_virtual(main: Coroutine[Any, Any, T], start_s: float = START_S) -> T:
    """``asyncio.run(main)`` on a ``VirtualTimeLoop``."""
    with asyncio.Runner(loop_factory=lambda: VirtualTimeLoop(start_s)) as runner:
        return runner.run(main)
