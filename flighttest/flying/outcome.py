"""What a flight is asked to do and how it ended: ``FlyRequest`` in, ``FlightOutcome`` out, with the
outcome and phase names every layer shares (``docs/CONTRACTS.md``, "Flight outcomes and phases").

``Outcome`` and ``Phase`` are ``StrEnum``: their values are the strings ``summary.json`` and
``events.jsonl`` have always held, so a comparison with the plain string still holds and a log read
back needs no conversion.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

from flighttest.flying.missions_config import MissionConfig
from flighttest.flying.preflight import PreflightResult
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import Trajectory


class Outcome(StrEnum):
    COMPLETED = "completed"  # flown to its end: landed, or holding with --no-land
    ABORTED = "aborted"  # the abort ladder ended the flight (guard, operator, pilot, link, error)
    PROBE_STOPPED = "probe_stopped"  # the probe stopped at what it was looking for (fluctuation, cap, floor)
    REFUSED = "refused"  # never armed: bad input, preflight failure, no-go
    DRY_RUN = "dry_run"  # --dry-run: preflight only


# the command's exit code for each outcome: 2 for what stopped before arming, 1 for an abort
EXIT_CODES = {Outcome.COMPLETED: 0, Outcome.DRY_RUN: 0, Outcome.PROBE_STOPPED: 0, Outcome.REFUSED: 2,
              Outcome.ABORTED: 1}  # fmt: skip


class Phase(StrEnum):
    """The runner's phases, in flight order (``phase`` events; ``phase_at_end`` in ``summary.json``)."""

    INIT = "init"
    CONNECT = "connect"
    PREFLIGHT = "preflight"
    DRY_RUN = "dry_run"
    ARM = "arm"
    TAKEOFF = "takeoff"  # PX4's takeoff
    CLIMB = "climb"  # offboard from here: up to the start point
    SETTLE = "settle"  # hover before and after the trajectory
    STREAM = "stream"  # the trajectory
    LAND = "land"  # PX4's Land
    LANDED = "landed"
    HOLD = "hold"  # --no-land: PX4's Hold after the flight
    # the abort ladder's rungs: logged as phase events (with ``nominal_phase``), never the runner's phase
    ABORT_RECOVER = "abort_recover"
    ABORT_HOLD = "abort_hold"
    ABORT_LAND = "abort_land"


OFFBOARD_FLOW = frozenset({Phase.CLIMB, Phase.SETTLE, Phase.STREAM})  # flighttest flies the vehicle


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
    wind_ned_mps: tuple[float, float, float] | None = None  # the operator's (a prior: flighttest.flying.wind)
    wind_sd_mps: float | None = None  # its uncertainty, 1 σ; None: flighttest.flying.wind.PRIOR_SD_MPS
    log_root: Path = Path("logs")
    show_panel: bool = False
    confirm: Callable[[PreflightResult], bool] | None = None  # go/no-go prompt
    print_fn: Callable[[Any], None] = print
    # plans made ahead for winds (flighttest.planner.wind_plans): the start hover flies the fastest that the
    # wind measured there leaves clear of the guard region, the trajectory above among them
    wind_plans: list[Trajectory] = field(default_factory=list)
    # the mission planned again for a profile (with the vehicle's own limits, read at the preflight): the plan
    # and its plans for winds; None: a trajectory file, flown as it is
    replan: Callable[[VehicleProfile], tuple[Trajectory, list[Trajectory]]] | None = None


@dataclass
class FlightOutcome:
    outcome: Outcome
    abort_reason: str | None
    descent_time_s: float | None
    log_dir: str | None  # None: refused before anything answered, no folder was left
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def exit_code(self) -> int:
        return EXIT_CODES.get(Outcome(self.outcome), 1)

    def summary(self) -> dict[str, Any]:
        return {"outcome": str(self.outcome), "abort_reason": self.abort_reason,
                "descent_time_s": self.descent_time_s, "log_dir": self.log_dir, **self.extra}  # fmt: skip


def final_mode(reported: str, armed: bool, while_armed: str | None) -> dict[str, Any]:
    """``final_mode`` of ``summary.json``: the mode the vehicle reports, or, once it has disarmed, the mode
    it was in when it disarmed (PX4 reports the mode before the landing after disarming: OFFBOARD
    or HOLD on the ground); ``final_mode_note`` says which, and what it reports now, when they differ."""
    if armed or while_armed is None or while_armed == reported:
        return {"final_mode": reported, "final_mode_note": None if armed or while_armed is None else "at disarm"}
    return {"final_mode": while_armed, "final_mode_note": f"at disarm; {reported} reported after disarming"}
