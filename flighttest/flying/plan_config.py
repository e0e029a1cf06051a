"""Each mission's ``[plan]`` table, typed, with its defaults in one place.

The mission scripts (``missions/*.py``), ``flighttest plan probe|vertical`` and the campaign read their
plan parameters through these dataclasses, so what ``flighttest plan probe`` shows is what ``flighttest
fly probe`` flies. A mission TOML may leave any key out (the default here applies); the shipped TOMLs
write every key out for the user to edit, and ``tests/test_plan_config.py`` holds them equal to these
defaults. The ranges each key is checked against live beside the TOML reader
(``flighttest.flying.missions_config``); the helix's tracking margins are ``flighttest.planner.tracking``'s.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

from flighttest.errors import FlighttestError


def _from_table(cls, plan: dict[str, Any], where: str):
    values: dict[str, Any] = {}
    for f in fields(cls):
        if f.name not in plan or plan[f.name] is None:
            continue
        v = plan[f.name]
        if f.type in ("float", "float | None"):
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise FlighttestError(f"{where} [plan]: '{f.name}' must be a number (got {v!r})")
            v = float(v)
        values[f.name] = v
    return cls(**values)


@dataclass(frozen=True)
class ProbePlanConfig:
    """The VRS probe's sweep (``missions/vrs_probe.py``, ``flighttest.planner.probe``)."""

    amplitude_m: float = 3.0  # sweep depth below the start
    omega0_rps2: float = 0.015  # chirp rate: phase ω0·t², the peak descent speed grows ≈ A·ω0 per second
    ramp_s: float = 3.0
    duration_s: float = 60.0
    # top descent speed: max_descent_mps if given, else max_descent_ratio × the profile's w_allow
    max_descent_ratio: float = 1.75
    max_descent_mps: float | None = None
    accel_fraction: float = 0.5  # of the vehicle's up/down acceleration the sweep may command

    @classmethod
    def from_table(cls, plan: dict[str, Any]) -> ProbePlanConfig:
        p = _from_table(cls, plan, "probe")
        if not 0 < p.accel_fraction <= 1:
            raise FlighttestError(f"probe: accel_fraction must lie in (0, 1] (got {p.accel_fraction:g})")
        return p

    def top_speed_mps(self, w_allow_mps: float) -> float:
        """The sweep's top descent speed: explicit, else a multiple of the vehicle's ``w_allow``."""
        return self.max_descent_mps if self.max_descent_mps is not None else self.max_descent_ratio * w_allow_mps


@dataclass(frozen=True)
class VerticalPlanConfig:
    """The vertical baseline (``missions/vertical_descent.py``, ``flighttest.planner.vertical``)."""

    descent_m: float = 3.0
    # of the vehicle's acceleration limits: gentle, PX4 overshoots a quick step
    accel_fraction: float = 0.15
    # cruise this far below the guard's bound (PX4's descent-rate estimate is off by 0.1-0.15 m/s, peaks 0.3)
    extra_margin_mps: float = 0.35
    # the acceleration changes no faster (and no faster than the autopilot's own limit): the guard predicts 0.1 s
    # ahead along the vehicle's trend, and a step into cruise read as 0.1·a above it aborted PX4 SITL's vertical
    # (bench/RESULTS.md, "The vertical's entry into cruise")
    jerk_max_mps3: float = 4.0

    @classmethod
    def from_table(cls, plan: dict[str, Any]) -> VerticalPlanConfig:
        return _from_table(cls, plan, "vertical")


@dataclass(frozen=True)
class HelixPlanConfig:
    """The helix descent's geometry and mesh (``missions/helix_descent.py``); its tracking margins are
    ``TrackingMargin.from_plan`` of the same table."""

    descent_m: float = 5.0
    radius_m: float = 3.0  # helix radius bound
    n_intervals: int = 60
    n_coarse: int = 30
    trajectory: str | None = None  # a planned file (NAME.csv + NAME.json beside the config), flown instead
    # helices planned ahead for winds up to [flight] max_wind_mps in these steps (0: none, calm only), each
    # clear of the guard region for any wind within wind_radius_mps of its own (flighttest.planner.wind_plans):
    # half a step, which keeps the plans solvable; the start hover judges each at the wind it measures, with its
    # uncertainty (bench/RESULTS.md, "Plans for the wind")
    wind_step_mps: float = 1.0
    wind_radius_mps: float = 0.5
    # the calm plan keeps clear for any wind within this of calm: the guard's radius in still air (2.45 σ of
    # its estimate, 0.45 m/s on the x500: an accelerometer bias of 0.05 m/s² over its drag reads as 0.18 m/s)
    calm_wind_radius_mps: float = 0.5

    @classmethod
    def from_table(cls, plan: dict[str, Any]) -> HelixPlanConfig:
        return _from_table(cls, plan, "helix")


@dataclass(frozen=True)
class DragPlanConfig:
    """The drag-calibration flight (``missions/drag_calibration.py``, ``flighttest.planner.calibration``)."""

    speed_min_mps: float = 1.0
    speed_max_mps: float = 3.0
    n_speeds: int = 3
    cruise_s: float = 2.0  # at speed, each way
    accel_mps2: float = 1.5
    pause_s: float = 1.0

    @classmethod
    def from_table(cls, plan: dict[str, Any]) -> DragPlanConfig:
        p = _from_table(cls, plan, "drag")
        if p.speed_min_mps > p.speed_max_mps:
            raise FlighttestError("drag: speed_min_mps must not exceed speed_max_mps")
        return p

    @property
    def speeds_mps(self) -> tuple[float, ...]:
        if self.n_speeds == 1:
            return (self.speed_max_mps,)
        step = (self.speed_max_mps - self.speed_min_mps) / (self.n_speeds - 1)
        return tuple(round(self.speed_min_mps + k * step, 3) for k in range(self.n_speeds))
