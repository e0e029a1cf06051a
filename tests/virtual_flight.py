"""A vertical descent flown by the real mission runner against ``sitl_fakes.scripted`` in virtual time: the
helper of ``tests/test_runner_virtual.py`` and ``tests/test_runner_safety.py`` (and a leaning descent for the
preflight's tilt check)."""

from __future__ import annotations

import json
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from flighttest.flying.mission_scripts import load_mission_module, mission_config_path
from flighttest.flying.missions_config import mission_config_from_dict
from flighttest.flying.runner import FlightOutcome, FlyRequest, MissionRunner
from flighttest.model.profiles import load_profile
from flighttest.model.trajectory import Trajectory
from sitl_fakes.scripted import ScriptedAutopilot
from sitl_fakes.virtual_time import run_virtual

X500 = load_profile("x500")
START_M, DESCENT_M = 4.0, 2.0
LOG_FILES = ("meta.json", "summary.json", "events.jsonl", "setpoints.csv", "guard.csv", "preflight.json",
             "params.json", "trajectory.csv")  # fmt: skip


@dataclass
class Flight:
    outcome: FlightOutcome
    ap: ScriptedAutopilot
    runner: MissionRunner
    events: list[dict[str, Any]]
    summary: dict[str, Any]

    def ladder(self) -> list[tuple[str, str]]:
        return [(x["rung"], x["why"]) for x in self.summary.get("ladder", [])]

    def t_of(self, event: str, **match: Any) -> float:
        """The runner's clock (the flight's t_s) at the first ``event`` with these fields."""
        return next(e["t_s"] for e in self.events
                    if e["event"] == event and all(e.get(k) == v for k, v in match.items()))  # fmt: skip

    def heard_after(self, t_s: float) -> list[str]:
        """The commands the vehicle heard after the flight's ``t_s``."""
        t0 = self.runner.log.t0_mono
        return [c for t, c in self.ap.commands if t - t0 > t_s + 1e-9]


def config(land: bool = True, **flight: Any) -> Any:
    raw = tomllib.loads(mission_config_path("vertical").read_text())
    raw["flight"].update(start_height_m=START_M, land=land, **flight)
    raw["plan"]["descent_m"] = DESCENT_M
    return mission_config_from_dict(raw, "vertical test")


def fly(tmp_path: Path, script: Callable[[ScriptedAutopilot, MissionRunner], None] | None = None,
        land: bool = True, traj: Trajectory | None = None, request: dict[str, Any] | None = None,
        flight: dict[str, Any] | None = None, summary_expected: bool = True, **autopilot: Any) -> Flight:  # fmt: skip
    """One vertical descent (START_M → START_M − DESCENT_M), or ``traj``, flown in virtual time;
    ``script(ap, runner)`` sets up what happens; ``request`` and ``flight`` override the request's fields
    and the mission's ``[flight]``."""
    cfg = config(land, **(flight or {}))
    traj = traj if traj is not None else load_mission_module("vertical").plan(X500, cfg)
    fields: dict[str, Any] = {"yes": True, "log_root": tmp_path, "print_fn": lambda _: None, **(request or {})}
    req = FlyRequest("udpin://0.0.0.0:14540", X500, cfg, traj, "vertical", **fields)
    ap = ScriptedAutopilot(**autopilot)
    runner = MissionRunner(req, open_link=lambda _tlog, _on_event: ap)
    if script is not None:
        script(ap, runner)
    outcome = run_virtual(runner.run())
    if outcome.outcome == "refused":  # never armed: no folder, the preflight in the outcome
        assert outcome.log_dir is None and not any(Path(tmp_path).iterdir())
        return Flight(outcome, ap, runner, [], outcome.summary())
    log_dir = Path(outcome.log_dir)
    for name in LOG_FILES:
        assert (log_dir / name).is_file() or (name == "summary.json" and not summary_expected), name
    summary = json.loads((log_dir / "summary.json").read_text()) if summary_expected else outcome.summary()
    assert summary["outcome"] == outcome.outcome and summary["abort_reason"] == outcome.abort_reason
    events = [json.loads(x) for x in (log_dir / "events.jsonl").read_text().splitlines()]
    if summary.get("log_complete", True):  # else the summary says which writes failed
        assert events[-1]["event"] == "end" and events[-1]["outcome"] == outcome.outcome
    return Flight(outcome, ap, runner, events, summary)


def in_phase(runner: MissionRunner, phase: str) -> Callable[[], bool]:
    return lambda: runner.phase == phase and not runner.ladder.active


def leaning_descent() -> Trajectory:
    """A descent of 1 m in 2 s under a steady 3 m/s² north: it leans atan(3 / (g − 0.5)) = 17.9° throughout."""
    t = np.arange(0.0, 2.0 + 1e-9, 0.02)
    z = np.zeros_like(t)
    return Trajectory.from_arrays(
        {"kind": "vertical", "vehicle": "x500", "problem": {"height_m": 1.0}, "status": "closed_form"},
        t_s=t, n_m=1.5 * t**2, e_m=z, d_m=0.25 * t**2, vn_mps=3.0 * t, ve_mps=z, vd_mps=0.5 * t,
        an_mps2=z + 3.0, ae_mps2=z, ad_mps2=z + 0.5, yaw_deg=z,
    )  # fmt: skip
