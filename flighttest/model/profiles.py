"""Vehicle profiles: TOML files describing a quadcopter and its VRS boundary, validated on load.

Shipped profiles live in ``flighttest/model/profiles/``. User profiles are searched first, in the folders
of ``$FLIGHTTEST_VEHICLES`` (``os.pathsep``-separated) and then ``~/.config/flighttest/vehicles``;
a path to a ``.toml`` file works wherever a name does. ``flighttest identify --write-profile``
writes measured boundaries into the user folder, never into the package.

An optional ``[autopilot]`` table (``AutopilotLimits``) names the autopilot and the limits its position
control shapes setpoints with (ArduCopter's GUIDED: WP_ACC_Z, WP_ACC, WP_SPD_DN, WP_SPD_UP); the planners
keep every plan for the profile within them (``flighttest.planner.autopilot_limits``). No table: no limits.
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import tomli_w

from flighttest.errors import FlighttestError
from flighttest.inputs import (
    MARGIN_MPS,
    MAX_SPEED_MPS,
    MAX_TOML_BYTES,
    W_ALLOW_POSITIVE_MPS,
    InputFileError,
    Range,
    atomic_write,
    check_input_file,
    check_output_path,
    check_text,
    did_you_mean,
    shown,
)
from flighttest.model import aero
from flighttest.model.drag import DragModel
from flighttest.model.frames import GuardRegion
from flighttest.tomlfile import read_toml

SHIPPED_DIR = Path(__file__).with_name("profiles")


def user_dirs() -> list[Path]:
    env = os.environ.get("FLIGHTTEST_VEHICLES", "")
    dirs = [Path(p).expanduser() for p in env.split(os.pathsep) if p]
    dirs.append(Path("~/.config/flighttest/vehicles").expanduser())
    return dirs


@dataclass(frozen=True)
class VrsBoundary:
    """Where the vehicle must not go in blade-frame velocity, and where that knowledge came from."""

    cone_deg: float = aero.CONE_DEG
    w_allow_mps: float | None = None  # None: Onera's VRS boundary at v_H = 0
    margin_mps: float = 0.1
    onera_k: float = aero.ONERA_K
    eps_vrs: float = aero.ONERA_EPS_VRS
    eps_tws: float = aero.ONERA_EPS_TWS
    source: str = "paper defaults (Talaeizadeh et al.): 20° cone, Onera k=6, eps_cr=0.4"


# The autopilots whose names a profile's [autopilot] table may give: flighttest.flying.autopilot's names
# (the model layer does not import the flying layer; tests/test_autopilot_limits.py holds the two equal)
AUTOPILOT_NAMES = ("PX4", "ArduPilot")


@dataclass(frozen=True)
class AutopilotLimits:
    """The limits the autopilot's position control shapes the setpoints it is sent with (ArduCopter's
    GUIDED: WP_ACC_Z, WP_ACC, WP_SPD_DN, WP_SPD_UP). A plan that asks for more is flown late and
    overshoots, so the planners keep inside them (``flighttest.planner.autopilot_limits``). None: that
    limit does not apply. All positive: accelerations in m/s² (vertical, horizontal), speeds in m/s."""

    name: str
    accel_z_max_mps2: float | None = None
    accel_h_max_mps2: float | None = None
    descent_max_mps: float | None = None
    climb_max_mps: float | None = None
    # the jerk its position controller ramps accelerations with (ArduCopter: PSC_JERK_NE, PSC_JERK_D), m/s³
    jerk_h_max_mps3: float | None = None
    jerk_z_max_mps3: float | None = None

    def summary(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class VehicleProfile:
    name: str
    mass_kg: float
    n_rotors: int
    rotor_diameter_m: float
    arm_length_m: float
    inertia_kgm2: tuple[float, float, float]
    max_thrust_per_rotor_n: float
    max_rate_dps: tuple[float, float, float]
    max_tilt_deg: float
    description: str = ""
    air_density_kgpm3: float = 1.225
    min_thrust_per_rotor_n: float = 0.0
    max_speed_mps: float = 12.0
    max_climb_mps: float = 3.0
    yaw_moment_per_thrust_m: float = 0.016
    # linear drag, N per m/s of air-relative velocity (PX4 SIH's SIH_KDV model; 0 = none). The
    # autopilot's feed-forward knows nothing of it, so flighttest adds what it costs (feedforward.py)
    drag_n_per_mps: float = 0.0
    # how far inside the guard's bound a helix must be planned for this vehicle's tracking, at least (the
    # mission's guard_margin_mps is the other floor: plans keep the larger; flighttest.planner.tracking)
    tracking_margin_mps: float = 0.0
    # … and how fast its body may turn in a plan, at most, as a fraction of max_rate_dps (the mission's
    # rate_fraction is the other bound: plans keep the lower)
    tracking_rate_fraction: float = 1.0
    vrs: VrsBoundary = field(default_factory=VrsBoundary)
    # the autopilot's setpoint-shaping limits the plans must fit within (None: no table, none apply)
    autopilot: AutopilotLimits | None = None
    # the [drag] table: linear and quadratic per body axis, with its uncertainty (None: drag_n_per_mps alone)
    drag_model: DragModel | None = None
    path: str = ""

    # -- derived quantities -------------------------------------------------------------------------
    @property
    def rotor_radius_m(self) -> float:
        return 0.5 * self.rotor_diameter_m

    @property
    def disk_area_m2(self) -> float:
        return math.pi * self.rotor_radius_m**2

    @property
    def hover_thrust_per_rotor_n(self) -> float:
        return self.mass_kg * aero.G_MPS2 / self.n_rotors

    @property
    def v_h_mps(self) -> float:
        """Hover induced velocity per rotor (CONVENTIONS §1), m/s."""
        return float(
            aero.hover_induced_velocity_mps(self.hover_thrust_per_rotor_n, self.air_density_kgpm3, self.disk_area_m2)
        )

    @property
    def w_allow_mps(self) -> float:
        """Straight-down descent rate tolerated (m/s): measured if the profile says so, else Onera's."""
        if self.vrs.w_allow_mps is not None:
            return self.vrs.w_allow_mps
        return aero.onera_vertical_boundary_n(self.vrs.eps_vrs) * self.v_h_mps

    @property
    def w_allow_source(self) -> str:
        if self.vrs.w_allow_mps is not None:
            return self.vrs.source
        return f"Onera VRS boundary at v_H=0 (eps_cr={self.vrs.eps_vrs})"

    @property
    def thrust_to_weight(self) -> float:
        return self.n_rotors * self.max_thrust_per_rotor_n / (self.mass_kg * aero.G_MPS2)

    @property
    def max_accel_up_mps2(self) -> float:
        """Largest upward acceleration (level attitude, all rotors at max thrust), m/s²."""
        return self.n_rotors * self.max_thrust_per_rotor_n / self.mass_kg - aero.G_MPS2

    @property
    def max_accel_down_mps2(self) -> float:
        """Largest downward acceleration with thrust ≥ min thrust (no flips), m/s²."""
        return aero.G_MPS2 - self.n_rotors * self.min_thrust_per_rotor_n / self.mass_kg

    @property
    def drag(self) -> DragModel | None:
        """The drag across the thrust axis (``flighttest.model.drag``): the ``[drag]`` table, else
        ``drag_n_per_mps`` as an assumed linear model; None for a profile with neither (no wind estimate)."""
        if self.drag_model is not None:
            return self.drag_model
        if self.drag_n_per_mps > 0:
            source = f"drag_n_per_mps {self.drag_n_per_mps:g}, assumed"
            return DragModel.isotropic_linear(self.drag_n_per_mps, source=source)
        return None

    def guard_region(self, w_allow_mps: float | None = None, margin_mps: float | None = None) -> GuardRegion:
        return GuardRegion(
            w_allow_mps=self.w_allow_mps if w_allow_mps is None else w_allow_mps,
            v_h_mps=self.v_h_mps,
            cone_deg=self.vrs.cone_deg,
            margin_mps=self.vrs.margin_mps if margin_mps is None else margin_mps,
        )

    def summary(self) -> dict[str, Any]:
        """Plain snake_case numbers with units in the names, as ``--json`` prints them."""
        return {
            "name": self.name,
            "description": self.description,
            "path": self.path,
            "mass_kg": self.mass_kg,
            "n_rotors": self.n_rotors,
            "rotor_diameter_m": self.rotor_diameter_m,
            "arm_length_m": self.arm_length_m,
            "max_thrust_per_rotor_n": self.max_thrust_per_rotor_n,
            "thrust_to_weight": round(self.thrust_to_weight, 4),
            "max_tilt_deg": self.max_tilt_deg,
            "air_density_kgpm3": self.air_density_kgpm3,
            "v_h_mps": round(self.v_h_mps, 4),
            "w_allow_mps": round(self.w_allow_mps, 4),
            "w_allow_n": round(self.w_allow_mps / self.v_h_mps, 4),
            "w_allow_source": self.w_allow_source,
            "cone_deg": self.vrs.cone_deg,
            "margin_mps": self.vrs.margin_mps,
            "tracking_margin_mps": self.tracking_margin_mps,
            "tracking_rate_fraction": self.tracking_rate_fraction,
            "autopilot": self.autopilot.summary() if self.autopilot is not None else None,
            "drag": self.drag.to_table() if self.drag is not None else None,
        }


# -- loading and validation -------------------------------------------------------------------------

# Every field has a type and a physical range (flighttest.inputs.Range). The ranges are wide — from
# a 1 g nano-quadcopter to a 500 kg lifter — but finite, so the derived figures (v_h, w_allow,
# accelerations) are finite too; a profile that passes them but still yields absurd derived figures
# is refused by _check_derived.
_NAME = "name"
_TEXT = "text"
_TOP_REQUIRED: dict[str, Any] = {
    "name": _NAME,
    "mass_kg": Range(0.001, 500.0, "kg"),
    "n_rotors": Range(3, 16, integer=True),
    "rotor_diameter_m": Range(0.01, 3.0, "m"),
    "arm_length_m": Range(0.01, 5.0, "m"),
    "inertia_kgm2": (Range(1e-8, 1000.0, "kg·m²"), 3),
    "max_thrust_per_rotor_n": Range(0.0, 5000.0, "N", lo_open=True),
    "max_rate_dps": (Range(1.0, 3600.0, "°/s"), 3),
    "max_tilt_deg": Range(0.0, 90.0, "°", lo_open=True, hi_open=True),
}
_TOP_OPTIONAL: dict[str, Any] = {
    "description": _TEXT,
    # sea level 1.225; 0.2 is above 12 km, 1.8 colder and denser than any surface air
    "air_density_kgpm3": Range(0.2, 1.8, "kg/m³"),
    "min_thrust_per_rotor_n": Range(0.0, 5000.0, "N"),
    "max_speed_mps": Range(0.0, MAX_SPEED_MPS, "m/s", lo_open=True),
    "max_climb_mps": Range(0.0, 50.0, "m/s", lo_open=True),
    "yaw_moment_per_thrust_m": Range(0.0, 1.0, "m", lo_open=True),
    "drag_n_per_mps": Range(0.0, 1000.0, "N·s/m"),
    "tracking_margin_mps": Range(0.0, 5.0, "m/s"),
    "tracking_rate_fraction": Range(0.0, 1.0, "", lo_open=True),
}
_VRS_FIELDS: dict[str, Any] = {
    "cone_deg": Range(0.0, 90.0, "°", lo_open=True, hi_open=True),
    "w_allow_mps": W_ALLOW_POSITIVE_MPS,
    "margin_mps": MARGIN_MPS,
    "onera_k": Range(0.0, 100.0, lo_open=True),
    "eps_vrs": Range(0.0, 5.0, lo_open=True),
    "eps_tws": Range(0.0, 5.0, lo_open=True),
    "source": _TEXT,
}
_AUTOPILOT_FIELDS: dict[str, Any] = {
    "name": _TEXT,
    # any positive limit up to 10 g for the accelerations (past any multicopter's), as fast as any speed
    "accel_z_max_mps2": Range(0.0, 100.0, "m/s²", lo_open=True),
    "accel_h_max_mps2": Range(0.0, 100.0, "m/s²", lo_open=True),
    "descent_max_mps": Range(0.0, MAX_SPEED_MPS, "m/s", lo_open=True),
    "climb_max_mps": Range(0.0, MAX_SPEED_MPS, "m/s", lo_open=True),
    "jerk_h_max_mps3": Range(0.0, 1000.0, "m/s³", lo_open=True),
    "jerk_z_max_mps3": Range(0.0, 1000.0, "m/s³", lo_open=True),
}
MAX_V_H_MPS = 50.0  # hover induced velocity: ~4 m/s on a Mambo, ~15 m/s on heavy lifters
MAX_THRUST_TO_WEIGHT = 30.0  # racing quadcopters reach ~15


def _bad(path: Path | str, key: str, why: str) -> FlighttestError:
    return FlighttestError(f"{path}: field '{key}' {why}")


def _check_value(path, key: str, value: Any, kind) -> Any:
    if isinstance(kind, tuple):
        elem, n = kind
        if not isinstance(value, list) or len(value) != n:
            raise _bad(path, key, f"must be a list of {n} numbers (got {shown(value)})")
        return tuple(_check_value(path, f"{key}[{i}]", v, elem) for i, v in enumerate(value))
    if kind is _NAME:
        # the name becomes part of file names (vehicles/NAME.toml, trajectories/helix-NAME-…)
        if not isinstance(value, str) or not value.strip() or len(value) > 64 or _NAME_BAD.search(value):
            raise _bad(path, key, f"must be a name of 1-64 characters without / \\ or control characters "
                                  f"(got {shown(value)})")  # fmt: skip
        return value
    if kind is _TEXT:
        try:
            return check_text(value, "", max_chars=MAX_TEXT_CHARS)
        except FlighttestError as exc:
            raise _bad(path, key, str(exc).strip()) from None
    if not kind.ok(value):
        raise _bad(path, key, f"must be {kind.describe()} (got {shown(value)})")
    return int(value) if kind.integer else float(value)


_NAME_BAD = re.compile(r"[/\\\x00-\x1f\x7f]")
MAX_TEXT_CHARS = 2000  # a profile's free text (description, the boundary's source)


def _check_derived(prof: VehicleProfile, path: Path | str) -> None:
    """The figures everything else divides by must come out finite and physical."""
    try:
        figures = {
            "v_h_mps": prof.v_h_mps,
            "w_allow_mps": prof.w_allow_mps,
            "thrust_to_weight": prof.thrust_to_weight,
            "max_accel_up_mps2": prof.max_accel_up_mps2,
            "max_accel_down_mps2": prof.max_accel_down_mps2,
        }
        figures["w_allow_n"] = figures["w_allow_mps"] / figures["v_h_mps"]
    except (ArithmeticError, ValueError) as exc:
        raise FlighttestError(f"{path}: the profile's derived figures cannot be computed ({exc})") from None
    for name, value in figures.items():
        if not (math.isfinite(value) and value > 0):
            raise FlighttestError(f"{path}: derived {name} = {value!r} is not a finite positive number")
    if figures["v_h_mps"] > MAX_V_H_MPS:
        raise FlighttestError(
            f"{path}: hover induced velocity v_h = {figures['v_h_mps']:.3g} m/s is not physical (at most "
            f"{MAX_V_H_MPS:g}; are the rotors too small for the mass, or the air too thin?)"
        )
    if figures["thrust_to_weight"] > MAX_THRUST_TO_WEIGHT:
        raise _bad(
            path,
            "max_thrust_per_rotor_n",
            f"gives thrust/weight {figures['thrust_to_weight']:.3g} (at most {MAX_THRUST_TO_WEIGHT:g})",
        )


def profile_from_dict(data: dict[str, Any], path: Path | str = "<profile>") -> VehicleProfile:
    """Validate a parsed TOML document into a profile; any problem is one FlighttestError line."""
    if not isinstance(data, dict):
        raise FlighttestError(f"{path}: a vehicle profile must be a TOML table")
    known = set(_TOP_REQUIRED) | set(_TOP_OPTIONAL) | {"vrs", "autopilot", "drag"}
    for key in data:
        if key not in known:
            raise _bad(path, shown(key, 40).strip("'"), "is not a known profile field")
    kwargs: dict[str, Any] = {}
    for key, kind in _TOP_REQUIRED.items():
        if key not in data:
            raise _bad(path, key, "is missing")
        kwargs[key] = _check_value(path, key, data[key], kind)
    for key, kind in _TOP_OPTIONAL.items():
        if key in data:
            kwargs[key] = _check_value(path, key, data[key], kind)
    vrs_raw = data.get("vrs", {})
    if not isinstance(vrs_raw, dict):
        raise _bad(path, "vrs", "must be a table")
    vrs_kwargs: dict[str, Any] = {}
    for key, value in vrs_raw.items():
        if key not in _VRS_FIELDS:
            raise _bad(path, f"vrs.{shown(key, 40).strip(chr(39))}", "is not a known field")
        vrs_kwargs[key] = _check_value(path, f"vrs.{key}", value, _VRS_FIELDS[key])
    vrs = VrsBoundary(**vrs_kwargs)
    if vrs.eps_tws > vrs.eps_vrs:
        raise _bad(path, "vrs.eps_tws", "must not exceed vrs.eps_vrs (the TWS lies inside the VRS)")
    autopilot = _autopilot_from(data["autopilot"], path) if "autopilot" in data else None
    drag = _drag_from(data["drag"], path) if "drag" in data else None
    prof = VehicleProfile(**kwargs, vrs=vrs, autopilot=autopilot, drag_model=drag, path=str(path))
    if prof.thrust_to_weight <= 1.0:
        twr = prof.thrust_to_weight
        raise _bad(path, "max_thrust_per_rotor_n", f"cannot lift the vehicle (thrust/weight {twr:.2f})")
    if prof.min_thrust_per_rotor_n >= prof.hover_thrust_per_rotor_n:
        raise _bad(path, "min_thrust_per_rotor_n", "must be below the hover thrust per rotor")
    _check_derived(prof, path)
    return prof


def _autopilot_from(raw: Any, path: Path | str) -> AutopilotLimits:
    """The ``[autopilot]`` table: which autopilot, and the limits its position control shapes setpoints with."""
    if not isinstance(raw, dict):
        raise _bad(path, "autopilot", "must be a table")
    values: dict[str, Any] = {}
    for key, value in raw.items():
        if key not in _AUTOPILOT_FIELDS:
            raise _bad(path, f"autopilot.{shown(key, 40).strip(chr(39))}", "is not a known field")
        values[key] = _check_value(path, f"autopilot.{key}", value, _AUTOPILOT_FIELDS[key])
    if "name" not in values:
        raise _bad(path, "autopilot.name", f"is missing (one of {', '.join(AUTOPILOT_NAMES)})")
    if values["name"] not in AUTOPILOT_NAMES:
        raise _bad(path, "autopilot.name", f"must be one of {', '.join(AUTOPILOT_NAMES)} (got {shown(values['name'])})")
    return AutopilotLimits(**values)


DRAG_N_PER_MPS = Range(0.0, 1000.0, "N·s/m")
DRAG_N_PER_MPS2 = Range(0.0, 1000.0, "N·s²/m²")
DRAG_REL_SD = Range(0.0, 10.0)


def _drag_from(raw: Any, path: Path | str) -> DragModel:
    """The ``[drag]`` table, each number in its range."""
    if not isinstance(raw, dict):
        raise _bad(path, "drag", "must be a table")
    for key, value in raw.items():
        kind = {"linear_n_per_mps": DRAG_N_PER_MPS, "quadratic_n_per_mps2": DRAG_N_PER_MPS2}.get(key)
        if kind is not None:
            for i, x in enumerate(value if isinstance(value, list) else [value]):
                _check_value(path, f"drag.{key}[{i}]", x, kind)
        elif key == "rel_sd":
            _check_value(path, "drag.rel_sd", value, DRAG_REL_SD)
        elif key == "source":
            _check_value(path, "drag.source", value, _TEXT)
    try:
        return DragModel.from_table(raw)
    except ValueError as exc:
        raise FlighttestError(f"{path}: {exc}") from None


def load_profile_file(path: Path | str) -> VehicleProfile:
    path = Path(path)
    data = read_toml(path, "vehicle profile")
    return profile_from_dict(data, path)


def _candidates() -> dict[str, Path]:
    """Profile name → file; user folders shadow shipped profiles."""
    found: dict[str, Path] = {}
    for d in [SHIPPED_DIR, *reversed(user_dirs())]:
        try:
            files = sorted(f for f in d.glob("*.toml") if not f.is_dir()) if d.is_dir() else []
        except OSError:  # an unreadable folder in $FLIGHTTEST_VEHICLES holds no profiles we can use
            files = []
        for f in files:
            found[f.stem] = f
    return found


def scan_profiles() -> tuple[list[VehicleProfile], list[str]]:
    """Every profile that loads, and one line per file that does not (``vehicle list`` shows both:
    one damaged file in a user folder must not hide the others)."""
    good: list[VehicleProfile] = []
    bad: list[str] = []
    for _, p in sorted(_candidates().items()):
        try:
            good.append(load_profile_file(p))
        except FlighttestError as exc:
            bad.append(str(exc))
    return good, bad


def list_profiles() -> list[VehicleProfile]:
    """The profiles that load (see :func:`scan_profiles` for the ones that do not)."""
    return scan_profiles()[0]


def load_profile(name_or_path: str | Path) -> VehicleProfile:
    """A profile by name (user folders first, then shipped) or by path to a ``.toml`` file."""
    s = str(name_or_path)
    if not s.strip():
        raise FlighttestError("vehicle: the name is empty (a profile name or a .toml path)")
    if s.endswith(".toml") or os.sep in s or "/" in s:
        try:
            check_input_file(s, "vehicle profile file", MAX_TOML_BYTES)
        except InputFileError as exc:
            if exc.reason == "not found":
                raise FlighttestError(f"vehicle profile file not found: {s}") from None
            raise
        return load_profile_file(s)
    cands = _candidates()
    if s not in cands:
        known = ", ".join(sorted(cands)) or "none"
        raise FlighttestError(f"unknown vehicle {shown(s)}{did_you_mean(s, cands)} (known: {known})")
    return load_profile_file(cands[s])


# what a flight's meta.json vehicle summary fixes for judging it later: v_h (mass, rotors, air) and the guard
# region (w_allow, cone, margin); the rest of the profile (inertia, rates) does not enter the analysis
AS_FLOWN_FIELDS = ("mass_kg", "n_rotors", "rotor_diameter_m", "air_density_kgpm3")
AS_FLOWN_VRS_FIELDS = ("w_allow_mps", "cone_deg", "margin_mps")


def profile_as_flown(profile: VehicleProfile, summary: Any, where: str = "meta.json") -> VehicleProfile:
    """``profile`` with the figures a flight flew with (``summary``: its ``summary()`` as ``meta.json``
    holds it): a profile since rewritten (``identify --write-profile``) must not re-judge old flights.
    A summary without these figures, or with one out of range, is one ``FlighttestError`` line."""
    if not isinstance(summary, dict):
        raise FlighttestError(f"{where}: no vehicle summary to judge the flight with")
    top = {k: _check_value(where, f"vehicle.{k}", summary[k], {**_TOP_REQUIRED, **_TOP_OPTIONAL}[k])
           for k in AS_FLOWN_FIELDS if k in summary}  # fmt: skip
    vrs = {k: _check_value(where, f"vehicle.{k}", summary[k], _VRS_FIELDS[k]) for k in AS_FLOWN_VRS_FIELDS
           if k in summary}  # fmt: skip
    if "w_allow_mps" not in vrs:
        raise FlighttestError(f"{where}: the vehicle summary has no w_allow_mps to judge the flight with")
    source = summary.get("w_allow_source")
    vrs["source"] = f"as flown ({where}): {source}" if isinstance(source, str) and source else f"as flown ({where})"
    return replace(profile, **top, vrs=replace(profile.vrs, **vrs))


def profile_to_dict(profile: VehicleProfile) -> dict[str, Any]:
    d = asdict(profile)
    d.pop("path")
    d["inertia_kgm2"] = list(profile.inertia_kgm2)
    d["max_rate_dps"] = list(profile.max_rate_dps)
    vrs = {k: v for k, v in d.pop("vrs").items() if v is not None}
    d["vrs"] = vrs
    autopilot = d.pop("autopilot")
    if autopilot is not None:  # TOML has no null: a limit that does not apply is left out
        d["autopilot"] = {k: v for k, v in autopilot.items() if v is not None}
    d.pop("drag_model")
    if profile.drag_model is not None:
        d["drag"] = profile.drag_model.to_table()
    return d


# Where a measured onset (a stored w_allow) can lie for a vehicle, relative to Onera's straight-down
# boundaries for the profile's own ε (aero.onera_vertical_boundary_n; defaults: the VRS is entered at
# 0.135 v_h, its core, the TWS, at 0.415 v_h, and left at 1.335 v_h). The paper's measured Mambo onset
# sits on Onera's entry; a third of it (0.045 v_h) leaves room for a rotor whose wake the frame disturbs
# early, and below it an "onset" is hover noise plus the descent's own accelerations. Past 1.5× the TWS
# entry (0.62 v_h) the ring would have to be fully formed and still calm: a rise found there is not the
# entry into the VRS. Below the guard's margin a boundary would leave the guard no descent to allow.
ONSET_MIN_OF_VRS_ENTRY = 1.0 / 3.0
ONSET_MAX_OF_TWS_ENTRY = 1.5


def plausible_w_allow_range(profile: VehicleProfile) -> tuple[float, float]:
    """``(lo, hi)`` m/s: a measured onset must lie strictly above ``lo`` and at most ``hi`` (see above)."""
    entry = aero.onera_vertical_boundary_n(profile.vrs.eps_vrs) * profile.v_h_mps
    core = aero.onera_vertical_boundary_n(profile.vrs.eps_tws) * profile.v_h_mps
    return max(profile.vrs.margin_mps, ONSET_MIN_OF_VRS_ENTRY * entry), ONSET_MAX_OF_TWS_ENTRY * core


def write_drag(profile: VehicleProfile, drag: DragModel, target: Path | None = None) -> Path:
    """Store an identified drag model in the user's copy of the profile (or in ``target``), its ``drag_n_per_mps``
    (the feed-forward's one coefficient) set from it too."""
    updated = replace(profile, drag_model=drag, drag_n_per_mps=round(drag.mean_linear_n_per_mps(), 4))
    return _write_profile(profile, updated, target)


def _write_profile(profile: VehicleProfile, updated: VehicleProfile, target: Path | None) -> Path:
    """``updated`` written where a measured value of ``profile`` belongs (:func:`w_allow_target`)."""
    target = w_allow_target(profile, target)
    try:
        with atomic_write(target) as tmp:
            tmp.write_text(tomli_w.dumps(profile_to_dict(updated)), encoding="utf-8")
    except OSError as exc:
        raise FlighttestError(f"cannot write the profile {target}: {exc.strerror or exc}") from None
    return target


def write_w_allow(profile: VehicleProfile, w_allow_mps: float, source: str, target: Path | None = None) -> Path:
    """Store a measured ``w_allow`` (with its provenance) in the user's copy of the profile, or in ``target``.
    A value the model cannot explain for this vehicle (:func:`plausible_w_allow_range`) is refused here
    too, whoever measured it: every later plan and guard would trust it."""
    if not (isinstance(w_allow_mps, int | float) and math.isfinite(w_allow_mps) and w_allow_mps > 0):
        raise FlighttestError(f"refusing to store w_allow={w_allow_mps!r}: must be a positive number")
    lo, hi = plausible_w_allow_range(profile)
    if not lo < w_allow_mps <= hi:
        raise FlighttestError(
            f"refusing to store w_allow={w_allow_mps:.4g} m/s for {profile.name}: not a plausible VRS onset "
            f"(must lie above {lo:.3f} m/s — the guard margin and a third of Onera's entry — and at most "
            f"{hi:.3f} m/s, 1.5× Onera's TWS entry; v_h {profile.v_h_mps:.2f} m/s)"
        )
    # what the loader refuses is never stored: every later command would stop on the profile
    source = check_text(source, "the w_allow source", max_chars=MAX_TEXT_CHARS)
    updated = replace(profile, vrs=replace(profile.vrs, w_allow_mps=float(w_allow_mps), source=source))
    return _write_profile(profile, updated, target)


def w_allow_target(profile: VehicleProfile, target: Path | str | None = None) -> Path:
    """The file :func:`write_w_allow` writes (``target``, else the profile itself when it is a user copy, else
    its copy in the first user folder), checked as an output: a folder there, a FIFO, a user folder that is
    a file or not writable is one line — callers check it before the work whose result it stores."""
    if target is None:
        src = Path(profile.path)
        in_user_dir = src.parent.resolve() in {d.resolve() for d in user_dirs()}
        target = src if in_user_dir else user_dirs()[0] / src.name
    return check_output_path(target, "the profile to write")
