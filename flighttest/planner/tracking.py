"""Planning margins for trajectories that will be flown: leave the controller room to track.

A minimum-time optimum rides its bounds (bang-bang thrust, tilt and rates at their limits, the
velocity on the guard's boundary). The autopilot flies it with feedback on top of the feed-forward,
and feedback needs headroom: an attitude loop that must tilt further than the plan to correct an
error cannot when the plan already sits at ``MPC_TILTMAX_AIR``; a thrust command at zero cannot be
reduced (PX4 keeps ``MPC_THR_MIN``, and rotors at idle lose attitude authority); a plan on the
guard's boundary is aborted by the first centimetre per second of tracking error; PX4 clips the
descent to ``MPC_Z_VEL_MAX_DN`` whatever the feed-forward says.

``TrackingMargin`` holds those margins (one place, one meaning, read from a mission's ``[plan]``
table); ``helix_problem_for_flight`` turns a vehicle profile and the margins into the helix problem
(within the profile's autopilot limits too, where it names them: ``helix.problem_for_vehicle``).
Offline planning (``flighttest plan``) does not use them: it reproduces the paper's optimum.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

from flighttest.errors import FlighttestError
from flighttest.model.profiles import VehicleProfile
from flighttest.planner.autopilot_limits import capped
from flighttest.planner.cone import VelocityConstraint
from flighttest.planner.helix import HelixProblem, problem_for_vehicle


@dataclass(frozen=True)
class TrackingMargin:
    """How far inside the guard's bound and the vehicle's hard limits a flown plan stays."""

    guard_margin_mps: float = 0.4  # plan this far inside the guard's bound (on top of its own margin)
    tilt_margin_deg: float = 10.0  # plan tilt ≤ vehicle max tilt − this
    rate_fraction: float = 0.35  # plan body rates ≤ this × the vehicle's max rates (PX4 trails faster turns)
    thrust_max_fraction: float = 0.75  # collective ≤ this × the rotors' maximum
    thrust_min_fraction: float = 0.2  # collective ≥ this × the rotors' maximum (never idle)
    descent_max_mps: float = 1.3  # v_D ≤ this: below PX4's MPC_Z_VEL_MAX_DN (1.5 m/s by default)
    # collective thrust changes ≤ this (m/s³): the optimum's thrust steps at the helix's end (a climb,
    # then a dip at +3 m/s² within 0.4 s) were overshot by PX4 SITL's vertical loop into the guard
    thrust_rate_max_mps3: float = 8.0

    def __post_init__(self) -> None:
        checks = (
            ("guard_margin_mps", self.guard_margin_mps >= 0),
            ("tilt_margin_deg", 0 <= self.tilt_margin_deg < 90),
            ("rate_fraction", 0 < self.rate_fraction <= 1),
            ("thrust_max_fraction", 0 < self.thrust_max_fraction <= 1),
            ("thrust_min_fraction", 0 <= self.thrust_min_fraction < self.thrust_max_fraction),
            ("descent_max_mps", self.descent_max_mps > 0),
            ("thrust_rate_max_mps3", self.thrust_rate_max_mps3 > 0),
        )
        for name, ok in checks:
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and ok):
                raise FlighttestError(f"tracking margin: '{name}' out of range (got {value!r})")

    @classmethod
    def from_plan(cls, plan: dict[str, Any]) -> TrackingMargin:
        """The margins from a mission's ``[plan]`` table (missing keys keep their defaults)."""
        values = {}
        for f in fields(cls):
            if f.name in plan:
                v = plan[f.name]
                if isinstance(v, bool) or not isinstance(v, int | float):
                    raise FlighttestError(f"tracking margin: '{f.name}' must be a number (got {v!r})")
                values[f.name] = float(v)
        return cls(**values)

    def tilt_max_deg(self, profile: VehicleProfile) -> float:
        tilt = profile.max_tilt_deg - self.tilt_margin_deg
        if tilt <= 5.0:
            raise FlighttestError(
                f"tracking margin: tilt margin {self.tilt_margin_deg:g}° leaves no tilt on '{profile.name}' "
                f"(max {profile.max_tilt_deg:g}°)"
            )
        return tilt


# What the hover before the descent keeps below w_allow at least: a plan whose margins leave less has no start
HOVER_ROOM_MPS = 0.08


def guard_margin_for(profile: VehicleProfile, margin: TrackingMargin) -> float:
    """How far inside the guard's bound the helix is planned: the mission's ``guard_margin_mps``, raised to the
    vehicle's ``tracking_margin_mps`` as far as its ``w_allow`` leaves the start hover room for (an onset
    identified low takes the mission's margin rather than no helix; bench/RESULTS.md, "Plans for the wind")."""
    room = profile.w_allow_mps - profile.vrs.margin_mps - HOVER_ROOM_MPS
    return max(margin.guard_margin_mps, min(profile.tracking_margin_mps, room))


def helix_problem_for_flight(
    profile: VehicleProfile,
    height_m: float,
    radius_m: float,
    margin: TrackingMargin,
    n_intervals: int = 60,
    n_coarse: int = 30,
    wind_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0),
    wind_radius_mps: float = 0.0,
) -> HelixProblem:
    """The helix problem against the guard's own region (``w_allow``, margin) with ``margin`` on top. For a
    wind (``wind_ned_mps`` known within ``wind_radius_mps``) the guard constraint judges the air the plan
    will meet, with the disk tilted against the profile's drag as the real vehicle's will be."""
    constraint = VelocityConstraint(
        cone_deg=profile.vrs.cone_deg,
        w_allow_mps=profile.w_allow_mps,
        margin_mps=profile.vrs.margin_mps + guard_margin_for(profile, margin),
    )
    rates_dps = min(profile.max_rate_dps[:2]) * min(margin.rate_fraction, profile.tracking_rate_fraction)
    p = problem_for_vehicle(
        profile,
        height_m=height_m,
        radius_m=radius_m,
        constraint=constraint,
        thrust_fraction=margin.thrust_max_fraction,
        tilt_max_deg=margin.tilt_max_deg(profile),
        rate_max_dps=rates_dps,
        n_intervals=n_intervals,
        n_coarse=n_coarse,
    )
    n_thrust = profile.n_rotors * profile.max_thrust_per_rotor_n / profile.mass_kg
    f_min = max(p.f_min_mps2, margin.thrust_min_fraction * n_thrust)
    # the lower of the margin's descent bound and the one the profile's autopilot sets (problem_for_vehicle)
    descent = capped(margin.descent_max_mps, p.descent_max_mps)
    thrust_rate = capped(margin.thrust_rate_max_mps3, p.thrust_rate_max_mps3)
    p = replace(p, f_min_mps2=f_min, descent_max_mps=descent, thrust_rate_max_mps3=thrust_rate)
    if any(wind_ned_mps) or wind_radius_mps > 0:
        drag = profile.drag
        airspeed = math.hypot(*wind_ned_mps[:2]) + 2.0  # about the helix's own speed on top of the wind
        drag_per_s = drag.mean_linear_n_per_mps(airspeed) / profile.mass_kg if drag is not None else 0.0
        p = replace(p, wind_ned_mps=tuple(float(x) for x in wind_ned_mps), wind_radius_mps=float(wind_radius_mps),
                    drag_per_s=drag_per_s)  # fmt: skip
    return p
