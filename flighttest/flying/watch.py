"""The flight's telemetry, watched: every state sample to the guard (``flighttest.flying.guard``), the
descent timed by the rule the analysis uses (``flighttest.analysis.descent_time``), the modes and the
link watched for a pilot or a failure, and stale telemetry judged between samples by phase. What calls
for an abort goes to the host's ``abort``; what happened goes to its log.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from typing import Any, Protocol

from flighttest.analysis import descent_time as dtime
from flighttest.flying import guard as gd
from flighttest.flying.autopilot import AutopilotRules
from flighttest.flying.link import Link
from flighttest.flying.log_writer import FlightLogWriter
from flighttest.flying.outcome import Phase
from flighttest.flying.streamer import SetpointStreamer

# a mode counts as reported while armed once the vehicle stayed armed this long after it arrived: PX4
# changes the mode it reports in the same heartbeat that says it disarmed (LAND → OFFBOARD or HOLD, the
# mode before), and MAVSDK hands the two over separately
MODE_SETTLE_S = 0.1


class WatchHost(Protocol):
    """What the watch needs of the flight it watches (``flighttest.flying.runner.MissionRunner``)."""

    phase: str
    rules: AutopilotRules  # the vehicle's autopilot: its offboard mode and its pilots' modes
    floor_active: bool  # the altitude floor applies (from the start point to the end of the descent)
    expect_offboard: bool  # flighttest flies offboard now: any other mode is a takeover or a failure
    ladder: gd.AbortLadder
    link: Link | None
    streamer: SetpointStreamer | None
    log: FlightLogWriter | None

    def now(self) -> float: ...
    def event(self, name: str, **fields: Any) -> None: ...
    def abort(self, reason: str, first: gd.Rung = gd.Rung.RECOVER, verdict: str = "") -> None: ...


class FlightWatch:
    def __init__(self, guard: gd.Guard, host: WatchHost) -> None:
        self.guard = guard
        self.limits = guard.limits
        self.host = host
        self.last_decision: gd.Decision | None = None
        self.first_inside_region_t: float | None = None  # first sample inside the region while streaming
        self.mode_while_armed: str | None = None  # the flight mode last reported while armed
        self._t_mode_change = -math.inf
        self.descent_timer: dtime.DescentTimer | None = None  # set when the descent starts
        self.descent_time_s: float | None = None
        self.horizontal_error_m: float | None = None  # off the end point sideways when the descent was reached

    def attach(self, link: Link) -> None:
        link.on_posvel.append(self.on_posvel)
        link.on_attitude.append(self.guard.note_state_sample)
        link.on_imu.append(self.on_imu)
        link.on_mode.append(self.on_mode)
        link.on_connection.append(self.on_connection)

    def wind_ned_mps(self) -> tuple[float, float, float]:
        """The wind the vehicle estimates, else the one given (``--wind``), else calm."""
        return self.host.link.state.wind_ned_mps or self.wind_default_ned_mps

    wind_default_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)  # --wind where the vehicle reports none

    def _logged(self, d: gd.Decision) -> None:
        if self.host.log is not None:
            self.host.log.guard(d)

    # -- listeners ----------------------------------------------------------------------------------
    def on_posvel(self, t: float) -> None:
        host = self.host
        st = host.link.state
        acc = host.streamer.planned_accel_mps2(self.limits.horizon_s) if host.streamer is not None else (0, 0, 0)
        s = gd.GuardSample(t, st.vn_mps, st.ve_mps, st.vd_mps, *st.q, st.alt_m, *self.wind_ned_mps(), *acc)
        # below the floor is normal on the ground and in takeoff/landing: there the guard judges the rest
        self.guard.floor_active = host.floor_active
        d = self.guard.on_sample(s)
        self.last_decision = d
        self._logged(d)
        if d.margin_mps < 0 and self.first_inside_region_t is None and host.phase == Phase.STREAM:
            self.first_inside_region_t = t
        if d.aborts:
            host.abort(d.reason, verdict=d.verdict)
        if st.armed and t - self._t_mode_change >= MODE_SETTLE_S:
            self.mode_while_armed = st.flight_mode
        timer = self.descent_timer
        if timer is not None and timer.result is None and host.phase in dtime.DESCENT_PHASES and not host.ladder.active:
            r = timer.update(t, st.n_m, st.e_m, st.d_m, st.vd_mps)
            if r is not None:
                self.descent_time_s, self.horizontal_error_m = r.descent_time_s, r.horizontal_error_m
                host.event("descent_reached", **r.fields(), reached_t_s=round(r.t_s - host.log.t0_mono, 3),
                           rule=timer.rule.describe())  # fmt: skip

    def on_imu(self, t: float) -> None:
        st = self.host.link.state
        for d in (self.guard.on_rates(t, *st.rates_rps), self.guard.on_vertical_accel(t, st.accel_frd_mps2[2])):
            if d is not None:
                self._logged(d)
                if d.aborts:
                    self.host.abort(d.reason, verdict=d.verdict)

    def on_mode(self, old: str, new: str) -> None:
        """A pilot mode is a takeover: the ladder finishes at once and nothing more is sent. Leaving
        offboard any other way while flighttest flies it is a failure: the ladder from Hold."""
        host = self.host
        rules = host.rules
        self._t_mode_change = host.now()
        host.event("mode", old=old, new=new)
        if host.phase == Phase.LAND and new in rules.pilot_modes and not host.ladder.active:
            # the pilot takes the landing over: send nothing more (the ladder, once started, sees it itself)
            host.abort(f"pilot took over ({new}) while landing", gd.Rung.LAND)
            host.ladder.finish(host.now(), f"pilot in control ({new})")
            return
        if not host.expect_offboard or new == rules.offboard_mode or host.ladder.active:
            return
        if new in rules.pilot_modes:
            host.abort(f"pilot took over ({new})", gd.Rung.HOLD)
            host.ladder.finish(host.now(), f"pilot in control ({new})")
        else:
            host.abort(f"left offboard unexpectedly ({old} → {new})", gd.Rung.HOLD)

    def on_connection(self, connected: bool) -> None:
        host = self.host
        host.event("link", connected=connected)
        if not connected and self.guard.armed:
            host.abort("link lost", gd.Rung.HOLD)
        elif not connected and host.phase == Phase.LAND and not host.ladder.active:
            # PX4 is landing (the guard is off for that): keep asking it to, and watch, in the ladder's Land
            host.abort("link lost while landing", gd.Rung.LAND)

    # -- between samples ----------------------------------------------------------------------------
    async def stale_ticker(self, every_tick: Callable[[], None] = lambda: None) -> None:
        """Stale telemetry between samples, every telemetry period, by phase (``flighttest.flying.guard``,
        "Stale telemetry"): while flighttest flies offboard, no state sample for ``stale_after_s`` aborts
        (the ladder starts at Recover). Where PX4 flies itself (arming, its takeoff, its Land, the Hold
        of --no-land) a gap is logged once per gap (``stale_while_landing`` / ``stale_while_<phase>``) and
        only one longer than ``autopilot_stale_s`` starts the ladder: at Hold, or at Land while landing,
        where the ladder's Land keeps re-sending Land and gives up after LINK_GIVE_UP_S. Once the ladder
        runs it watches the telemetry itself. Each phase's longest gap goes to the log (``telemetry_gaps``).
        ``every_tick`` is the host's housekeeping at each tick (the collector's safe point, log flushes)."""
        host, lim = self.host, self.limits
        period = lim.telemetry_period_s
        host.event("stale_rule", offboard_s=lim.stale_after_s, autopilot_s=lim.autopilot_stale_s,
                   velocity_factor=gd.VELOCITY_STALE_FACTOR, tick_s=period)  # fmt: skip
        gap_noted = False
        gaps_phase = host.phase
        try:
            while True:
                await asyncio.sleep(period)
                if host.phase != gaps_phase:
                    self.log_gaps(gaps_phase)
                    gaps_phase = host.phase
                d = self.guard.on_tick(host.now(), host.phase)
                if d is not None:
                    # samples MAVSDK already handed over wait in the subscription queues until their
                    # tasks run: let them run (a busy loop wakes this timer first), then judge again
                    for _ in range(3):
                        await asyncio.sleep(0)
                    d = self.guard.on_tick(host.now(), host.phase)
                if d is None:
                    gap_noted = False
                elif host.ladder.active:
                    pass  # the ladder judges freshness itself (telemetry_fresh), and Land watches it
                elif d.aborts:
                    self.last_decision = d
                    self._logged(d)
                    host.abort(d.reason, gd.stale_rung(host.phase), verdict=d.verdict)
                elif d.action == gd.OBSERVE and not gap_noted:
                    gap_noted = True
                    self._logged(d)
                    host.event("stale_while_landing" if host.phase == Phase.LAND else f"stale_while_{host.phase}",
                               reason=d.reason)  # fmt: skip
                every_tick()
        finally:
            self.log_gaps(gaps_phase)

    def log_gaps(self, phase: str) -> None:
        """The longest gap between state samples (any stream, as the loop handled them) in ``phase``."""
        if self.guard.max_gap_s > 0:
            self.host.event("telemetry_gaps", phase=phase, max_gap_ms=round(self.guard.max_gap_s * 1000.0, 1))
        self.guard.max_gap_s = 0.0
