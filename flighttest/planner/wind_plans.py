"""Helix plans made ahead for the winds a flight may meet, so that the start hover only has to choose.

A helix takes several seconds of IPOPT, too long to plan in the hover before the descent. The descent
runs from hover to hover on one vertical line, and gravity is the same whichever way the wind blows, so a
plan made for a wind of speed ``s`` from one direction serves that speed from any direction turned about
the vertical (``flighttest.flying.wind.rotate_plan``). Plans are made for a ladder of speeds up to the
mission's ``max_wind_mps``, each keeping clear of the guard region for any wind within ``wind_radius_mps``
of its own and with the disk tilted against the profile's drag (``flighttest.planner.tracking``), and
kept in a cache keyed by everything they depend on: a second flight of the same mission plans nothing.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from flighttest import __version__
from flighttest.errors import FlighttestError
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import Trajectory

# Each IPOPT solve of a plan for the wind stops after this long: a wind the vehicle can barely serve can
# otherwise take IPOPT thousands of slow iterations (arducopter_sitl, 5 m/s: bench/RESULTS.md, "Plans for
# the wind"), and a ladder that would serve it no better is left without that rung.
SOLVE_MAX_S = 20.0
WALL_TIME_STATUS = "Maximum_WallTime_Exceeded"  # IPOPT's status for a solve SOLVE_MAX_S stopped


def cache_dir() -> Path:
    return Path(os.environ.get("FLIGHTTEST_CACHE", "~/.cache/flighttest")).expanduser() / "plans"


def wind_speeds(max_wind_mps: float, step_mps: float) -> list[float]:
    """The ladder of wind speeds plans are made for (above calm, which the mission's own plan flies)."""
    if step_mps <= 0 or max_wind_mps <= 0:
        return []
    n = int(max_wind_mps / step_mps + 1e-9)
    return [round(step_mps * (k + 1), 3) for k in range(n)]


def _key(profile: VehicleProfile, plan: dict[str, Any], speed_mps: float, radius_mps: float) -> str:
    # the profile's content, not where it lies: a campaign's copy of a vehicle plans as the original
    summary = {k: v for k, v in profile.summary().items() if k != "path"}
    what = {"profile": summary, "plan": plan, "speed_mps": speed_mps, "radius_mps": radius_mps,
            "flighttest": __version__}  # fmt: skip
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
        yield
    finally:
        os.close(fd)  # closing releases the lock


def helix_plans_for_winds(profile: VehicleProfile, plan: dict[str, Any], speeds_mps: list[float], radius_mps: float,
                          solve: Callable[[float, float], Trajectory],
                          progress: Callable[[str], None] = lambda _: None) -> list[Trajectory]:  # fmt: skip
    """One plan per speed, the wind along +east (NED (0, s, 0)), from the cache or ``solve(speed, radius)``.
    A speed the planner cannot serve is left out (said through ``progress``): the hover then has fewer to
    choose from, and refuses to descend where none fits."""
    out = []
    root = cache_dir()
    for s in speeds_mps:
        base = root / f"helix-{profile.name}-{_key(profile, plan, s, radius_mps)}"
        failed = base.parent / f"{base.name}.failed"
        timed_out = base.parent / f"{base.name}.timedout"
        with planning_lock(base):
            try:
                out.append(Trajectory.load(base, profile))
                continue
            except FlighttestError:
                pass
            # a speed the planner cannot serve is not tried again at every flight (arducopter_sitl's 2 and 3 m/s
            # at a radius of 1.25 ran out of iterations: bench/RESULTS.md, "Plans for the wind"); one that ran
            # out of time is, once, since a busier machine than this one's next flight may have stopped it
            with contextlib.suppress(OSError, UnicodeDecodeError):
                progress(f"no helix for {s:g} m/s of wind: {failed.read_text().strip()} (planned before; "
                         f"delete {failed} to plan it again)")  # fmt: skip
                continue
            progress(f"planning the helix for {s:g} m/s of wind (±{radius_mps:g} m/s): up to a minute")
            try:
                traj = solve(s, radius_mps)
            except FlighttestError as exc:
                progress(f"no helix for {s:g} m/s of wind: {exc}")
                stopped = WALL_TIME_STATUS in str(exc)
                with contextlib.suppress(OSError):
                    base.parent.mkdir(parents=True, exist_ok=True)
                    # stopped the first time: tried once more at the next flight. arducopter_sitl's 5 m/s runs out
                    # of time on an idle machine too, 28 s before every flight (bench/RESULTS.md "Plans for the wind")
                    if stopped and not timed_out.exists():
                        timed_out.touch()
                    else:  # deleting .failed gives it both tries again
                        failed.write_text(f"{exc}, twice, after {SOLVE_MAX_S:g} s each\n" if stopped else f"{exc}\n")
                        timed_out.unlink(missing_ok=True)
                continue
            try:
                base.parent.mkdir(parents=True, exist_ok=True)
                traj.save(base)
            except OSError:
                pass  # a cache that cannot be written plans again next time, nothing worse
            out.append(traj)
    return out

