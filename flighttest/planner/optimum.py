"""The planner's optimum for a plan: the yardstick of a flight's efficiency (``flown_over_optimum``).

A flown descent is compared with the fastest descent the planner finds for the same vehicle, height,
radius, end point and wind, with **no** guard margin and the vehicle's full limits: the guard's own
region (``w_allow``) with margin 0, no tracking margins (tilt, rates and thrust as the planner's own
defaults allow), the autopilot's limits at their full values rather than ``AUTOPILOT_LIMIT_FRACTION`` of
them. It is timed hover to hover by the flights' rule (``descent_time.HOVER_RULE``), so a vehicle flying
the optimum exactly scores 1.

A helix optimum takes an IPOPT solve (about 5 s): it is made once per plan and kept in a trajectory's
metadata (``OPTIMUM_KEY``) and in a cache keyed by what it depends on, so a second flight of the same
mission solves nothing. A plan the planner has no optimum for (the probe, a planar file) has none.
"""

from __future__ import annotations

import contextlib
import json
import math
from dataclasses import asdict, dataclass
from typing import Any

from flighttest.errors import FlighttestError
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import Trajectory

OPTIMUM_KEY = "optimum"  # in a trajectory's metadata
OPTIMUM_FORMAT = "flighttest-optimum/1"
KINDS = ("helix", "vertical")
# every solve stops after this long (as the wind plans' do): a flight's summary waits for it
SOLVE_MAX_S = 30.0
# the optimum's fine mesh: the flown helices' own (missions/helix_descent.toml n_intervals)
N_INTERVALS = 60


@dataclass(frozen=True)
class Optimum:
    """``optimum_s`` hover to hover (None: the planner found none, ``why`` says why) for ``kind``."""

    kind: str
    optimum_s: float | None
    height_m: float
    wind_ned_mps: tuple[float, float, float]
    radius_m: float | None = None
    why: str | None = None
    basis: str = "the planner's optimum: guard region with margin 0, the vehicle's and its autopilot's full limits"

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["wind_ned_mps"] = list(self.wind_ned_mps)
        return {"format": OPTIMUM_FORMAT, **d}

    @classmethod
    def from_dict(cls, d: Any) -> Optimum | None:
        """An optimum a trajectory or the cache holds; None for anything else (an older or edited file)."""
        if not isinstance(d, dict) or d.get("format") != OPTIMUM_FORMAT:
            return None
        try:
            t = d["optimum_s"]
            wind = tuple(float(x) for x in d["wind_ned_mps"])
            ok = (t is None or (isinstance(t, int | float) and math.isfinite(t) and t > 0)) and len(wind) == 3
            if not ok or d["kind"] not in KINDS:
                return None
            return cls(d["kind"], None if t is None else float(t), float(d["height_m"]), wind,  # type: ignore[arg-type]
                       None if d.get("radius_m") is None else float(d["radius_m"]), d.get("why"))  # fmt: skip
        except (KeyError, TypeError, ValueError):
            return None


def _timed(traj: Trajectory) -> float | None:
    from flighttest.analysis.descent_time import HOVER_RULE, planned_descent

    df = traj.df
    p = planned_descent(df["t_s"], df["n_m"], df["e_m"], df["d_m"], df["vd_mps"], rule=HOVER_RULE,
                        vn_mps=df["vn_mps"], ve_mps=df["ve_mps"])  # fmt: skip
    return None if p is None or p.descent_time_s is None else round(float(p.descent_time_s), 3)


def vertical_optimum(profile: VehicleProfile, height_m: float, wind_d_mps: float = 0.0) -> Optimum:
    """Straight down at ``w_allow`` (margin 0) with the vehicle's full accelerations, within its
    autopilot's full limits (``planner.vertical``)."""
    from flighttest.planner.export import vertical_trajectory
    from flighttest.planner.vertical import plan_vertical

    wind = (0.0, 0.0, float(wind_d_mps))
    try:
        vp = plan_vertical(profile, height_m, margin_mps=0.0, accel_fraction=1.0, wind_d_mps=wind_d_mps,
                           limit_fraction=1.0)  # fmt: skip
    except FlighttestError as exc:
        return Optimum("vertical", None, height_m, wind, why=str(exc))
    return Optimum("vertical", _timed(vertical_trajectory(vp, profile.name, profile.mass_kg)), height_m, wind)


def helix_optimum(profile: VehicleProfile, height_m: float, radius_m: float,
                  wind_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0),
                  end_ne_m: tuple[float, float] = (0.0, 0.0)) -> Optimum:  # fmt: skip
    """The minimum-time helix (``planner.helix``) against the guard's region with margin 0, the planner's
    default thrust range and the vehicle's full tilt, rates and autopilot limits; in wind, drag on the
    air-relative velocity as the flown plans have it."""
    from dataclasses import replace

    from flighttest.planner.cone import VelocityConstraint
    from flighttest.planner.export import helix_trajectory
    from flighttest.planner.helix import problem_for_vehicle, solve_helix

    wind = tuple(float(x) for x in wind_ned_mps)
    region = VelocityConstraint(cone_deg=profile.vrs.cone_deg, w_allow_mps=profile.w_allow_mps, margin_mps=0.0)
    try:
        p = problem_for_vehicle(profile, height_m=height_m, radius_m=radius_m, constraint=region,
                                end_ne_m=tuple(end_ne_m), n_intervals=N_INTERVALS, n_coarse=N_INTERVALS // 2,
                                limit_fraction=1.0)  # fmt: skip
        if any(wind):
            drag = profile.drag
            airspeed = math.hypot(*wind[:2]) + 2.0  # as helix_problem_for_flight: the helix's own speed on the wind
            per_s = drag.mean_linear_n_per_mps(airspeed) / profile.mass_kg if drag is not None else 0.0
            p = replace(p, wind_ned_mps=wind, drag_per_s=per_s)
        sol = solve_helix(p, max_solve_s=SOLVE_MAX_S)
    except FlighttestError as exc:
        return Optimum("helix", None, height_m, wind, radius_m, why=str(exc))  # type: ignore[arg-type]
    if not sol.success:
        return Optimum("helix", None, height_m, wind, radius_m,  # type: ignore[arg-type]
                       why=f"the planner did not converge ({sol.result.status})")  # fmt: skip
    traj = helix_trajectory(sol, profile.name, profile.mass_kg)
    return Optimum("helix", _timed(traj), height_m, wind, radius_m)  # type: ignore[arg-type]


def _num(d: dict, key: str, default: float = 0.0) -> float:
    v = d.get(key, default)
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise FlighttestError(f"plan metadata: '{key}' is not a number ({v!r})")
    return float(v)


def question(meta: dict[str, Any]) -> dict[str, Any] | None:
    """What the optimum of a plan with this metadata depends on (its kind, height, radius, end, wind), None
    for a kind without an optimum. The wind is the plan's own (a plan turned for another direction keeps its
    speed: its optimum is the same)."""
    kind = meta.get("kind")
    problem = meta.get("problem")
    if kind not in KINDS or not isinstance(problem, dict):
        return None
    if kind == "vertical":
        return {"kind": kind, "height_m": _num(problem, "height_m"), "wind_d_mps": _num(problem, "wind_d_mps")}
    wind = problem.get("wind_ned_mps") or [0.0, 0.0, 0.0]
    if not (isinstance(wind, list) and len(wind) == 3 and all(isinstance(x, int | float) for x in wind)):
        raise FlighttestError(f"plan metadata: 'wind_ned_mps' is not a vector ({wind!r})")
    return {"kind": kind, "height_m": _num(problem, "height_m"), "radius_m": _num(problem, "radius_m"),
            "end_ne_m": [_num(problem, "end_n_m"), _num(problem, "end_e_m")],
            "wind_ned_mps": [round(float(x), 3) for x in wind]}  # fmt: skip


def solve(profile: VehicleProfile, q: dict[str, Any]) -> Optimum:
    """The optimum a :func:`question` asks for."""
    if q["kind"] == "vertical":
        return vertical_optimum(profile, q["height_m"], q["wind_d_mps"])
    return helix_optimum(profile, q["height_m"], q["radius_m"], tuple(q["wind_ned_mps"]), tuple(q["end_ne_m"]))


def _cache_path(profile: VehicleProfile, q: dict[str, Any]):
    from flighttest.planner.plan_cache import cache_dir, cache_key

    return cache_dir() / f"optimum-{profile.name}-{cache_key(profile, {**q, 'format': OPTIMUM_FORMAT})}.json"


def optimum_for(traj: Trajectory, profile: VehicleProfile, progress=lambda _: None) -> Optimum | None:
    """The optimum of the plan ``traj`` for ``profile``: from its metadata, else from the cache, else solved
    (and cached). None for a plan of a kind without one (``KINDS``)."""
    held = Optimum.from_dict(traj.meta.get(OPTIMUM_KEY))
    if held is not None:
        return held
    try:
        q = question(traj.meta)
    except FlighttestError:  # a file's metadata the planner cannot read: no yardstick, not a reason to refuse
        return None
    if q is None:
        return None
    from flighttest.planner.plan_cache import planning_lock, prune, used
    from flighttest.planner.wind_plans import WALL_TIME_STATUS

    path = _cache_path(profile, q)
    with planning_lock(path):
        with contextlib.suppress(OSError, ValueError):
            cached = Optimum.from_dict(json.loads(path.read_text(encoding="utf-8")))
            if cached is not None:
                used(path)
                return cached
        if q["kind"] == "helix":
            progress("the planner's optimum for this helix (margin 0, full limits): a few seconds")
        opt = solve(profile, q)
        if opt.why is not None and WALL_TIME_STATUS in opt.why:  # a busier moment stopped it: not for ever
            return opt
        with contextlib.suppress(OSError):
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(".tmp")
            tmp.write_text(json.dumps(opt.to_dict(), indent=2) + "\n", encoding="utf-8")
            tmp.replace(path)
        prune(path.parent)
    return opt


def with_optimum(traj: Trajectory, profile: VehicleProfile, progress=lambda _: None) -> Trajectory:
    """``traj`` with its optimum in its metadata (``OPTIMUM_KEY``; unchanged for a kind without one)."""
    opt = optimum_for(traj, profile, progress)
    if opt is not None:
        traj.meta[OPTIMUM_KEY] = opt.to_dict()
    return traj


EFFICIENCY_KEYS = ("hover_to_hover_s", "optimum_s", "flown_over_optimum")


def efficiency(hover_to_hover_s: float | None, optimum_s: float | None) -> dict[str, Any]:
    """The efficiency keys of a flight's record (``EFFICIENCY_KEYS``): ``hover_to_hover_s``, ``optimum_s`` and
    ``flown_over_optimum``, flown / optimum (None where either is missing)."""

    def num(x: Any) -> float | None:
        return float(x) if isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) else None

    flown, best = num(hover_to_hover_s), num(optimum_s)
    return {"hover_to_hover_s": None if flown is None else round(flown, 3),
            "optimum_s": None if best is None else round(best, 3),
            "flown_over_optimum": round(flown / best, 3) if flown is not None and best else None}  # fmt: skip


def logged_optimum_s(meta: dict[str, Any] | None) -> float | None:
    """A flight log folder's optimum: its summary's ``optimum_s`` (the plan flown, the wind's included), else
    the one its ``trajectory.json`` holds; None for a folder older than the optimum."""
    if not isinstance(meta, dict):
        return None
    summary = meta.get("summary")
    t = summary.get("optimum_s") if isinstance(summary, dict) else None
    if isinstance(t, int | float) and not isinstance(t, bool) and math.isfinite(t) and t > 0:
        return float(t)
    tm = meta.get("trajectory_meta")
    held = Optimum.from_dict(tm.get(OPTIMUM_KEY)) if isinstance(tm, dict) else None
    return held.optimum_s if held is not None else None
