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
from flighttest.flying.wind import WindEstimate, WindSources

# a mode counts as reported while armed once the vehicle stayed armed this long after it arrived: PX4
# changes the mode it reports in the same heartbeat that says it disarmed (LAND → OFFBOARD or HOLD, the
# mode before), and MAVSDK hands the two over separately
MODE_SETTLE_S = 0.1
# from the arm command on, a pilot's mode is a takeover and the autopilot's own failsafe modes are followed
ARMED_PHASES = frozenset({Phase.ARM, Phase.TAKEOFF, Phase.CLIMB, Phase.SETTLE, Phase.STREAM, Phase.LAND, Phase.HOLD})
# the wind is estimated in flight, clear of the ground's reaction and the takeoff's ground effect
WIND_PHASES = frozenset({Phase.TAKEOFF, Phase.CLIMB, Phase.SETTLE, Phase.STREAM, Phase.LAND, Phase.HOLD})
WIND_MIN_HEIGHT_M = 0.5
GUST_PHASES = frozenset({Phase.CLIMB, Phase.SETTLE, Phase.HOLD})
WHERE = {Phase.ARM: " while arming", Phase.TAKEOFF: " during the takeoff", Phase.LAND: " while landing",
         Phase.HOLD: " in the hold after the flight"}  # fmt: skip


class WatchHost(Protocol):
    """What the watch needs of the flight it watches (``flighttest.flying.runner.MissionRunner``)."""

    phase: str
    rules: AutopilotRules  # the vehicle's autopilot: its offboard mode and its pilots' modes
    floor_active: bool  # the altitude floor applies (from the start point to the end of the descent)
    expect_offboard: bool  # flighttest flies offboard now: any other mode is a takeover or a failure
    ground_alt_m: float  # the estimate's height of the ground, seen at arming: heights count from it
    wind: WindSources
    ladder: gd.AbortLadder
    link: Link | None
    streamer: SetpointStreamer | None
    log: FlightLogWriter | None

    def now(self) -> float: ...
    def event(self, name: str, **fields: Any) -> None: ...
    def abort(self, reason: str, first: gd.Rung = gd.Rung.RECOVER, verdict: str = "") -> None: ...
    def takeover(self, reason: str, mode: str) -> None: ...
    def follow_autopilot(self, reason: str) -> None: ...


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
        self.hover_timer: dtime.DescentTimer | None = None  # the same, hover to hover (dtime.HOVER_RULE)
        self.descent_time_s: float | None = None
        self.horizontal_error_m: float | None = None  # off the end point sideways when the descent was reached

    def attach(self, link: Link) -> None:
        link.on_posvel.append(self.on_posvel)
        link.on_attitude.append(self.on_attitude)
        link.on_imu.append(self.on_imu)
        link.on_mode.append(self.on_mode)
        link.on_connection.append(self.on_connection)

    def wind(self) -> WindEstimate:
        """The wind as flighttest knows it now (``flighttest.flying.wind``)."""
        return self.host.wind.current(self.host.link.state, self.host.now())

    def wind_ned_mps(self) -> tuple[float, float, float]:
        return self.wind().ned_mps

    def _logged(self, d: gd.Decision) -> None:
        if self.host.log is not None:
            self.host.log.guard(d)

    # -- listeners ----------------------------------------------------------------------------------
    def on_attitude(self, t: float) -> None:
        self.guard.note_attitude(t, self.host.link.state.t_att_vehicle_s)

    def on_posvel(self, t: float) -> None:
        host = self.host
        st = host.link.state
        acc = host.streamer.planned_accel_mps2(self.limits.horizon_s) if host.streamer is not None else (0, 0, 0)
        wind = self.wind()
        att_age = t - st.t_att if st.t_att is not None else math.inf
        s = gd.GuardSample(t, st.vn_mps, st.ve_mps, st.vd_mps, *st.q, st.alt_m - host.ground_alt_m, *wind.ned_mps,
                           *acc, wind_radius_mps=wind.radius_mps, att_age_s=att_age,
                           updraft_mps=wind.updraft_mps)  # fmt: skip
        # below the floor is normal on the ground and in takeoff/landing: there the guard judges the rest
        self.guard.floor_active = host.floor_active
        d = self.guard.on_sample(s)
        self.last_decision = d
        if host.log is not None:
            host.log.guard(d, wind)
        if d.margin_mps < 0 and self.first_inside_region_t is None and host.phase == Phase.STREAM:
            self.first_inside_region_t = t
        if d.aborts:
            host.abort(d.reason, gd.stale_rung(host.phase) if d.verdict == gd.STALE else gd.Rung.RECOVER, d.verdict)
        if st.armed and t - self._t_mode_change >= MODE_SETTLE_S:
            self.mode_while_armed = st.flight_mode
        if host.phase not in dtime.DESCENT_PHASES or host.ladder.active:
            return
        timer = self.descent_timer
        if timer is not None and timer.result is None:
            r = timer.update(t, st.n_m, st.e_m, st.d_m, st.vd_mps)
            if r is not None:
                self.descent_time_s, self.horizontal_error_m = r.descent_time_s, r.horizontal_error_m
                host.event("descent_reached", **r.fields(), reached_t_s=round(r.t_s - host.log.t0_mono, 3),
                           rule=timer.rule.describe())  # fmt: skip
        hover = self.hover_timer
        if hover is not None and hover.result is None:
            r = hover.update(t, st.n_m, st.e_m, st.d_m, st.vd_mps, st.vn_mps, st.ve_mps)
            if r is not None:
                host.event("hover_reached", hover_to_hover_s=round(r.descent_time_s, 3),
                           horizontal_error_m=round(r.horizontal_error_m, 3),
                           reached_t_s=round(r.t_s - host.log.t0_mono, 3), rule=hover.rule.describe())  # fmt: skip

    @property
    def hover_to_hover_s(self) -> float | None:
        r = self.hover_timer.result if self.hover_timer is not None else None
        return r.descent_time_s if r is not None else None

    def on_imu(self, t: float) -> None:
        host = self.host
        st = host.link.state
        if host.phase in WIND_PHASES and st.in_air and st.alt_m - host.ground_alt_m > WIND_MIN_HEIGHT_M:
            # across the thrust axis the IMU feels the air's drag: the wind; its spread while the vehicle holds
            # still, the gusts (the descent's manoeuvres move the estimate too)
            host.wind.on_imu(t, st, measure_gusts=host.phase in GUST_PHASES)
        for d in (self.guard.on_rates(t, *st.rates_rps), self.guard.on_vertical_accel(t, st.accel_frd_mps2[2])):
            if d is not None:
                self._logged(d)
                if d.aborts:
                    self.host.abort(d.reason, verdict=d.verdict)

    def on_mode(self, old: str, new: str) -> None:
        """From the arm command on, a pilot mode is a takeover: the run ends at once and nothing more is
        sent. The autopilot's own Land or return (a failsafe) is followed, never overridden. Leaving
        offboard any other way while flighttest flies it is a failure: the ladder from Hold."""
        host = self.host
        rules = host.rules
        self._t_mode_change = host.now()
        host.event("mode", old=old, new=new)
        if host.phase not in ARMED_PHASES or host.ladder.done:
            return
        if new in rules.pilot_modes:
            # the ladder, once running, sees the pilot itself (LadderExecutor, AbortLadder.step)
            if not host.ladder.active:
                host.takeover(f"pilot took over ({new}){WHERE.get(host.phase, '')}", new)
            return
        if host.ladder.active or host.phase == Phase.LAND:
            return  # the ladder watches the modes itself; Land is flighttest's own here
        if new in rules.failsafe_modes:
            host.follow_autopilot(f"the autopilot switched to {new}{WHERE.get(host.phase, '')}: following it")
        elif host.expect_offboard and new != rules.offboard_mode:
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
