"""Vehicle profiles: TOML files describing a quadcopter and its VRS boundary, validated on load.

Shipped profiles live in ``flighttest/profiles/``. User profiles are searched first, in the folders
of ``$FLIGHTTEST_VEHICLES`` (``os.pathsep``-separated) and then ``~/.config/flighttest/vehicles``;
a path to a ``.toml`` file works wherever a name does. ``flighttest identify --write-profile``
writes measured boundaries into the user folder, never into the package.
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import tomli_w

from flighttest import aero
from flighttest.errors import FlighttestError
from flighttest.frames import GuardRegion
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
    vrs: VrsBoundary = field(default_factory=VrsBoundary)
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
        """Hover induced velocity per rotor (NOTES §1), m/s."""
        return float(
            aero.hover_induced_velocity_mps(
                self.hover_thrust_per_rotor_n, self.air_density_kgpm3, self.disk_area_m2
            )
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
        }


# -- loading and validation -------------------------------------------------------------------------

_TOP_REQUIRED = {
    "name": str,
    "mass_kg": float,
    "n_rotors": int,
    "rotor_diameter_m": float,
    "arm_length_m": float,
    "inertia_kgm2": (float, 3),
    "max_thrust_per_rotor_n": float,
    "max_rate_dps": (float, 3),
    "max_tilt_deg": float,
}
_TOP_OPTIONAL = {
    "description": str,
    "air_density_kgpm3": float,
    "min_thrust_per_rotor_n": float,
    "max_speed_mps": float,
    "max_climb_mps": float,
    "yaw_moment_per_thrust_m": float,
}
_VRS_FIELDS = {
    "cone_deg": float,
    "w_allow_mps": float,
    "margin_mps": float,
    "onera_k": float,
    "eps_vrs": float,
    "eps_tws": float,
    "source": str,
}
# fields that may be zero; every other number must be > 0
_NON_NEGATIVE = {"min_thrust_per_rotor_n", "margin_mps"}


def _bad(path: Path | str, key: str, why: str) -> FlighttestError:
    return FlighttestError(f"{path}: field '{key}' {why}")


def _check_value(path, key: str, value: Any, kind) -> Any:
    if isinstance(kind, tuple):
        elem, n = kind
        if not isinstance(value, list) or len(value) != n:
            raise _bad(path, key, f"must be a list of {n} numbers (got {value!r})")
        return tuple(_check_value(path, f"{key}[{i}]", v, elem) for i, v in enumerate(value))
    if kind is str:
        if not isinstance(value, str):
            raise _bad(path, key, f"must be a string (got {value!r})")
        return value
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise _bad(path, key, f"must be a positive integer (got {value!r})")
        return value
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise _bad(path, key, f"must be a finite number (got {value!r})")
    base = key.split("[")[0].split(".")[-1]
    if base in _NON_NEGATIVE:
        if value < 0:
            raise _bad(path, key, f"must be ≥ 0 (got {value!r})")
    elif value <= 0:
        raise _bad(path, key, f"must be > 0 (got {value!r})")
    return float(value)


def profile_from_dict(data: dict[str, Any], path: Path | str = "<profile>") -> VehicleProfile:
    """Validate a parsed TOML document into a profile; any problem is one FlighttestError line."""
    known = set(_TOP_REQUIRED) | set(_TOP_OPTIONAL) | {"vrs"}
    for key in data:
        if key not in known:
            raise _bad(path, key, "is not a known profile field")
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
            raise _bad(path, f"vrs.{key}", "is not a known field")
        vrs_kwargs[key] = _check_value(path, f"vrs.{key}", value, _VRS_FIELDS[key])
    vrs = VrsBoundary(**vrs_kwargs)
    if not 0 < vrs.cone_deg < 90:
        raise _bad(path, "vrs.cone_deg", f"must lie in (0, 90) degrees (got {vrs.cone_deg})")
    if vrs.eps_tws > vrs.eps_vrs:
        raise _bad(path, "vrs.eps_tws", "must not exceed vrs.eps_vrs (the TWS lies inside the VRS)")
    if not 0 < kwargs["max_tilt_deg"] < 90:
        raise _bad(path, "max_tilt_deg", f"must lie in (0, 90) degrees (got {kwargs['max_tilt_deg']})")
    prof = VehicleProfile(**kwargs, vrs=vrs, path=str(path))
    if prof.thrust_to_weight <= 1.0:
        twr = prof.thrust_to_weight
        raise _bad(path, "max_thrust_per_rotor_n", f"cannot lift the vehicle (thrust/weight {twr:.2f})")
    if prof.min_thrust_per_rotor_n >= prof.hover_thrust_per_rotor_n:
        raise _bad(path, "min_thrust_per_rotor_n", "must be below the hover thrust per rotor")
    return prof


def load_profile_file(path: Path | str) -> VehicleProfile:
    path = Path(path)
    data = read_toml(path, "vehicle profile")
    return profile_from_dict(data, path)


def _candidates() -> dict[str, Path]:
    """Profile name → file; user folders shadow shipped profiles."""
    found: dict[str, Path] = {}
    for d in [SHIPPED_DIR, *reversed(user_dirs())]:
        if d.is_dir():
            for f in sorted(d.glob("*.toml")):
                found[f.stem] = f
    return found


def list_profiles() -> list[VehicleProfile]:
    return [load_profile_file(p) for _, p in sorted(_candidates().items())]


def load_profile(name_or_path: str | Path) -> VehicleProfile:
    """A profile by name (user folders first, then shipped) or by path to a ``.toml`` file."""
    s = str(name_or_path)
    if s.endswith(".toml") or os.sep in s:
        if not Path(s).is_file():
            raise FlighttestError(f"vehicle profile file not found: {s}")
        return load_profile_file(s)
    cands = _candidates()
    if s not in cands:
        known = ", ".join(sorted(cands)) or "none"
        raise FlighttestError(f"unknown vehicle '{s}' (known: {known})")
    return load_profile_file(cands[s])


def profile_to_dict(profile: VehicleProfile) -> dict[str, Any]:
    d = asdict(profile)
    d.pop("path")
    d["inertia_kgm2"] = list(profile.inertia_kgm2)
    d["max_rate_dps"] = list(profile.max_rate_dps)
    vrs = {k: v for k, v in d.pop("vrs").items() if v is not None}
    d["vrs"] = vrs
    return d


def write_w_allow(profile: VehicleProfile, w_allow_mps: float, source: str, target: Path | None = None) -> Path:
    """Store a measured ``w_allow`` (with its provenance) in the user's copy of the profile, or in ``target``."""
    if not (math.isfinite(w_allow_mps) and w_allow_mps > 0):
        raise FlighttestError(f"refusing to store w_allow={w_allow_mps!r}: must be a positive number")
    updated = replace(profile, vrs=replace(profile.vrs, w_allow_mps=float(w_allow_mps), source=source))
    if target is None:
        src = Path(profile.path)
        in_user_dir = src.parent.resolve() in {d.resolve() for d in user_dirs()}
        target = src if in_user_dir else user_dirs()[0] / src.name
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_suffix(".toml.tmp")
    tmp.write_text(tomli_w.dumps(profile_to_dict(updated)), encoding="utf-8")
    tmp.replace(target)
    return target
