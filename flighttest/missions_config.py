"""Mission configs: a TOML file beside each mission script, validated into dataclasses on load.

::

    mission = "vertical"          # probe | helix | vertical | file
    [flight]    start_height_m, min_alt_m, geofence_radius_m, settle_s, rate_hz, land, takeoff_timeout_s
    [plan]      mission-specific planner inputs (free-form numbers/strings, passed to the planner)
    [guard]     horizon_s, debounce_samples, clear_violation_mps, stale_periods, observe_region,
                max_descent_mps, fluct_window_s, max_rate_std_dps, max_accel_std_mps2, fluct_ratio,
                fluct_min_rate_std_dps, fluct_min_accel_std_mps2
    [abort]     recover_max_s, arrested_vd_mps, hold_confirm_s, hold_dwell_s, recovery_lateral_mps,
                recovery_climb_mps, recovery_s

Unknown keys, wrong types and out-of-range numbers are one ``FlighttestError`` line naming the file
and the key.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from flighttest.errors import FlighttestError
from flighttest.tomlfile import read_toml

MISSION_KINDS = ("probe", "helix", "vertical", "file")


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


@dataclass(frozen=True)
class GuardConfig:
    horizon_s: float = 0.2
    debounce_samples: int = 3
    clear_violation_mps: float = 0.05
    stale_periods: float = 3.0
    observe_region: bool = False
    max_descent_mps: float | None = None
    fluct_window_s: float = 0.5
    max_rate_std_dps: float | None = None  # absolute fluctuation limits while streaming
    max_accel_std_mps2: float | None = None
    fluct_ratio: float | None = None  # × the hover fluctuation measured in the settle before streaming
    fluct_min_rate_std_dps: float = 0.0  # the ratio's threshold is never below these
    fluct_min_accel_std_mps2: float = 0.0


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
class MissionConfig:
    mission: str
    flight: FlightConfig = field(default_factory=FlightConfig)
    plan: dict[str, Any] = field(default_factory=dict)
    guard: GuardConfig = field(default_factory=GuardConfig)
    abort: AbortConfig = field(default_factory=AbortConfig)
    path: str = ""

    def to_dict(self) -> dict[str, Any]:
        from dataclasses import asdict

        return {
            "mission": self.mission,
            "flight": asdict(self.flight),
            "plan": dict(self.plan),
            "guard": asdict(self.guard),
            "abort": asdict(self.abort),
            "path": self.path,
        }

    def with_flight(self, **changes: Any) -> MissionConfig:
        return replace(self, flight=_validated(FlightConfig, {**_as_dict(self.flight), **changes}, "options"))


def _as_dict(obj) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in fields(obj)}


# numbers that may be zero (everything else numeric must be > 0)
_NON_NEGATIVE = {"horizon_s", "clear_violation_mps", "settle_s", "min_alt_m", "recovery_lateral_mps",
                 "recovery_climb_mps", "recovery_s", "hold_dwell_s", "min_battery_percent",
                 "fluct_min_rate_std_dps", "fluct_min_accel_std_mps2"}  # fmt: skip


def _validated(cls, raw: dict[str, Any], where: str):
    known = {f.name: f for f in fields(cls)}
    out: dict[str, Any] = {}
    for key, value in raw.items():
        if key not in known:
            raise FlighttestError(f"{where}: unknown key '{key}' (known: {', '.join(known)})")
        default = known[key].default
        if isinstance(default, bool):
            if not isinstance(value, bool):
                raise FlighttestError(f"{where}: '{key}' must be true or false (got {value!r})")
        elif isinstance(default, int) and not isinstance(default, bool) and key == "debounce_samples":
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise FlighttestError(f"{where}: '{key}' must be an integer ≥ 1 (got {value!r})")
        else:  # float or optional float
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise FlighttestError(f"{where}: '{key}' must be a finite number (got {value!r})")
            value = float(value)
            if value < 0 or (value == 0 and key not in _NON_NEGATIVE):
                rel = "≥ 0" if key in _NON_NEGATIVE else "> 0"
                raise FlighttestError(f"{where}: '{key}' must be {rel} (got {value!r})")
        out[key] = value
    return cls(**out)


def mission_config_from_dict(data: dict[str, Any], path: str = "<config>") -> MissionConfig:
    allowed = {"mission", "flight", "plan", "guard", "abort"}
    for key in data:
        if key not in allowed:
            raise FlighttestError(f"{path}: unknown section or key '{key}' (known: {', '.join(sorted(allowed))})")
    mission = data.get("mission")
    if mission not in MISSION_KINDS:
        raise FlighttestError(f"{path}: 'mission' must be one of {', '.join(MISSION_KINDS)} (got {mission!r})")
    sections = {}
    for name in ("flight", "plan", "guard", "abort"):
        raw = data.get(name, {})
        if not isinstance(raw, dict):
            raise FlighttestError(f"{path}: [{name}] must be a table")
        sections[name] = raw
    flight = _validated(FlightConfig, sections["flight"], f"{path} [flight]")
    guard = _validated(GuardConfig, sections["guard"], f"{path} [guard]")
    abort = _validated(AbortConfig, sections["abort"], f"{path} [abort]")
    if flight.start_height_m <= flight.min_alt_m:
        raise FlighttestError(f"{path} [flight]: start_height_m must exceed min_alt_m")
    if not 1.0 <= flight.rate_hz <= 200.0:
        raise FlighttestError(f"{path} [flight]: rate_hz must lie in [1, 200] (got {flight.rate_hz:g})")
    for key, value in sections["plan"].items():
        ok = isinstance(value, str | bool) or (isinstance(value, int | float) and math.isfinite(value))
        if not ok and not (isinstance(value, list) and all(isinstance(v, int | float) for v in value)):
            raise FlighttestError(f"{path} [plan]: '{key}' must be a number, string, bool or list of numbers")
    return MissionConfig(mission, flight, dict(sections["plan"]), guard, abort, str(path))


def load_mission_config(path: Path | str) -> MissionConfig:
    path = Path(path)
    data = read_toml(path, "mission config")
    return mission_config_from_dict(data, str(path))
