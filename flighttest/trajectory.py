"""Trajectory files: one format for every planner output, a validating loader, and resampling.

A trajectory is a CSV ``NAME.csv`` (for people and spreadsheets) plus a JSON sidecar ``NAME.json``
with the same stem (metadata). See docs/CONTRACTS.md "Trajectory files".

CSV columns (required): ``t_s, n_m, e_m, d_m, vn_mps, ve_mps, vd_mps, an_mps2, ae_mps2, ad_mps2,
yaw_deg``; optional: ``qw, qx, qy, qz, thrust_n`` (collective), ``roll_deg, pitch_deg``.
Positions are NED relative to the start point (first row 0, 0, 0; descending means ``d_m`` grows).

Sidecar keys: ``format`` (``"flighttest-trajectory/1"``), ``kind`` (planar|helix|vertical|probe),
``vehicle``, ``problem``, ``status``, ``objective``, ``t_f_s``, ``solve_s``, ``flighttest_version``,
plus kind-specific extras (the probe's ``speed_first_reached``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from flighttest import __version__
from flighttest.aero import G_MPS2
from flighttest.errors import FlighttestError
from flighttest.frames import quat_to_rotmat

if TYPE_CHECKING:
    from flighttest.profiles import VehicleProfile

FORMAT = "flighttest-trajectory/1"
KINDS = ("planar", "helix", "vertical", "probe")
REQUIRED_COLUMNS = (
    "t_s", "n_m", "e_m", "d_m",
    "vn_mps", "ve_mps", "vd_mps",
    "an_mps2", "ae_mps2", "ad_mps2",
    "yaw_deg",
)  # fmt: skip
OPTIONAL_COLUMNS = ("qw", "qx", "qy", "qz", "thrust_n", "roll_deg", "pitch_deg")
QUAT_COLUMNS = ("qw", "qx", "qy", "qz")
REQUIRED_META = ("format", "kind", "vehicle", "problem", "status", "t_f_s")

# Tolerances of the loader's limit checks: planners work to solver tolerance, so a hair over a
# bound is numerics, not a plan that breaks the vehicle.
START_TOL_M = 1e-3
LIMIT_REL_TOL = 0.01
TILT_TOL_DEG = 0.5
QUAT_NORM_TOL = 1e-3


def _paths(path: Path | str) -> tuple[Path, Path]:
    """``(csv, json)`` paths for ``NAME``, ``NAME.csv`` or ``NAME.json``."""
    p = Path(path)
    stem = p.with_suffix("") if p.suffix.lower() in {".csv", ".json"} else p
    return stem.with_name(stem.name + ".csv"), stem.with_name(stem.name + ".json")


@dataclass
class Trajectory:
    """Time-stamped NED reference (``df``, one row per sample) and its metadata (``meta``)."""

    df: pd.DataFrame
    meta: dict[str, Any] = field(default_factory=dict)

    # -- construction -----------------------------------------------------------------------------
    @classmethod
    def from_arrays(cls, meta: dict[str, Any], **columns: Any) -> Trajectory:
        """Build from column arrays (names as in the CSV); fills ``format``/``version``/``t_f_s``."""
        unknown = set(columns) - set(REQUIRED_COLUMNS) - set(OPTIONAL_COLUMNS)
        if unknown:
            raise ValueError(f"unknown trajectory columns: {sorted(unknown)}")
        order = [c for c in (*REQUIRED_COLUMNS, *OPTIONAL_COLUMNS) if c in columns]
        df = pd.DataFrame({c: np.asarray(columns[c], dtype=float) for c in order})
        full = {"format": FORMAT, "flighttest_version": __version__, **meta}
        full.setdefault("t_f_s", float(df["t_s"].iloc[-1] - df["t_s"].iloc[0]))
        traj = cls(df=df, meta=full)
        traj.validate()
        return traj

    # -- accessors --------------------------------------------------------------------------------
    @property
    def t_s(self) -> np.ndarray:
        return self.df["t_s"].to_numpy()

    @property
    def duration_s(self) -> float:
        return float(self.df["t_s"].iloc[-1] - self.df["t_s"].iloc[0])

    @property
    def kind(self) -> str:
        return str(self.meta.get("kind", ""))

    def column(self, name: str) -> np.ndarray:
        return self.df[name].to_numpy()

    def has_attitude(self) -> bool:
        return all(c in self.df for c in QUAT_COLUMNS)

    def attitude_quat(self) -> np.ndarray | None:
        """(N, 4) quaternions body → NED, or None when the planner's model has no attitude."""
        if not self.has_attitude():
            return None
        return self.df[list(QUAT_COLUMNS)].to_numpy()

    # -- validation -------------------------------------------------------------------------------
    def validate(self, profile: VehicleProfile | None = None, where: str = "trajectory") -> None:
        """Raise ``FlighttestError`` (one line) unless the data is well formed and, with a profile,
        flyable by that vehicle: speed, climb rate, tilt and collective thrust within its limits."""
        df = self.df
        missing = [c for c in REQUIRED_COLUMNS if c not in df]
        if missing:
            raise FlighttestError(f"{where}: missing column(s) {', '.join(missing)}")
        extra = [c for c in df.columns if c not in REQUIRED_COLUMNS and c not in OPTIONAL_COLUMNS]
        if extra:
            raise FlighttestError(f"{where}: unknown column(s) {', '.join(map(str, extra))}")
        quat_present = [c for c in QUAT_COLUMNS if c in df]
        if quat_present and len(quat_present) != 4:
            raise FlighttestError(f"{where}: attitude needs all of qw, qx, qy, qz")
        if len(df) < 2:
            raise FlighttestError(f"{where}: needs at least 2 rows (has {len(df)})")
        try:
            values = df.to_numpy(dtype=float)
        except (TypeError, ValueError):
            raise FlighttestError(f"{where}: non-numeric values") from None
        bad = ~np.isfinite(values)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise FlighttestError(f"{where}: non-finite value in column '{df.columns[col]}' at row {row + 1}")
        t = df["t_s"].to_numpy()
        if abs(t[0]) > 1e-9:
            raise FlighttestError(f"{where}: time must start at 0 s (starts at {t[0]:g} s)")
        steps = np.diff(t)
        if (steps <= 0).any():
            i = int(np.argmax(steps <= 0))
            raise FlighttestError(f"{where}: time not strictly increasing at row {i + 2} (t={t[i + 1]:g} s)")
        start = df[["n_m", "e_m", "d_m"]].iloc[0].to_numpy()
        if np.abs(start).max() > START_TOL_M:
            raise FlighttestError(f"{where}: positions must be relative to the start (first row {start.tolist()})")
        if quat_present:
            q = self.attitude_quat()
            norm = np.linalg.norm(q, axis=1)
            if np.abs(norm - 1.0).max() > QUAT_NORM_TOL:
                i = int(np.argmax(np.abs(norm - 1.0)))
                raise FlighttestError(f"{where}: quaternion at row {i + 1} is not unit length (|q|={norm[i]:.4f})")
        meta_missing = [k for k in REQUIRED_META if k not in self.meta]
        if meta_missing:
            raise FlighttestError(f"{where}: metadata lacks {', '.join(meta_missing)}")
        if self.meta["format"] != FORMAT:
            raise FlighttestError(f"{where}: unknown format {self.meta['format']!r} (expected {FORMAT!r})")
        if self.meta["kind"] not in KINDS:
            raise FlighttestError(f"{where}: unknown kind {self.meta['kind']!r} (one of {', '.join(KINDS)})")
        if profile is not None:
            self._check_limits(profile, where)

    def _check_limits(self, profile: VehicleProfile, where: str) -> None:
        df = self.df
        tol = 1.0 + LIMIT_REL_TOL
        v = df[["vn_mps", "ve_mps", "vd_mps"]].to_numpy()
        speed = np.linalg.norm(v, axis=1)
        _limit(where, "speed", speed, profile.max_speed_mps * tol, "m/s", df)
        _limit(where, "climb rate", -v[:, 2], profile.max_climb_mps * tol, "m/s", df)
        # Specific force the rotors must produce: a − g (NED); its size is thrust/mass.
        spec = df[["an_mps2", "ae_mps2", "ad_mps2"]].to_numpy() - np.array([0.0, 0.0, G_MPS2])
        max_thrust_n = profile.n_rotors * profile.max_thrust_per_rotor_n
        min_thrust_n = profile.n_rotors * profile.min_thrust_per_rotor_n
        if "thrust_n" in df:
            thrust = df["thrust_n"].to_numpy()
            _limit(where, "collective thrust", thrust, max_thrust_n * tol, "N", df)
            low = thrust < min_thrust_n - LIMIT_REL_TOL * max_thrust_n
            if low.any():
                i = int(np.argmax(low))
                raise FlighttestError(
                    f"{where}: collective thrust {thrust[i]:.3g} N at t={df['t_s'].iloc[i]:.3f} s is below the "
                    f"vehicle minimum ({min_thrust_n:.3g} N; fixed-pitch rotors cannot reverse)"
                )
        else:
            _limit(where, "required thrust", np.linalg.norm(spec, axis=1) * profile.mass_kg, max_thrust_n * tol,
                   "N", df)  # fmt: skip
        if self.has_attitude():
            r = quat_to_rotmat(self.attitude_quat())
            tilt = np.degrees(np.arccos(np.clip(r[:, 2, 2], -1.0, 1.0)))
        else:
            # Without attitude, the tilt is where the specific force points (thrust along −z_body).
            up = -spec[:, 2] / np.maximum(np.linalg.norm(spec, axis=1), 1e-9)
            tilt = np.degrees(np.arccos(np.clip(up, -1.0, 1.0)))
        _limit(where, "tilt", tilt, profile.max_tilt_deg + TILT_TOL_DEG, "deg", df)

    # -- files ------------------------------------------------------------------------------------
    def save(self, path: Path | str) -> tuple[Path, Path]:
        """Write ``NAME.csv`` and ``NAME.json``; returns both paths."""
        csv_path, json_path = _paths(path)
        csv_path.parent.mkdir(parents=True, exist_ok=True)
        self.df.to_csv(csv_path, index=False, float_format="%.9g")
        json_path.write_text(json.dumps(_json_safe(self.meta), indent=2) + "\n", encoding="utf-8")
        return csv_path, json_path

    @classmethod
    def load(cls, path: Path | str, profile: VehicleProfile | None = None) -> Trajectory:
        """Read and validate a trajectory (``NAME``, ``NAME.csv`` or ``NAME.json``).

        With a vehicle profile it also refuses trajectories that break that vehicle's limits.
        Every problem is one ``FlighttestError`` line naming the file.
        """
        csv_path, json_path = _paths(path)
        for p in (csv_path, json_path):
            if not p.is_file():
                raise FlighttestError(f"trajectory file not found: {p}")
        try:
            meta = json.loads(json_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise FlighttestError(f"{json_path}: malformed trajectory metadata ({exc})") from None
        if not isinstance(meta, dict):
            raise FlighttestError(f"{json_path}: metadata must be a JSON object")
        try:
            df = pd.read_csv(csv_path)
        except (OSError, UnicodeDecodeError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
            raise FlighttestError(f"{csv_path}: malformed trajectory CSV ({str(exc).strip()})") from None
        for c in df.columns:
            if not pd.api.types.is_numeric_dtype(df[c]):
                converted = pd.to_numeric(df[c], errors="coerce")
                if converted.isna().any():
                    row = int(np.argmax(converted.isna().to_numpy()))
                    raise FlighttestError(f"{csv_path}: non-numeric value {df[c].iloc[row]!r} in column '{c}'")
                df[c] = converted
        traj = cls(df=df.astype(float), meta=meta)
        traj.validate(profile, where=str(csv_path))
        return traj

    # -- resampling -------------------------------------------------------------------------------
    def resample(self, rate_hz: float) -> Trajectory:
        """The same trajectory on a uniform clock at ``rate_hz`` (last sample exactly at ``t_f``).

        Position and velocity use cubic Hermite interpolation with their derivatives (velocity and
        acceleration), so the streamed setpoints stay consistent with each other; acceleration,
        thrust and angles are linear (angles unwrapped); quaternions are normalised-linear with the
        sign kept continuous.
        """
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise FlighttestError(f"resample rate must be a positive number of Hz (got {rate_hz!r})")
        t = self.t_s
        n = max(math.floor(self.duration_s * rate_hz + 1e-9), 1)
        tn = np.arange(n + 1) / rate_hz
        if tn[-1] < t[-1] - 1e-9:
            tn = np.append(tn, t[-1])
        tn[-1] = min(tn[-1], t[-1])
        out: dict[str, np.ndarray] = {"t_s": tn}
        for p_col, v_col, a_col in (("n_m", "vn_mps", "an_mps2"), ("e_m", "ve_mps", "ae_mps2"),
                                    ("d_m", "vd_mps", "ad_mps2")):  # fmt: skip
            p, v, a = self.column(p_col), self.column(v_col), self.column(a_col)
            out[p_col] = _hermite(t, p, v, tn)
            out[v_col] = _hermite(t, v, a, tn)
            out[a_col] = np.interp(tn, t, a)
        for c in ("yaw_deg", "roll_deg", "pitch_deg"):
            if c in self.df:
                unwrapped = np.degrees(np.unwrap(np.radians(self.column(c))))
                out[c] = _wrap_deg(np.interp(tn, t, unwrapped))
        if "thrust_n" in self.df:
            out["thrust_n"] = np.interp(tn, t, self.column("thrust_n"))
        if self.has_attitude():
            q = self.attitude_quat().copy()
            # q and −q are the same attitude: flip signs so neighbours stay close before blending.
            for i in range(1, len(q)):
                if np.dot(q[i], q[i - 1]) < 0:
                    q[i] = -q[i]
            qi = np.stack([np.interp(tn, t, q[:, k]) for k in range(4)], axis=1)
            qi /= np.linalg.norm(qi, axis=1, keepdims=True)
            for k, c in enumerate(QUAT_COLUMNS):
                out[c] = qi[:, k]
        order = [c for c in self.df.columns if c in out]
        meta = {**self.meta, "resampled_hz": float(rate_hz)}
        return Trajectory(df=pd.DataFrame({c: out[c] for c in order}), meta=meta)


def _hermite(t: np.ndarray, y: np.ndarray, dy: np.ndarray, tn: np.ndarray) -> np.ndarray:
    i = np.clip(np.searchsorted(t, tn, side="right") - 1, 0, len(t) - 2)
    h = t[i + 1] - t[i]
    s = (tn - t[i]) / h
    h00 = 2 * s**3 - 3 * s**2 + 1
    h10 = s**3 - 2 * s**2 + s
    h01 = -2 * s**3 + 3 * s**2
    h11 = s**3 - s**2
    return h00 * y[i] + h10 * h * dy[i] + h01 * y[i + 1] + h11 * h * dy[i + 1]


def _wrap_deg(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def _limit(where: str, what: str, values: np.ndarray, bound: float, unit: str, df: pd.DataFrame) -> None:
    if (values > bound).any():
        i = int(np.argmax(values))
        raise FlighttestError(
            f"{where}: {what} {values[i]:.3g} {unit} at t={df['t_s'].iloc[i]:.3f} s breaks the vehicle limit "
            f"({bound:.3g} {unit})"
        )


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, np.ndarray):
        return _json_safe(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
