"""Helix plans made ahead for the winds a flight may meet, so that the start hover only has to choose.

A helix takes several seconds of IPOPT, too long to plan in the hover before the descent. The descent
runs from hover to hover on one vertical line, and gravity is the same whichever way the wind blows, so a
plan made for a wind of speed ``s`` from one direction serves that speed from any direction turned about
the vertical (``flighttest.flying.wind.rotate_plan``). Plans are made for a ladder of speeds up to the
mission's ``max_wind_mps``, each keeping clear of the guard region for any wind within ``wind_radius_mps``
of its own and with the disk tilted against the profile's drag (``flighttest.planner.tracking``), and
kept in a cache keyed by everything they depend on (``flighttest.planner.plan_cache``): a second flight of the
same mission plans nothing.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from typing import Any

from flighttest.errors import FlighttestError
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import Trajectory
from flighttest.planner.plan_cache import cache_dir, cache_key, load_plan, planning_lock, save_quietly

# Each IPOPT solve of a plan for the wind stops after this long: a wind the vehicle can barely serve can
# otherwise take IPOPT thousands of slow iterations (arducopter_sitl, 5 m/s: bench/RESULTS.md, "Plans for
# the wind"), and a ladder that would serve it no better is left without that rung.
SOLVE_MAX_S = 20.0
WALL_TIME_STATUS = "Maximum_WallTime_Exceeded"  # IPOPT's status for a solve SOLVE_MAX_S stopped


def wind_speeds(max_wind_mps: float, step_mps: float) -> list[float]:
    """The ladder of wind speeds plans are made for (above calm, which the mission's own plan flies)."""
    if step_mps <= 0 or max_wind_mps <= 0:
        return []
    n = int(max_wind_mps / step_mps + 1e-9)
    return [round(step_mps * (k + 1), 3) for k in range(n)]


def question(plan: dict[str, Any], speed_mps: float, radius_mps: float) -> dict[str, Any]:
    """What a plan for the wind depends on besides the profile and the code (``plan_cache.cache_key``)."""
    return {"plan": plan, "speed_mps": speed_mps, "radius_mps": radius_mps}


def helix_plans_for_winds(profile: VehicleProfile, plan: dict[str, Any], speeds_mps: list[float], radius_mps: float,
                          solve: Callable[[float, float], Trajectory],
                          progress: Callable[[str], None] = lambda _: None) -> list[Trajectory]:  # fmt: skip
    """One plan per speed, the wind along +east (NED (0, s, 0)), from the cache or ``solve(speed, radius)``.
    A speed the planner cannot serve is left out (said through ``progress``): the hover then has fewer to
    choose from, and refuses to descend where none fits."""
    out = []
    root = cache_dir()
    for s in speeds_mps:
        base = root / f"helix-{profile.name}-{cache_key(profile, question(plan, s, radius_mps), solve)}"
        failed = base.parent / f"{base.name}.failed"
        timed_out = base.parent / f"{base.name}.timedout"
        with planning_lock(base):
            try:
                out.append(load_plan(base, profile))
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
            save_quietly(traj, base)
            out.append(traj)
    return out
