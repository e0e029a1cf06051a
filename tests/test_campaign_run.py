"""``flighttest.campaign.run``: the step loop as a library, driven without a terminal.

Every step is swapped for a stand-in that returns the outputs the real one would (nothing flies, nothing
is planned), so these tests show what the loop records and says whatever ends a step: done, declined,
failed, interrupted inside it, or stopped after it by a Ctrl-C.
"""

from __future__ import annotations

import contextlib
import json
import signal
from pathlib import Path
from typing import Any

import pytest

from flighttest.campaign import steps as campaign_steps
from flighttest.campaign.run import (
    SIM_DEFAULT_PARAMS,
    Campaign,
    CampaignHooks,
    CampaignRequest,
    SimOptions,
    clock_text,
    step_brief,
)
from flighttest.campaign.state import (
    FLIGHT_STEPS,
    STATUSES,
    STEPS,
    TITLES,
    CampaignOutcome,
    CampaignState,
    StepStatus,
)
from flighttest.errors import FlighttestError

URL = "udpin://0.0.0.0:14540"


class Operator:
    """The hooks' other end: what the campaign said, and its answers to "go on with STEP?"."""

    def __init__(self, decline: str | None = None) -> None:
        self.lines: list[str] = []
        self.headings: list[str] = []
        self.busy: list[str] = []
        self.asked: list[str] = []
        self.decline = decline

    def ask(self, step: str) -> bool:
        self.asked.append(step)
        return step != self.decline

    @contextlib.contextmanager
    def spinner(self, text: str):
        self.busy.append(text)
        yield

    def hooks(self, ask: bool = True) -> CampaignHooks:
        return CampaignHooks(say=lambda x: self.lines.append(str(x)), heading=self.headings.append,
                             step_heading=self.headings.append, busy=self.spinner,
                             ask_step=self.ask if ask else None)  # fmt: skip

    def said(self, needle: str) -> bool:
        return any(needle in line for line in self.lines)


def _outputs(root: Path, step: str) -> dict[str, Any]:
    """What each real step returns (docs/CONTRACTS.md, campaign folders), paths absolute as they return them."""
    if step in FLIGHT_STEPS:
        return {"log_dir": str(root / "flights" / f"20261201-120000-{step}"), "guard_aborts": 0,
                "outcome": "probe_stopped" if step == "probe" else "completed", "abort_reason": None,
                "descent_time_s": {"probe": None, "vertical": 4.0, "helix": 2.5}[step],
                "horizontal_error_m": None}  # fmt: skip
    if step == "identify":
        return {"onset_found": True, "w_onset_mps": 0.93, "uncertainty_mps": 0.05, "w_onset_lower_bound_mps": None,
                "prior_w_allow_mps": 0.85, "profile": str(root / "vehicles" / "x500.toml"),
                "identify_json": str(root / "identify.json")}  # fmt: skip
    if step == "plan":
        return {"w_allow_mps": 0.93, "w_allow_from": "identified", "vertical": str(root / "plans" / "vertical.csv"),
                "helix": str(root / "plans" / "helix.csv"), "vertical_t_f_s": 4.0, "helix_t_f_s": 2.5}  # fmt: skip
    report = root / "report"
    report.mkdir(parents=True, exist_ok=True)
    (report / "summary.json").write_text(json.dumps({"vehicle": "x500", "helix_descent_s": 2.5}))
    return {"report_dir": str(report), "files": [str(report / "summary.json")], "speedup_helix_vs_vertical": 1.6}


@pytest.fixture
def stand_ins(monkeypatch) -> dict[str, Any]:
    """Every step's runner replaced: ``calls`` lists the steps run; ``raise_in[step]`` makes one raise."""
    seen: dict[str, Any] = {"calls": [], "raise_in": {}, "urls": []}

    def runner(step: str):
        def run(ctx: campaign_steps.StepContext) -> dict[str, Any]:
            seen["calls"].append(step)
            if step in FLIGHT_STEPS:
                seen["urls"].append(ctx.connect())
            if step in seen["raise_in"]:
                raise seen["raise_in"][step]
            return _outputs(ctx.dir.root, step)

        return run

    for step in STEPS:
        monkeypatch.setitem(campaign_steps.RUNNERS, step, runner(step))
    return seen


def _statuses(root: Path) -> list[str]:
    return [rec["status"] for rec in json.loads((root / "campaign.json").read_text())["steps"].values()]


def test_statuses_are_the_bare_strings_of_the_record(tmp_path):
    assert STATUSES == tuple(StepStatus) == ("pending", "running", "done", "failed", "interrupted")
    assert tuple(CampaignOutcome) == ("refused", "failed", "interrupted", "stopped")
    state = CampaignState.open(tmp_path / "c", "x500")
    state.begin("probe")
    state.finish("probe", "done", {"x": 1})  # a bare string still works
    state.begin("identify")
    state.finish("identify", StepStatus.INTERRUPTED, error="interrupted by the operator")
    raw = json.loads((tmp_path / "c" / "campaign.json").read_text())["steps"]
    assert raw["probe"]["status"] == "done" and raw["identify"]["status"] == "interrupted"
    again = CampaignState.open(tmp_path / "c", "x500")
    assert again.steps["probe"].status is StepStatus.DONE and again.steps["plan"].status is StepStatus.PENDING
    assert f"{again.steps['identify'].status}" == "interrupted" and json.dumps(StepStatus.DONE) == '"done"'
    with pytest.raises(ValueError):
        state.finish("plan", "finished")


def test_run_takes_every_step_in_order_and_says_so(tmp_path, stand_ins):
    root = tmp_path / "c"
    op = Operator()
    campaign = Campaign.open(CampaignRequest(out_dir=root, vehicle="x500", connect=URL))
    assert campaign.steps == list(STEPS) and not campaign.started and not root.exists()  # open writes nothing
    result = campaign.run(op.hooks())
    assert result.steps_done == STEPS and result.stopped_before is None
    assert stand_ins["calls"] == list(STEPS) and op.asked == list(STEPS)
    assert stand_ins["urls"] == [URL] * 3
    assert _statuses(root) == ["done"] * 6 and campaign.current_step is None and campaign.started
    assert (root / "config" / "helix_descent.toml").is_file()  # the missions' configs, copied once
    assert op.headings[0] == f"[bold]flighttest campaign — x500 — {root}"
    assert op.headings[4] == f"[bold]step 4/6: vertical[/] — {TITLES['vertical']}"
    assert op.busy == [f"{s}: {TITLES[s]} …" for s in ("identify", "plan", "report")]
    assert op.said("✓ plan[/] in 0:00  vertical 4.00 s, helix 2.50 s planned")
    assert op.said("VRS onset 0.930 ± 0.050 m/s → " + str(root / "vehicles" / "x500.toml"))
    assert op.said(f"completed, descent 2.50 s; log {root / 'flights' / '20261201-120000-helix'}")
    assert op.said("after this: the summary")
    # paths in the record are relative to the folder; the summary is the report's, with each step's time
    assert campaign.state.steps["probe"].outputs["log_dir"] == "flights/20261201-120000-probe"
    summary = campaign.summary()
    assert summary["helix_descent_s"] == 2.5 and set(summary["steps_elapsed_s"]) == set(STEPS)

    # the same request again: nothing to run, nothing asked
    op2 = Operator()
    again = Campaign.open(CampaignRequest(out_dir=root, vehicle="x500", connect=URL))
    assert again.steps == [] and again.run(op2.hooks()).steps_done == ()
    assert op2.said("every step is done") and op2.asked == []


def test_a_declined_step_stops_the_campaign_before_it(tmp_path, stand_ins):
    root = tmp_path / "c"
    op = Operator(decline="plan")
    campaign = Campaign.open(CampaignRequest(out_dir=root, connect=URL))
    result = campaign.run(op.hooks())
    assert result.stopped_before == "plan" and result.steps_done == ("probe", "identify")
    assert stand_ins["calls"] == ["probe", "identify"]
    assert _statuses(root) == ["done", "done", "pending", "pending", "pending", "pending"]
    assert op.said("stopped before 'plan'. Run the same command again to go on from here.")
    assert campaign.current_step is None and campaign.summary_so_far()["steps"]["plan"] == "pending"
    # resumed: from the step declined, the done ones not run again
    resumed = Campaign.open(CampaignRequest(out_dir=root, connect=URL, yes=True))
    assert resumed.steps == ["plan", "vertical", "helix", "report"]


def test_unattended_needs_yes_or_a_way_to_ask(tmp_path, stand_ins):
    root = tmp_path / "c"
    with pytest.raises(FlighttestError, match="asks before each step"):
        Campaign.open(CampaignRequest(out_dir=root, connect=URL)).run(Operator().hooks(ask=False))
    assert not root.exists() and stand_ins["calls"] == []
    op = Operator()
    Campaign.open(CampaignRequest(out_dir=root, connect=URL, yes=True)).run(op.hooks(ask=False))
    assert _statuses(root) == ["done"] * 6 and op.asked == []


@pytest.mark.parametrize(
    ("raised", "status", "said"),
    [
        (campaign_steps.StepFailed("vertical flight aborted: guard", {"outcome": "aborted", "guard_aborts": 1}),
         "failed", "fix the cause, then run the same command again to resume from this step"),
        (KeyboardInterrupt(), "interrupted", "interrupted during 'vertical'"),
        (RuntimeError("surprise"), "failed", None),
    ],
    ids=["step-failed", "interrupted", "unexpected"],
)  # fmt: skip
def test_whatever_ends_a_step_is_recorded(tmp_path, stand_ins, raised, status, said):
    root = tmp_path / "c"
    stand_ins["raise_in"]["vertical"] = raised
    campaign = Campaign.open(CampaignRequest(out_dir=root, connect=URL, yes=True))
    op = Operator()
    with pytest.raises(type(raised)):
        campaign.run(op.hooks(ask=False))
    assert _statuses(root) == ["done", "done", "done", status, "pending", "pending"]
    rec = campaign.state.steps["vertical"]
    assert rec.error == (str(raised) or "interrupted by the operator") and rec.elapsed_s is not None
    if isinstance(raised, campaign_steps.StepFailed):  # the aborted flight's outputs, kept for the report
        assert rec.outputs == {"outcome": "aborted", "guard_aborts": 1}
    assert campaign.current_step == "vertical"  # what the CLI prints as failed_step
    if said:
        assert op.said(said)
    # resuming runs it again; --only with the same step too
    assert Campaign.open(CampaignRequest(out_dir=root, connect=URL)).steps == ["vertical", "helix", "report"]


def test_ctrl_c_in_a_ground_step_finishes_it_then_stops(tmp_path, stand_ins, monkeypatch):
    root = tmp_path / "c"
    original = signal.getsignal(signal.SIGINT)
    at_begin: dict[str, Any] = {}
    begin = CampaignState.begin

    def watched_begin(self, step):
        at_begin[step] = signal.getsignal(signal.SIGINT)  # the handler in place when the record says running
        begin(self, step)

    monkeypatch.setattr(CampaignState, "begin", watched_begin)

    def plan_interrupted(ctx):
        signal.raise_signal(signal.SIGINT)  # the operator's Ctrl-C while the planner works
        return _outputs(ctx.dir.root, "plan")

    monkeypatch.setitem(campaign_steps.RUNNERS, "plan", plan_interrupted)
    op = Operator()
    with pytest.raises(KeyboardInterrupt):
        Campaign.open(CampaignRequest(out_dir=root, connect=URL, yes=True)).run(op.hooks(ask=False))
    assert _statuses(root) == ["done", "done", "done", "pending", "pending", "pending"]
    assert op.said("Ctrl-C: stopping after this step") and op.said("stopped after 'plan' (Ctrl-C)")
    assert at_begin["plan"] is not original and at_begin["identify"] is not original
    assert at_begin["probe"] is original  # a flight handles Ctrl-C itself (its abort ladder)
    assert signal.getsignal(signal.SIGINT) is original  # restored

    def plan_interrupted_twice(ctx):
        signal.raise_signal(signal.SIGINT)
        signal.raise_signal(signal.SIGINT)  # the second stops at once
        raise AssertionError("not reached")

    monkeypatch.setitem(campaign_steps.RUNNERS, "plan", plan_interrupted_twice)
    with pytest.raises(KeyboardInterrupt):
        Campaign.open(CampaignRequest(out_dir=root, connect=URL, only="plan")).run(Operator().hooks())
    assert _statuses(root)[2] == "interrupted"
    assert signal.getsignal(signal.SIGINT) is original


def test_the_fake_starts_at_the_first_flight_and_stops_at_the_end(tmp_path, stand_ins, monkeypatch):
    import sitl_fakes.launcher

    started: list[dict[str, Any]] = []
    stopped: list[bool] = []

    class Fake:
        url = "udpout://127.0.0.1:14999"

        def __init__(self, **kwargs: Any) -> None:
            started.append(kwargs)

        def __enter__(self) -> Fake:
            return self

        def __exit__(self, *exc: object) -> None:
            stopped.append(True)

    monkeypatch.setattr(sitl_fakes.launcher, "FakeVehicle", Fake)
    root = tmp_path / "c"
    sim = SimOptions(truth_onset_mps=0.95, seed=7, params={**SIM_DEFAULT_PARAMS, "MIS_TAKEOFF_ALT": 3.0})
    op = Operator()
    Campaign.open(CampaignRequest(out_dir=root, sim=sim, yes=True)).run(op.hooks(ask=False))
    assert len(started) == 1 and stopped == [True] and stand_ins["urls"] == [Fake.url] * 3
    kw = started[0]
    assert kw["vehicle"] == "x500" and kw["truth_onset"] == 0.95 and kw["seed"] == 7 and "wind_ned" not in kw
    assert kw["param"] == {"MPC_Z_VEL_MAX_DN": 3.0, "MIS_TAKEOFF_ALT": 3.0}
    assert kw["truth_log"].parent == root / "sim"
    assert op.said(f"fake vehicle: {Fake.url} (ground truth: {kw['truth_log']})")
    # no flight, no fake
    started.clear()
    Campaign.open(CampaignRequest(out_dir=root, sim=SimOptions(), only="plan")).run(Operator().hooks())
    assert started == []


def test_open_refuses_before_anything_is_written(tmp_path):
    root = tmp_path / "c"
    with pytest.raises(FlighttestError, match="needs the files of step 'plan'"):
        Campaign.open(CampaignRequest(out_dir=root, connect=URL, only="helix"))
    with pytest.raises(FlighttestError, match="unknown vehicle"):
        Campaign.open(CampaignRequest(out_dir=root, vehicle="no_such_vehicle", connect=URL))
    assert not root.exists()
    for bad in ({}, {"connect": URL, "sim": SimOptions()}, {"connect": URL, "only": "fly"},
                {"connect": URL, "only": "plan", "start": "plan"}):  # fmt: skip
        with pytest.raises(ValueError):
            CampaignRequest(out_dir=root, **bad)


def test_sim_options_are_the_fakes_flags():
    assert SimOptions().launcher_options() == {"param": {"MPC_Z_VEL_MAX_DN": 3.0}}
    opts = SimOptions(wind_ned_mps=(2.0, 0.0, 0.0), seed=0).launcher_options()
    assert opts["wind_ned"] == (2.0, 0.0, 0.0) and opts["seed"] == 0


def test_clock_and_briefs():
    assert clock_text(0.4) == "0:00" and clock_text(75.4) == "1:15" and clock_text(3600) == "60:00"
    flight = {"outcome": "aborted", "descent_time_s": None, "log_dir": "flights/x"}
    assert step_brief("vertical", flight) == "aborted; log flights/x"
    no_onset = {"onset_found": False, "message": "no onset up to 1.31 m/s", "profile": "vehicles/x500.toml"}
    assert step_brief("identify", no_onset) == "no onset up to 1.31 m/s → vehicles/x500.toml"
    assert step_brief("report", {"report_dir": "r"}) == "r"
