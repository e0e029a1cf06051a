"""What each campaign step does, reading the files earlier steps wrote and returning what it wrote.

Steps raise :class:`StepFailed` when the vehicle did not do what the step needs (an aborted
flight, a probe log identify cannot use); the campaign stops there and the step runs again on resume.
A probe that stayed quiet up to its top speed is a result, not a failure: identify records that lower
bound, the campaign's profile keeps the prior ``w_allow`` and the campaign goes on with it.
"""

from __future__ import annotations

import asyncio
import dataclasses
import hashlib
import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
import tomli_w

from flighttest.campaign.build_up import (
    BUILD_UP_KEYS,
    EXPAND_KEYS,
    BuildUpFlight,
    MarginBudget,
    best_flight,
    expand_caps,
    first_budget,
    halfway_budget,
    next_budget,
    stop_reason,
)
from flighttest.campaign.state import CampaignDir, CampaignState
from flighttest.errors import FlighttestError
from flighttest.flying.log_writer import write_json_atomic
from flighttest.flying.mission_scripts import MISSIONS, load_mission_module, mission_config_path
from flighttest.flying.missions_config import DESCENT_KEYS, MissionConfig, load_mission_config
from flighttest.flying.outcome import Outcome
from flighttest.inputs import atomic_write
from flighttest.model.profiles import VehicleProfile, load_profile, profile_to_dict, write_w_allow
from flighttest.model.trajectory import Trajectory
from flighttest.planner.optimum import EFFICIENCY_KEYS, OPTIMUM_KEY, with_optimum

BUDGET_KEY = "margin_budget"  # a plan's metadata and a descent step's outputs: the margin and its terms
# the outcomes that make a flight step done (docs/CONTRACTS.md, "Flight outcomes and phases")
FLIGHT_OK = {"probe": (Outcome.PROBE_STOPPED, Outcome.COMPLETED), "vertical": (Outcome.COMPLETED,),
             "helix": (Outcome.COMPLETED,)}  # fmt: skip


class StepFailed(FlighttestError):
    """The step ran but did not reach its goal (exit code 1: not bad input, a result)."""

    exit_code = 1

    def __init__(self, message: str, outputs: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.outputs = outputs or {}


@dataclass
class StepContext:
    state: CampaignState
    vehicle: str  # the user's profile: name or .toml path
    connect: Callable[[], str]  # the link URL; with --sim the fake starts on the first call
    yes: bool = False  # skip each flight's go/no-go prompt
    stale_periods: float | None = None
    show_panel: bool = False
    confirm: Callable[[Any], bool] | None = None  # the flight's go/no-go after preflight
    print_fn: Callable[[Any], None] = print
    build_up: int = 1  # the most flights of each descent (flighttest.campaign.build_up); 1: one flight

    @property
    def dir(self) -> CampaignDir:
        return self.state.dir

    def config(self, mission: str) -> MissionConfig:
        cfg = load_mission_config(self.dir.config / mission_config_path(mission).name)
        if self.stale_periods is not None:
            cfg = dataclasses.replace(cfg, guard=dataclasses.replace(cfg.guard, stale_periods=self.stale_periods))
        return cfg

    def identified_profile(self) -> VehicleProfile:
        return load_profile(self.state.path("identify", "profile"))


def write_configs(d: CampaignDir) -> None:
    """The missions' own TOML files, copied into the campaign (comments and all) unless already there,
    so edits made for this campaign survive a resume. The vertical baseline starts at the helix's
    height and descends as far, so the two descent times compare like for like (the paper: 5 m)."""
    d.config.mkdir(parents=True, exist_ok=True)
    helix = load_mission_config(mission_config_path("helix"))
    for mission in MISSIONS:
        src = mission_config_path(mission)
        dst = d.config / src.name
        if dst.exists():
            continue
        text = src.read_text(encoding="utf-8")
        if mission == "vertical":
            same = "  # = the helix's, like for like"
            h0, dh = helix.flight.start_height_m, float(helix.plan[DESCENT_KEYS["helix"]])
            key = DESCENT_KEYS["vertical"]  # the [plan] key `fly --descent` sets
            text = re.sub(r"(?m)^start_height_m\s*=.*$", f"start_height_m = {h0!r}{same}", text)
            text = re.sub(rf"(?m)^{key}\s*=.*$", f"{key} = {dh!r}{same}", text)
        dst.write_text(text, encoding="utf-8")
    for mission in MISSIONS:  # validate now, before anything flies
        load_mission_config(d.config / mission_config_path(mission).name)


def _fly(ctx: StepContext, step: str, profile: VehicleProfile, cfg: MissionConfig, traj: Trajectory,
         traj_path: str = "", wind_plans: list[Trajectory] | None = None, replan=None) -> dict[str, Any]:  # fmt: skip
    rec = _flight(ctx, step, profile, cfg, traj, traj_path, wind_plans, replan)
    if rec["outcome"] not in FLIGHT_OK[step]:
        raise StepFailed(failure_line(step, rec), rec)
    return rec


def failure_line(step: str, rec: dict[str, Any]) -> str:
    why = rec.get("abort_reason") or "no reason given"
    return f"{step} flight {rec['outcome']}: {why}" + (f" (log {rec['log_dir']})" if rec.get("log_dir") else "")


def _flight(ctx: StepContext, step: str, profile: VehicleProfile, cfg: MissionConfig, traj: Trajectory,
            traj_path: str = "", wind_plans: list[Trajectory] | None = None,
            replan=None) -> dict[str, Any]:  # fmt: skip
    """One flight and its record, whatever its outcome."""
    from flighttest.flying.runner import FlyRequest, fly

    req = FlyRequest(
        connect=ctx.connect(), profile=profile, config=cfg, trajectory=traj, mission_name=step,
        trajectory_path=traj_path, yes=ctx.yes, log_root=ctx.dir.flights, show_panel=ctx.show_panel,
        confirm=ctx.confirm, print_fn=ctx.print_fn, wind_plans=wind_plans or [], replan=replan,
    )  # fmt: skip
    out = asyncio.run(fly(req))
    # log_dir is None when nothing answered (the flight left no folder)
    aborts = guard_aborts(Path(out.log_dir)) if out.log_dir else 0
    rec = {"log_dir": out.log_dir, "outcome": out.outcome, "abort_reason": out.abort_reason,
           "descent_time_s": out.descent_time_s, "planned_descent_s": out.extra.get("planned_descent_s"),
           "horizontal_error_m": out.extra.get("horizontal_error_m"), "guard_aborts": aborts,
           **{k: out.extra.get(k) for k in EFFICIENCY_KEYS}}  # fmt: skip
    return rec


def guard_aborts(log_dir: Path) -> int:
    """How many times the guard ordered an abort in a flight (``guard.csv`` action ``abort``)."""
    path = log_dir / "guard.csv"
    if not path.is_file():
        return 0
    actions = pd.read_csv(path, usecols=["action"], dtype=str)["action"]
    return int((actions == "abort").sum())


def run_probe(ctx: StepContext) -> dict[str, Any]:
    profile = load_profile(ctx.vehicle)
    cfg = ctx.config("probe")
    traj = load_mission_module("probe").plan(profile, cfg)
    return _fly(ctx, "probe", profile, cfg, traj)


def _keep_profile(profile: VehicleProfile, target: Path) -> None:
    """The campaign's copy of the profile as it is, prior ``w_allow`` and all: plan, flights and report
    read the profile from there whatever identify found."""
    with atomic_write(target) as tmp:
        tmp.write_text(tomli_w.dumps(profile_to_dict(profile)), encoding="utf-8")


def run_identify(ctx: StepContext) -> dict[str, Any]:
    from flighttest.analysis import identify as idf
    from flighttest.analysis.batch import quiet_numerics
    from flighttest.analysis.loaders import load_log

    profile = load_profile(ctx.vehicle)
    log_dir = ctx.state.path("probe", "log_dir")
    target = ctx.dir.vehicles / f"{profile.name}.toml"
    prior = profile.w_allow_mps
    base = {"probe_log": str(log_dir), "vehicle": profile.name, "prior_w_allow_mps": prior}
    try:
        with quiet_numerics():  # numpy's all-NaN windows of streams a log lacks: nothing to tell the user
            onset = idf.identify_onset(load_log(log_dir), profile)
    except idf.NoOnset as none:  # quiet up to the top speed: the onset lies above it; fly by the prior
        line = idf.no_onset_line(none.lower_bound_mps, prior)
        _keep_profile(profile, target)
        write_json_atomic(ctx.dir.identify_file, {**base, **none.summary(), "profile": str(target), "message": line})
        return {"onset_found": False, "w_onset_mps": None, "uncertainty_mps": None,
                "w_onset_lower_bound_mps": none.lower_bound_mps, "prior_w_allow_mps": prior,
                "profile": str(target), "identify_json": str(ctx.dir.identify_file), "message": line}  # fmt: skip
    except idf.ImplausibleOnset as bad:
        # a probe in too much wind that never descended through its disk says nothing against the prior
        # (PX4 SITL in 3 m/s: bench/RESULTS.md, "Issue 21 on real firmware")
        measured_nothing = isinstance(bad, idf.WindyProbe) and not math.isfinite(bad.w_onset_mps)
        if not measured_nothing and not bad.agrees_with(prior):  # the probe says the onset may lie below the prior
            raise StepFailed(f"cannot identify the onset from the probe's log {log_dir}: {bad}") from None
        # e.g. a small vehicle's onset known to ±30 % where 25 % is asked: the prior lies in its band
        line = idf.windy_probe_line(bad, prior) if measured_nothing else idf.untrusted_onset_line(bad, prior)
        _keep_profile(profile, target)
        write_json_atomic(ctx.dir.identify_file, {**base, "onset_found": False, "refused": str(bad),
                                                  "profile": str(target), "message": line})  # fmt: skip
        return {"onset_found": False, "w_onset_mps": None, "uncertainty_mps": None, "w_onset_lower_bound_mps": None,
                "prior_w_allow_mps": prior, "profile": str(target), "identify_json": str(ctx.dir.identify_file),
                "message": line}  # fmt: skip
    except FlighttestError as exc:  # not a probe's sweep, damaged, too few samples
        raise StepFailed(f"cannot identify the onset from the probe's log {log_dir}: {exc}") from None
    write_w_allow(profile, onset.w_onset_mps, onset.provenance(log_dir, "flighttest campaign"), target=target)
    write_json_atomic(ctx.dir.identify_file, {**base, **onset.summary(), "profile": str(target)})
    return {"onset_found": True, "w_onset_mps": onset.w_onset_mps, "uncertainty_mps": onset.uncertainty_mps,
            "w_onset_lower_bound_mps": None, "prior_w_allow_mps": prior, "profile": str(target),
            "identify_json": str(ctx.dir.identify_file)}  # fmt: skip


def run_plan(ctx: StepContext) -> dict[str, Any]:
    profile = ctx.identified_profile()
    ctx.dir.plans.mkdir(parents=True, exist_ok=True)
    found = ctx.state.steps["identify"].outputs.get("onset_found", True)  # older records: always found
    out: dict[str, Any] = {"w_allow_mps": profile.w_allow_mps, "w_allow_from": "identified" if found else "prior"}
    for mission in ("vertical", "helix"):
        module = load_mission_module(mission)
        # with the planner's optimum for it, the yardstick of the flight's efficiency (one solve, cached)
        cfg = ctx.config(mission)
        traj = with_optimum(module.plan(profile, cfg), profile, ctx.print_fn)
        traj.meta[BUDGET_KEY] = config_budget(mission, cfg).to_dict()
        path = ctx.dir.plans / f"{mission}.csv"
        traj.save(path)
        out[mission] = str(path)
        out[f"{mission}_t_f_s"] = traj.duration_s
        out[f"{mission}_optimum_s"] = (traj.meta.get(OPTIMUM_KEY) or {}).get("optimum_s")
        # the plans for winds the start hover chooses from (flighttest.planner.wind_plans), made now, kept here
        for k, wind_plan in enumerate(_wind_plans(ctx, module, profile, mission)):
            wind_plan.save(ctx.dir.plans / f"{mission}-wind{k + 1}.csv")
    return out


def _wind_plans(ctx: StepContext, module: Any, profile: VehicleProfile, mission: str,
                cfg: MissionConfig | None = None) -> list[Trajectory]:  # fmt: skip
    if not hasattr(module, "plans_for_wind"):
        return []
    return module.plans_for_wind(profile, cfg or ctx.config(mission), ctx.print_fn)


def config_budget(mission: str, cfg: MissionConfig) -> MarginBudget:
    """The descent's margin inside the guard's bound (``BUILD_UP_KEYS``) and its tracking room (``EXPAND_KEYS``)
    as its config sets them: a vehicle with no history."""
    from flighttest.flying.plan_config import VerticalPlanConfig
    from flighttest.planner.tracking import TrackingMargin

    values = VerticalPlanConfig.from_table(cfg.plan) if mission == "vertical" else TrackingMargin.from_plan(cfg.plan)
    key = BUILD_UP_KEYS[mission]
    return first_budget(key, getattr(values, key), {k: getattr(values, k) for k in EXPAND_KEYS[mission]})


def run_descent(ctx: StepContext, mission: str) -> dict[str, Any]:
    profile = ctx.identified_profile()
    path = ctx.state.path("plan", mission)
    traj = Trajectory.load(path, profile)
    wind_plans = [Trajectory.load(p, profile) for p in sorted(ctx.dir.plans.glob(f"{mission}-wind*.csv"))]
    module = load_mission_module(mission)
    if ctx.build_up > 1:
        return _build_up(ctx, mission, profile, module, traj, Path(path), wind_plans)
    return _fly(ctx, mission, profile, ctx.config(mission), traj, str(path), wind_plans,
                _replanner(ctx, module, mission, ctx.config(mission)))  # fmt: skip


def _replanner(ctx: StepContext, module: Any, mission: str, cfg: MissionConfig):
    def replan(p: VehicleProfile) -> tuple[Trajectory, list[Trajectory]]:
        """The plan step's work again for ``p``, the vehicle's own limits (read at the flight's preflight)."""
        return with_optimum(module.plan(p, cfg), p, ctx.print_fn), _wind_plans(ctx, module, p, mission, cfg)

    return replan


def _build_up(ctx: StepContext, mission: str, profile: VehicleProfile, module: Any, first: Trajectory,
              first_path: Path, first_wind_plans: list[Trajectory]) -> dict[str, Any]:  # fmt: skip
    """Up to ``ctx.build_up`` flights of ``mission``, each narrower than the last by what they proved; the
    record of each written as it lands, so that a resume goes on from the next one."""
    from flighttest.analysis.margin_evidence import flight_evidence, no_evidence

    cfg0 = ctx.config(mission)
    key, rules = BUILD_UP_KEYS[mission], cfg0.build_up
    record = ctx.dir.build_up_file(mission)
    plan_id = hashlib.sha256(first_path.read_bytes()).hexdigest()
    flights = _build_up_so_far(record, plan_id)
    others = _estimates_elsewhere(ctx, mission)
    budget = config_budget(mission, cfg0) if not flights else next_budget(key, flights, rules,
                                                                          expand_caps(mission, profile), others,
                                                                          profile.vrs.margin_mps)
    fixed = mission == "helix" and bool(cfg0.plan.get("trajectory"))  # a planned file flies as planned
    # resumed: the flights so far may already end it (a smaller N this time)
    why = stop_reason(flights, budget, ctx.build_up, rules) if flights else None
    halved = False  # this flight's plan is already the halfway one
    # the vehicle as the last preflight found it: where its own limits differed from the profile's, the flights
    # after it plan within them at once instead of planning twice, once for the preflight to throw away
    live = profile

    def replanner(cfg: MissionConfig):
        replan = _replanner(ctx, module, mission, cfg)

        def recording(p: VehicleProfile) -> tuple[Trajectory, list[Trajectory]]:
            nonlocal live
            live = p
            return replan(p)

        return recording

    while why is None:
        k = len(flights) + 1
        cfg = cfg0 if k == 1 else dataclasses.replace(cfg0, plan={**cfg0.plan, **budget.plan_changes()})
        if k == 1:
            traj, path, wind_plans = first, first_path, first_wind_plans
        else:
            room = ", ".join(f"{name} {v:.3g}" for name, v in budget.expanded)
            ctx.print_fn(f"build-up {mission} flight {k}: {key} {budget.margin_mps:.3f} m/s ({budget.note}), "
                         f"{room}; planning …")
            try:
                traj = with_optimum(module.plan(live, cfg), live, ctx.print_fn)
                wind_plans = _wind_plans(ctx, module, live, mission, cfg)
            except FlighttestError as exc:  # no plan for these margins: halfway once, else the flights so far
                half = None if halved else halfway_budget(budget, flights[-1], str(exc))
                if half is not None:
                    budget, halved = half, True
                    continue
                why = f"no plan for flight {k}'s margins: {exc}"
                ctx.print_fn(f"build-up {mission}: stops: {why}")
                break
            traj.meta[BUDGET_KEY] = budget.to_dict()
            path = ctx.dir.plans / f"{mission}-build-up-{k}.csv"
            traj.save(path)
        rec = _flight(ctx, mission, live, cfg, traj, str(path), wind_plans, replanner(cfg))
        if k == 1 and rec["outcome"] not in FLIGHT_OK[mission]:
            raise StepFailed(failure_line(mission, rec), rec)  # the first flight is the campaign's single flight
        evidence = flight_evidence(rec["log_dir"]) if rec.get("log_dir") else no_evidence(rec.get("outcome"))
        flights.append(BuildUpFlight(k, budget, evidence, str(path), rec))
        halved = False
        budget = next_budget(key, flights, rules, expand_caps(mission, live), others, live.vrs.margin_mps)
        why = ("the helix flies a planned file ([plan] trajectory): nothing to narrow" if fixed
               else stop_reason(flights, budget, ctx.build_up, rules))  # fmt: skip
        _write_build_up(record, plan_id, flights, why)
        ctx.print_fn(f"build-up {mission} flight {k}: {build_up_line(flights[-1])}"
                     + (f"; stops: {why}" if why else f"; next {key} {budget.margin_mps:.3f} m/s"))  # fmt: skip
    _write_build_up(record, plan_id, flights, why)  # finished: a later run starts a new build-up
    best = best_flight(flights)
    rows = [{**f.row(), "log_dir": ctx.state.relative(f.evidence.log_dir), "plan": ctx.state.relative(f.plan)}
            for f in flights]  # fmt: skip
    if best is None:  # cannot happen: the first flight completed or the step failed above
        raise StepFailed(f"{mission}: no build-up flight completed", {"build_up": rows})
    return {**best.record, "build_up": rows, "build_up_stop": why, "build_up_best": best.k,
            BUDGET_KEY: best.budget.to_dict()}  # fmt: skip


def build_up_line(f: BuildUpFlight) -> str:
    e = f.evidence
    h2h = f"{e.hover_to_hover_s:.2f} s hover to hover" if e.hover_to_hover_s is not None else "no hover-to-hover time"
    least = f", guard's least margin {e.min_margin_mps:.3f} m/s" if e.min_margin_mps is not None else ""
    return f"{e.outcome}, margin {f.margin_mps:.3f} m/s, {h2h}{least}" + ("" if e.guard_silent else ", guard spoke")


def _estimates_elsewhere(ctx: StepContext, mission: str) -> tuple[tuple[float, str], ...]:
    """The estimate's error the campaign's other descents measured on this vehicle (their build-up records)."""
    out = []
    for other in BUILD_UP_KEYS:
        if other == mission:
            continue
        try:
            data = json.loads(ctx.dir.build_up_file(other).read_text(encoding="utf-8"))
            flights = [BuildUpFlight.from_dict(d) for d in data["flights"]]
        except (OSError, ValueError, KeyError, TypeError):
            continue
        out += [(float(f.evidence.estimate_mps), f"the {other}'s flight {f.k}: {f.evidence.estimate_source}")
                for f in flights if f.evidence.estimate_mps is not None]  # fmt: skip
    return tuple(out)


def _build_up_so_far(path: Path, plan_id: str) -> list[BuildUpFlight]:
    """The flights of an unfinished build-up of the same plan; none for a finished one, another plan's or a
    damaged record (a new build-up starts)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if data.get("plan_sha256") != plan_id or data.get("stopped"):
            return []
        return [BuildUpFlight.from_dict(d) for d in data["flights"]]
    except (OSError, ValueError, KeyError, TypeError):
        return []


def _write_build_up(path: Path, plan_id: str, flights: list[BuildUpFlight], why: str | None) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, {"plan_sha256": plan_id, "stopped": why, "flights": [f.to_dict() for f in flights]})


def run_report(ctx: StepContext) -> dict[str, Any]:
    from flighttest.campaign.summary import write_campaign_report

    return write_campaign_report(ctx.state, ctx.identified_profile())


RUNNERS: dict[str, Callable[[StepContext], dict[str, Any]]] = {
    "probe": run_probe,
    "identify": run_identify,
    "plan": run_plan,
    "vertical": lambda ctx: run_descent(ctx, "vertical"),
    "helix": lambda ctx: run_descent(ctx, "helix"),
    "report": run_report,
}

