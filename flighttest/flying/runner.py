"""The mission runner: connect → preflight → arm → take off → climb to the start height → settle →
stream the trajectory → settle → land (or hold with ``--no-land``).

Ctrl-C, SIGTERM, an exception, a guard abort, stale telemetry, link loss or leaving offboard at any
point cancel the nominal flow and run the abort ladder (``flighttest.flying.ladder_executor``) until the
vehicle is held or on the ground; a second Ctrl-C skips to the next rung. The outcome, its reason
and the log folder come back as a ``FlightOutcome``; ``summary.json`` is written last.

The runner owns the flow and its lifecycle; its collaborators each own one job: ``FlightWatch``
(``flighttest.flying.watch``) turns telemetry into guard decisions, descent timing and takeover
detection, ``LadderExecutor`` carries the abort ladder out, ``FlightPauses`` keeps the garbage
collector out of the flight. It flies through any ``Link`` (``open_link``) on its event loop's clock:
MAVSDK in flight, a scripted autopilot in virtual time in ``tests/test_runner_virtual.py``.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import math
import signal
import sys
import time
import traceback
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from flighttest.analysis import descent_time as dtime
from flighttest.errors import FlighttestError
from flighttest.flying import guard as gd
from flighttest.flying.autopilot import ARDUPILOT, PX4_RULES, AutopilotRules
from flighttest.flying.feedforward import (
    CatchUpLimit,
    Feedforward,
    for_autopilot,
    hold_accel_ned,
    z_position_gain_per_s,
)
from flighttest.flying.ground import GroundEvidence
from flighttest.flying.ladder_executor import LADDER_TIMEOUT_S, LINK_GIVE_UP_S, LadderExecutor
from flighttest.flying.link import GCS_SYSID, Link, VehicleLink
from flighttest.flying.live_limits import (
    ARDUPILOT_LIMITS,
    ARDUPILOT_POS_TILT,
    ARDUPILOT_TILT,
    LiveLimit,
    ardupilot_limits,
    plans_bound,
    px4_limits,
    with_live_limits,
)
from flighttest.flying.log_writer import FlightLogWriter
from flighttest.flying.outcome import FlightOutcome, FlyRequest, Outcome, Phase, final_mode
from flighttest.flying.pauses import FlightPauses
from flighttest.flying.preflight import (
    ABORT_PARAMS,
    ARDUPILOT_PARAMS,
    PreflightResult,
    ardupilot_param_checks,
    disk_check,
    ground_height_check,
    mode_check,
    param_checks,
    telemetry_rates_ok,
    trajectory_checks,
    trajectory_stats,
    vehicle_checks,
    wind_check,
)
from flighttest.flying.settling import SettleCheck
from flighttest.flying.streamer import Setpoint, SetpointStreamer
from flighttest.flying.watch import FlightWatch
from flighttest.flying.wind import PRIOR_SD_MPS, WindEstimate, WindSources, plan_margin_in_wind, rotate_plan
from flighttest.inputs import MAX_DURATION_S
from flighttest.model.trajectory import Trajectory
from flighttest.planner.optimum import EFFICIENCY_KEYS, OPTIMUM_KEY, efficiency, optimum_for, with_optimum

# re-exported: what callers of the runner have always imported from here
__all__ = ["LADDER_TIMEOUT_S", "LINK_GIVE_UP_S", "FlightOutcome", "FlyRequest", "MissionRunner", "final_mode", "fly"]
CLIMB_RATE_MPS = 1.0
# the climb's heading swing (flighttest.model.wind_estimate: the accelerometer's bias as a state): a quarter turn
# tells a body-fixed bias from the wind, more tells it better; short of a half turn, which the autopilot may take
# either way round (bench/RESULTS.md, "The climb looks around")
LOOK_AROUND_DEG = 150.0
LOOK_AROUND_RATE_DPS = 120.0  # at the swing's peak: PX4's MC_YAWRATE_MAX is 200°/s
LOOK_AROUND_SHARE = 0.7  # of the climb: the fake's yaw trailed the swing by 1-2 s (bench/RESULTS.md, as above)
HANDOVER_ALT_M = 2.0  # the autopilot's takeoff hands over to flighttest's offboard climb from this height
HEARTBEAT_WAIT_S = 2.5  # two and a half heartbeat periods: one lost heartbeat is not a lost link
HEALTH_PROGRESS_S = 10.0  # while waiting for the vehicle's health, a progress line this often
# settled: within this of the hover point, this slow (PX4's estimate wanders 0.3-0.8 m and its velocity
# is off by 0.1-0.2 m/s: ../shared/px4_sih; tighter and a real vehicle never settles)
SETTLE_TOL_M = 0.6
SETTLE_SPEED_MPS = 0.25
SETTLE_WINDOW_S = 1.0  # … or its position moved that slowly over this window (flighttest.flying.settling)
# a trajectory longer than this outlasts the battery (flighttest.inputs): a damaged file, not a flight,
# and resampling it at the setpoint rate could need more memory than there is
MAX_TRAJECTORY_S = MAX_DURATION_S
# the progress line at the start of each phase (the climb's and the second settle's are made where they start)
PROGRESS = {Phase.PREFLIGHT: "connected: preflight checks", Phase.ARM: "arming",
            Phase.TAKEOFF: "taking off", Phase.SETTLE: "settling at the start point",
            Phase.STREAM: "descent started", Phase.LAND: "landing", Phase.LANDED: "landed and disarmed",
            Phase.HOLD: "holding at the end point"}  # fmt: skip
# while PX4 flies itself (its takeoff, its Land) telemetry missing longer than this starts the ladder
LAND_STALE_S = gd.AUTOPILOT_STALE_S
PARAMS_TIMEOUT_S = 3.0  # the preflight parameter snapshot may delay a flight by at most this
RATE_WAIT_S = 10.0  # the preflight waits this long at most for the telemetry rate it asked for


class _Refused(Exception):
    pass


# builds the (unopened) link a flight flies through, from its .tlog path and the runner's event sink
LinkFactory = Callable[[Path, Callable[[str, dict[str, Any]], None]], Link]


def _healthy(st) -> bool:
    return bool(st.health) and all(st.health.values())


READY_POSVEL_AGE_S = 0.5  # the local position counts as flowing when a sample is at most this old


def _ready(st, now_s: float) -> bool:
    """Healthy, and the estimator's local position flowing: ArduCopter reports its sensors healthy ~25 s
    before its EKF has an origin and sends LOCAL_POSITION_NED at all (../shared/ardupilot_sitl, SITL)."""
    return _healthy(st) and st.t_posvel is not None and now_s - st.t_posvel <= READY_POSVEL_AGE_S


class MissionRunner:
    def __init__(self, req: FlyRequest, open_link: LinkFactory | None = None) -> None:
        self.req = req
        self.open_link = open_link or self._vehicle_link
        self.cfg = req.config
        self.fl = req.config.flight
        self.mission_name = req.mission_name
        self.phase: str = Phase.INIT
        self.rules: AutopilotRules = PX4_RULES  # the vehicle's autopilot's, once it answered
        self.link: Link | None = None
        self.streamer: SetpointStreamer | None = None
        self.log: FlightLogWriter | None = None
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
        self.watch = FlightWatch(self.guard, self)
        prior = None
        if req.wind_ned_mps is not None:
            sd = PRIOR_SD_MPS if req.wind_sd_mps is None else req.wind_sd_mps
            prior = WindEstimate(tuple(float(x) for x in req.wind_ned_mps), sd, "operator")
        self.wind = WindSources.for_flight(req.profile.drag, req.profile.mass_kg, prior, self.cfg.guard.gust_sd_mps)
        self.ground = GroundEvidence()  # the arm and takeoff commands: "on the ground" needs evidence after them
        self.ground_alt_m = 0.0  # the estimate's height of the ground, as seen at arming
        self.ladder_run = LadderExecutor(self.ladder, self.cfg.abort, self.fl.rate_hz, self.limits.stale_after_s,
                                         self, lambda: self.log.t0_mono)  # fmt: skip
        self.pauses = FlightPauses(self.event)
        self.floor_active = False
        check_duration(req.trajectory)
        self.traj = req.trajectory.resample(self.fl.rate_hz)
        self.stream_traj = self.traj  # what is sent: the plan with the autopilot's feed-forward (preflight)
        self.stream_wind_ned: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the wind its feed-forward carries
        self.origin: tuple[float, float, float] | None = None
        self.end_point: tuple[float, float, float] | None = None
        self.t_stream_start: float | None = None
        self.expect_offboard = False
        self.abort_event = asyncio.Event()
        self.abort_verdict = ""
        self._bg: list[asyncio.Task] = []
        self._signals = 0
        self.connected = False  # an autopilot answered: from then on the log folder is kept
        self.panel = None  # the live panel while flying from a terminal
        self.preflight: PreflightResult | None = None
        self.ff = Feedforward()  # the autopilot's feed-forward corrections, once its parameters are read

    # -- helpers -------------------------------------------------------------------------------------
    @staticmethod
    def now() -> float:
        """The runner's clock: its event loop's (``time.monotonic`` in flight, virtual in the runner's
        tests, ``sitl_fakes.virtual_time``); every time the runner keeps or compares is on it."""
        try:
            return asyncio.get_running_loop().time()
        except RuntimeError:  # a decision judged outside a loop (tests of one listener)
            return time.monotonic()

    def event(self, name: str, **fields: Any) -> None:
        if self.log is not None:
            self.log.event(self.now(), name, **fields)

    def set_phase(self, phase: str) -> None:
        settled_before = self.phase == Phase.STREAM
        self.phase = phase
        self.event("phase", phase=phase)
        text = PROGRESS.get(phase)
        if phase == Phase.SETTLE and settled_before:
            text = "descent flown: settling at the end point"
        if phase == Phase.CLIMB:
            text = f"took off: climbing to {self.fl.start_height_m:g} m in {self.rules.offboard_mode}"
        if text:
            self.progress(text)

    def progress(self, text: str) -> None:
        """A line of what the flight is doing, where no live panel shows it (no terminal, ``--json``)."""
        if self.panel is None and self.log is not None:
            self.req.print_fn(f"[{self.now() - self.log.t0_mono:6.1f} s] {text}")

    def abort(self, reason: str, first: gd.Rung = gd.Rung.RECOVER, verdict: str = "") -> None:
        """Start (or join) the abort ladder; safe to call from any callback on the loop."""
        if self.ladder.done:
            return
        first_time = not self.ladder.active
        cmd = self.ladder.trigger(self.now(), reason, first)
        if first_time:
            self._aborted(reason, verdict)
        if cmd:
            self.ladder_run.queue(cmd)
        self.abort_event.set()

    def _aborted(self, reason: str, verdict: str) -> None:
        self.abort_verdict = verdict
        self.guard.armed = False  # decisions keep being logged; the ladder is in charge now
        self.event("abort", reason=reason, rung=self.ladder.rung.name, phase=self.phase)
        self.progress(f"ABORT in {self.phase}: {reason}")

    def takeover(self, reason: str, mode: str) -> None:
        """A pilot has the sticks (``mode``): the run ends here and nothing more is sent, queued or not."""
        if self.ladder.active:
            return
        self.ladder.reason = reason
        self.ladder.finish(self.now(), f"pilot in control ({mode})")
        self._aborted(reason, "pilot")
        self.abort_event.set()

    def follow_autopilot(self, reason: str) -> None:
        """The autopilot lands or returns by itself (a failsafe): the ladder follows it, sending nothing."""
        if self.ladder.active:
            return
        self.ladder.follow(self.now(), reason)
        self._aborted(reason, "autopilot")
        self.abort_event.set()

    def on_ground(self) -> str | None:
        """Why the vehicle is on the ground, armed or not, from evidence (``flighttest.flying.ground``), or None."""
        return self.ground.on_ground(self.link.state, self.now()) if self.link is not None else "never connected"

    def disarmed(self) -> str | None:
        """Why the vehicle is disarmed on the ground, from evidence, or None."""
        return self.ground.disarmed(self.link.state, self.now()) if self.link is not None else "never connected"

    @property
    def last_decision(self) -> gd.Decision | None:
        """The guard's latest decision (the live panel, the ladder's "region ok")."""
        return self.watch.last_decision

    @property
    def descent_time_s(self) -> float | None:
        return self.watch.descent_time_s

    def _every_tick(self) -> None:
        """Housekeeping at every stale-ticker period: a young collection if due, the log flushed if due."""
        self.pauses.tick()
        if self.log is not None:
            self.log.flush_if_due()

    def _vehicle_link(self, tlog_path: Path, on_event: Callable[[str, dict[str, Any]], None]) -> Link:
        """The real link: MAVSDK to ``--connect``, with its .tlog recorder."""
        req = self.req
        return VehicleLink(req.connect, sysid=req.sysid, tlog_path=tlog_path, telemetry_hz=self.fl.telemetry_hz,
                           connect_timeout_s=self.fl.connect_timeout_s, on_event=on_event)  # fmt: skip

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

    # -- the run -------------------------------------------------------------------------------------
    async def run(self) -> FlightOutcome:
        req = self.req
        self.log = FlightLogWriter(req.log_root, self.mission_name, clock=self.now)
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
                loop.add_signal_handler(sig, self.interrupt, sig.name)
        outcome: FlightOutcome | None = None
        try:
            outcome = await self._run_linked()
        except _Refused as exc:
            outcome = self._outcome(Outcome.REFUSED, str(exc))
        except FlighttestError as exc:
            outcome = self._outcome(Outcome.REFUSED, str(exc))
        except Exception as exc:  # a bug or a library's surprise: logged in full, one line for the user
            self.event("exception", error=repr(exc), traceback=traceback.format_exc())
            outcome = self._outcome(Outcome.ABORTED, self.ladder.reason or f"internal error: {exc!r}")
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                    loop.remove_signal_handler(sig)
            if outcome is None:  # cancelled: still leave a summary
                outcome = self._outcome(Outcome.ABORTED, self.ladder.reason or "internal error")
            self.event("end", outcome=outcome.outcome, reason=outcome.abort_reason)
            if not self.connected or outcome.outcome == Outcome.REFUSED:
                # never armed: no flight, so no flight folder (`analyse logs/` would list it as one); a refused
                # preflight travels in the outcome (summary "preflight") and was printed
                self.log.discard()
                outcome.log_dir = None
            else:
                self._write_summary(outcome)
        return outcome

    def _write_summary(self, outcome: FlightOutcome) -> None:
        """``summary.json`` last, saying whether every write before it succeeded; a log that could not be
        completed is said on the console too (the disk may be full: nothing here may raise)."""
        log = self.log
        outcome.extra.update(log.log_state())
        try:
            log.write_summary(outcome.summary())
        except OSError as exc:
            log.write_failed(exc)
            outcome.extra.update(log.log_state())
        log.close()
        if not log.complete:
            self.req.print_fn(f"the flight log in {log.dir} is incomplete: {log.write_errors} write(s) failed "
                              f"(first: {log.first_error})")  # fmt: skip

    def interrupt(self, name: str = "SIGINT") -> None:
        """What the operator's Ctrl-C (or SIGTERM) does: the first aborts (the ladder from Recover), each
        further one skips to the next rung."""
        self._signals += 1
        self.event("signal", signal=name, count=self._signals)
        if self.ladder.active:
            self.ladder_run.queue(self.ladder.escalate(self.now(), f"{name} again"))
        else:
            self.abort(f"{name} from the operator", verdict="signal")

    def _outcome(self, outcome: Outcome, reason: str | None) -> FlightOutcome:
        extra: dict[str, Any] = {"mission": self.mission_name, "phase_at_end": self.phase}
        if self.streamer is not None:
            j = self.streamer.jitter()
            extra.update(setpoint_jitter_p99_ms=j["p99_ms"], setpoint_rate_hz=j["rate_hz"],
                         setpoints_sent=self.streamer.sent, watchdog_fired=self.streamer.watchdog_fired)  # fmt: skip
        if self.link is not None:
            st = self.link.state
            extra.update(final_armed=st.armed, final_landed_state=st.landed_state, final_alt_m=st.alt_m,
                         **final_mode(st.flight_mode, st.armed, self.watch.mode_while_armed))  # fmt: skip
        extra["horizontal_error_m"] = self.watch.horizontal_error_m
        extra["main_descent"] = main = self._main_descent()
        extra["planned_descent_s"] = main["planned_descent_s"]
        main.update(self._efficiency(outcome))
        extra.update({k: main[k] for k in EFFICIENCY_KEYS})
        if self.link is not None:
            extra.update(self.watch.wind().describe())
        if self.ladder.history:
            extra["ladder"] = [{"t_s": round(t - self.log.t0_mono, 3), "rung": r, "why": w}
                               for t, r, w in self.ladder.history]  # fmt: skip
        if self.abort_verdict:
            extra["abort_verdict"] = self.abort_verdict
        if self.preflight is not None:
            extra["preflight"] = self.preflight.to_dict()
        return FlightOutcome(outcome, reason, self.watch.descent_time_s, str(self.log.dir), extra)

    def _efficiency(self, outcome: Outcome) -> dict[str, Any]:
        """Hover to hover against the planner's optimum for the plan flown (``flighttest.planner.optimum``): held
        in the plan since the preflight, or solved now for a plan the start hover chose for the wind."""
        optimum = None
        if outcome != Outcome.REFUSED and self.t_stream_start is not None:
            try:
                optimum = optimum_for(self.traj, self.req.profile, self.req.print_fn)
            except Exception as exc:  # the flight is flown: no optimum is no reason to lose its summary
                self.event("optimum_failed", error=repr(exc))
        return efficiency(self.watch.hover_to_hover_s, optimum.optimum_s if optimum is not None else None)

    def _main_descent(self) -> dict[str, Any]:
        """The main descent as the live timer saw it (``flighttest.analysis.descent_time``: what the
        analysis of this folder gives too), times on the log's clock, beside the plan timed by the same rule."""
        df = self.traj.df
        planned = dtime.planned_descent(df["t_s"], df["n_m"], df["e_m"], df["d_m"], df["vd_mps"])
        timer = self.watch.descent_timer
        flown = timer.flown() if timer is not None else None
        if self.t_stream_start is None:
            note = "the flight never began its descent"
        elif timer is None:
            note = "the trajectory returns to its start: no descent to time"
        elif flown is None or flown.reached is None:
            after = Phase.LAND if self.fl.land else Phase.HOLD  # what ends the descent's phases (window())
            note = dtime.not_reached(timer.rule, "the abort" if self.ladder.history else f"the {after} phase")
        else:
            note = None
        t0, unix0 = self.log.times(self.t_stream_start) if self.t_stream_start is not None else (0.0, None)
        rec = dtime.main_descent_record(flown, planned, start_unix_s=unix0, ground_alt_m=self.ground_alt_m,
                                        note=note)  # fmt: skip
        if flown is not None:  # the log's clock, as events.jsonl has it
            rec["start_s"], rec["end_s"] = round(t0, 3), round(t0 + flown.duration_s, 3)
        # samples are timed here as they arrive (tens of ms of jitter on a loaded machine, 0.15 m/s on a 0.2 s
        # rate); the analysis has the vehicle's own clock in the tlog and gives the max rate
        rec["max_rate_mps"] = None
        return rec

    async def _run_linked(self) -> FlightOutcome:
        req = self.req
        link = self.open_link(self.log.tlog_path, lambda n, f: self.event(n, **f))
        self.link = link
        self.set_phase(Phase.CONNECT)
        connect_task = asyncio.create_task(link.open())
        try:
            await self._race(connect_task)
        except BaseException:
            await link.close()
            raise
        self.connected = connect_task.done() and not connect_task.cancelled()
        if self.connected:
            self.rules = link.rules
            self.ladder.rules = link.rules
            self.event("autopilot", **link.rules.describe())
        if self.ladder.active:  # Ctrl-C while connecting
            await link.close()
            return self._outcome(Outcome.ABORTED, self.ladder.reason)
        try:
            self.pauses.freeze()  # connected, nothing flying yet: the one long collection goes here
            self.streamer = SetpointStreamer(link.offboard_setters(), self.log, self.fl.rate_hz,
                                             here=lambda: (link.state.n_m, link.state.e_m, link.state.d_m),
                                             clock=self.now)  # fmt: skip
            self.ladder_run.bind(link, self.streamer)
            self.watch.attach(link)
            self._bg.append(asyncio.create_task(self.watch.stale_ticker(self._every_tick)))
            panel = None
            if req.show_panel:
                from flighttest.console import console
                from flighttest.flying.panel import LivePanel

                panel = LivePanel(self, console)
            self.panel = panel
            with panel if panel is not None else contextlib.nullcontext():
                return await self._fly()
        finally:
            await self._shut_down(link)

    async def _shut_down(self, link: Link) -> None:
        """Every step, whatever the one before it did: the link is always closed (MAVSDK destroyed)."""

        async def background() -> None:
            for t in self._bg:
                t.cancel()
            await asyncio.gather(*self._bg, return_exceptions=True)

        async def watchdog() -> None:
            if self.streamer is not None:
                self.streamer.stop_watchdog()

        async def pauses() -> None:
            self.pauses.restore()

        for name, step in (("background tasks", background), ("ladder", self.ladder_run.close),
                           ("setpoint watchdog", watchdog), ("link", link.close), ("collector", pauses)):  # fmt: skip
            try:
                await step()
            except Exception as exc:
                self.event("shutdown_error", step=name, error=repr(exc))

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
            return self._outcome(Outcome.ABORTED, self.ladder.reason)
        if req.dry_run:
            self.set_phase(Phase.DRY_RUN)
            return self._outcome(Outcome.DRY_RUN, None)
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
            first = gd.Rung.LAND if self.phase == Phase.LAND else gd.Rung.RECOVER
            self.abort(f"error: {exc}", first, verdict="exception")
            result = None
        if not self.ladder.active and result is not None:
            return result
        await self.ladder_run.run()
        outcome = Outcome.ABORTED
        if self.cfg.mission == "probe" and self.abort_verdict in (gd.FLUCTUATION, gd.SPEED_CAP, gd.FLOOR):
            outcome = Outcome.PROBE_STOPPED
        return self._outcome(outcome, self.ladder.reason)

    async def _wait_for_health(self, timeout_s: float) -> None:
        """A vehicle that has just booted (ArduCopter SITL: 42 s until its EKF uses GPS) or landed (the
        campaign's next flight; PX4 SITL: more than 10 s) is not armable for a while: wait for it, saying
        what is missing every ``HEALTH_PROGRESS_S``, before the preflight judges it."""
        link = self.link
        t0 = self.now()

        def not_ok() -> list[str]:
            bad = sorted(k.removeprefix("is_") for k, v in link.state.health.items() if not v)
            if not _ready(link.state, self.now()) and not bad and link.state.health:
                bad.append("no local position yet")
            return bad

        self.event("waiting_for_health", not_ok=not_ok(), timeout_s=timeout_s)
        while self.now() - t0 < timeout_s:
            wait_s = min(HEALTH_PROGRESS_S, timeout_s - (self.now() - t0))
            if await link.wait_for(lambda st: _ready(st, self.now()), wait_s):
                self.event("healthy", after_s=round(self.now() - t0, 1))
                return
            missing = ", ".join(not_ok()) or "health not reported"
            self.req.print_fn(f"waiting for the vehicle to be ready ({missing}): {self.now() - t0:.0f} s "
                              f"of at most {timeout_s:.0f} s")  # fmt: skip

    async def _leave_mode(self, modes: frozenset[str], why: str) -> None:
        """Disarmed in one of ``modes``: ask for the autopilot's armable mode, and wait a heartbeat or two
        for the answer to show (a refusal shows as the mode staying; the caller judges that)."""
        link, rules = self.link, self.rules
        mode = link.state.flight_mode
        if link.state.armed or mode not in modes:
            return
        self.event("mode_reset", old=mode, new=rules.armable_mode, why=f"disarmed in {mode}: {why}")
        with contextlib.suppress(Exception):
            if rules.armable_mode == rules.hold_mode:
                await link.hold(5.0)
            else:
                await link.set_mode(rules.armable_mode, 5.0)
        await link.wait_for(lambda s: s.flight_mode not in modes, 3.0)

    async def _preflight(self) -> PreflightResult:
        self.set_phase(Phase.PREFLIGHT)
        link, req = self.link, self.req
        # the mode too: read before its first heartbeat arrived, "UNKNOWN" left ArduCopter in STABILIZE, not asked
        # to leave it, and the preflight failed on it (CI of 5b3ce63, a busy box)
        await link.wait_for(lambda s: s.t_posvel is not None and s.t_att is not None and bool(s.health)
                            and s.flight_mode != "UNKNOWN", 5.0)  # fmt: skip
        rules = self.rules
        # the campaign's next flight on the same vehicle: PX4 stays in Offboard after an offboard flight
        # lands, ArduCopter in LAND; neither arms from there (autopilot.AutopilotRules.not_armable_modes)
        await self._leave_mode(rules.not_armable_modes, "is not armable")
        if not _ready(link.state, self.now()):
            await self._wait_for_health(rules.health_wait_s)
        # a pilot's mode before arming (ArduCopter boots in STABILIZE, PX4 may sit in Position): from the arm
        # on, a pilot's mode means a takeover (flighttest.flying.watch), so the flight starts from another
        await self._leave_mode(rules.pilot_modes, "is a pilot's mode")
        await asyncio.sleep(1.0)  # a second of telemetry to measure its rate
        # ArduCopter SITL took seconds to send the rate asked of it on a second connection (21 Hz of 50 in the
        # last second before the check): wait for it, bounded; still short, the check says so
        await link.wait_for(lambda s: telemetry_rates_ok(s, self.now(), self.fl.telemetry_hz), RATE_WAIT_S)
        # judged now: reading every parameter below takes the link's bandwidth for a moment (ArduCopter SITL's
        # 1354 over TCP: 23 Hz of telemetry in the second after)
        checks = vehicle_checks(link.state, self.now(), self.fl.telemetry_hz, self.fl.min_battery_percent)
        # every parameter, read once and bounded (a slow link must not hold the flight up): the checks take
        # theirs from it; without it each is asked for alone (a name the firmware lacks waits out a timeout)
        from flighttest.analysis.params import snapshot

        all_params, note = None, None
        try:
            all_params = await link.get_all_params(PARAMS_TIMEOUT_S) or None
            note = None if all_params else "the vehicle sent no parameters; kept the preflight check's"
        except Exception as exc:
            note = f"reading all parameters failed ({exc}); kept the preflight check's"
        params: dict[str, Any] = {}
        wanted = ARDUPILOT_PARAMS if rules.name == ARDUPILOT else ABORT_PARAMS
        for name, kind in wanted.items():
            params[name] = all_params.get(name) if all_params else await link.get_param(name, kind)
        if rules.name == ARDUPILOT and all_params:  # older firmware's names of the GUIDED limits too
            params.update({n: all_params[n] for names in (*ARDUPILOT_LIMITS.values(), ARDUPILOT_TILT,
                                                          ARDUPILOT_POS_TILT)
                           for n, _ in names if n in all_params})  # fmt: skip
            await self._plan_within(ardupilot_limits(params), ARDUPILOT)
        elif rules.name != ARDUPILOT:
            await self._plan_within(px4_limits(all_params or params), rules.name)
        # the parameter snapshot of this flight (params.json): everything relevant; else the values just read
        snap = snapshot(all_params, params, await link.autopilot_name(), time.time(), note)
        try:
            self.log.write_params(snap)
            self.event("params", source=snap["source"], kept=len(snap["params"]), read=snap["params_read"], note=note)
        except OSError as exc:
            self.event("warning", what=f"params.json not written ({exc})")
        self.ff = self._feedforward(all_params, await link.autopilot_name())
        self.stream_wind_ned = self.watch.wind_ned_mps()
        self.stream_traj = for_autopilot(self.traj, self.ff, self.stream_wind_ned)
        accel = max(0.5 * req.profile.max_accel_up_mps2, 0.5)
        stats = trajectory_stats(self.traj, self.limits.region, accel, self.ff.drag_per_s, self.watch.wind_ned_mps())
        ab = self.cfg.abort
        checks.append(mode_check(link.state.flight_mode, rules))
        wind = self.watch.wind()
        checks.append(wind_check(math.hypot(*wind.ned_mps[:2]), wind.sd_mps, wind.source, self.fl.max_wind_mps))
        checks.append(ground_height_check(link.state.alt_m))
        checks.append(disk_check(self.log.dir, self.traj.duration_s + 120.0, self.fl.telemetry_hz))
        if rules.name == ARDUPILOT:
            checks += ardupilot_param_checks(params, stats, req.profile.w_allow_mps, GCS_SYSID, ab.recovery_climb_mps)
        else:
            checks += param_checks(params, stats.descent_max_mps, req.profile.w_allow_mps,
                                   self.fl.start_height_m + stats.rise_max_m)  # fmt: skip
        checks += trajectory_checks(stats, req.profile, self.fl.start_height_m, self.fl.min_alt_m,
                                    self.fl.geofence_radius_m, ab.recovery_lateral_mps * ab.recovery_s,
                                    self.cfg.guard.observe_region)  # fmt: skip
        pre = PreflightResult(checks)
        self.preflight = pre
        try:
            self.log.write_preflight({**pre.to_dict(), "params": params, "trajectory": stats.__dict__})
        except OSError as exc:  # before arming: a flight whose log cannot be written does not start
            raise _Refused(f"cannot write the flight log in {self.log.dir} ({exc.strerror or exc})") from None
        self.event("preflight", ok=pre.ok, failures=[c.name for c in pre.failures])
        return pre

    async def _plan_within(self, live: dict[str, LiveLimit], autopilot: str) -> None:
        """Plan the mission again within the vehicle's own limits (ArduCopter's GUIDED shaping, PX4's vertical
        speeds) where they differ from the profile's (``flighttest.flying.live_limits``): a limit raised for the
        test day lets the plan go faster, one lowered keeps it flyable. Where only PX4's differ, the plans stand
        and their optimum is made again for the vehicle as it is. A trajectory file is flown as it is, and the
        preflight judges it against the vehicle's own limits."""
        req = self.req
        profile, diffs = with_live_limits(req.profile, live, autopilot)
        if not diffs:
            return
        if req.replan is None:
            self.event("live_limits", changed=diffs, replanned=False)
            req.profile = profile
            return
        if not plans_bound(req.profile, profile):
            # the yardstick is the vehicle's: an optimum faster than its autopilot lets it fly is not one
            # (PX4's helix optimum 2.90 s without MPC_Z_VEL_MAX_DN, 3.96 s within its 1.5 m/s: bench/RESULTS.md)
            self.event("live_limits", changed=diffs, replanned=False)
            for traj in (req.trajectory, self.traj, *req.wind_plans):
                traj.meta.pop(OPTIMUM_KEY, None)
            req.profile = profile
            try:
                await asyncio.to_thread(with_optimum, req.trajectory, profile, req.print_fn)
            except Exception as exc:  # no yardstick is no reason to refuse the flight
                self.event("optimum_failed", error=repr(exc))
            if OPTIMUM_KEY in req.trajectory.meta:
                self.traj.meta[OPTIMUM_KEY] = req.trajectory.meta[OPTIMUM_KEY]
            try:
                self.log.save_trajectory(req.trajectory)
            except OSError as exc:
                raise _Refused(f"cannot write the flight log in {self.log.dir} ({exc.strerror or exc})") from None
            return
        self.event("live_limits", changed=diffs, replanned=True)
        self.progress(f"the vehicle's own limits differ from the profile's: {'; '.join(diffs)}: planning within them")
        try:
            traj, wind_plans = await asyncio.to_thread(req.replan, profile)
        except Exception as exc:  # the planner's failure, whatever it raised: one line, nothing armed
            raise _Refused(f"no plan within the vehicle's own limits ({'; '.join(diffs)}): {exc}") from None
        check_duration(traj)
        req.profile, req.trajectory, req.wind_plans = profile, traj, wind_plans
        self.traj = self.stream_traj = traj.resample(self.fl.rate_hz)
        try:
            self.log.save_trajectory(traj)
        except OSError as exc:
            raise _Refused(f"cannot write the flight log in {self.log.dir} ({exc.strerror or exc})") from None
        self.event("replanned", t_f_s=round(traj.duration_s, 3), wind_plans=len(wind_plans),
                   autopilot=profile.autopilot.summary() if profile.autopilot else None)  # fmt: skip

    # -- nominal flow ------------------------------------------------------------------------------
    async def _nominal(self) -> FlightOutcome | None:
        """The nominal flow; returns None once an abort has started (the ladder takes over)."""
        link, fl = self.link, self.fl
        st = link.state
        H = fl.start_height_m
        self.pauses.hold_off()
        # every height of the flight counts from where the estimate puts the ground at arming: after a landing
        # it may sit tenths of a metre off home (the preflight's "height on the ground" says how far)
        self.ground_alt_m = st.alt_m if math.isfinite(st.alt_m) else 0.0
        self.event("ground", alt_m=round(self.ground_alt_m, 3))
        self.set_phase(Phase.ARM)
        self.guard.armed = True
        await self._ground_command(link.arm(10.0), 10.0)
        self.event("armed")
        self.set_phase(Phase.TAKEOFF)
        with contextlib.suppress(Exception):
            # ArduCopter's takeoff ends where asked and holds there: asked for the start height it is still
            # climbing fast at the handover and overshoots (bench/RESULTS.md, "The fake's ArduCopter personality")
            await link.set_takeoff_altitude(min(H, HANDOVER_ALT_M) if self.rules.takeoff_to_handover else H, 5.0)
        await self._ground_command(link.takeoff(10.0), 10.0)
        handover_m = min(H, HANDOVER_ALT_M)
        ground_m = self.ground_alt_m
        ok = await link.wait_for(lambda s: s.alt_m - ground_m >= handover_m - 0.3 and s.in_air, fl.takeoff_timeout_s)
        if not ok:
            raise RuntimeError(f"takeoff did not reach {handover_m:.1f} m within {fl.takeoff_timeout_s:g} s")
        # a pilot's switch during the takeoff shows with the next heartbeat (1 Hz): one more before offboard
        # starts, so that flighttest never takes a vehicle from the sticks (flighttest.flying.watch)
        t_reached = self.now()
        if not await link.wait_for(lambda s: s.t_armed is not None and s.t_armed > t_reached, HEARTBEAT_WAIT_S):
            raise RuntimeError(f"no heartbeat within {HEARTBEAT_WAIT_S:g} s at the handover height")
        if self.ladder.active:
            return None
        # offboard from here: climb to the exact start point, holding the trajectory's initial yaw
        self.set_phase(Phase.CLIMB)
        yaw0 = float(self.traj.df["yaw_deg"].iloc[0])
        here = Setpoint(st.n_m, st.e_m, st.d_m, yaw_deg=yaw0)
        self.streamer.send(here, Phase.CLIMB)
        loop = asyncio.get_running_loop()
        if link.realtime:  # a thread on the wall clock: it cannot judge a virtual stream
            self.streamer.start_watchdog(lambda: loop.call_soon_threadsafe(lambda: self.event("setpoint_watchdog")))
        self.expect_offboard = True
        await link.start_offboard(10.0)
        self.event("offboard", active=True)
        start = (st.n_m, st.e_m, -(self.ground_alt_m + H))
        d0 = st.d_m
        n_climb = max(int(abs(start[2] - d0) / CLIMB_RATE_MPS * fl.rate_hz), 1)

        # the swing ends before the climb does: the heading has settled when the hover's baseline begins. Only
        # before a descent, which the hover judges in the wind (a trajectory file's too: ± 0.20 m/s without the
        # swing on ArduCopter SITL, ± 0.10 with it: bench/RESULTS.md, "One change at a time, the climb's turn ...");
        # a probe, which returns to its start, holds its heading: the swing left the yaw ringing into the hover
        # identify references (its onset's uncertainty 0.07 → 0.35-0.45 m/s: bench/RESULTS.md, as above)
        n_look = max(int(LOOK_AROUND_SHARE * n_climb), 1)
        descends = bool(self.req.wind_plans) or dtime.goes_somewhere(self.traj.df[["n_m", "e_m", "d_m"]].iloc[-1])
        look_deg = look_around_deg(n_look / fl.rate_hz) if descends else 0.0

        def climb_at(k: int) -> Setpoint | None:
            if k > n_climb:
                return None
            f = k / n_climb
            # the heading swings out and back: the accelerometer's bias turns with the body, the wind does
            # not, so the wind filter tells them apart before the start hover judges the air
            yaw = yaw0 + look_deg * 0.5 * (1.0 - math.cos(2.0 * math.pi * min(k / n_look, 1.0)))
            return Setpoint(start[0], start[1], d0 + f * (start[2] - d0), yaw_deg=yaw)

        await self.streamer.stream(climb_at, Phase.CLIMB, lambda: self.ladder.active)
        if self.ladder.active:  # the ladder owns the vehicle now: this flow must not send anything
            return None
        self.set_phase(Phase.SETTLE)
        hold = Setpoint(*start, yaw_deg=yaw0)
        await self._settle(hold, fl.settle_s, fl.settle_s * 3 + 10.0, baseline=True)
        if self.ladder.active or not self._plan_for_wind():
            return None
        self.origin = start
        last = self.traj.df.iloc[-1]
        if dtime.goes_somewhere((last["n_m"], last["e_m"], last["d_m"])):
            # a descent time only where the trajectory goes somewhere (the probe returns to its start)
            self.end_point = (start[0] + last["n_m"], start[1] + last["e_m"], start[2] + last["d_m"])
        self.set_phase(Phase.STREAM)
        self.floor_active = True
        self.t_stream_start = self.now()
        if self.end_point is not None:
            self.watch.descent_timer = dtime.DescentTimer(self.t_stream_start, self.end_point)
            self.watch.hover_timer = dtime.DescentTimer(self.t_stream_start, self.end_point, dtime.HOVER_RULE)
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
        an, ae, _ = hold_accel_ned(self.traj, self.ff, self.stream_wind_ned)
        end_sp = dataclasses.replace(end_sp, an_mps2=an, ae_mps2=ae)
        self.set_phase(Phase.SETTLE)
        # hover on until the descent counts as reached, vertically and hover to hover (their rules are stricter
        # than settling: an overshoot of the end height settles before it is back within 0.2 m), or time out
        timers = [t for t in (self.watch.descent_timer, self.watch.hover_timer) if t is not None]
        await self._settle(end_sp, fl.settle_s, fl.settle_s * 3 + 10.0, must_settle=False,
                           also=lambda: all(t.result is not None for t in timers))  # fmt: skip
        if self.ladder.active:
            return None
        self.floor_active = False
        self.expect_offboard = False
        if fl.land:
            self.set_phase(Phase.LAND)
            self.guard.armed = False  # landing below the floor is the point; stale/link still end it
            await link.land(10.0)
            ok = await link.wait_for(lambda s: self.disarmed() is not None, max(H, 1.0) / 0.5 + 30.0)
            if not ok:
                raise RuntimeError("did not land and disarm in time")
            self.set_phase(Phase.LANDED)
        else:
            self.set_phase(Phase.HOLD)
            rules = self.rules
            await (link.stop_offboard(10.0) if rules.hold_by_offboard_stop else link.hold(10.0))
            if not await link.wait_for(lambda s: s.flight_mode == rules.hold_mode, 5.0):
                raise RuntimeError(f"{rules.hold_mode.title()} not confirmed after the flight (--no-land)")
        return self._outcome(Outcome.COMPLETED, None)

    def _plan_for_wind(self) -> bool:
        """In the start hover, the plan for the wind measured there (flighttest.flying.wind): the fastest of the
        mission's own and those made ahead for winds (turned to this wind's direction) that the guard will
        find clear of its region at the worst air the wind's uncertainty allows. None clear, or more wind than
        ``max_wind_mps``: the ladder from Hold, before the descent."""
        wind, prof = self.watch.wind(), self.req.profile
        speed = math.hypot(*wind.ned_mps[:2])
        said = f"{speed:.1f} ± {wind.sd_mps:.2f} m/s ({wind.source})"
        if speed > self.fl.max_wind_mps:
            self.abort(f"wind at the start {said}: above max_wind_mps {self.fl.max_wind_mps:g} m/s", gd.Rung.HOLD,
                       "wind")  # fmt: skip
            return False
        heading = math.atan2(wind.ned_mps[1], wind.ned_mps[0])
        cands = [self.req.trajectory]
        for plan in self.req.wind_plans:  # made for the wind along +east
            cands.append(rotate_plan(plan, heading - math.pi / 2))
        judged = []
        for c in cands:
            margin, at = plan_margin_in_wind(c, self.limits.region, prof.drag, prof.mass_kg, wind)
            planned = (c.meta.get("problem") or {}).get("wind_ned_mps") or [0.0, 0.0, 0.0]
            judged.append((c, margin, {"planned_wind_mps": round(math.hypot(*planned[:2]), 2),
                                       "duration_s": round(c.duration_s, 2), "margin_mps": round(margin, 3),
                                       "at_s": round(at, 2)}))  # fmt: skip
        clear = [j for j in judged if j[1] >= 0.0 or self.cfg.guard.observe_region]
        self.event("wind_plan", **wind.describe(), candidates=[x for *_, x in judged])
        if not clear:
            best = max(judged, key=lambda j: j[1])
            gusts = f", updrafts to {wind.updraft_mps:.2f} m/s allowed for its gusts" if wind.updraft_mps else ""
            self.abort(f"no plan clears the guard region in the wind at the start, {said}{gusts} (best margin "
                       f"{best[1]:.2f} m/s)", gd.Rung.HOLD, "wind")  # fmt: skip
            return False
        # the fastest that keeps, in this air, the tracking margin it was planned with (a plan for another wind
        # judged clear by less flies into the guard: bench/RESULTS.md, "Plans for the wind"); else the clearest
        keeps = [j for j in clear if j[1] >= _tracking_margin_mps(j[0], self.limits.region.margin_mps)]
        if keeps:
            chosen, _, info = min(keeps, key=lambda j: j[0].duration_s)
        else:
            chosen, _, info = max(clear, key=lambda j: j[1])
        self.progress(f"wind {said}: flying the plan for {info['planned_wind_mps']:g} m/s of wind")
        if chosen is not self.req.trajectory:
            check_duration(chosen)
            self.traj = chosen.resample(self.fl.rate_hz)
            self.log.save_trajectory(chosen)
        self.stream_traj = for_autopilot(self.traj, self.ff, wind.ned_mps)
        self.stream_wind_ned = wind.ned_mps
        return True

    async def _ground_command(self, command: Awaitable[Any], timeout_s: float) -> None:
        """An arm or takeoff command, noted for the ground evidence (``flighttest.flying.ground``): given up on
        before its answer, the vehicle may still act on it until its timeout."""
        t0 = self.now()
        done_t = t0 + timeout_s
        self.ground.command_sent(t0)
        try:
            await command
            done_t = self.now()
        except Exception:
            done_t = self.now()
            raise
        finally:
            self.ground.command_done(done_t)

    async def _settle(self, sp: Setpoint, min_s: float, max_s: float, baseline: bool = False,
                      must_settle: bool = True, also: Callable[[], bool] | None = None) -> None:  # fmt: skip
        """Hover at ``sp`` until settled (and ``also()``); with ``baseline`` the guard's hover
        fluctuation baseline is the settled part of it (the climb's transient is not the hover). Not
        settling within ``max_s`` is an error only where it must (before the descent)."""
        self.pauses.safe_point()  # PX4 holds the position: a pause of a few ms costs nothing here
        st = self.link.state
        t0 = self.now()
        settled_since = None
        check = SettleCheck((sp.n_m, sp.e_m, sp.d_m), SETTLE_TOL_M, SETTLE_SPEED_MPS, SETTLE_WINDOW_S)

        def done() -> bool:
            nonlocal settled_since
            if self.ladder.active:
                return True
            now = self.now()
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


def look_around_deg(climb_s: float) -> float:
    """How far the climb turns the heading (out and back, a raised cosine): ``LOOK_AROUND_DEG``, less where the
    climb is too short to turn that far at ``LOOK_AROUND_RATE_DPS``."""
    return min(LOOK_AROUND_DEG, LOOK_AROUND_RATE_DPS * max(climb_s, 0.0) / math.pi)


def _tracking_margin_mps(traj: Trajectory, region_margin_mps: float) -> float:
    """How far inside the guard's bound the plan was made to stay (its problem's margin over the region's own;
    0 for a file that does not say)."""
    planned = (traj.meta.get("problem") or {}).get("margin_mps")
    if not isinstance(planned, int | float) or not math.isfinite(planned):
        return 0.0
    return max(0.0, float(planned) - region_margin_mps)


def check_duration(traj: Trajectory, what: str = "trajectory") -> None:
    """A finite, bounded duration before anything resamples or streams the trajectory."""
    d = traj.duration_s
    if not (math.isfinite(d) and 0 <= d <= MAX_TRAJECTORY_S):
        raise FlighttestError(f"{what} lasts {d:g} s: a flight's must be finite and at most {MAX_TRAJECTORY_S:g} s")


async def fly(req: FlyRequest) -> FlightOutcome:
    return await MissionRunner(req).run()
