"""Mission configs: a TOML file beside each mission script, validated into dataclasses on load.

::

    mission = "vertical"          # probe | helix | vertical | file
    [flight]    start_height_m, min_alt_m, geofence_radius_m, settle_s, rate_hz, land, takeoff_timeout_s
    [plan]      the mission's planner inputs (per mission: see _PLAN)
    [guard]     horizon_s, debounce_samples, clear_violation_mps, stale_after_s (or stale_periods), observe_region,
                max_descent_mps, fluct_window_s, max_rate_std_dps, max_accel_std_mps2, fluct_ratio,
                fluct_min_rate_std_dps, fluct_min_accel_std_mps2, gust_sd_mps
    [abort]     recover_max_s, arrested_vd_mps, hold_confirm_s, hold_dwell_s, recovery_lateral_mps,
                recovery_climb_mps, recovery_s
    [build_up]  floor_mps, reserve_mps, estimate_default_mps, max_narrow_fraction, min_gain_fraction,
                expand_fraction
                (``flighttest campaign --build-up N``: vertical and helix)

Every key has a type and a physical range (``_RANGES``; ``[plan]``: ``_PLAN``, per mission). Unknown
keys, wrong types and out-of-range numbers are one ``FlighttestError`` line naming the file and the
key, at load, before anything is planned or flown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from flighttest.errors import FlighttestError
from flighttest.flying.guard import AUTOPILOT_STALE_S, STALE_AFTER_S
from flighttest.inputs import (
    ALTITUDE_FLOOR_M,
    CHIRP_RATE_RPS2,
    DISTANCE_M,
    DURATION_S,
    FRACTION,
    HEIGHT_M,
    INTERVALS,
    MARGIN_MPS,
    MAX_ACCEL_MPS2,
    MAX_DURATION_S,
    SPEED_MPS,
    START_HEIGHT_M,
    Range,
    check_text,
    shown,
)
from flighttest.tomlfile import read_toml

MISSION_KINDS = ("probe", "helix", "vertical", "drag", "file")


@dataclass(frozen=True)
class FlightConfig:
    start_height_m: float = 5.0  # height above home where the trajectory starts
    min_alt_m: float = 1.0  # the guard's altitude floor; the plan must stay above it
    geofence_radius_m: float = 30.0  # horizontal room around the start point
    settle_s: float = 2.0  # hover before and after the trajectory
    rate_hz: float = 50.0  # setpoint rate
    telemetry_hz: float = 50.0  # state telemetry rate asked of the vehicle
    land: bool = True
    takeoff_timeout_s: float = 40.0
    connect_timeout_s: float = 15.0
    min_battery_percent: float = 30.0
    # the acceleration feed-forward is sent this much ahead of the plan (flighttest.flying.feedforward): the
    # autopilot's tilt trails a new thrust direction by about this long
    feedforward_lead_s: float = 0.2
    # catching up with the plan, the autopilot is never asked to descend faster than
    # max(plan + catch_up_excess_mps, catch_up_floor_mps) (flighttest.flying.feedforward.CatchUpLimit): an EKF
    # that trails a descent would otherwise turn its position error into a descent rate the guard aborts on
    catch_up_excess_mps: float = 0.1
    catch_up_floor_mps: float = 0.3
    # the most wind a flight starts in (the preflight, from the operator's or the autopilot's wind; the start
    # hover, from flighttest's own estimate): stronger, and a small multicopter's guard has no air to judge
    max_wind_mps: float = 6.0


@dataclass(frozen=True)
class GuardConfig:
    horizon_s: float = 0.1
    debounce_samples: int = 3
    clear_violation_mps: float = 0.05
    # no state telemetry this long while flighttest flies offboard: abort (flighttest.flying.guard "Stale telemetry")
    stale_after_s: float = STALE_AFTER_S
    stale_periods: float | None = None  # the older spelling, in telemetry periods: when given it wins
    observe_region: bool = False
    max_descent_mps: float | None = None
    fluct_window_s: float = 0.5
    max_rate_std_dps: float | None = None  # absolute fluctuation limits while streaming
    max_accel_std_mps2: float | None = None
    fluct_ratio: float | None = None  # × the hover fluctuation measured in the settle before streaming
    fluct_min_rate_std_dps: float = 0.0  # the ratio's threshold is never below these
    fluct_min_accel_std_mps2: float = 0.0
    # the day's gusts as the operator knows them (1 σ, m/s): the guard allows an updraft of 1.96 × the larger
    # of this and what it measures itself (flighttest.flying.wind.GustMeter), which no autopilot reports
    gust_sd_mps: float = 0.0


@dataclass(frozen=True)
class AbortConfig:
    recovery_s: float = 1.0  # how long the lateral escape speed is commanded
    recovery_lateral_mps: float = 1.0  # added horizontal speed away from obstacles
    recovery_climb_mps: float = 0.3  # small climb while arresting the sink
    recover_max_s: float = 2.0
    arrested_vd_mps: float = 0.3
    hold_confirm_s: float = 3.0
    hold_dwell_s: float = 2.0


@dataclass(frozen=True)
class BuildUpConfig:
    """How ``flighttest campaign --build-up N`` narrows a descent's margin from flight to flight
    (``flighttest.campaign.build_up``): the helix's ``guard_margin_mps``, the vertical's ``extra_margin_mps``."""

    floor_mps: float = 0.1  # never narrower than this, whatever the evidence
    reserve_mps: float = 0.05  # kept on top of what the evidence measured
    # the estimate's error where the log has no barometer to measure it against: PX4 SIH's EKF2 vertical
    # velocity, 0.15 m/s median (sitl_fakes/estimator.py), with room
    estimate_default_mps: float = 0.2
    max_narrow_fraction: float = 0.5  # one flight narrows the margin by at most this fraction of it
    min_gain_fraction: float = 0.02  # a flight not this much faster (hover to hover) than the last ends it
    # the tracking room (the helix's rate fraction and thrust rate, the vertical's acceleration fraction) grows
    # by this after a clean flight
    expand_fraction: float = 0.25


@dataclass(frozen=True)
class MissionConfig:
    mission: str
    flight: FlightConfig = field(default_factory=FlightConfig)
    plan: dict[str, Any] = field(default_factory=dict)
    guard: GuardConfig = field(default_factory=GuardConfig)
    abort: AbortConfig = field(default_factory=AbortConfig)
    path: str = ""
    build_up: BuildUpConfig = field(default_factory=BuildUpConfig)

    def to_dict(self) -> dict[str, Any]:
        from dataclasses import asdict

        return {
            "mission": self.mission,
            "flight": asdict(self.flight),
            "plan": dict(self.plan),
            "guard": asdict(self.guard),
            "abort": asdict(self.abort),
            "build_up": asdict(self.build_up),
            "path": self.path,
        }

    def with_flight(self, **changes: Any) -> MissionConfig:
        return replace(self, flight=_validated(FlightConfig, {**_as_dict(self.flight), **changes}, "options"))


def _as_dict(obj) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in fields(obj)}


# Every field's type and physical range (flighttest.inputs). Booleans are the fields whose default is
# a bool; everything else is a number in its range (the optional ones may be absent).
_S = "s"
_RANGES: dict[str, Range] = {
    # [flight]
    "start_height_m": START_HEIGHT_M,
    "min_alt_m": ALTITUDE_FLOOR_M,
    "geofence_radius_m": DISTANCE_M,
    "settle_s": Range(0.0, 60.0, _S),
    "rate_hz": Range(0.0, None, "Hz", lo_open=True),  # then [1, 200] below, with its own message
    "telemetry_hz": Range(1.0, 200.0, "Hz"),
    "takeoff_timeout_s": Range(0.0, MAX_DURATION_S, _S, lo_open=True),
    "connect_timeout_s": Range(0.0, MAX_DURATION_S, _S, lo_open=True),
    "min_battery_percent": Range(0.0, 100.0, "%"),
    "feedforward_lead_s": Range(0.0, 1.0, _S),
    "catch_up_excess_mps": Range(0.0, 5.0, "m/s"),
    "catch_up_floor_mps": Range(0.0, 5.0, "m/s"),
    "max_wind_mps": Range(0.0, 30.0, "m/s"),
    # [guard]
    "horizon_s": Range(0.0, 5.0, _S),
    "debounce_samples": Range(1, 100, integer=True),
    "clear_violation_mps": MARGIN_MPS,
    "gust_sd_mps": Range(0.0, 3.0, "m/s"),
    "stale_after_s": Range(0.0, AUTOPILOT_STALE_S, _S, lo_open=True),  # beyond: longer than PX4 flying itself
    "stale_periods": Range(0.0, 100.0, lo_open=True),
    "max_descent_mps": SPEED_MPS,
    "fluct_window_s": Range(0.0, 10.0, _S, lo_open=True),
    "max_rate_std_dps": Range(0.0, 3600.0, "°/s", lo_open=True),
    "max_accel_std_mps2": Range(0.0, MAX_ACCEL_MPS2, "m/s²", lo_open=True),
    "fluct_ratio": Range(0.0, 100.0, lo_open=True),
    "fluct_min_rate_std_dps": Range(0.0, 3600.0, "°/s"),
    "fluct_min_accel_std_mps2": Range(0.0, MAX_ACCEL_MPS2, "m/s²"),
    # [abort]
    "recovery_s": Range(0.0, 10.0, _S),
    "recovery_lateral_mps": Range(0.0, 5.0, "m/s"),
    "recovery_climb_mps": Range(0.0, 5.0, "m/s"),
    "recover_max_s": Range(0.0, 30.0, _S, lo_open=True),
    "arrested_vd_mps": Range(0.0, 5.0, "m/s", lo_open=True),
    "hold_confirm_s": Range(0.0, 30.0, _S, lo_open=True),
    "hold_dwell_s": Range(0.0, 60.0, _S),
    # [build_up]
    "floor_mps": Range(0.0, 2.0, "m/s"),
    "reserve_mps": Range(0.0, 2.0, "m/s"),
    "estimate_default_mps": Range(0.0, 2.0, "m/s"),
    "max_narrow_fraction": Range(0.0, 1.0, lo_open=True),
    "min_gain_fraction": Range(0.0, 1.0),
    "expand_fraction": Range(0.0, 1.0),
}

# [plan]: what each mission's planner reads (missions/*.py), typed and bounded. A key that is not
# here would be silently ignored by the planner (a typo flies the default), so it is refused.
_TEXT = "text"
_PLAN: dict[str, dict[str, Range | str]] = {
    "vertical": {
        "descent_m": HEIGHT_M,
        "accel_fraction": FRACTION,
        "extra_margin_mps": MARGIN_MPS,
        "jerk_max_mps3": Range(0.0, 1000.0, "m/s³", lo_open=True),
    },
    "probe": {
        "amplitude_m": HEIGHT_M,
        "omega0_rps2": CHIRP_RATE_RPS2,
        "ramp_s": DURATION_S,
        "duration_s": DURATION_S,
        "max_descent_ratio": Range(0.0, 10.0, lo_open=True),
        "max_descent_mps": Range(0.0, 20.0, "m/s", lo_open=True),
        "accel_fraction": FRACTION,
    },
    "helix": {
        "trajectory": _TEXT,  # a planned file (NAME.csv + NAME.json) beside the config, flown instead
        "descent_m": HEIGHT_M,
        "radius_m": DISTANCE_M,
        "n_intervals": INTERVALS,
        "n_coarse": Range(5, 1000, integer=True),
        "guard_margin_mps": MARGIN_MPS,
        "tilt_margin_deg": Range(0.0, 90.0, "°", hi_open=True),
        "rate_fraction": FRACTION,
        "thrust_max_fraction": FRACTION,
        "thrust_min_fraction": Range(0.0, 1.0, hi_open=True),
        "descent_max_mps": SPEED_MPS,
        "thrust_rate_max_mps3": Range(0.0, 1000.0, "m/s³", lo_open=True),
        "wind_step_mps": Range(0.0, 30.0, "m/s"),
        "wind_radius_mps": Range(0.0, 10.0, "m/s"),
        "calm_wind_radius_mps": Range(0.0, 10.0, "m/s"),
    },
    "drag": {
        "speed_min_mps": Range(0.2, 10.0, "m/s"),
        "speed_max_mps": Range(0.2, 10.0, "m/s"),
        "n_speeds": Range(1, 10, integer=True),
        "cruise_s": Range(0.5, 30.0, "s"),
        "accel_mps2": Range(0.2, 5.0, "m/s²"),
        "pause_s": Range(0.0, 10.0, "s"),
    },
    "file": {},  # a trajectory file is flown as planned
}
# how far below its start height each mission goes: the [plan] key `flighttest fly --descent` sets
# (the probe's sweep depth is its amplitude; a trajectory file's descent is in the file)
DESCENT_KEYS = {"probe": "amplitude_m", "helix": "descent_m", "vertical": "descent_m"}


def _number(where: str, key: str, value: Any, rng: Range) -> float | int:
    """One number of a config: the type first (a string or a bool is not a number), then the range."""
    kind = "an integer " if rng.integer else ""
    if isinstance(value, bool) or not isinstance(value, int | float) or (rng.integer and not isinstance(value, int)):
        kind = "an integer" if rng.integer else "a finite number"
        raise FlighttestError(f"{where}: '{key}' must be {kind} {rng.bounds()} (got {shown(value)})")
    if isinstance(value, float) and not math.isfinite(value):
        raise FlighttestError(f"{where}: '{key}' must be a finite number (got {shown(value)})")
    if not rng.ok(value):
        raise FlighttestError(f"{where}: '{key}' must be {kind}{rng.bounds()} (got {shown(value)})")
    return int(value) if rng.integer else float(value)


def _validated(cls, raw: dict[str, Any], where: str):
    known = {f.name: f for f in fields(cls)}
    out: dict[str, Any] = {}
    for key, value in raw.items():
        if key not in known:
            raise FlighttestError(f"{where}: unknown key {shown(key, 40)} (known: {', '.join(known)})")
        if isinstance(known[key].default, bool):
            if not isinstance(value, bool):
                raise FlighttestError(f"{where}: '{key}' must be true or false (got {shown(value)})")
            out[key] = value
        else:
            out[key] = _number(where, key, value, _RANGES[key])
    return cls(**out)


def _validated_plan(mission: str, raw: dict[str, Any], where: str) -> dict[str, Any]:
    schema = _PLAN[mission]
    out: dict[str, Any] = {}
    for key, value in raw.items():
        if key not in schema:
            known = ", ".join(schema) or "none: a trajectory file is flown as planned"
            raise FlighttestError(f"{where}: unknown key {shown(key, 40)} for mission '{mission}' (known: {known})")
        kind = schema[key]
        if kind == _TEXT:
            out[key] = check_text(value, f"{where}: '{key}'", max_chars=1000, single_line=True)
        else:
            assert isinstance(kind, Range)
            out[key] = _number(where, key, value, kind)
    lo, hi = out.get("thrust_min_fraction"), out.get("thrust_max_fraction")
    if lo is not None and hi is not None and lo >= hi:
        raise FlighttestError(f"{where}: 'thrust_min_fraction' ({lo:g}) must be below 'thrust_max_fraction' ({hi:g})")
    return out


def mission_config_from_dict(data: dict[str, Any], path: str = "<config>") -> MissionConfig:
    if not isinstance(data, dict):
        raise FlighttestError(f"{path}: a mission config must be a TOML table")
    allowed = {"mission", "flight", "plan", "guard", "abort", "build_up"}
    for key in data:
        if key not in allowed:
            raise FlighttestError(
                f"{path}: unknown section or key {shown(key, 40)} (known: {', '.join(sorted(allowed))})"
            )
    mission = data.get("mission")
    if not isinstance(mission, str) or mission not in MISSION_KINDS:
        raise FlighttestError(f"{path}: 'mission' must be one of {', '.join(MISSION_KINDS)} (got {shown(mission)})")
    sections = {}
    for name in ("flight", "plan", "guard", "abort", "build_up"):
        raw = data.get(name, {})
        if not isinstance(raw, dict):
            raise FlighttestError(f"{path}: [{name}] must be a table")
        sections[name] = raw
    flight = _validated(FlightConfig, sections["flight"], f"{path} [flight]")
    guard = _validated(GuardConfig, sections["guard"], f"{path} [guard]")
    abort = _validated(AbortConfig, sections["abort"], f"{path} [abort]")
    plan = _validated_plan(mission, sections["plan"], f"{path} [plan]")
    build_up = _validated(BuildUpConfig, sections["build_up"], f"{path} [build_up]")
    if flight.start_height_m <= flight.min_alt_m:
        raise FlighttestError(f"{path} [flight]: start_height_m must exceed min_alt_m")
    if not 1.0 <= flight.rate_hz <= 200.0:
        raise FlighttestError(f"{path} [flight]: rate_hz must lie in [1, 200] (got {flight.rate_hz:g})")
    return MissionConfig(mission, flight, plan, guard, abort, str(path), build_up)


def load_mission_config(path: Path | str) -> MissionConfig:
    path = Path(path)
    data = read_toml(path, "mission config")
    return mission_config_from_dict(data, str(path))
