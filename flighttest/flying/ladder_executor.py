"""The abort ladder carried out: ``flighttest.flying.guard.AbortLadder`` decides (Recover → Hold → Land),
``LadderExecutor`` watches the vehicle for it and sends what it decides, until it is done.

Every command runs so that the ladder keeps watching meanwhile: Recover streams in a task of its own,
Hold and Land go out in the background (with the link gone a command takes its whole timeout, and the
ladder must go on judging — and give up after ``LINK_GIVE_UP_S`` — while it waits). Each rung it
commands is logged once as a ``phase`` event (``abort_recover`` / ``abort_hold`` / ``abort_land``), and
every decision as a ``ladder`` event.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from typing import Any, Protocol

from flighttest.flying import guard as gd
from flighttest.flying.autopilot import AutopilotRules
from flighttest.flying.link import Link
from flighttest.flying.missions_config import AbortConfig
from flighttest.flying.outcome import OFFBOARD_FLOW, Phase
from flighttest.flying.streamer import Setpoint, SetpointStreamer

LINK_GIVE_UP_S = 5.0  # no telemetry this long during the ladder: the vehicle's failsafe is in charge
LADDER_TIMEOUT_S = 120.0
STEP_S = 0.05  # the ladder judges this often
COMMAND_TIMEOUT_S = 5.0


class LadderHost(Protocol):
    """What the executor needs of the flight it ends (``flighttest.flying.runner.MissionRunner``)."""

    phase: str  # the nominal flow's phase: where the flight was when it aborted
    rules: AutopilotRules  # the vehicle's autopilot: its offboard mode, how to reach its hold mode
    origin: tuple[float, float, float] | None  # the trajectory's start point, once settled there
    last_decision: gd.Decision | None

    def now(self) -> float: ...
    def event(self, name: str, **fields: Any) -> None: ...
    def progress(self, text: str) -> None: ...
    def on_ground(self) -> str | None: ...  # why the vehicle is on the ground, from evidence (flying.ground)
    def disarmed(self) -> str | None: ...  # why it is disarmed on the ground, from evidence


class LadderExecutor:
    def __init__(self, ladder: gd.AbortLadder, abort_cfg: AbortConfig, rate_hz: float, stale_after_s: float,
                 host: LadderHost, t0_s: Callable[[], float]) -> None:  # fmt: skip
        self.ladder = ladder
        self.cfg = abort_cfg
        self.rate_hz = rate_hz
        self.stale_after_s = stale_after_s
        self.host = host
        self.t0_s = t0_s  # the log's time origin, for ``decided_t_s``
        self.link: Link | None = None
        self.streamer: SetpointStreamer | None = None
        self.phase: str | None = None  # the last ladder phase logged (abort_recover|abort_hold|abort_land)
        self._queue: asyncio.Queue[str] = asyncio.Queue()
        self._recovery: asyncio.Task | None = None
        self._sends: dict[str, asyncio.Task] = {}  # Hold / Land going out in the background

    def queue(self, cmd: str | None) -> None:
        """A command the ladder decided outside ``run`` (a trigger in a listener, a Ctrl-C)."""
        if cmd:
            self._queue.put_nowait(cmd)

    def bind(self, link: Link, streamer: SetpointStreamer) -> None:
        self.link, self.streamer = link, streamer

    # -- the loop -----------------------------------------------------------------------------------
    async def run(self) -> None:
        """Until the ladder is done: send what it decides, judge the vehicle every ``STEP_S``."""
        host, st = self.host, self.link.state
        host.event("ladder_start", reason=self.ladder.reason, rung=self.ladder.rung.name)
        t_start = host.now()
        logged = 0  # from the trigger on (made in a listener, before this loop ran)

        def log_decisions() -> None:  # every rung change and every decision within a rung, as it happens
            nonlocal logged
            for t, rung, why in self.ladder.history[logged:]:
                host.event("ladder", rung=rung, why=why, decided_t_s=round(t - self.t0_s(), 3))
            logged = len(self.ladder.history)

        ground = None if self.ladder.done else host.disarmed()
        if ground is not None:
            self.ladder.finish(host.now(), f"vehicle on the ground ({ground})")
        while not self.ladder.done:
            while not self._queue.empty() and not self.ladder.done:
                await self.execute(self._queue.get_nowait())
            log_decisions()
            now = host.now()
            fresh = st.t_posvel is not None and now - st.t_posvel <= self.stale_after_s
            heard = max((t for t in (st.t_posvel, st.t_att, st.t_imu) if t is not None), default=t_start)
            d = host.last_decision
            ob = gd.LadderObservation(
                # the region is ok only on a judged margin: none yet, or NaN (stale, non-finite), is unknown
                t_s=now, vd_mps=st.vd_mps, region_ok=d is not None and d.margin_mps >= 0.0,
                telemetry_fresh=fresh, mode=st.flight_mode,
                landed=host.disarmed() is not None, on_ground=host.on_ground() is not None, link_ok=st.connected,
                armed=st.armed,
                heard_age_s=now - max(heard, t_start),
            )  # fmt: skip
            cmd = self.ladder.step(ob)
            log_decisions()
            if cmd:
                await self.execute(cmd)
            if not self.ladder.done and now - t_start > LADDER_TIMEOUT_S:
                self.ladder.finish(now, "ladder timed out")
            log_decisions()
            await asyncio.sleep(STEP_S)
        log_decisions()
        host.event("ladder_end", history=[(round(t - self.t0_s(), 3), r, w) for t, r, w in self.ladder.history],
                   mode=st.flight_mode, armed=st.armed)  # fmt: skip

    async def execute(self, cmd: str) -> None:
        host, st = self.host, self.link.state
        rules = host.rules
        if st.flight_mode in rules.pilot_modes:  # nothing is ever sent to take a vehicle from the sticks
            host.event("ladder_command_skipped", command=cmd, why=f"pilot in control ({st.flight_mode})")
            self.ladder.finish(host.now(), f"pilot took over ({st.flight_mode}): sending nothing more")
            return
        host.event("ladder_command", command=cmd)
        if cmd == gd.CMD_RECOVER:
            if st.flight_mode != rules.offboard_mode or host.phase not in OFFBOARD_FLOW:
                nxt = self.ladder.escalate(host.now(), f"not in offboard ({st.flight_mode})")
                if nxt:
                    await self.execute(nxt)
                return
            self.log_phase(Phase.ABORT_RECOVER)
            self._recovery = asyncio.create_task(self._recover())
        elif cmd == gd.CMD_HOLD:
            self.log_phase(Phase.ABORT_HOLD)
            await self.stop_recovery()
            if math.isfinite(st.n_m):
                yaw = self.streamer.last.yaw_deg if self.streamer.last else 0.0
                self.streamer.leave_hold(st.n_m, st.e_m, st.d_m, yaw, "abort_hold")
            if st.flight_mode == rules.offboard_mode and rules.hold_by_offboard_stop:
                self._send(cmd, lambda: self.link.stop_offboard(COMMAND_TIMEOUT_S, "offboard stop (hold)"))
            else:
                self._send(cmd, lambda: self.link.hold(COMMAND_TIMEOUT_S))
        elif cmd == gd.CMD_LAND:
            self.log_phase(Phase.ABORT_LAND)
            await self.stop_recovery()
            self._send(cmd, lambda: self.link.land(COMMAND_TIMEOUT_S))
        elif cmd == gd.CMD_DISARM:
            self._send(cmd, lambda: self.link.disarm(COMMAND_TIMEOUT_S))

    def _send(self, cmd: str, command: Callable[[], Any]) -> None:
        """``command()`` in the background; the last of the same kind still unanswered is not doubled."""
        last = self._sends.get(cmd)
        if last is not None and not last.done():
            what = {gd.CMD_LAND: "Land", gd.CMD_HOLD: "Hold", gd.CMD_DISARM: "disarm"}.get(cmd, cmd)
            self.host.event("ladder_command_skipped", command=cmd, why=f"the last {what} is still unanswered")
            return
        self._sends[cmd] = asyncio.create_task(self._sent(cmd, command))

    async def _sent(self, cmd: str, command: Callable[[], Any]) -> None:
        try:
            await command()
        except Exception as exc:  # the log says why; a failed Hold goes on to Land, Land is re-sent
            self.host.event("ladder_command_failed", command=cmd, error=str(exc))
            if cmd == gd.CMD_HOLD and self.ladder.rung == gd.Rung.HOLD:
                self.queue(self.ladder.escalate(self.host.now(), f"hold failed: {exc}"))

    def log_phase(self, phase: Phase) -> None:
        """A ``phase`` event for the rung the ladder now commands (once per rung), so whatever the vehicle
        does from here (PX4's own Land after an abort included) is labelled an abort in the log and never
        taken for the flight's descent. The host's phase stays the nominal flow's: where the flight was
        when it aborted (``phase_at_end``)."""
        if phase != self.phase:
            self.phase = phase
            self.host.event("phase", phase=phase, nominal_phase=self.host.phase)
            self.host.progress(f"abort ladder: {phase.removeprefix('abort_')}")

    async def stop_recovery(self) -> None:
        if self._recovery is not None:
            self._recovery.cancel()
            await asyncio.gather(self._recovery, return_exceptions=True)
            self._recovery = None

    async def close(self) -> None:
        """Every task of the ladder ended (the flight is over, whatever it was waiting for)."""
        await self.stop_recovery()
        for task in self._sends.values():
            task.cancel()
        await asyncio.gather(*self._sends.values(), return_exceptions=True)

    # -- rung 1 -------------------------------------------------------------------------------------
    def recovery_direction(self) -> tuple[float, float]:
        """Unit horizontal direction for the escape: keep moving the way we move (it adds u and the
        plan cleared that path); when nearly still, back towards the start point (the plan's clear
        area); else the nose direction."""
        st = self.link.state
        vh = math.hypot(st.vn_mps, st.ve_mps)
        if vh > 0.3:
            return st.vn_mps / vh, st.ve_mps / vh
        origin = self.host.origin
        if origin is not None:
            dn, de = origin[0] - st.n_m, origin[1] - st.e_m
            dist = math.hypot(dn, de)
            if dist > 0.5:
                return dn / dist, de / dist
        yaw = math.radians(self.streamer.last.yaw_deg if self.streamer.last else 0.0)
        return math.cos(yaw), math.sin(yaw)

    async def _recover(self) -> None:
        """Rung 1: level, arrest the sink (small climb), add lateral speed; then hold position."""
        ab, st = self.cfg, self.link.state
        un, ue = self.recovery_direction()
        yaw = self.streamer.last.yaw_deg if self.streamer.last else 0.0
        lat = ab.recovery_lateral_mps

        def rec_at(k: int) -> Setpoint:
            return Setpoint(st.n_m, st.e_m, st.d_m, un * lat, ue * lat, -ab.recovery_climb_mps, yaw_deg=yaw,
                            velocity_only=True)  # fmt: skip

        ticks = max(int(ab.recovery_s * self.rate_hz), 1)
        await self.streamer.stream(rec_at, "recover", max_ticks=ticks)
        hold = Setpoint(st.n_m, st.e_m, st.d_m, yaw_deg=yaw)
        await self.streamer.stream(lambda k: hold, "recover_hold")
