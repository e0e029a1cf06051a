"""The mission runner: connect → preflight → arm → take off → climb to the start height → settle →
stream the trajectory → settle → land (or hold with ``--no-land``).

Ctrl-C, SIGTERM, an exception, a guard abort, stale telemetry, link loss or leaving offboard at any
point cancel the nominal flow and run the abort ladder (``flighttest.flying.guard.AbortLadder``) until the
vehicle is held or on the ground; a second Ctrl-C skips to the next rung. The outcome, its reason
and the log folder come back as a ``FlightOutcome``; ``summary.json`` is written last.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import signal
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flighttest.analysis import descent_time as dtime
from flighttest.errors import FlighttestError
from flighttest.flying import guard as gd
from flighttest.flying.feedforward import CatchUpLimit, Feedforward, for_autopilot, z_position_gain_per_s
from flighttest.flying.link import VehicleLink
from flighttest.flying.log_writer import FlightLogWriter
from flighttest.flying.missions_config import MissionConfig
from flighttest.flying.pauses import FlightCollector
from flighttest.flying.preflight import (
    PreflightResult,
    param_checks,
    trajectory_checks,
    trajectory_stats,
    vehicle_checks,
)
from flighttest.flying.settling import SettleCheck
from flighttest.flying.streamer import Setpoint, SetpointStreamer
from flighttest.inputs import MAX_DURATION_S
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import Trajectory

PILOT_MODES = gd.PILOT_MODES
CLIMB_RATE_MPS = 1.0
HEALTH_WAIT_S = 30.0  # how long the preflight waits for every health flag before it judges them
# settled: within this of the hover point, this slow (PX4's estimate wanders 0.3-0.8 m and its velocity
# is off by 0.1-0.2 m/s: ../shared/px4_sih; tighter and a real vehicle never settles)
SETTLE_TOL_M = 0.6
SETTLE_SPEED_MPS = 0.25
SETTLE_WINDOW_S = 1.0  # … or its position moved that slowly over this window (flighttest.flying.settling)
LINK_GIVE_UP_S = 5.0  # no telemetry this long during the ladder: the vehicle's failsafe is in charge
# a trajectory longer than this outlasts the battery (flighttest.inputs): a damaged file, not a flight,
# and resampling it at the setpoint rate could need more memory than there is
MAX_TRAJECTORY_S = MAX_DURATION_S
LADDER_TIMEOUT_S = 120.0
# while PX4 flies itself (its takeoff, its Land) telemetry missing longer than this starts the ladder
LAND_STALE_S = gd.AUTOPILOT_STALE_S
PARAMS_TIMEOUT_S = 3.0  # the preflight parameter snapshot may delay a flight by at most this
# a mode counts as reported while armed once the vehicle stayed armed this long after it arrived: PX4
# changes the mode it reports in the same heartbeat that says it disarmed (LAND → OFFBOARD or HOLD, the
# mode before), and MAVSDK hands the two over separately
MODE_SETTLE_S = 0.1


@dataclass
class FlyRequest:
    connect: str
    profile: VehicleProfile
    config: MissionConfig
    trajectory: Trajectory  # relative to its start point, as planned
    mission_name: str
    trajectory_path: str = ""
    sysid: int | None = None
    yes: bool = False
    dry_run: bool = False
    wind_ned_mps: tuple[float, float, float] | None = None
    log_root: Path = Path("logs")
    show_panel: bool = False
    confirm: Callable[[PreflightResult], bool] | None = None  # go/no-go prompt
    print_fn: Callable[[Any], None] = print


@dataclass
class FlightOutcome:
    outcome: str  # completed | aborted | probe_stopped | refused | dry_run
    abort_reason: str | None
    descent_time_s: float | None
    log_dir: str | None  # None: refused before anything answered, no folder was left
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def exit_code(self) -> int:
        return {"completed": 0, "dry_run": 0, "probe_stopped": 0, "refused": 2}.get(self.outcome, 1)

    def summary(self) -> dict[str, Any]:
        return {"outcome": self.outcome, "abort_reason": self.abort_reason,
                "descent_time_s": self.descent_time_s, "log_dir": self.log_dir, **self.extra}  # fmt: skip


class _Refused(Exception):
    pass


def _healthy(st) -> bool:
    return bool(st.health) and all(st.health.values())


class MissionRunner:
    _collector: FlightCollector | None = None  # the garbage collector held off while flying (flighttest.flying.pauses)

    def __init__(self, req: FlyRequest) -> None:
        self.req = req
        self.cfg = req.config
        self.fl = req.config.flight
        self.mission_name = req.mission_name
        self.phase = "init"
        self.link: VehicleLink | None = None
        self.streamer: SetpointStreamer | None = None
        self.log: FlightLogWriter | None = None
        self.last_decision: gd.Decision | None = None
        self.ladder = gd.AbortLadder(gd.LadderTiming(
            recover_max_s=self.cfg.abort.recover_max_s, arrested_vd_mps=self.cfg.abort.arrested_vd_mps,
            hold_confirm_s=self.cfg.abort.hold_confirm_s, hold_dwell_s=self.cfg.abort.hold_dwell_s,
            link_give_up_s=LINK_GIVE_UP_S, land=self.fl.land,
        ))  # fmt: skip
        region = req.profile.guard_region()
        g = self.cfg.guard
        self.limits = gd.GuardLimits(
            region=region, telemetry_period_s=1.0 / self.fl.telemetry_hz, stale_after_s=g.stale_after_s,
            stale_periods=g.stale_periods,
            horizon_s=g.horizon_s, debounce_samples=g.debounce_samples, clear_violation_mps=g.clear_violation_mps,
            observe_region=g.observe_region, min_alt_m=self.fl.min_alt_m, max_descent_mps=g.max_descent_mps,
            fluct_window_s=g.fluct_window_s, max_rate_std_dps=g.max_rate_std_dps,
            max_accel_std_mps2=g.max_accel_std_mps2, fluct_ratio=g.fluct_ratio,
            fluct_min_rate_std_dps=g.fluct_min_rate_std_dps, fluct_min_accel_std_mps2=g.fluct_min_accel_std_mps2,
        )  # fmt: skip
        self.guard = gd.Guard(self.limits)
        self.guard.armed = False
        self.guard.fluct_active = False  # judged only while streaming, against this flight's hover
        self.floor_active = False
        check_duration(req.trajectory)
        self.traj = req.trajectory.resample(self.fl.rate_hz)
        self.stream_traj = self.traj  # what is sent: the plan with the autopilot's feed-forward (preflight)
        self.origin: tuple[float, float, float] | None = None
        self.end_point: tuple[float, float, float] | None = None
        self.t_stream_start: float | None = None
        self.descent_time_s: float | None = None
        self.horizontal_error_m: float | None = None  # off the end point sideways when the descent was reached
        self.descent_timer: dtime.DescentTimer | None = None  # the vertical-axis rule (analysis.descent_time)
        self.ladder_phase: str | None = None  # the abort ladder's last phase event (abort_recover|hold|land)
        self.mode_while_armed: str | None = None  # the flight mode last reported while armed
        self._t_mode_change = -math.inf
        self.expect_offboard = False
        self.abort_event = asyncio.Event()
        self.abort_verdict = ""
        self._ladder_cmds: asyncio.Queue[str] = asyncio.Queue()
        self._recovery_task: asyncio.Task | None = None
        self._land_task: asyncio.Task | None = None  # the ladder's Land command, sent in the background
        self._bg: list[asyncio.Task] = []
        self._signals = 0
        self.first_inside_region_t: float | None = None
        self.connected = False  # an autopilot answered: from then on the log folder is kept
        self.panel = None  # the live panel while flying from a terminal

    # -- helpers -------------------------------------------------------------------------------------
    def event(self, name: str, **fields: Any) -> None:
        if self.log is not None:
            self.log.event(time.monotonic(), name, **fields)

    def set_phase(self, phase: str) -> None:
        self.phase = phase
        self.event("phase", phase=phase)

    def abort(self, reason: str, first: gd.Rung = gd.Rung.RECOVER, verdict: str = "") -> None:
        """Start (or join) the abort ladder; safe to call from any callback on the loop."""
        if self.ladder.done:
            return
        first_time = not self.ladder.active
        cmd = self.ladder.trigger(time.monotonic(), reason, first)
        if first_time:
            self.abort_verdict = verdict
            self.guard.armed = False  # decisions keep being logged; the ladder is in charge now
            self.event("abort", reason=reason, rung=self.ladder.rung.name, phase=self.phase)
        if cmd:
            self._ladder_cmds.put_nowait(cmd)
        self.abort_event.set()

    # -- telemetry listeners -------------------------------------------------------------------------
    def _feedforward(self, params: dict[str, Any] | None, autopilot: str | None) -> Feedforward:
        """The feed-forward corrections for this vehicle and autopilot (``flighttest.flying.feedforward``):
        PX4 decouples the tilt from the vertical acceleration unless ``MPC_ACC_DECOUPLE`` is 0. Also
        gives the streamer its catch-up limit, through the autopilot's vertical position gain."""
        decoupled = autopilot == "PX4"
        if params and "MPC_ACC_DECOUPLE" in params:
            with contextlib.suppress(TypeError, ValueError):
                decoupled = int(float(params["MPC_ACC_DECOUPLE"])) != 0
        prof = self.req.profile
        ff = Feedforward(self.fl.feedforward_lead_s, prof.drag_n_per_mps / prof.mass_kg, decoupled)
        catch_up = CatchUpLimit(self.fl.catch_up_excess_mps, self.fl.catch_up_floor_mps,
                                z_position_gain_per_s(params, autopilot))  # fmt: skip
        if self.streamer is not None:
            self.streamer.catch_up = catch_up
        self.event("feedforward", **ff.describe(), **catch_up.describe())
        return ff

    def _wind(self) -> tuple[float, float, float]:
        st = self.link.state
        if st.wind_ned_mps is not None:
            return st.wind_ned_mps
        return self.req.wind_ned_mps or (0.0, 0.0, 0.0)

    def _on_posvel(self, t: float) -> None:
        st = self.link.state
        acc = self.streamer.planned_accel_mps2(self.limits.horizon_s) if self.streamer is not None else (0, 0, 0)
        s = gd.GuardSample(t, st.vn_mps, st.ve_mps, st.vd_mps, *st.q, st.alt_m, *self._wind(), *acc)
        # below the floor is normal on the ground and in takeoff/landing: there the guard judges the rest
        self.guard.floor_active = self.floor_active
        d = self.guard.on_sample(s)
        self.last_decision = d
        if self.log is not None:
            self.log.guard(d)
        if d.margin_mps < 0 and self.first_inside_region_t is None and self.phase == "stream":
            self.first_inside_region_t = t
        if d.aborts:
            self.abort(d.reason, verdict=d.verdict)
        if st.armed and t - self._t_mode_change >= MODE_SETTLE_S:
            self.mode_while_armed = st.flight_mode
        timer = self.descent_timer
        if timer is not None and timer.result is None and self.phase in dtime.DESCENT_PHASES and not self.ladder.active:
            r = timer.update(t, st.n_m, st.e_m, st.d_m, st.vd_mps)
            if r is not None:
                self.descent_time_s, self.horizontal_error_m = r.descent_time_s, r.horizontal_error_m
                self.event("descent_reached", **r.fields(), reached_t_s=round(r.t_s - self.log.t0_mono, 3),
                           rule=timer.rule.describe())  # fmt: skip

    def _on_imu(self, t: float) -> None:
        st = self.link.state
        for d in (self.guard.on_rates(t, *st.rates_rps), self.guard.on_vertical_accel(t, st.accel_frd_mps2[2])):
            if d is not None:
                if self.log is not None:
                    self.log.guard(d)
                if d.aborts:
                    self.abort(d.reason, verdict=d.verdict)

    def _on_mode(self, old: str, new: str) -> None:
        self._t_mode_change = time.monotonic()
        self.event("mode", old=old, new=new)
        if self.phase == "land" and new in PILOT_MODES and not self.ladder.active:
            # the pilot takes the landing over: send nothing more (the ladder, once started, sees it itself)
            self.abort(f"pilot took over ({new}) while landing", gd.Rung.LAND)
            self.ladder.finish(time.monotonic(), f"pilot in control ({new})")
            return
        if not self.expect_offboard or new == "OFFBOARD" or self.ladder.active:
            return
        if new in PILOT_MODES:
            self.abort(f"pilot took over ({new})", gd.Rung.HOLD)
            self.ladder.finish(time.monotonic(), f"pilot in control ({new})")
        elif new == "LAND":
            self.abort(f"left offboard unexpectedly ({old} → {new})", gd.Rung.HOLD)
        else:
            self.abort(f"left offboard unexpectedly ({old} → {new})", gd.Rung.HOLD)

    def _on_connection(self, connected: bool) -> None:
        self.event("link", connected=connected)
        if not connected and self.guard.armed:
            self.abort("link lost", gd.Rung.HOLD)
        elif not connected and self.phase == "land" and not self.ladder.active:
            # PX4 is landing (the guard is off for that): keep asking it to, and watch, in the ladder's Land
            self.abort("link lost while landing", gd.Rung.LAND)

    async def _stale_ticker(self) -> None:
        """Stale telemetry between samples, every telemetry period, by phase (``flighttest.flying.guard``,
        "Stale telemetry"): while flighttest flies offboard, no state sample for ``stale_after_s`` aborts
        (the ladder starts at Recover). Where PX4 flies itself (arming, its takeoff, its Land, the Hold
        of --no-land) a gap is logged once per gap (``stale_while_landing`` / ``stale_while_<phase>``) and
        only one longer than ``autopilot_stale_s`` starts the ladder: at Hold, or at Land while landing,
        where the ladder's Land keeps re-sending Land and gives up after LINK_GIVE_UP_S. Once the ladder
        runs it watches the telemetry itself. Each phase's longest gap goes to the log (``telemetry_gaps``)."""
        lim = self.limits
        period = lim.telemetry_period_s
        self.event("stale_rule", offboard_s=lim.stale_after_s, autopilot_s=lim.autopilot_stale_s,
                   velocity_factor=gd.VELOCITY_STALE_FACTOR, tick_s=period)  # fmt: skip
        gap_noted = False
        gaps_phase = self.phase
        try:
            while True:
                await asyncio.sleep(period)
                if self.phase != gaps_phase:
                    self._log_gaps(gaps_phase)
                    gaps_phase = self.phase
                d = self.guard.on_tick(time.monotonic(), self.phase)
                if d is not None:
                    # samples MAVSDK already handed over wait in the subscription queues until their
                    # tasks run: let them run (a busy loop wakes this timer first), then judge again
                    for _ in range(3):
                        await asyncio.sleep(0)
                    d = self.guard.on_tick(time.monotonic(), self.phase)
                if d is None:
                    gap_noted = False
                elif self.ladder.active:
                    pass  # the ladder judges freshness itself (telemetry_fresh), and Land watches it
                elif d.aborts:
                    self.last_decision = d
                    if self.log is not None:
                        self.log.guard(d)
                    self.abort(d.reason, gd.stale_rung(self.phase), verdict=d.verdict)
                elif d.action == gd.OBSERVE and not gap_noted:
                    gap_noted = True
                    if self.log is not None:
                        self.log.guard(d)
                    self.event("stale_while_landing" if self.phase == "land" else f"stale_while_{self.phase}",
                               reason=d.reason)  # fmt: skip
                if self._collector is not None:
                    self._collector.maybe_collect()
                if self.log is not None:
                    self.log.flush_if_due()
        finally:
            self._log_gaps(gaps_phase)

    def _log_gaps(self, phase: str) -> None:
        """The longest gap between state samples (any stream, as the loop handled them) in ``phase``."""
        if self.guard.max_gap_s > 0:
            self.event("telemetry_gaps", phase=phase, max_gap_ms=round(self.guard.max_gap_s * 1000.0, 1))
        self.guard.max_gap_s = 0.0

    # -- loop pauses: the garbage collector (flighttest.flying.pauses) --------------------------------------
    def _freeze_heap(self) -> None:
        """Connected, before the preflight: one full collection (a full one of this heap pauses the process
        for up to a few hundred ms) and everything alive frozen, out of every later collection."""
        if self._collector is None:
            self._collector = FlightCollector().__enter__()
            st = self._collector.stats
            self.event("gc", what="heap frozen", ms=round(st.entry_ms, 1), frozen=st.frozen)

    def _hold_off_collector(self) -> None:
        """Preflight done, arming next: what it made frozen too, and no automatic collections until the
        flight is over (only at the safe points)."""
        if self._collector is not None:
            ms = self._collector.hold_off()
            self.event("gc", what="held off", ms=round(ms, 1), frozen=self._collector.stats.frozen)

    def _collect_now(self) -> None:
        """A safe point: collect what the flight made so far (the rest is frozen: a few ms)."""
        if self._collector is not None:
            self.event("gc", what="safe point", ms=round(self._collector.safe_point(), 2))

    def _restore_collector(self) -> None:
        """Every exit of a flight: the collector as it was before, and what it did meanwhile."""
        if self._collector is not None:
            gcx, self._collector = self._collector, None
            gcx.__exit__(None, None, None)
            self.event("gc", what="restored", **gcx.stats.to_dict())

    # -- the run -------------------------------------------------------------------------------------
    async def run(self) -> FlightOutcome:
        req = self.req
        self.log = FlightLogWriter(req.log_root, self.mission_name)
        try:
            self.log.write_meta({
                "mission": self.mission_name, "config": self.cfg.to_dict(), "vehicle": req.profile.summary(),
                "trajectory_path": req.trajectory_path, "trajectory_meta": req.trajectory.meta,
                "connect": req.connect, "sysid": req.sysid, "dry_run": req.dry_run,
                "wind_ned_mps": req.wind_ned_mps, "argv": sys.argv,
            })  # fmt: skip
            self.log.save_trajectory(req.trajectory)
        except OSError as exc:
            self.log.discard()
            raise FlighttestError(f"cannot write the flight log in {self.log.dir} ({exc.strerror or exc})") from None
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                loop.add_signal_handler(sig, self._on_signal, sig.name)
        outcome: FlightOutcome | None = None
        try:
            outcome = await self._run_linked()
        except _Refused as exc:
            outcome = self._outcome("refused", str(exc))
        except FlighttestError as exc:
            outcome = self._outcome("refused", str(exc))
        except Exception as exc:  # a bug or a library's surprise: logged in full, one line for the user
            self.event("exception", error=repr(exc), traceback=traceback.format_exc())
            outcome = self._outcome("aborted", self.ladder.reason or f"internal error: {exc!r}")
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                    loop.remove_signal_handler(sig)
            if outcome is None:  # cancelled: still leave a summary
                outcome = self._outcome("aborted", self.ladder.reason or "internal error")
            self.event("end", outcome=outcome.outcome, reason=outcome.abort_reason)
            if not self.connected:
                # nothing answered, nothing flew: no folder (an empty .tlog would only break `analyse logs/`)
                self.log.discard()
                outcome.log_dir = None
            else:
                self.log.write_summary(outcome.summary())
                self.log.close()
        return outcome

    def _on_signal(self, name: str) -> None:
        self._signals += 1
        self.event("signal", signal=name, count=self._signals)
        if self.ladder.active:
            cmd = self.ladder.escalate(time.monotonic(), f"{name} again")
            if cmd:
                self._ladder_cmds.put_nowait(cmd)
        else:
            self.abort(f"{name} from the operator", verdict="signal")

    def _outcome(self, outcome: str, reason: str | None) -> FlightOutcome:
        extra: dict[str, Any] = {"mission": self.mission_name, "phase_at_end": self.phase}
        if self.streamer is not None:
            j = self.streamer.jitter()
            extra.update(setpoint_jitter_p99_ms=j["p99_ms"], setpoint_rate_hz=j["rate_hz"],
                         setpoints_sent=self.streamer.sent, watchdog_fired=self.streamer.watchdog_fired)  # fmt: skip
        if self.link is not None:
            st = self.link.state
            extra.update(final_armed=st.armed, final_landed_state=st.landed_state, final_alt_m=st.alt_m,
                         **final_mode(st.flight_mode, st.armed, self.mode_while_armed))  # fmt: skip
        extra["horizontal_error_m"] = self.horizontal_error_m
        if self.ladder.history:
            extra["ladder"] = [{"t_s": round(t - self.log.t0_mono, 3), "rung": r, "why": w}
                               for t, r, w in self.ladder.history]  # fmt: skip
        if self.abort_verdict:
            extra["abort_verdict"] = self.abort_verdict
        return FlightOutcome(outcome, reason, self.descent_time_s, str(self.log.dir), extra)

    async def _run_linked(self) -> FlightOutcome:
        req = self.req
        link = VehicleLink(req.connect, sysid=req.sysid, tlog_path=self.log.tlog_path,
                           telemetry_hz=self.fl.telemetry_hz, connect_timeout_s=self.fl.connect_timeout_s,
                           on_event=lambda n, f: self.event(n, **f))  # fmt: skip
        self.link = link
        self.set_phase("connect")
        connect_task = asyncio.create_task(link.open())
        try:
            await self._race(connect_task)
        except BaseException:
            await link.close()
            raise
        self.connected = connect_task.done() and not connect_task.cancelled()
        if self.ladder.active:  # Ctrl-C while connecting
            await link.close()
            return self._outcome("aborted", self.ladder.reason)
        try:
            self._freeze_heap()  # connected, nothing flying yet: the one long collection goes here
            self.streamer = SetpointStreamer(link.offboard_setters(), self.log, self.fl.rate_hz,
                                             here=lambda: (link.state.n_m, link.state.e_m, link.state.d_m))  # fmt: skip
            link.on_posvel.append(self._on_posvel)
            link.on_attitude.append(self.guard.note_state_sample)
            link.on_imu.append(self._on_imu)
            link.on_mode.append(self._on_mode)
            link.on_connection.append(self._on_connection)
            self._bg.append(asyncio.create_task(self._stale_ticker()))
            panel = None
            if req.show_panel:
                from flighttest.console import console
                from flighttest.flying.panel import LivePanel

                panel = LivePanel(self, console)
            self.panel = panel
            with panel if panel is not None else contextlib.nullcontext():
                return await self._fly()
        finally:
            self._restore_collector()
            for t in self._bg:
                t.cancel()
            await asyncio.gather(*self._bg, return_exceptions=True)
            for task in (self._recovery_task, self._land_task):
                if task is not None:
                    task.cancel()
                    await asyncio.gather(task, return_exceptions=True)
            if self.streamer is not None:
                self.streamer.stop_watchdog()
            await link.close()

    async def _race(self, task: asyncio.Task):
        """Await ``task`` unless an abort comes first (then cancel it). Re-raises the task's error."""
        waiter = asyncio.create_task(self.abort_event.wait())
        try:
            await asyncio.wait({task, waiter}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            waiter.cancel()
        if not task.done():
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
            return None
        return task.result()

    async def _fly(self) -> FlightOutcome:
        req = self.req
        pre = await self._preflight()
        req.print_fn(pre.table(f"Preflight — {self.mission_name} on '{req.profile.name}'"))
        if not pre.ok:
            raise _Refused(f"preflight failed: {pre.first_failure()}")
        if self.ladder.active:
            return self._outcome("aborted", self.ladder.reason)
        if req.dry_run:
            self.set_phase("dry_run")
            return self._outcome("dry_run", None)
        if not req.yes:
            if not sys.stdin.isatty():
                raise _Refused("no terminal to confirm arming: pass --yes to fly without the go/no-go prompt")
            with self.panel.paused() if self.panel is not None else contextlib.nullcontext():
                go = req.confirm is not None and req.confirm(pre)
            if not go:
                raise _Refused("no-go from the operator")
            self.event("go", by="operator")
        flow = asyncio.create_task(self._nominal())
        try:
            result = await self._race(flow)
        except Exception as exc:  # the flow failed: treat like any other abort
            self.event("exception", error=repr(exc), traceback=traceback.format_exc())
            # a landing that went wrong goes on landing: Recover and Hold would stop it mid-air
            self.abort(f"error: {exc}", gd.Rung.LAND if self.phase == "land" else gd.Rung.RECOVER, verdict="exception")
            result = None
        if not self.ladder.active and result is not None:
            return result
        await self._run_ladder()
        outcome = "aborted"
        if self.cfg.mission == "probe" and self.abort_verdict in (gd.FLUCTUATION, gd.SPEED_CAP, gd.FLOOR):
            outcome = "probe_stopped"
        return self._outcome(outcome, self.ladder.reason)

    async def _preflight(self) -> PreflightResult:
        self.set_phase("preflight")
        link, req = self.link, self.req
        await link.wait_for(lambda s: s.t_posvel is not None and s.t_att is not None and bool(s.health), 5.0)
        if not link.state.armed and link.state.flight_mode == "OFFBOARD":
            # PX4 stays in Offboard after an offboard flight lands, and Offboard without a setpoint
            # stream is not armable (the campaign's next flight on the same vehicle): Hold is armable
            self.event("mode_reset", old="OFFBOARD", new="HOLD", why="disarmed in Offboard is not armable")
            with contextlib.suppress(Exception):
                await link.call(link.action.hold(), "hold", 5.0)
        if not _healthy(link.state):
            # a vehicle that has just landed (the campaign's next flight) or booted is not armable
            # for some seconds (PX4 SITL: more than 10 s after a landing); wait before judging it
            self.event("waiting_for_health", not_ok=sorted(k for k, v in link.state.health.items() if not v),
                       timeout_s=HEALTH_WAIT_S)  # fmt: skip
            if await link.wait_for(_healthy, HEALTH_WAIT_S):
                self.event("healthy")
        await asyncio.sleep(1.0)  # a second of telemetry to measure its rate
        params = {}
        from flighttest.flying.preflight import ABORT_PARAMS

        for name, kind in ABORT_PARAMS.items():
            params[name] = await link.get_param(name, kind)
        # the parameter snapshot of this flight (params.json): everything relevant, read once and
        # bounded (a slow link must not hold the flight up); else the values just read, noted
        from flighttest.analysis.params import snapshot

        all_params, note = None, None
        try:
            all_params = await link.get_all_params(PARAMS_TIMEOUT_S) or None
            note = None if all_params else "the vehicle sent no parameters; kept the preflight check's"
        except Exception as exc:
            note = f"reading all parameters failed ({exc}); kept the preflight check's"
        snap = snapshot(all_params, params, await link.autopilot_name(), time.time(), note)
        try:
            self.log.write_params(snap)
            self.event("params", source=snap["source"], kept=len(snap["params"]), read=snap["params_read"], note=note)
        except OSError as exc:
            self.event("warning", what=f"params.json not written ({exc})")
        self.stream_traj = for_autopilot(self.traj, self._feedforward(all_params, await link.autopilot_name()),
                                         self._wind())  # fmt: skip
        accel = max(0.5 * req.profile.max_accel_up_mps2, 0.5)
        stats = trajectory_stats(self.traj, self.limits.region, accel)
        ab = self.cfg.abort
        checks = vehicle_checks(link.state, time.monotonic(), self.fl.telemetry_hz, self.fl.min_battery_percent)
        checks += param_checks(params, stats.descent_max_mps, req.profile.w_allow_mps)
        checks += trajectory_checks(stats, req.profile, self.fl.start_height_m, self.fl.min_alt_m,
                                    self.fl.geofence_radius_m, ab.recovery_lateral_mps * ab.recovery_s,
                                    self.cfg.guard.observe_region)  # fmt: skip
        pre = PreflightResult(checks)
        self.log.write_preflight({**pre.to_dict(), "params": params, "trajectory": stats.__dict__})
        self.event("preflight", ok=pre.ok, failures=[c.name for c in pre.failures])
        return pre

    # -- nominal flow ------------------------------------------------------------------------------
    async def _nominal(self) -> FlightOutcome | None:
        """The nominal flow; returns None once an abort has started (the ladder takes over)."""
        link, fl = self.link, self.fl
        st = link.state
        H = fl.start_height_m
        self._hold_off_collector()
        self.set_phase("arm")
        self.guard.armed = True
        await link.call(link.action.arm(), "arm", 10.0)
        self.event("armed")
        self.set_phase("takeoff")
        with contextlib.suppress(Exception):
            await link.call(link.action.set_takeoff_altitude(H), "set takeoff altitude", 5.0)
        await link.call(link.action.takeoff(), "takeoff", 10.0)
        ok = await link.wait_for(lambda s: s.alt_m >= min(H, 2.0) - 0.3 and s.in_air, fl.takeoff_timeout_s)
        if not ok:
            raise RuntimeError(f"takeoff did not reach {min(H, 2.0):.1f} m within {fl.takeoff_timeout_s:g} s")
        # offboard from here: climb to the exact start point, holding the trajectory's initial yaw
        self.set_phase("climb")
        yaw0 = float(self.traj.df["yaw_deg"].iloc[0])
        here = Setpoint(st.n_m, st.e_m, st.d_m, yaw_deg=yaw0)
        self.streamer.send(here, "climb")
        loop = asyncio.get_running_loop()
        self.streamer.start_watchdog(lambda: loop.call_soon_threadsafe(lambda: self.event("setpoint_watchdog")))
        self.expect_offboard = True
        await link.call(link.offboard.start(), "offboard start", 10.0)
        self.event("offboard", active=True)
        start = (st.n_m, st.e_m, -H)
        d0 = st.d_m
        n_climb = max(int(abs(start[2] - d0) / CLIMB_RATE_MPS * fl.rate_hz), 1)

        def climb_at(k: int) -> Setpoint | None:
            if k > n_climb:
                return None
            f = k / n_climb
            return Setpoint(start[0], start[1], d0 + f * (start[2] - d0), yaw_deg=yaw0)

        await self.streamer.stream(climb_at, "climb", lambda: self.ladder.active)
        if self.ladder.active:  # the ladder owns the vehicle now: this flow must not send anything
            return None
        self.set_phase("settle")
        hold = Setpoint(*start, yaw_deg=yaw0)
        await self._settle(hold, fl.settle_s, fl.settle_s * 3 + 10.0, baseline=True)
        if self.ladder.active:
            return None
        self.origin = start
        last = self.traj.df.iloc[-1]
        if dtime.goes_somewhere((last["n_m"], last["e_m"], last["d_m"])):
            # a descent time only where the trajectory goes somewhere (the probe returns to its start)
            self.end_point = (start[0] + last["n_m"], start[1] + last["e_m"], start[2] + last["d_m"])
        self.set_phase("stream")
        self.floor_active = True
        self.t_stream_start = time.monotonic()
        if self.end_point is not None:
            self.descent_timer = dtime.DescentTimer(self.t_stream_start, self.end_point)
        self.event("stream_start", origin_ned=list(start), rows=len(self.traj.df),
                   end_ned=None if self.end_point is None else [float(x) for x in self.end_point])  # fmt: skip
        rate_base, accel_base = self.guard.freeze_baseline()
        rate_thr, accel_thr = self.guard.fluct_thresholds()
        self.event("fluct_baseline", rate_std_dps=rate_base, accel_std_mps2=accel_base,
                   rate_threshold_dps=rate_thr, accel_threshold_mps2=accel_thr)  # fmt: skip
        self.guard.fluct_active = True
        try:
            res = await self.streamer.fly_trajectory(self.stream_traj, start, lambda: self.ladder.active)
        finally:
            self.guard.fluct_active = False
        self.event("stream_end", result=res, jitter=self.streamer.jitter())
        if self.ladder.active:
            return None
        end_sp = self.streamer.last_planned.hold() if self.streamer.last_planned else hold
        self.set_phase("settle")
        # hover on until the descent counts as reached too (its rule is stricter than settling: an
        # overshoot of the end height settles before it is back within 0.2 m), or the settle times out
        timer = self.descent_timer
        await self._settle(end_sp, fl.settle_s, fl.settle_s * 3 + 10.0, must_settle=False,
                           also=lambda: timer is None or timer.result is not None)  # fmt: skip
        if self.ladder.active:
            return None
        self.floor_active = False
        self.expect_offboard = False
        if fl.land:
            self.set_phase("land")
            self.guard.armed = False  # landing below the floor is the point; stale/link still end it
            await link.call(link.action.land(), "land", 10.0)
            ok = await link.wait_for(lambda s: not s.armed, max(H, 1.0) / 0.5 + 30.0)
            if not ok:
                raise RuntimeError("did not land and disarm in time")
            self.set_phase("landed")
        else:
            self.set_phase("hold")
            await link.call(link.offboard.stop(), "offboard stop", 10.0)
            if not await link.wait_for(lambda s: s.flight_mode == "HOLD", 5.0):
                raise RuntimeError("Hold not confirmed after the flight (--no-land)")
        return self._outcome("completed", None)

    async def _settle(self, sp: Setpoint, min_s: float, max_s: float, baseline: bool = False,
                      must_settle: bool = True, also: Callable[[], bool] | None = None) -> None:  # fmt: skip
        """Hover at ``sp`` until settled (and ``also()``); with ``baseline`` the guard's hover
        fluctuation baseline is the settled part of it (the climb's transient is not the hover). Not
        settling within ``max_s`` is an error only where it must (before the descent)."""
        self._collect_now()  # PX4 holds the position: a pause of a few ms costs nothing here
        st = self.link.state
        t0 = time.monotonic()
        settled_since = None
        check = SettleCheck((sp.n_m, sp.e_m, sp.d_m), SETTLE_TOL_M, SETTLE_SPEED_MPS, SETTLE_WINDOW_S)

        def done() -> bool:
            nonlocal settled_since
            if self.ladder.active:
                return True
            now = time.monotonic()
            if check.update(now, (st.n_m, st.e_m, st.d_m), (st.vn_mps, st.ve_mps, st.vd_mps)):
                if settled_since is None and baseline:
                    self.guard.start_baseline()
                settled_since = now if settled_since is None else settled_since
            else:
                settled_since = None
            if now - t0 >= max_s:
                if not must_settle:  # after the descent: it is flown; hovering on is all that is left
                    self.event("settle_timeout", at_ned=[sp.n_m, sp.e_m, sp.d_m], after_s=max_s)
                    return True
                raise RuntimeError(f"did not settle at ({sp.n_m:.1f}, {sp.e_m:.1f}, {sp.d_m:.1f}) within {max_s:g} s")
            return (settled_since is not None and now - settled_since >= min(min_s, 1.0) and now - t0 >= min_s
                    and (also is None or also()))

        await self.streamer.stream(lambda k: sp, self.phase, done)

    # -- the abort ladder ----------------------------------------------------------------------------
    async def _run_ladder(self) -> None:
        link = self.link
        st = link.state
        self.event("ladder_start", reason=self.ladder.reason, rung=self.ladder.rung.name)
        t_start = time.monotonic()
        logged = 0  # from the trigger on (made in a listener, before this loop ran)

        def log_decisions() -> None:  # every rung change and every decision within a rung, as it happens
            nonlocal logged
            for t, rung, why in self.ladder.history[logged:]:
                self.event("ladder", rung=rung, why=why, decided_t_s=round(t - self.log.t0_mono, 3))
            logged = len(self.ladder.history)

        if not st.armed and not st.in_air:
            self.ladder.finish(time.monotonic(), "vehicle on the ground")
        while not self.ladder.done:
            while not self._ladder_cmds.empty():
                await self._execute(self._ladder_cmds.get_nowait())
            log_decisions()
            now = time.monotonic()
            fresh = st.t_posvel is not None and now - st.t_posvel <= self.limits.stale_after_s
            heard = max((t for t in (st.t_posvel, st.t_att, st.t_imu) if t is not None), default=t_start)
            d = self.last_decision
            ob = gd.LadderObservation(
                t_s=now, vd_mps=st.vd_mps, region_ok=d is None or not (d.margin_mps < 0),
                telemetry_fresh=fresh, mode=st.flight_mode,
                landed=not st.armed, link_ok=st.connected,  # done when disarmed, not at touchdown
                heard_age_s=now - max(heard, t_start),
            )  # fmt: skip
            cmd = self.ladder.step(ob)
            log_decisions()
            if cmd:
                await self._execute(cmd)
            if not self.ladder.done and now - t_start > LADDER_TIMEOUT_S:
                self.ladder.finish(now, "ladder timed out")
            log_decisions()
            await asyncio.sleep(0.05)
        log_decisions()
        self.event("ladder_end", history=[(round(t - self.log.t0_mono, 3), r, w) for t, r, w in self.ladder.history],
                   mode=st.flight_mode, armed=st.armed)  # fmt: skip

    async def _execute(self, cmd: str) -> None:
        link, st = self.link, self.link.state
        self.event("ladder_command", command=cmd)
        try:
            if cmd == gd.CMD_RECOVER:
                if st.flight_mode != "OFFBOARD" or self.phase not in ("climb", "settle", "stream"):
                    nxt = self.ladder.escalate(time.monotonic(), f"not in offboard ({st.flight_mode})")
                    if nxt:
                        await self._execute(nxt)
                    return
                self._ladder_phase("abort_recover")
                self._recovery_task = asyncio.create_task(self._recover())
            elif cmd == gd.CMD_HOLD:
                self._ladder_phase("abort_hold")
                await self._stop_recovery()
                if math.isfinite(st.n_m):
                    yaw = self.streamer.last.yaw_deg if self.streamer.last else 0.0
                    self.streamer.leave_hold(st.n_m, st.e_m, st.d_m, yaw, "abort_hold")
                if st.flight_mode == "OFFBOARD":
                    await link.call(link.offboard.stop(), "offboard stop (hold)", 5.0)
                else:
                    await link.call(link.action.hold(), "hold", 5.0)
            elif cmd == gd.CMD_LAND:
                self._ladder_phase("abort_land")
                await self._stop_recovery()
                # in the background: with the link gone the call takes its whole timeout, and the
                # ladder must go on watching (and give up) meanwhile
                if self._land_task is not None and not self._land_task.done():
                    self.event("ladder_command_skipped", command=cmd, why="the last Land is still unanswered")
                else:
                    self._land_task = asyncio.create_task(self._send_land())
        except Exception as exc:
            self.event("ladder_command_failed", command=cmd, error=str(exc))
            if cmd == gd.CMD_HOLD:
                nxt = self.ladder.escalate(time.monotonic(), f"hold failed: {exc}")
                if nxt:
                    self._ladder_cmds.put_nowait(nxt)

    def _ladder_phase(self, phase: str) -> None:
        """A ``phase`` event for the rung the ladder now commands (once per rung), so whatever the vehicle
        does from here (PX4's own Land after an abort included) is labelled an abort in the log and never
        taken for the flight's descent. ``self.phase`` stays the nominal flow's: where the flight was
        when it aborted (``phase_at_end``)."""
        if phase != self.ladder_phase:
            self.ladder_phase = phase
            self.event("phase", phase=phase, nominal_phase=self.phase)

    async def _send_land(self) -> None:
        try:
            await self.link.call(self.link.action.land(), "land", 5.0)
        except Exception as exc:  # the ladder re-sends it; the log says why this one failed
            self.event("ladder_command_failed", command=gd.CMD_LAND, error=str(exc))

    async def _stop_recovery(self) -> None:
        if self._recovery_task is not None:
            self._recovery_task.cancel()
            await asyncio.gather(self._recovery_task, return_exceptions=True)
            self._recovery_task = None

    def _recovery_direction(self) -> tuple[float, float]:
        """Unit horizontal direction for the escape: keep moving the way we move (it adds u and the
        plan cleared that path); when nearly still, back towards the start point (the plan's clear
        area); else the nose direction."""
        st = self.link.state
        vh = math.hypot(st.vn_mps, st.ve_mps)
        if vh > 0.3:
            return st.vn_mps / vh, st.ve_mps / vh
        if self.origin is not None:
            dn, de = self.origin[0] - st.n_m, self.origin[1] - st.e_m
            dist = math.hypot(dn, de)
            if dist > 0.5:
                return dn / dist, de / dist
        yaw = math.radians(self.streamer.last.yaw_deg if self.streamer.last else 0.0)
        return math.cos(yaw), math.sin(yaw)

    async def _recover(self) -> None:
        """Rung 1: level, arrest the sink (small climb), add lateral speed; then hold position."""
        ab, st = self.cfg.abort, self.link.state
        un, ue = self._recovery_direction()
        yaw = self.streamer.last.yaw_deg if self.streamer.last else 0.0
        lat = ab.recovery_lateral_mps

        def rec_at(k: int) -> Setpoint:
            return Setpoint(st.n_m, st.e_m, st.d_m, un * lat, ue * lat, -ab.recovery_climb_mps, yaw_deg=yaw,
                            velocity_only=True)  # fmt: skip

        ticks = max(int(ab.recovery_s * self.fl.rate_hz), 1)
        await self.streamer.stream(rec_at, "recover", max_ticks=ticks)
        hold = Setpoint(st.n_m, st.e_m, st.d_m, yaw_deg=yaw)
        await self.streamer.stream(lambda k: hold, "recover_hold")


def final_mode(reported: str, armed: bool, while_armed: str | None) -> dict[str, Any]:
    """``final_mode`` of ``summary.json``: the mode the vehicle reports, or, once it has disarmed, the mode
    it was in when it disarmed (PX4 reports the mode before the landing after disarming: OFFBOARD
    or HOLD on the ground); ``final_mode_note`` says which, and what it reports now, when they differ."""
    if armed or while_armed is None or while_armed == reported:
        return {"final_mode": reported, "final_mode_note": None if armed or while_armed is None else "at disarm"}
    return {"final_mode": while_armed, "final_mode_note": f"at disarm; {reported} reported after disarming"}


def check_duration(traj: Trajectory, what: str = "trajectory") -> None:
    """A finite, bounded duration before anything resamples or streams the trajectory."""
    d = traj.duration_s
    if not (math.isfinite(d) and 0 <= d <= MAX_TRAJECTORY_S):
        raise FlighttestError(f"{what} lasts {d:g} s: a flight's must be finite and at most {MAX_TRAJECTORY_S:g} s")


async def fly(req: FlyRequest) -> FlightOutcome:
    return await MissionRunner(req).run()
