"""Running a campaign's steps: what ``flighttest campaign`` does between its arguments and its summary.

::

    campaign = Campaign.open(CampaignRequest(out_dir=Path("logs/c"), vehicle="x500", sim=SimOptions(), yes=True))
    result = campaign.run(CampaignHooks(say=console.print))
    summary = campaign.summary()

:meth:`Campaign.open` reads the folder and refuses what cannot run (nothing is written);
:meth:`Campaign.run` writes the configs and ``campaign.json``, then runs the steps in order, recording
each one's status (:class:`~flighttest.campaign.state.StepStatus`) whatever ends it. Everything that
talks to the operator — progress lines, the question before each step, each flight's GO — comes in
through :class:`CampaignHooks`, so the loop runs the same under the CLI, a test or another front end.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import signal
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flighttest.campaign.rehearsal import SIM_DEFAULT_PARAMS, SIM_DEFAULT_PARAMS_ARDUPILOT  # noqa: F401 (re-export)
from flighttest.campaign.state import FLIGHT_STEPS, STEPS, TITLES, CampaignState, StepStatus
from flighttest.campaign.steps import RUNNERS, StepContext, StepFailed, write_configs
from flighttest.campaign.summary import known_summary, read_summary
from flighttest.errors import FlighttestError
from flighttest.model.profiles import VehicleProfile, load_profile


def _default_sim_params() -> dict[str, float]:
    return dict(SIM_DEFAULT_PARAMS)


@dataclass(frozen=True)
class SimOptions:
    """The built-in fake vehicle a rehearsal flies (``sitl_fakes.launcher.FakeVehicle``); None: its default."""

    truth_onset_mps: float | None = None
    wind_ned_mps: tuple[float, float, float] | None = None
    seed: int | None = None
    # the autopilot's parameters, ints as ints (PX4's or ArduPilot's names, as ``autopilot`` says)
    params: Mapping[str, float] = field(default_factory=_default_sim_params)
    autopilot: str = "px4"  # the fake's personality: "px4" or "ardupilot" (sitl_fakes --autopilot)

    def launcher_options(self) -> dict[str, Any]:
        """``FakeVehicle``'s keyword options (each one a flag of the fake's process)."""
        opts: dict[str, Any] = {"param": dict(self.params)}
        if self.autopilot != "px4":
            opts["autopilot"] = self.autopilot
        if self.truth_onset_mps is not None:
            opts["truth_onset"] = self.truth_onset_mps
        if self.wind_ned_mps:
            opts["wind_ned"] = tuple(self.wind_ned_mps)
        if self.seed is not None:
            opts["seed"] = self.seed
        return opts


@dataclass(frozen=True)
class CampaignRequest:
    """One run of a campaign, its inputs already checked: exactly one of ``connect`` and ``sim``."""

    out_dir: Path  # the campaign's folder (created on the first run, resumed on the next)
    vehicle: str = "x500"  # the user's profile: name or .toml path (never written to)
    connect: str | None = None  # the vehicle's link URL
    sim: SimOptions | None = None  # fly the fake instead, started at the first flight and stopped at the end
    only: str | None = None  # run just this step, from the files of the earlier ones
    start: str | None = None  # run this step and every one after it
    yes: bool = False  # ask neither before each step nor for each flight's GO
    stale_periods: float | None = None  # the guard's stale-telemetry allowance; None: the mission configs'
    show_panel: bool = False  # each flight's live panel (a terminal that shows only progress)
    build_up: int = 1  # the most flights of each descent, margins narrowed (flighttest.campaign.build_up)

    def __post_init__(self) -> None:
        if (self.connect is None) == (self.sim is None):
            raise ValueError("a campaign flies either a link (connect) or the fake (sim), exactly one")
        for name, step in (("only", self.only), ("start", self.start)):
            if step is not None and step not in STEPS:
                raise ValueError(f"{name}: {step!r} is not a step ({', '.join(STEPS)})")
        if self.only and self.start:
            raise ValueError("only and start exclude each other")
        if isinstance(self.build_up, bool) or not isinstance(self.build_up, int) or self.build_up < 1:
            raise ValueError(f"build_up: the most flights per descent, an integer ≥ 1 (got {self.build_up!r})")


def _not_busy(text: str) -> contextlib.AbstractContextManager[Any]:
    return contextlib.nullcontext()


@dataclass(frozen=True)
class CampaignHooks:
    """The campaign's terminal I/O, supplied by its caller. Text is rich console markup."""

    say: Callable[[Any], None] = print  # a progress line (flights also print their preflight table here)
    heading: Callable[[str], None] = print  # the campaign's title
    step_heading: Callable[[str], None] = print  # each step's title
    busy: Callable[[str], contextlib.AbstractContextManager[Any]] = _not_busy  # around a ground step
    ask_step: Callable[[str], bool] | None = None  # go on with this step? (needed unless request.yes)
    confirm_flight: Callable[[Any], bool] | None = None  # a flight's GO after its preflight checks


@dataclass(frozen=True)
class RunResult:
    steps_done: tuple[str, ...] = ()  # the steps this run completed, in order
    stopped_before: str | None = None  # the operator declined this step: the campaign stopped there


def clock_text(seconds: float) -> str:
    """``m:ss``, the way the campaign shows times."""
    m, s = divmod(round(seconds), 60)
    return f"{m:d}:{s:02d}"


def step_brief(step: str, outputs: dict[str, Any]) -> str:
    """The one line after a step's tick: what it found or flew and where it wrote it."""
    o = outputs
    if step in FLIGHT_STEPS:
        d, plan = o.get("descent_time_s"), o.get("planned_descent_s")
        planned = f" (planned {plan:.2f} s)" if isinstance(plan, int | float) else ""
        return f"{o['outcome']}" + (f", descent {d:.2f} s{planned}" if d else "") + f"; log {o['log_dir']}"
    if step == "identify":
        if o.get("onset_found") is False:
            return f"{o['message']} → {o['profile']}"
        return f"VRS onset {o['w_onset_mps']:.3f} ± {o['uncertainty_mps']:.3f} m/s → {o['profile']}"
    if step == "plan":
        return f"vertical {o['vertical_t_f_s']:.2f} s, helix {o['helix_t_f_s']:.2f} s planned"
    if step == "report":
        return f"{o['report_dir']}"
    return ""


@contextlib.contextmanager
def _stop_after_step(stop: list[str], say: Callable[[Any], None]) -> Iterator[None]:
    """Ctrl-C (or SIGTERM) during a ground step asks to stop after it (IPOPT, inside the planner, would
    swallow the interrupt and go on anyway); a second one stops at once."""

    def on_sigint(signum, frame) -> None:
        if stop:
            raise KeyboardInterrupt
        stop.append("sigint")
        say("[yellow]Ctrl-C: stopping after this step (Ctrl-C again: at once)[/]")

    previous = {sig: signal.signal(sig, on_sigint) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


class Campaign:
    """The campaign in a folder and the steps one run of it takes: open it, then run it."""

    def __init__(self, request: CampaignRequest, profile: VehicleProfile, state: CampaignState,
                 steps: list[str]) -> None:  # fmt: skip
        self.request = request
        self.profile = profile
        self.state = state
        self.steps = steps  # what run() will run, in order
        self.started = False  # campaign.json written by this run: a stop from here on has a summary so far
        self.current_step: str | None = None  # the step begun and not finished (the failed one, after a failure)

    @classmethod
    def open(cls, request: CampaignRequest, profile: VehicleProfile | None = None) -> Campaign:
        """The campaign in ``request.out_dir`` (new or resumed) with the steps this run takes, refused
        (FlighttestError, one line) when the folder holds another vehicle's campaign or the first step's
        inputs are missing. Nothing is written. ``profile``: the vehicle's, if the caller loaded it."""
        profile = profile or load_profile(request.vehicle)
        state = CampaignState.open(request.out_dir, profile.name)
        steps = state.to_run(request.only, request.start)
        state.check_needs(steps)
        return cls(request, profile, state, steps)

    def run(self, hooks: CampaignHooks) -> RunResult:
        """Run the steps, each recorded in ``campaign.json`` as it begins and ends; raises what stopped a
        step (StepFailed, KeyboardInterrupt, anything else) after recording it failed or interrupted."""
        req, state, steps = self.request, self.state, self.steps
        if steps and not req.yes and hooks.ask_step is None:
            raise FlighttestError("the campaign asks before each step: give it ask_step, or yes to run unattended")
        write_configs(state.dir)
        state.save()
        self.started = True
        done: list[str] = []
        with contextlib.ExitStack() as stack:
            link: list[str] = []  # the URL, once the first flight asked for it

            def connect() -> str:
                if not link:
                    link.append(self._start_fake(stack, req.sim, hooks) if req.sim else str(req.connect))
                return link[0]

            ctx = StepContext(state=state, vehicle=req.vehicle, connect=connect, yes=req.yes,
                              stale_periods=req.stale_periods, show_panel=req.show_panel,
                              confirm=hooks.confirm_flight, print_fn=hooks.say,
                              build_up=req.build_up)  # fmt: skip
            t0 = time.monotonic()
            stop: list[str] = []  # a Ctrl-C during a ground step: finish it, then stop
            hooks.heading(f"[bold]flighttest campaign — {self.profile.name} — {state.dir.root}")
            if not steps:
                hooks.say("every step is done (use --only STEP or --from STEP to run one again)")
            for k, step in enumerate(steps):
                nxt = steps[k + 1] if k + 1 < len(steps) else "the summary"
                hooks.step_heading(f"[bold]step {STEPS.index(step) + 1}/{len(STEPS)}: {step}[/] — {TITLES[step]}")
                hooks.say(f"[dim]campaign time {clock_text(time.monotonic() - t0)}; after this: {nxt}[/]")
                if not req.yes and hooks.ask_step is not None and not hooks.ask_step(step):
                    hooks.say(f"stopped before '{step}'. Run the same command again to go on from here.")
                    return RunResult(tuple(done), stopped_before=step)
                if not req.only:
                    state.invalidate(steps[k + 1 :])
                outputs = self._run_step(step, ctx, hooks, stop)
                done.append(step)
                took = clock_text(state.steps[step].elapsed_s or 0)
                hooks.say(f"[green]✓ {step}[/] in {took}  {step_brief(step, outputs)}")
                if stop and k + 1 < len(steps):
                    hooks.say(f"[yellow]stopped after '{step}' (Ctrl-C)[/]; run the same command again to go on")
                    raise KeyboardInterrupt
        return RunResult(tuple(done))

    def _run_step(self, step: str, ctx: StepContext, hooks: CampaignHooks, stop: list[str]) -> dict[str, Any]:
        """One step, recorded whatever ends it; its outputs as the step returned them."""
        state = self.state
        ground = step not in FLIGHT_STEPS  # a flight handles Ctrl-C itself: its abort ladder
        # a ground step's Ctrl-C handler is in place before campaign.json says it is running
        stop_after = _stop_after_step(stop, hooks.say) if ground else contextlib.nullcontext()
        try:
            with stop_after:
                state.begin(step)
                self.current_step = step
                if ground:
                    with hooks.busy(f"{step}: {TITLES[step]} …"):
                        outputs = RUNNERS[step](ctx)
                else:
                    outputs = RUNNERS[step](ctx)
        except KeyboardInterrupt:
            state.finish(step, StepStatus.INTERRUPTED, error="interrupted by the operator")
            hooks.say(f"[yellow]interrupted during '{step}'[/]; run the same command again to resume from it")
            raise
        except StepFailed as exc:
            state.finish(step, StepStatus.FAILED, outputs=exc.outputs, error=str(exc))
            hooks.say(f"[red]{step} failed[/]: {exc}")
            hooks.say("fix the cause, then run the same command again to resume from this step")
            raise
        except BaseException as exc:
            state.finish(step, StepStatus.FAILED, error=str(exc) or type(exc).__name__)
            raise
        state.finish(step, StepStatus.DONE, outputs)
        self.current_step = None
        return outputs

    def _start_fake(self, stack: contextlib.ExitStack, sim: SimOptions, hooks: CampaignHooks) -> str:
        from sitl_fakes.launcher import FakeVehicle

        self.state.dir.sim.mkdir(parents=True, exist_ok=True)
        truth = self.state.dir.sim / f"truth-{dt.datetime.now():%Y%m%d-%H%M%S}.csv"
        fake = stack.enter_context(FakeVehicle(vehicle=self.profile.name, truth_log=truth, **sim.launcher_options()))
        hooks.say(f"fake vehicle: {fake.url} (ground truth: {truth})")
        return fake.url

    def summary_so_far(self) -> dict[str, Any]:
        """The summary's keys from what ``campaign.json`` knows, with each step's status under ``steps``
        (``flighttest.campaign.summary.known_summary``): no log is analysed."""
        return known_summary(self.state, self.profile)

    def summary(self) -> dict[str, Any]:
        """What the campaign reports at the end of a run: the report's ``summary.json`` with each step's
        time once the report is done, else :meth:`summary_so_far`."""
        if not self.state.done("report"):
            return self.summary_so_far()
        summary = read_summary(self.state.dir.report)
        summary["steps_elapsed_s"] = {s: self.state.steps[s].elapsed_s for s in STEPS}
        return summary
