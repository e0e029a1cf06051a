"""The plan cache: plans and optima that take seconds of IPOPT, kept on disk and keyed by all they depend on.

Kept in ``$FLIGHTTEST_CACHE/plans`` (``~/.cache/flighttest/plans`` by default). A key covers:

- the vehicle profile, every field of it but where it lies (a campaign's copy of a vehicle plans as the
  original): body rates, inertia and thrust limits shape a helix as much as the guard's boundary does;
- the question: the mission's plan table, the wind, the radius, ...;
- the code that plans: flighttest's own source, the mission script that asked (users edit theirs) and
  CasADi's version. flighttest's version number stays the same from one commit to the next, so a key on it
  alone kept an older planner's plans flying after an update.

Every update of flighttest so changes every key: a file no flight has loaded or written for
``KEEP_UNUSED_DAYS`` is removed whenever a new plan is kept.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import inspect
import json
import os
import time
from collections.abc import Callable, Iterator
from importlib import metadata
from pathlib import Path
from typing import Any

from flighttest.errors import FlighttestError
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import Trajectory, file_paths

PACKAGE_ROOT = Path(__file__).resolve().parents[1]  # flighttest/
KEEP_UNUSED_DAYS = 30.0  # a month of test days: a vehicle flown again within it plans nothing


def cache_dir() -> Path:
    return Path(os.environ.get("FLIGHTTEST_CACHE", "~/.cache/flighttest")).expanduser() / "plans"


def source_digest(root: Path) -> str:
    """The hash of every ``*.py`` under ``root``, names and contents."""
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode())
        with contextlib.suppress(OSError):
            h.update(path.read_bytes())
    return h.hexdigest()


@functools.cache
def code_fingerprint() -> str:
    """flighttest's own source and CasADi's version: what a plan made by this code depends on."""
    try:
        casadi = metadata.version("casadi")
    except metadata.PackageNotFoundError:
        casadi = "?"
    return f"{source_digest(PACKAGE_ROOT)}-casadi-{casadi}"


def _source_of(fn: Callable[..., Any] | None) -> str:
    """The hash of the file that defines ``fn`` (a mission script's solver), empty where there is none."""
    if fn is None:
        return ""
    try:
        return hashlib.sha256(Path(inspect.getsourcefile(fn) or "").read_bytes()).hexdigest()
    except (OSError, TypeError):
        return ""


def cache_key(profile: VehicleProfile, question: dict[str, Any], script: Callable[..., Any] | None = None) -> str:
    """The key of the plan ``question`` asks for ``profile``, made by this code and ``script``'s file."""
    fields = {k: v for k, v in dataclasses.asdict(profile).items() if k not in ("path", "description")}
    what = {"profile": fields, "question": question, "code": code_fingerprint(), "script": _source_of(script)}
    return hashlib.sha256(json.dumps(what, sort_keys=True, default=str).encode()).hexdigest()[:20]


@contextlib.contextmanager
def planning_lock(base: Path) -> Iterator[None]:
    """One process plans a key at a time: a second flighttest (a campaign's next step, another test) waits for
    the first's plan and loads it instead of spending the same minute of IPOPT beside it."""
    try:
        import fcntl
    except ImportError:  # Windows: no advisory locks, both plan
        yield
        return
    try:
        base.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(f"{base}.lock", os.O_CREAT | os.O_RDWR, 0o644)
    except OSError:
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        with contextlib.suppress(OSError, NotImplementedError):
            os.utime(fd)  # a lock in use is never old enough for prune()
        yield
    finally:
        os.close(fd)  # closing releases the lock


def used(*paths: Path) -> None:
    """Mark cache files as used now (their modification time), so that ``prune`` keeps them."""
    for path in paths:
        with contextlib.suppress(OSError):
            os.utime(path)


def load_plan(base: Path, profile: VehicleProfile) -> Trajectory:
    """The plan kept under ``base``, marked as used; ``FlighttestError`` where there is none."""
    traj = Trajectory.load(base, profile)
    used(*file_paths(base))
    return traj


def prune(root: Path, keep_days: float = KEEP_UNUSED_DAYS, now_s: float | None = None) -> int:
    """Remove the files in ``root`` not used for ``keep_days``; how many were removed."""
    cutoff = (time.time() if now_s is None else now_s) - keep_days * 86400.0
    removed = 0
    with contextlib.suppress(OSError):
        for path in root.iterdir():
            with contextlib.suppress(OSError):
                if path.is_file() and path.stat().st_mtime < cutoff:
                    path.unlink()
                    removed += 1
    return removed


def save_quietly(traj: Trajectory, base: Path) -> None:
    """Into the cache, the unused files pruned; a cache that cannot be written plans again next time, nothing
    worse."""
    try:
        base.parent.mkdir(parents=True, exist_ok=True)
        traj.save(base)
    except OSError:
        pass
    prune(base.parent)


def cached_plan(kind: str, profile: VehicleProfile, question: dict[str, Any],
                solve: Callable[[], Trajectory]) -> Trajectory:  # fmt: skip
    """The plan from the cache, else ``solve()``'s, kept for the next flight. A plan the planner does not find
    (``FlighttestError``) is not kept: the next flight tries again."""
    base = cache_dir() / f"{kind}-{profile.name}-{cache_key(profile, question, solve)}"
    with planning_lock(base):
        try:
            return load_plan(base, profile)
        except FlighttestError:
            pass
        traj = solve()
        save_quietly(traj, base)
        return traj
