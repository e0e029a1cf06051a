"""Offboard setpoint streaming at a fixed rate with deadline pacing, and the safe setpoint it leaves.

MAVSDK re-sends the last setpoint at 20 Hz on its own, also when our loop is stuck. So:

- the streamer owns the rate (default 50 Hz): tick ``k`` is due at ``t0 + k/rate``; a late tick
  sends the row that belongs to *now* instead of bursting the backlog, so trajectory time stays
  locked to the wall clock; every interval between sends is kept to report jitter;
- whenever it stops — end of trajectory, abort, exception — it leaves a *hold* setpoint (position
  here, zero velocity and acceleration) as the one MAVSDK keeps re-sending;
- with a ``catch_up`` limit, every position setpoint is sent at most that far below the vehicle
  (``flighttest.flying.feedforward.CatchUpLimit``); the setpoint log holds what was sent;
- a watchdog thread leaves that hold setpoint too if the loop stops sending for ``stuck_after_s``
  (an event loop blocked by something else must not keep a descent's feed-forward alive).

Setpoints are absolute local NED (the autopilot's frame); trajectories are relative to their start
point and are offset by ``origin``. The setters are called on the loop thread: MAVSDK's offboard
setters only store the setpoint and queue one message (no acknowledgement), so they do not block,
and no call can be left in flight when the link is destroyed.
"""

from __future__ import annotations

import asyncio
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from flighttest.flying.feedforward import CatchUpLimit
from flighttest.model.trajectory import Trajectory


@dataclass(frozen=True, slots=True)
class Setpoint:
    n_m: float
    e_m: float
    d_m: float
    vn_mps: float = 0.0
    ve_mps: float = 0.0
    vd_mps: float = 0.0
    an_mps2: float = 0.0
    ae_mps2: float = 0.0
    ad_mps2: float = 0.0
    yaw_deg: float = 0.0
    velocity_only: bool = False  # recovery: velocity control, no position target

    def hold(self) -> Setpoint:
        return Setpoint(self.n_m, self.e_m, self.d_m, yaw_deg=self.yaw_deg)


def jitter_stats_ms(intervals_s: np.ndarray, period_s: float) -> dict[str, float]:
    """Setpoint interval jitter ``|interval − period|`` in ms: p50, p99, max; and the mean rate."""
    iv = np.asarray(intervals_s, float)
    if iv.size == 0:
        return {"n": 0, "p50_ms": math.nan, "p99_ms": math.nan, "max_ms": math.nan, "rate_hz": math.nan}
    j = np.abs(iv - period_s) * 1000.0
    return {
        "n": int(iv.size),
        "p50_ms": float(np.percentile(j, 50)),
        "p99_ms": float(np.percentile(j, 99)),
        "max_ms": float(j.max()),
        "rate_hz": float(1.0 / iv.mean()),
    }


class SetpointStreamer:
    """Sends setpoints through MAVSDK's offboard plugin and logs each one with its send time."""

    def __init__(self, offboard_plugin, log=None, rate_hz: float = 50.0, stuck_after_s: float = 0.15,
                 here: Callable[[], tuple[float, float, float]] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:  # fmt: skip
        from mavsdk.plugins.offboard import AccelerationNed, PositionNedYaw, VelocityNedYaw

        self._P, self._V, self._A = PositionNedYaw, VelocityNedYaw, AccelerationNed
        # the synchronous plugin under mavsdk.asyncio's OffboardAsync (see module docstring)
        self._plugin = offboard_plugin
        self.log = log
        self.rate_hz = rate_hz
        self.period_s = 1.0 / rate_hz
        self.stuck_after_s = stuck_after_s
        # the loop's clock (the runner's): send times, their intervals and the watchdog's judgement
        self.clock = clock
        self.last: Setpoint | None = None
        self.phase = ""
        self.intervals_s: list[float] = []
        self._last_send_pc: float | None = None
        self.sent = 0
        self.send_errors = 0
        self._lock = threading.Lock()
        self._watchdog_stop = threading.Event()
        self._watchdog: threading.Thread | None = None
        self.watchdog_fired = 0
        self.on_send: list[Callable[[float, Setpoint], None]] = []
        # where the vehicle is now (local NED): a stream that stops early holds there
        self.here = here
        # bounds each position setpoint's downward catch-up (flighttest.flying.feedforward.CatchUpLimit)
        self.catch_up: CatchUpLimit | None = None
        self.last_planned: Setpoint | None = None  # the last setpoint before that bound

    # -- one setpoint ------------------------------------------------------------------------------
    def send(self, sp: Setpoint, phase: str) -> bool:
        now_pc = t_mono = self.clock()
        planned, sp = sp, self._limited(sp)
        with self._lock:
            ok = self._send_raw(sp)
            self.last = sp
            self.last_planned = planned
            self.phase = phase
            if self._last_send_pc is not None and phase == self._interval_phase:
                self.intervals_s.append(now_pc - self._last_send_pc)
            self._last_send_pc = now_pc
            self._interval_phase = phase
        self.sent += 1
        if self.log is not None:
            self.log.setpoint(t_mono, phase, sp.n_m, sp.e_m, sp.d_m, sp.vn_mps, sp.ve_mps, sp.vd_mps,
                              sp.an_mps2, sp.ae_mps2, sp.ad_mps2, sp.yaw_deg)  # fmt: skip
        for cb in self.on_send:
            cb(t_mono, sp)
        return ok

    _interval_phase = ""

    def _limited(self, sp: Setpoint) -> Setpoint:
        """``sp`` with its down position kept within the catch-up limit of the vehicle's position."""
        if self.catch_up is None or self.here is None or sp.velocity_only:
            return sp
        d_here = self.here()[2]
        if not math.isfinite(d_here):
            return sp
        d_m = self.catch_up.limit(sp.d_m, d_here, sp.vd_mps)
        return sp if d_m == sp.d_m else replace(sp, d_m=d_m)

    def _send_raw(self, sp: Setpoint) -> bool:
        try:
            if sp.velocity_only:
                self._plugin.set_velocity_ned(self._V(sp.vn_mps, sp.ve_mps, sp.vd_mps, sp.yaw_deg))
            else:
                self._plugin.set_position_velocity_acceleration_ned(
                    self._P(sp.n_m, sp.e_m, sp.d_m, sp.yaw_deg),
                    self._V(sp.vn_mps, sp.ve_mps, sp.vd_mps, sp.yaw_deg),
                    self._A(sp.an_mps2, sp.ae_mps2, sp.ad_mps2),
                )
            return True
        except Exception:  # an OffboardError or a destroyed plugin: counted, the runner watches modes
            self.send_errors += 1
            return False

    def leave_hold(self, n_m: float, e_m: float, d_m: float, yaw_deg: float, phase: str = "hold") -> Setpoint:
        """Leave the safe setpoint in MAVSDK's resend: hold at (n, e, d), zero velocity."""
        sp = Setpoint(n_m, e_m, d_m, yaw_deg=yaw_deg)
        self.send(sp, phase)
        return sp

    # -- paced loops -------------------------------------------------------------------------------
    async def stream(
        self,
        setpoint_at: Callable[[int], Setpoint | None],
        phase: str,
        should_stop: Callable[[], bool] = lambda: False,
        max_ticks: int | None = None,
    ) -> str:
        """Send ``setpoint_at(k)`` at tick ``k`` until it returns None (→ "done"), ``should_stop()``
        (→ "stopped") or ``max_ticks`` (→ "done"). Deadline pacing on the loop's clock.

        Whatever ends it, the setpoint left for MAVSDK's resend is a hold: at the last setpoint's
        position when the stream ran out, at the vehicle's position (``here``) when it was stopped,
        cancelled or failed. A setpoint that already holds is not sent again."""
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        k = 0
        result = "failed"
        try:
            while True:
                if should_stop():
                    result = "stopped"
                    return result
                sp = setpoint_at(k)
                if sp is None:
                    result = "done"
                    return result
                self.send(sp, phase)
                if max_ticks is not None and k + 1 >= max_ticks:
                    result = "done"
                    return result
                nxt = k + 1
                delay = t0 + nxt * self.period_s - loop.time()
                if delay < -self.period_s:  # more than a tick late: send the row that belongs to now
                    nxt = int((loop.time() - t0) / self.period_s) + 1
                    delay = t0 + nxt * self.period_s - loop.time()
                await asyncio.sleep(max(delay, 0.0))
                k = nxt
        finally:
            self.leave_safe(phase, at_vehicle=result != "done")

    def leave_safe(self, phase: str, at_vehicle: bool = True) -> Setpoint | None:
        """Make the setpoint MAVSDK keeps re-sending a hold (zero velocity and acceleration); at the
        vehicle's position if ``at_vehicle`` and known, else at the last setpoint's planned position."""
        last, planned = self.last, self.last_planned
        if last is None or planned is None or last == last.hold():
            return None
        n, e, d = planned.n_m, planned.e_m, planned.d_m  # the hold the plan meant, not the catch-up's
        if at_vehicle and self.here is not None:
            pos = self.here()
            if all(math.isfinite(x) for x in pos):
                n, e, d = pos
        return self.leave_hold(n, e, d, last.yaw_deg, f"{phase}_hold")

    async def fly_trajectory(
        self, traj: Trajectory, origin_ned: tuple[float, float, float], should_stop: Callable[[], bool],
        phase: str = "stream",
    ) -> str:
        """Stream a trajectory already resampled at ``rate_hz`` (rows relative to its start point)."""
        df = traj.df
        cols = [df[c].to_numpy(float) for c in ("n_m", "e_m", "d_m", "vn_mps", "ve_mps", "vd_mps",
                                                 "an_mps2", "ae_mps2", "ad_mps2", "yaw_deg")]  # fmt: skip
        rows = np.stack(cols, axis=1)
        rows[:, 0] += origin_ned[0]
        rows[:, 1] += origin_ned[1]
        rows[:, 2] += origin_ned[2]
        n = len(rows)
        self._rows, self._k = rows, 0

        def at(k: int) -> Setpoint | None:
            if k >= n:
                return None
            self._k = k
            return Setpoint(*(float(x) for x in rows[k]))

        try:
            return await self.stream(at, phase, should_stop)
        finally:
            self._rows = None

    _rows: np.ndarray | None = None
    _k = 0

    def planned_accel_mps2(self, horizon_s: float) -> tuple[float, float, float]:
        """Mean commanded acceleration over the next ``horizon_s`` of the trajectory being streamed:
        the planned velocity change over the horizon divided by it (the plan ends at rest). Zero when
        no trajectory is streaming. This is what the guard's prediction integrates: a constant
        acceleration extrapolated past the end of an acceleration phase would overshoot."""
        rows = self._rows
        if rows is None:
            return 0.0, 0.0, 0.0
        k = min(self._k, len(rows) - 1)
        m = max(round(horizon_s * self.rate_hz), 1)
        j = k + m
        v_end = rows[j, 3:6] if j < len(rows) else np.zeros(3)
        a = (v_end - rows[k, 3:6]) / (m * self.period_s)
        return float(a[0]), float(a[1]), float(a[2])

    async def hold_for(self, sp: Setpoint, seconds: float, phase: str, should_stop: Callable[[], bool]) -> str:
        ticks = max(round(seconds * self.rate_hz), 1)
        return await self.stream(lambda k: sp, phase, should_stop, max_ticks=ticks)

    # -- watchdog ----------------------------------------------------------------------------------
    def start_watchdog(self, on_fire: Callable[[], None] | None = None) -> None:
        if self._watchdog is not None:
            return
        self._watchdog_stop.clear()

        def run() -> None:
            while not self._watchdog_stop.wait(self.period_s):
                with self._lock:
                    last, last_t = self.last, self._last_send_pc
                    if last is None or last_t is None:
                        continue
                    if self.clock() - last_t > self.stuck_after_s and (last != last.hold()):
                        self._send_raw(last.hold())
                        self.last = last.hold()
                        self.watchdog_fired += 1
                        fired = True
                    else:
                        fired = False
                if fired and on_fire is not None:
                    on_fire()

        self._watchdog = threading.Thread(target=run, name="setpoint-watchdog", daemon=True)
        self._watchdog.start()

    def stop_watchdog(self) -> None:
        self._watchdog_stop.set()
        if self._watchdog is not None:
            self._watchdog.join(timeout=1.0)
            self._watchdog = None

    def jitter(self) -> dict[str, float]:
        return jitter_stats_ms(np.asarray(self.intervals_s), self.period_s)
