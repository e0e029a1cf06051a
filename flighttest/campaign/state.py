"""A campaign folder and its record ``campaign.json``: which steps are done, when, and what they wrote."""

from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass, field, fields
from enum import StrEnum
from pathlib import Path
from typing import Any

from flighttest.errors import FlighttestError
from flighttest.flying.log_writer import write_json_atomic
from flighttest.inputs import MAX_JSON_BYTES, InputFileError, read_text_file, shown


class StepStatus(StrEnum):
    """A step's ``status`` in ``campaign.json`` (docs/CONTRACTS.md, "Campaign step statuses"). A ``str``:
    the record and ``campaign --json`` carry the bare value, and it compares equal to it."""

    PENDING = "pending"  # not run, or made stale by an earlier step run again
    RUNNING = "running"  # begun; left so only when the process died inside the step
    DONE = "done"  # finished; its outputs are what later steps read
    FAILED = "failed"  # ended by an error (StepFailed: with the outputs it had, e.g. the aborted flight's log)
    INTERRUPTED = "interrupted"  # ended by the operator's Ctrl-C inside the step


class CampaignOutcome(StrEnum):
    """How a ``flighttest campaign`` run ended early: ``outcome`` in its ``--json`` document."""

    REFUSED = "refused"  # bad input or a refused operation (exit code 2)
    FAILED = "failed"  # a step failed, or an unexpected error (exit code 1)
    INTERRUPTED = "interrupted"  # Ctrl-C (exit code 130)
    STOPPED = "stopped"  # the operator said no before a step (exit code 1)


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

    def build_up_file(self, mission: str) -> Path:
        """A descent's build-up so far (``flighttest.campaign.build_up``): what a resume goes on from."""
        return self.root / "build_up" / f"{mission}.json"


@dataclass
class StepRecord:
    status: StepStatus = StepStatus.PENDING
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
        root = Path(root)
        d = CampaignDir(root)
        if root.exists() and not root.is_dir():
            raise FlighttestError(f"{root} is a file, not a campaign folder")
        if not d.state_file.exists():
            return cls(d, vehicle, time.time(), {s: StepRecord() for s in STEPS})
        try:
            text = read_text_file(d.state_file, "campaign record", MAX_JSON_BYTES)
        except InputFileError as exc:
            raise FlighttestError(f"{d.state_file}: not a campaign record ({exc.reason})") from None
        try:
            raw = json.loads(text)
        except (ValueError, RecursionError) as exc:
            why = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
            raise FlighttestError(f"{d.state_file}: not a campaign record ({why})") from None
        state = cls(d, *_parse_record(raw, d.state_file))
        if state.vehicle != vehicle:
            raise FlighttestError(
                f"{root} holds a campaign of vehicle {shown(state.vehicle)}, not '{vehicle}': choose another -o folder"
            )
        return state

    def save(self) -> None:
        self.dir.root.mkdir(parents=True, exist_ok=True)
        write_json_atomic(self.dir.state_file, {
            "format": FORMAT, "vehicle": self.vehicle, "created_unix_s": self.created_unix_s,
            "steps": {s: asdict(r) for s, r in self.steps.items()},
        })  # fmt: skip

    def done(self, step: str) -> bool:
        return self.steps[step].status == StepStatus.DONE

    def output(self, step: str, key: str) -> Any:
        """An earlier step's output; a missing one is one error line saying which step to run."""
        rec = self.steps[step]
        if rec.status != StepStatus.DONE or key not in rec.outputs:
            raise FlighttestError(f"step '{step}' has not completed in {self.dir.root}: run it first (--only {step})")
        return rec.outputs[key]

    def path(self, step: str, key: str) -> Path:
        """An earlier step's file (stored relative to the folder, so a campaign can be moved or copied)."""
        return self.dir.root / self.output(step, key)

    def maybe_path(self, step: str, key: str) -> Path | None:
        value = self.steps[step].outputs.get(key)
        return self.dir.root / value if value else None

    def relative(self, value: Any) -> Any:
        """A path (or a list of them) relative to the campaign folder; anything else as it is."""
        if isinstance(value, list):
            return [self.relative(v) for v in value]
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
            if self.steps[s].status != StepStatus.PENDING:
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
        self.steps[step] = StepRecord(status=StepStatus.RUNNING, started_unix_s=time.time())
        self.save()

    def finish(self, step: str, status: StepStatus | str, outputs: dict[str, Any] | None = None,
               error: str | None = None) -> None:  # fmt: skip
        rec = self.steps[step]
        rec.status = StepStatus(status)  # a bare "done" too; anything else is a bug, refused here
        rec.elapsed_s = round(time.time() - (rec.started_unix_s or time.time()), 3)
        rec.outputs = {k: self.relative(v) if k in PATH_KEYS else v for k, v in (outputs or {}).items()}
        rec.error = error
        self.save()


# -- reading campaign.json: every field of its documented type (docs/CONTRACTS.md), or one line ----------

STATUSES = tuple(StepStatus)
_NUMBER_KEYS = frozenset({"guard_aborts", "speedup_helix_vs_vertical"})


def _is_number(v: Any) -> bool:
    return not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)


def _check_output(step: str, key: str, value: Any) -> str | None:
    """Why an output value is not of its kind (paths are strings, figures finite numbers), or None."""
    if value is None:
        return None
    if key == "files":
        ok = isinstance(value, list) and all(isinstance(v, str) for v in value)
        return None if ok else "must be a list of paths"
    if key in PATH_KEYS:
        return None if isinstance(value, str) and value.strip() else "must be a path"
    if key in _NUMBER_KEYS or key.endswith(("_s", "_mps", "_mps2", "_m")):
        return None if _is_number(value) else "must be a finite number"
    if isinstance(value, str | bool | int | float):
        return None
    return None if isinstance(value, list | dict) else "has an unknown type"


def _parse_record(raw: Any, where: Path) -> tuple[str, float, dict[str, StepRecord]]:
    """``(vehicle, created_unix_s, steps)`` of a parsed ``campaign.json``; any other JSON shape —
    a list, a string, steps as a list, numbers as strings — is one FlighttestError line."""

    def bad(why: str) -> FlighttestError:
        return FlighttestError(f"{where}: not a campaign record ({why})")

    if not isinstance(raw, dict):
        raise bad(f"a JSON {type(raw).__name__}, not an object")
    if raw.get("format") != FORMAT:
        raise bad(f"format {shown(raw.get('format'))}, expected {FORMAT!r}")
    vehicle = raw.get("vehicle")
    if not isinstance(vehicle, str) or not vehicle.strip():
        raise bad(f"'vehicle' must be a name (got {shown(vehicle)})")
    created = raw.get("created_unix_s")
    if not _is_number(created):
        raise bad(f"'created_unix_s' must be a number (got {shown(created)})")
    steps_raw = raw.get("steps", {})
    if not isinstance(steps_raw, dict):
        raise bad(f"'steps' must be an object of the steps {', '.join(STEPS)} (got {shown(steps_raw)})")
    for name in steps_raw:
        if name not in STEPS:
            raise bad(f"unknown step {shown(name)} (steps: {', '.join(STEPS)})")
    steps: dict[str, StepRecord] = {}
    known = {f.name for f in fields(StepRecord)}
    for name in STEPS:
        rec = steps_raw.get(name, {})
        if not isinstance(rec, dict):
            raise bad(f"step '{name}' must be an object (got {shown(rec)})")
        for key in rec:
            if key not in known:
                raise bad(f"step '{name}': unknown key {shown(key)}")
        status = rec.get("status", StepStatus.PENDING)
        if not isinstance(status, str) or status not in STATUSES:
            raise bad(f"step '{name}': status must be one of {', '.join(STATUSES)} (got {shown(status)})")
        for key in ("started_unix_s", "elapsed_s"):
            if rec.get(key) is not None and not _is_number(rec[key]):
                raise bad(f"step '{name}': '{key}' must be a number (got {shown(rec[key])})")
        outputs = rec.get("outputs", {})
        if outputs is None:
            outputs = {}
        if not isinstance(outputs, dict):
            raise bad(f"step '{name}': 'outputs' must be an object (got {shown(outputs)})")
        for key, value in outputs.items():
            why = _check_output(name, key, value)
            if why:
                raise bad(f"step '{name}': output '{key}' {why} (got {shown(value)})")
        error = rec.get("error")
        if error is not None and not isinstance(error, str):
            raise bad(f"step '{name}': 'error' must be text (got {shown(error)})")
        steps[name] = StepRecord(status=StepStatus(status), started_unix_s=rec.get("started_unix_s"),
                                 elapsed_s=rec.get("elapsed_s"), outputs=dict(outputs), error=error)  # fmt: skip
    return vehicle, float(created), steps
