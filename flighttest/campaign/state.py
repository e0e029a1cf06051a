"""A campaign folder and its record ``campaign.json``: which steps are done, when, and what they wrote."""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from flighttest.errors import FlighttestError
from flighttest.flightlog import write_json_atomic

STEPS = ("probe", "identify", "plan", "vertical", "helix", "report")
FLIGHT_STEPS = frozenset({"probe", "vertical", "helix"})
NEEDS = {  # step → the earlier steps whose files it reads
    "probe": (),
    "identify": ("probe",),
    "plan": ("identify",),
    "vertical": ("plan",),
    "helix": ("plan",),
    "report": ("identify", "vertical", "helix"),
}
TITLES = {
    "probe": "fly the sine-sweep VRS probe",
    "identify": "identify the VRS onset and store it as w_allow in the campaign's profile",
    "plan": "plan the vertical baseline and the helix with the identified boundary",
    "vertical": "fly the vertical baseline with the guard",
    "helix": "fly the helix with the guard",
    "report": "compare the descents and write the report",
}
STATE_FILE = "campaign.json"
PATH_KEYS = frozenset({"log_dir", "profile", "identify_json", "vertical", "helix", "report_dir", "files"})
FORMAT = "flighttest-campaign/1"


@dataclass(frozen=True)
class CampaignDir:
    """Where each step's files go."""

    root: Path

    @property
    def state_file(self) -> Path:
        return self.root / STATE_FILE

    @property
    def config(self) -> Path:
        return self.root / "config"

    @property
    def flights(self) -> Path:
        return self.root / "flights"

    @property
    def vehicles(self) -> Path:
        return self.root / "vehicles"

    @property
    def plans(self) -> Path:
        return self.root / "plans"

    @property
    def report(self) -> Path:
        return self.root / "report"

    @property
    def sim(self) -> Path:
        return self.root / "sim"

    @property
    def identify_file(self) -> Path:
        return self.root / "identify.json"


@dataclass
class StepRecord:
    status: str = "pending"  # pending | running | done | failed | interrupted
    started_unix_s: float | None = None
    elapsed_s: float | None = None
    outputs: dict[str, Any] = field(default_factory=dict)
    error: str | None = None


@dataclass
class CampaignState:
    dir: CampaignDir
    vehicle: str
    created_unix_s: float
    steps: dict[str, StepRecord]

    @classmethod
    def open(cls, root: Path, vehicle: str) -> CampaignState:
        """The campaign in ``root``: resumed if its record exists (for the same vehicle), else a new one."""
        d = CampaignDir(Path(root))
        if root.exists() and not root.is_dir():
            raise FlighttestError(f"{root} is a file, not a campaign folder")
        if not d.state_file.is_file():
            return cls(d, vehicle, time.time(), {s: StepRecord() for s in STEPS})
        try:
            raw = json.loads(d.state_file.read_text(encoding="utf-8"))
            if raw.get("format") != FORMAT:
                raise ValueError(f"format {raw.get('format')!r}, expected {FORMAT!r}")
            steps = {s: StepRecord(**raw["steps"].get(s, {})) for s in STEPS}
            state = cls(d, str(raw["vehicle"]), float(raw["created_unix_s"]), steps)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise FlighttestError(f"{d.state_file}: not a campaign record ({exc})") from None
        if state.vehicle != vehicle:
            raise FlighttestError(
                f"{root} holds a campaign of vehicle '{state.vehicle}', not '{vehicle}': choose another -o folder"
            )
        return state

    def save(self) -> None:
        self.dir.root.mkdir(parents=True, exist_ok=True)
        write_json_atomic(self.dir.state_file, {
            "format": FORMAT, "vehicle": self.vehicle, "created_unix_s": self.created_unix_s,
            "steps": {s: asdict(r) for s, r in self.steps.items()},
        })  # fmt: skip

    def done(self, step: str) -> bool:
        return self.steps[step].status == "done"

    def output(self, step: str, key: str) -> Any:
        """An earlier step's output; a missing one is one error line saying which step to run."""
        rec = self.steps[step]
        if rec.status != "done" or key not in rec.outputs:
            raise FlighttestError(f"step '{step}' has not completed in {self.dir.root}: run it first (--only {step})")
        return rec.outputs[key]

    def path(self, step: str, key: str) -> Path:
        """An earlier step's file (stored relative to the folder, so a campaign can be moved or copied)."""
        return self.dir.root / self.output(step, key)

    def maybe_path(self, step: str, key: str) -> Path | None:
        value = self.steps[step].outputs.get(key)
        return self.dir.root / value if value else None

    def _relative(self, value: Any) -> Any:
        if isinstance(value, list):
            return [self._relative(v) for v in value]
        try:
            return str(Path(value).resolve().relative_to(self.dir.root.resolve()))
        except (TypeError, ValueError):
            return value

    def to_run(self, only: str | None = None, start: str | None = None) -> list[str]:
        """The steps this invocation runs: ``only`` one step, everything from ``start`` on, or (resuming)
        everything from the first step not done — a re-run step makes every later one stale."""
        if only:
            return [only]
        if start:
            return list(STEPS[STEPS.index(start):])
        for i, s in enumerate(STEPS):
            if not self.done(s):
                return list(STEPS[i:])
        return []

    def invalidate(self, steps: list[str]) -> None:
        """Mark ``steps`` pending before a run that redoes them in order: a later step flown with an earlier
        step's old files must not count as done if this run stops half-way."""
        for s in steps:
            if self.steps[s].status != "pending":
                self.steps[s] = StepRecord()

    def check_needs(self, steps: list[str]) -> None:
        """Before anything flies: the first step's inputs must already be on disk."""
        if not steps:
            return
        running = set(steps)
        for need in NEEDS[steps[0]]:
            if need not in running and not self.done(need):
                raise FlighttestError(
                    f"step '{steps[0]}' needs the files of step '{need}', which has not completed in "
                    f"{self.dir.root} (run the campaign without --only/--from to resume from the start)"
                )

    def begin(self, step: str) -> None:
        self.steps[step] = StepRecord(status="running", started_unix_s=time.time())
        self.save()

    def finish(self, step: str, status: str, outputs: dict[str, Any] | None = None, error: str | None = None) -> None:
        rec = self.steps[step]
        rec.status = status
        rec.elapsed_s = round(time.time() - (rec.started_unix_s or time.time()), 3)
        rec.outputs = {k: self._relative(v) if k in PATH_KEYS else v for k, v in (outputs or {}).items()}
        rec.error = error
        self.save()
