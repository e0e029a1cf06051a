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
from flighttest.errors import FlighttestError
from flighttest.inputs import (
    MAX_ACCEL_MPS2,
    MAX_CSV_BYTES,
    MAX_DURATION_S,
    MAX_HEIGHT_M,
    MAX_HORIZONTAL_M,
    MAX_JSON_BYTES,
    MAX_SPEED_MPS,
    InputFileError,
    atomic_write,
    check_input_file,
    read_text_file,
    shown,
)
from flighttest.model.aero import G_MPS2
from flighttest.model.frames import quat_to_rotmat

if TYPE_CHECKING:
    from flighttest.model.profiles import VehicleProfile

FORMAT = "flighttest-trajectory/1"
KINDS = ("planar", "helix", "vertical", "probe", "calibration")
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
ORIGIN_TOL_M = 1e-3
LIMIT_REL_TOL = 0.01
TILT_TOL_DEG = 0.5
QUAT_NORM_TOL = 1e-3

# Bounds on any trajectory, vehicle or not (flighttest.inputs: why these numbers).
MAX_ROWS = 600_001  # 600 s at 1 kHz
MAX_ABS_DEG = 3600.0  # yaw/roll/pitch: a few turns of unwrapped angle at most
MAX_THRUST_N = 1e5
MAX_META_DEPTH = 32  # nesting of the JSON sidecar (a planner writes 3 levels)
# Kinematic consistency (positions vs integrated velocities, velocities vs integrated accelerations,
# trapezoid rule per step and over the whole file). Planners are consistent to well under a
# millimetre; the tolerance takes a few cm of rounding in hand-made files plus a share of the step,
# plus what a step in acceleration inside a sample interval can do to the trapezoid rule
# (|Δa|·h²/8 in position, |Δa|·h/2 in velocity: bang-bang plans switch between samples).
POS_TOL_M = 0.02
VEL_TOL_MPS = 0.05
STEP_REL_TOL = 0.02
DRIFT_TOL_M = 0.10
DRIFT_TOL_MPS = 0.10


def file_paths(path: Path | str) -> tuple[Path, Path]:
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

    def tilt_deg(self) -> np.ndarray:
        """The disk's tilt from level at each sample: the plan's own attitude, else where its specific force
        points (thrust along −z_body)."""
        if self.has_attitude():
            return np.degrees(np.arccos(np.clip(quat_to_rotmat(self.attitude_quat())[:, 2, 2], -1.0, 1.0)))
        spec = self.df[["an_mps2", "ae_mps2", "ad_mps2"]].to_numpy() - np.array([0.0, 0.0, G_MPS2])
        up = -spec[:, 2] / np.maximum(np.linalg.norm(spec, axis=1), 1e-9)
        return np.degrees(np.arccos(np.clip(up, -1.0, 1.0)))

    def validate(self, profile: VehicleProfile | None = None, where: str = "trajectory", coarse: bool = False) -> None:
        """Raise ``FlighttestError`` (one line) unless the data is well formed, physically consistent
        and, with a profile, flyable by that vehicle: speed, climb rate, tilt and collective thrust
        within its limits. ``coarse``: the samples came from resampling (``resample``), which loses
        what the acceleration did between them; the consistency check then allows the trajectory's
        own peak acceleration over each step."""
        df = self.df
        missing = [c for c in REQUIRED_COLUMNS if c not in df]
        if missing:
            raise FlighttestError(f"{where}: missing column(s) {', '.join(missing)}")
        extra = [c for c in df.columns if c not in REQUIRED_COLUMNS and c not in OPTIONAL_COLUMNS]
        if extra:
            raise FlighttestError(f"{where}: unknown column(s) {shown(', '.join(map(str, extra)), 80)}")
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
        late = np.abs(t) > MAX_DURATION_S  # t_s = 1e308 stops here, before any arithmetic on it
        if late.any():
            i = int(np.argmax(late))
            raise FlighttestError(
                f"{where}: t_s = {t[i]:.6g} s at row {i + 1} (a trajectory lasts at most {MAX_DURATION_S:g} s)"
            )
        steps = np.diff(t)
        if (steps <= 0).any():
            i = int(np.argmax(steps <= 0))
            raise FlighttestError(f"{where}: time not strictly increasing at row {i + 2} (t={t[i + 1]:g} s)")
        start = df[["n_m", "e_m", "d_m"]].iloc[0].to_numpy()
        if np.abs(start).max() > ORIGIN_TOL_M:
            raise FlighttestError(f"{where}: positions must be relative to the start (first row {start.tolist()})")
        self._check_bounds(where)  # before any arithmetic on the values: nothing overflows after it
        if quat_present:
            q = self.attitude_quat()
            norm = np.linalg.norm(q, axis=1)
            if np.abs(norm - 1.0).max() > QUAT_NORM_TOL:
                i = int(np.argmax(np.abs(norm - 1.0)))
                raise FlighttestError(f"{where}: quaternion at row {i + 1} is not unit length (|q|={norm[i]:.4f})")
        self._check_consistency(where, coarse)
        self._check_meta(where)
        if profile is not None:
            self._check_limits(profile, where)

    def _check_bounds(self, where: str) -> None:
        """Sizes no flight test has: more rows than 600 s at 1 kHz, longer than 600 s, heights
        beyond 120 m, speeds beyond 100 m/s, accelerations beyond 10 g (``t_s = 1e308`` is refused
        here, not inside the flight)."""
        df = self.df
        if len(df) > MAX_ROWS:
            raise FlighttestError(f"{where}: {len(df):,} rows (at most {MAX_ROWS:,}: 600 s at 1 kHz)")
        if self.duration_s > MAX_DURATION_S:
            raise FlighttestError(f"{where}: lasts {self.duration_s:.6g} s (at most {MAX_DURATION_S:g} s)")
        bounds = (
            (("n_m", "e_m"), MAX_HORIZONTAL_M, "m"), (("d_m",), MAX_HEIGHT_M, "m"),
            (("vn_mps", "ve_mps", "vd_mps"), MAX_SPEED_MPS, "m/s"),
            (("an_mps2", "ae_mps2", "ad_mps2"), MAX_ACCEL_MPS2, "m/s²"),
            (("yaw_deg", "roll_deg", "pitch_deg"), MAX_ABS_DEG, "°"), (("thrust_n",), MAX_THRUST_N, "N"),
            (QUAT_COLUMNS, 2.0, ""),
        )  # fmt: skip
        for cols, bound, unit in bounds:
            for c in cols:
                if c not in df:
                    continue
                v = np.abs(df[c].to_numpy(float))
                if (v > bound).any():
                    i = int(np.argmax(v > bound))
                    raise FlighttestError(
                        f"{where}: {c} = {df[c].iloc[i]:.6g} at row {i + 1} is beyond ±{bound:g} {unit}"
                    )

    def _check_consistency(self, where: str, coarse: bool = False) -> None:
        """Positions must be what the velocities integrate to, velocities what the accelerations
        integrate to (a 3 m jump in 10 ms at zero velocity is a broken file, not a manoeuvre)."""
        df = self.df
        t = df["t_s"].to_numpy(float)
        h = np.diff(t)
        p = df[["n_m", "e_m", "d_m"]].to_numpy(float)
        v = df[["vn_mps", "ve_mps", "vd_mps"]].to_numpy(float)
        a = df[["an_mps2", "ae_mps2", "ad_mps2"]].to_numpy(float)
        da = np.linalg.norm(np.diff(a, axis=0), axis=1)
        # between resampled samples the acceleration may have been anything up to its peak
        peak = float(np.linalg.norm(a, axis=1).max()) if coarse else 0.0
        for what, x, dx, tol, drift_tol, jump in (
            ("position", p, v, POS_TOL_M, DRIFT_TOL_M, da * h * h / 8.0 + peak * h * h / 2.0),
            ("velocity", v, a, VEL_TOL_MPS, DRIFT_TOL_MPS, da * h / 2.0 + peak * h),
        ):
            step_int = 0.5 * (dx[1:] + dx[:-1]) * h[:, None]  # trapezoid rule per step
            err = np.linalg.norm(np.diff(x, axis=0) - step_int, axis=1)
            travel = np.linalg.norm(step_int, axis=1)
            allowed = tol + STEP_REL_TOL * travel + jump
            if (err > allowed).any():
                i = int(np.argmax(err - allowed))
                rate = "velocities" if what == "position" else "accelerations"
                raise FlighttestError(
                    f"{where}: {what} changes by {np.linalg.norm(x[i + 1] - x[i]):.3g} between rows {i + 1} and "
                    f"{i + 2} (t={t[i]:.3f}–{t[i + 1]:.3f} s) but the {rate} integrate to "
                    f"{travel[i]:.3g} (off by {err[i]:.3g}): the file is not physically consistent"
                )
            drift = np.linalg.norm((x[1:] - x[0]) - np.cumsum(step_int, axis=0), axis=1)
            allowed = drift_tol + STEP_REL_TOL * np.cumsum(travel) + np.cumsum(jump)
            if (drift > allowed).any():
                i = int(np.argmax(drift - allowed))
                rate = "velocities" if what == "position" else "accelerations"
                raise FlighttestError(
                    f"{where}: by t={t[i + 1]:.3f} s the {what} has drifted {drift[i]:.3g} from what the {rate} "
                    "integrate to: the file is not physically consistent"
                )

    def _check_meta(self, where: str) -> None:
        meta = self.meta
        meta_missing = [k for k in REQUIRED_META if k not in meta]
        if meta_missing:
            raise FlighttestError(f"{where}: metadata lacks {', '.join(meta_missing)}")
        if meta["format"] != FORMAT:
            raise FlighttestError(f"{where}: unknown format {shown(meta['format'])} (expected {FORMAT!r})")
        if meta["kind"] not in KINDS:
            raise FlighttestError(f"{where}: unknown kind {shown(meta['kind'])} (one of {', '.join(KINDS)})")
        for key in ("vehicle", "status"):
            if not isinstance(meta[key], str):
                raise FlighttestError(f"{where}: metadata '{key}' must be a string (got {shown(meta[key])})")
        if not isinstance(meta["problem"], dict):
            raise FlighttestError(f"{where}: metadata 'problem' must be an object (got {shown(meta['problem'])})")
        t_f = meta["t_f_s"]
        if isinstance(t_f, bool) or not isinstance(t_f, int | float) or not math.isfinite(t_f):
            raise FlighttestError(f"{where}: metadata 't_f_s' must be a finite number (got {shown(t_f)})")
        if abs(t_f - self.duration_s) > 0.05 + 0.01 * self.duration_s:
            raise FlighttestError(f"{where}: metadata t_f_s = {t_f:.6g} s but the samples last {self.duration_s:.6g} s")
        if _depth(meta) > MAX_META_DEPTH:
            raise FlighttestError(f"{where}: metadata nested deeper than {MAX_META_DEPTH} levels")

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
        # what the accelerations ask of the rotors, whatever a thrust column says
        required = np.linalg.norm(spec, axis=1) * profile.mass_kg
        _limit(where, "required thrust", required, max_thrust_n * tol, "N", df)
        low = required < min_thrust_n - LIMIT_REL_TOL * max_thrust_n
        if low.any():
            i = int(np.argmax(low))
            raise FlighttestError(
                f"{where}: the acceleration at t={df['t_s'].iloc[i]:.3f} s needs {required[i]:.3g} N of thrust, below "
                f"the vehicle minimum ({min_thrust_n:.3g} N): it falls faster than the rotors allow"
            )
        _limit(where, "tilt", self.tilt_deg(), profile.max_tilt_deg + TILT_TOL_DEG, "deg", df)

    # -- files ------------------------------------------------------------------------------------
    def save(self, path: Path | str) -> tuple[Path, Path]:
        """Write ``NAME.csv`` and ``NAME.json``; returns both paths."""
        csv_path, json_path = file_paths(path)
        # each file appears whole (a reader never sees half a CSV); missing folders are created
        with atomic_write(csv_path) as tmp:
            self.df.to_csv(tmp, index=False, float_format="%.9g")
        with atomic_write(json_path) as tmp:
            tmp.write_text(json.dumps(_json_safe(self.meta), indent=2) + "\n", encoding="utf-8")
        return csv_path, json_path

    @classmethod
    def load(cls, path: Path | str, profile: VehicleProfile | None = None) -> Trajectory:
        """Read and validate a trajectory (``NAME``, ``NAME.csv`` or ``NAME.json``).

        With a vehicle profile it also refuses trajectories that break that vehicle's limits.
        Every problem is one ``FlighttestError`` line naming the file.
        """
        if not str(path).strip():
            raise FlighttestError("trajectory file: the path is empty")
        csv_path, json_path = file_paths(path)
        for p, limit in ((csv_path, MAX_CSV_BYTES), (json_path, MAX_JSON_BYTES)):
            try:
                check_input_file(p, "trajectory file", limit)
            except InputFileError as exc:
                if exc.reason == "not found":
                    raise FlighttestError(f"trajectory file not found: {p}") from None
                raise
        try:
            meta = json.loads(read_text_file(json_path, "trajectory metadata", MAX_JSON_BYTES))
        except InputFileError as exc:
            raise FlighttestError(f"{json_path}: malformed trajectory metadata ({exc.reason})") from None
        except (json.JSONDecodeError, RecursionError) as exc:
            why = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
            raise FlighttestError(f"{json_path}: malformed trajectory metadata ({why})") from None
        if not isinstance(meta, dict):
            raise FlighttestError(f"{json_path}: metadata must be a JSON object")
        try:
            # one row more than allowed is enough to refuse a file without reading all of it
            df = pd.read_csv(csv_path, nrows=MAX_ROWS + 1, encoding="utf-8")
        except (OSError, UnicodeDecodeError, ValueError, pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
            why = " ".join(str(exc).split())[:120]
            raise FlighttestError(f"{csv_path}: malformed trajectory CSV ({why})") from None
        for c in df.columns:
            if not pd.api.types.is_numeric_dtype(df[c]):
                converted = pd.to_numeric(df[c], errors="coerce")
                if converted.isna().any():
                    row = int(np.argmax(converted.isna().to_numpy()))
                    raise FlighttestError(
                        f"{csv_path}: non-numeric value {shown(df[c].iloc[row])} in column {shown(c, 40)}"
                    )
                df[c] = converted
            elif pd.api.types.is_bool_dtype(df[c]):
                raise FlighttestError(f"{csv_path}: non-numeric values (true/false) in column {shown(c, 40)}")
        traj = cls(df=df.astype(float), meta=meta)
        rate = meta.get("resampled_hz")  # a flown copy (flight logs keep the resampled trajectory)
        coarse = isinstance(rate, int | float) and not isinstance(rate, bool) and math.isfinite(rate)
        traj.validate(profile, where=str(csv_path), coarse=coarse)
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


def _depth(obj: Any) -> int:
    """Nesting depth of a JSON value, without recursion (a hostile sidecar may be deep)."""
    deepest, stack = 0, [(obj, 1)]
    while stack:
        o, d = stack.pop()
        deepest = max(deepest, d)
        if d > MAX_META_DEPTH:
            break
        if isinstance(o, dict):
            stack.extend((v, d + 1) for v in o.values())
        elif isinstance(o, list):
            stack.extend((v, d + 1) for v in o)
    return deepest


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


# a grid time this close to a phase boundary is dropped: the file's 9 significant digits would print the
# two as one time (the vertical's t2 = 50.000000001 beside the grid's 50.0: "time not strictly increasing")
SAMPLE_MIN_GAP_FRACTION = 0.01


def sample_times(t_f_s: float, rate_hz: float, breaks_s: tuple[float, ...] = ()) -> np.ndarray:
    """A ``rate_hz`` grid from 0 to ``t_f_s`` with the phase boundaries ``breaks_s`` and ``t_f_s`` in it,
    strictly increasing by at least ``SAMPLE_MIN_GAP_FRACTION`` of a period.

    Refused (one line) before anything is allocated: a duration or rate that is not a positive finite
    number, a duration beyond ``MAX_DURATION_S`` or more than ``MAX_ROWS`` samples — a plan made from a
    near-zero speed or acceleration would otherwise ask for terabytes here."""
    if not (math.isfinite(t_f_s) and t_f_s > 0 and math.isfinite(rate_hz) and rate_hz > 0):
        raise FlighttestError(f"trajectory sampling: duration {t_f_s!r} s at {rate_hz!r} Hz (both must be > 0)")
    if t_f_s > MAX_DURATION_S:
        raise FlighttestError(f"trajectory sampling: lasts {t_f_s:.6g} s (at most {MAX_DURATION_S:g} s)")
    if t_f_s * rate_hz + len(breaks_s) + 1 > MAX_ROWS:
        raise FlighttestError(f"trajectory sampling: {t_f_s:.6g} s at {rate_hz:g} Hz is more than {MAX_ROWS:,} rows")
    grid = np.arange(0.0, t_f_s, 1.0 / rate_hz)
    gap = SAMPLE_MIN_GAP_FRACTION / rate_hz
    # boundaries that (nearly) coincide are one: a jerk-limited ramp that never reaches its acceleration has
    # its two corners 1e-12 s apart, one time in a file written to 9 digits
    keys = np.array([k for k in sorted(breaks_s) if k < t_f_s - gap] + [t_f_s], dtype=float)
    keys = keys[np.concatenate([np.diff(keys) >= gap, [True]])]
    near = np.min(np.abs(grid[:, None] - keys[None, :]), axis=1) < gap
    near[0] = False  # the start stays: every boundary lies after it
    return np.union1d(grid[~near], keys)
