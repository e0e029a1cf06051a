"""Fly a named mission or a trajectory file from Python: what ``flighttest fly`` does, as a library call.

    from flighttest import fly_mission

    outcome = fly_mission("helix", connect="udpin://0.0.0.0:14540", vehicle="x500", height_m=7, yes=True)
    print(outcome.outcome, outcome.descent_time_s, outcome.log_dir)

``prepare_flight`` checks everything that can be checked before anything connects (the numbers, the
profile, the config, the plan, the log folder, the link's address) and raises ``FlighttestError`` with one
line naming what is wrong; ``fly_mission`` (and ``fly_mission_async`` inside a running event loop) then
flies it and returns the ``FlightOutcome`` — ``summary()`` is what ``flighttest fly --json`` prints. The
command line (``flighttest.cli.fly``) and the mission scripts are thin over these.
"""

from __future__ import annotations

import asyncio
import dataclasses
from collections.abc import Callable, Mapping
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

from flighttest.errors import FlighttestError
from flighttest.flying.mission_scripts import MISSIONS, load_mission_module
from flighttest.flying.missions_config import DESCENT_KEYS, MissionConfig, load_mission_config
from flighttest.flying.outcome import FlightOutcome, FlyRequest
from flighttest.flying.preflight import PreflightResult

if TYPE_CHECKING:
    from flighttest.model.profiles import VehicleProfile

# each keyword's name in messages: the library's own; the command line passes its options' names instead
KEYWORD_NAMES = {"height_m": "height_m", "descent_m": "descent_m", "min_alt_m": "min_alt_m",
                 "geofence_radius_m": "geofence_radius_m", "max_descent_mps": "max_descent_mps",
                 "sysid": "sysid", "wind_ned_mps": "wind_ned_mps", "wind_sd_mps": "wind_sd_mps",
                 "log_dir": "log_dir"}  # fmt: skip


def prepare_flight(
    target: str | Path,
    *,
    connect: str,
    vehicle: str | Path,
    config: str | Path | None = None,
    height_m: float | None = None,
    descent_m: float | None = None,
    min_alt_m: float | None = None,
    geofence_radius_m: float | None = None,
    max_descent_mps: float | None = None,
    land: bool = True,
    wind_ned_mps: tuple[float, float, float] | None = None,
    wind_sd_mps: float | None = None,
    sysid: int | None = None,
    log_dir: str | Path | None = None,
    yes: bool = False,
    dry_run: bool = False,
    confirm: Callable[[PreflightResult], bool] | None = None,
    print_fn: Callable[[Any], None] | None = None,
    show_panel: bool = False,
    module: ModuleType | None = None,
    names: Mapping[str, str] = KEYWORD_NAMES,
) -> FlyRequest:
    """The flight ``target`` asks for — "probe", "helix", "vertical" (the mission scripts: see
    ``flighttest fly --help``) or a trajectory file — checked and planned, nothing connected yet.

    ``config`` replaces the mission's own TOML; ``height_m``, ``descent_m``, ``min_alt_m``,
    ``geofence_radius_m``, ``max_descent_mps`` (probe) and ``land`` override it. ``wind_ned_mps`` (with
    ``wind_sd_mps``, its 1 σ) is a wind measured on the ground: a prior for the guard. Without ``yes`` the
    flight asks ``confirm(preflight)`` before arming and refuses to arm without a terminal."""
    from flighttest.console import console
    from flighttest.flying.link import check_connection, check_url
    from flighttest.flying.runner import check_duration
    from flighttest.model.profiles import load_profile
    from flighttest.model.trajectory import Trajectory
    from flighttest.planner.optimum import with_optimum

    # the progress lines and the preflight table (a rich Table: plain print() would show its repr)
    print_fn = print_fn or console.print

    check_url(connect)
    _check_numbers(names, height_m=height_m, descent_m=descent_m, min_alt_m=min_alt_m,
                   geofence_radius_m=geofence_radius_m, max_descent_mps=max_descent_mps, sysid=sysid,
                   wind_ned_mps=wind_ned_mps, wind_sd_mps=wind_sd_mps)  # fmt: skip
    root = log_root(log_dir, names["log_dir"])
    profile = load_profile(str(vehicle))
    target = str(target)
    if module is None and target in MISSIONS:
        module = load_mission_module(target)
    if module is None:
        _check_trajectory_target(target)
    if module is not None:
        cfg = load_mission_config(config or module.CONFIG)
        mission = target if target in MISSIONS else cfg.mission
        if config is not None and cfg.mission != mission:
            raise FlighttestError(f"{config} is the {cfg.mission} mission's config, not the {mission} mission's")
    elif config is not None:
        cfg = load_mission_config(config)
    else:
        cfg = MissionConfig("file")
    overrides: dict[str, Any] = {}
    if height_m is not None:
        overrides["start_height_m"] = height_m
    if min_alt_m is not None:
        overrides["min_alt_m"] = min_alt_m
    if geofence_radius_m is not None:
        overrides["geofence_radius_m"] = geofence_radius_m
    if not land:
        overrides["land"] = False
    if overrides:
        cfg = cfg.with_flight(**overrides)
    if max_descent_mps is not None:
        if cfg.mission != "probe":
            raise FlighttestError(f"{names['max_descent_mps']} applies to the probe mission only")
        cfg = dataclasses.replace(cfg, plan={**cfg.plan, "max_descent_mps": max_descent_mps})
    cfg = with_descent(cfg, descent_m, target, names["descent_m"])
    check_room(cfg, names)
    check_gusts(cfg, profile)
    if module is not None:
        try:
            traj = module.plan(profile, cfg)
        except FlighttestError:
            raise
        except Exception as exc:  # the plan follows from the profile and the config alone: they are at fault
            where = cfg.path or "its config"
            raise FlighttestError(f"cannot plan the {cfg.mission} mission from {where}: {exc}") from None
        name, traj_path = cfg.mission, ""
    else:
        traj = Trajectory.load(target, profile)
        name, traj_path = Path(target).stem, target
    check_duration(traj, f"trajectory {traj_path}" if traj_path else f"the {name} mission's trajectory")
    if not dry_run:  # the yardstick of the flight's efficiency, made before arming (a helix: one solve, cached)
        traj = with_optimum(traj, profile, print_fn)
    wind_plans = []
    if module is not None and hasattr(module, "plans_for_wind") and not dry_run:
        wind_plans = module.plans_for_wind(profile, cfg, print_fn)
    replan = None
    if module is not None:
        plan_module = module

        def replan(p: VehicleProfile) -> tuple[Trajectory, list[Trajectory]]:
            """The mission planned again for ``p`` (the vehicle's own limits, read at the preflight)."""
            again = with_optimum(plan_module.plan(p, cfg), p, print_fn)
            has_wind = hasattr(plan_module, "plans_for_wind") and not dry_run
            return again, plan_module.plans_for_wind(p, cfg, print_fn) if has_wind else []

    check_connection(connect)  # last: it may wait a moment for a host name to resolve
    return FlyRequest(
        connect=connect, profile=profile, config=cfg, trajectory=traj, mission_name=name,
        trajectory_path=traj_path, sysid=sysid, yes=yes, dry_run=dry_run,
        wind_ned_mps=tuple(float(x) for x in wind_ned_mps) if wind_ned_mps is not None else None,
        wind_sd_mps=wind_sd_mps, log_root=root, show_panel=show_panel, confirm=confirm, print_fn=print_fn,
        wind_plans=wind_plans, replan=replan,
    )  # fmt: skip


async def fly_mission_async(target: str | Path, open_link: Any = None, **kwargs: Any) -> FlightOutcome:
    """``fly_mission`` on the running event loop (``open_link``: another link than MAVSDK's, for tests)."""
    from flighttest.flying.runner import MissionRunner

    return await MissionRunner(prepare_flight(target, **kwargs), open_link=open_link).run()


def fly_mission(target: str | Path, **kwargs: Any) -> FlightOutcome:
    """Prepare (``prepare_flight``'s keywords) and fly ``target``; the outcome, whatever it was."""
    return asyncio.run(fly_mission_async(target, **kwargs))


# -- the checks --------------------------------------------------------------------------------------


def _check_trajectory_target(target: str) -> None:
    """A target that is no mission must be a trajectory file: a name that is neither says what would be."""
    from flighttest.inputs import did_you_mean
    from flighttest.model.trajectory import file_paths

    csv_path, json_path = file_paths(target)
    if csv_path.exists() or json_path.exists():
        return
    raise FlighttestError(
        f"trajectory file not found: {csv_path}, and no mission {target!r}{did_you_mean(target, MISSIONS)} "
        f"(missions: {', '.join(MISSIONS)}; a trajectory file is NAME.csv with NAME.json beside it)"
    )


def _check_numbers(names: Mapping[str, str], **values: Any) -> None:
    """Every number within its physical range (``flighttest.inputs``), before any file is read or anything
    connects."""
    from flighttest import inputs as ip

    ranges = {"height_m": ip.START_HEIGHT_M, "descent_m": ip.HEIGHT_M, "min_alt_m": ip.ALTITUDE_FLOOR_M,
              "geofence_radius_m": ip.DISTANCE_M, "max_descent_mps": ip.SPEED_MPS, "sysid": ip.SYSID,
              "wind_sd_mps": ip.SPEED_MPS}  # fmt: skip
    for key, rng in ranges.items():
        if values.get(key) is not None:
            rng.check(values[key], names[key])
    wind = values.get("wind_ned_mps")
    if wind is not None:
        if len(wind) != 3:
            raise FlighttestError(f"{names['wind_ned_mps']}: three numbers, N E D in m/s")
        for axis, w in zip("NED", wind):
            ip.WIND_MPS.check(w, f"{names['wind_ned_mps']} {axis}")


def log_root(text: str | Path | None, name: str = "log_dir") -> Path:
    """The root folder of flight logs (``text``, else ``$FLIGHTTEST_LOG_DIR``, else ``logs``), checked
    before anything connects: a folder there must be possible. Nothing is created here."""
    import os

    from flighttest.inputs import check_output_folder

    if text is None:
        env = os.environ.get("FLIGHTTEST_LOG_DIR")
        name, text = "$FLIGHTTEST_LOG_DIR", (env if env is not None else "logs")
    return check_output_folder(text, name)


def with_descent(cfg: MissionConfig, descent_m: float | None, target: str, name: str = "descent_m") -> MissionConfig:
    """The config with the descent applied (``missions_config.DESCENT_KEYS``), refused for a trajectory
    file (and a helix config flying a planned file): their descent is in the file."""
    if descent_m is None:
        return cfg
    if cfg.mission == "drag":
        raise FlighttestError(f"{name} does not apply to the drag calibration: it flies level")
    if cfg.mission not in DESCENT_KEYS:
        raise FlighttestError(
            f"{name} does not apply to a trajectory file ({target}): its descent is in the file "
            "(plan another with `flighttest plan ... --height M`, or fly a named mission)"
        )
    if cfg.plan.get("trajectory"):
        raise FlighttestError(f"{name} does not apply: {cfg.path or 'the config'} flies the planned file "
                              f"{cfg.plan['trajectory']!r}, whose descent is in the file")  # fmt: skip
    return dataclasses.replace(cfg, plan={**cfg.plan, DESCENT_KEYS[cfg.mission]: float(descent_m)})


def check_gusts(cfg: MissionConfig, profile: VehicleProfile) -> None:
    """The operator's gusts (``[guard] gust_sd_mps``) leave the hover outside the guard's region: the guard
    allows their updraft for the whole flight, so one that alone puts a hover in the region aborts every
    flight the moment it arms (one line, before anything connects)."""
    from flighttest.flying.wind import UPDRAFT_SIGMAS

    sd = cfg.guard.gust_sd_mps
    updraft = UPDRAFT_SIGMAS * sd
    region = profile.guard_region()
    margin = float(region.margin(updraft, 0.0))
    if margin < 0.0:
        at_most = max(0.0, (region.w_allow_mps - region.margin_mps) / UPDRAFT_SIGMAS)
        where = cfg.path or "the config"
        raise FlighttestError(
            f"[guard] gust_sd_mps {sd:g} m/s in {where}: the guard allows updrafts to {updraft:.2f} m/s for such "
            f"gusts, which put even a hover {-margin:.2f} m/s inside {profile.name}'s guard region (w_allow "
            f"{region.w_allow_mps:.2f} − margin {region.margin_mps:.2f} m/s): no descent can be flown in them "
            f"(at most {at_most:.2f} m/s, 1 σ, leaves its hover clear)"
        )


def check_room(cfg: MissionConfig, names: Mapping[str, str] = KEYWORD_NAMES) -> None:
    """The mission's descent fits between its start height and the altitude floor (one line, before
    anything connects)."""
    fl = cfg.flight
    if fl.start_height_m <= fl.min_alt_m:
        raise FlighttestError(f"start height {fl.start_height_m:g} m must exceed the altitude floor {fl.min_alt_m:g} m")
    key = DESCENT_KEYS.get(cfg.mission)
    depth = cfg.plan.get(key) if key and not cfg.plan.get("trajectory") else None
    room = fl.start_height_m - fl.min_alt_m
    if depth is not None and depth > room + 1e-9:
        raise FlighttestError(
            f"the {cfg.mission} mission's descent of {depth:g} m from {fl.start_height_m:g} m goes below the "
            f"altitude floor {fl.min_alt_m:g} m: at most {room:g} m "
            f"(set {names['descent_m']}, {names['height_m']} or {names['min_alt_m']})"
        )
