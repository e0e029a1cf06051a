"""The one tidy table every loader produces, whatever wrote the log.

A loaded log is a :class:`FlightLog`: the vehicle **state** table (one row per sample of the
position stream, every other stream resampled onto those instants), and, where the source has
them, the **setpoints** and **guard** decisions (flighttest log folders, PX4 setpoint topics) and
**events**, all on the same clock ``t_s``.

State columns (``STATE_COLUMNS``), all SI, NED/FRD as in CONVENTIONS §1:

=================  ===========================================================================
``t_s``            seconds since the first state sample of the log (float64)
``unix_s``         UNIX time of the sample, s (NaN when the source has no wall clock)
``n_m e_m d_m``    position NED relative to the local origin, m (``d_m`` grows going down)
``vn_mps ve_mps vd_mps``  velocity NED, m/s (``vd_mps > 0`` descending)
``qw qx qy qz``    attitude quaternion body FRD → NED (w first)
``p_radps q_radps r_radps``  body rates about x, y, z FRD, rad/s
``ax_mps2 ay_mps2 az_mps2``  specific force in body FRD (accelerometer), m/s²; ≈ (0, 0, −9.81) in hover
``ad_mps2``        kinematic acceleration along NED down, m/s² (from the IMU rotated to NED plus g
                   when the IMU stream is at least half the position rate, else the derivative of
                   ``vd_mps``: a 5 Hz IMU stream interpolated to 50 Hz would hide the shaking)
``motor_0 …``      motor outputs normalised to 0..1 (PWM µs: (pwm − 1000)/1000); as many as the
                   log shows active (usually 4)
``mode``           flight mode name as pymavlink/PX4/ArduPilot name it (string)
``armed``          armed flag (float 1/0, NaN unknown)
``landed``         the autopilot's land detector: 1 on the ground, 0 in the air (taking off and
                   landing count as in the air), NaN unknown (most logs before ArduCopter 4 and PX4
                   1.x tlogs without ``EXTENDED_SYS_STATE``)
``wn_mps we_mps wd_mps``  wind NED (velocity of the air), m/s: the autopilot's own estimate
                   (``FlightLog.wind_reported``), NaN where the log has none — a report of exact
                   zeros is what an estimator that does not estimate the wind sends, not a calm. The
                   wind the analysis judges the air with, whatever its source, is ``FlightLog.wind``
                   (:mod:`flighttest.analysis.wind`)
``boot_s``         the autopilot's own clock (s since its boot) at the sample; NaN when unknown. It is
                   the clock PX4's ``.ulg``, ArduPilot's ``.bin`` and the MAVLink ``time_boot_ms``
                   fields share, so logs of one flight written by different programs line up on it
``glitch``         estimator glitch flag set by :mod:`flighttest.analysis.segment` (bool)
=================  ===========================================================================

Besides the state table a log carries every **height source** it has (:class:`HeightSource`: the
estimator's local or home-relative height, the barometer, GPS, a rangefinder), each at its own
rate on the state clock, for :mod:`flighttest.analysis.heights` to check against each other and
against the ground; the **attitude source** the quaternion columns came from; and the
**parameters** the autopilot logged (or flighttest read at preflight).

Every source's conventions are converted in its loader and documented there (ArduPilot's cm,
centidegrees and up-positive altitudes; PX4 topic names; streams at different rates). A stream
the source lacks leaves its columns NaN and adds a line to ``FlightLog.missing`` saying what
cannot be computed; loaders raise ``FlighttestError`` only when there is no position at all.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from flighttest.errors import FlighttestError
from flighttest.inputs import display_path
from flighttest.model import aero

POSITION = ["n_m", "e_m", "d_m"]
VELOCITY = ["vn_mps", "ve_mps", "vd_mps"]
QUATERNION = ["qw", "qx", "qy", "qz"]
RATES = ["p_radps", "q_radps", "r_radps"]
ACCEL_BODY = ["ax_mps2", "ay_mps2", "az_mps2"]
WIND = ["wn_mps", "we_mps", "wd_mps"]
STATE_COLUMNS = [
    "t_s",
    "unix_s",
    *POSITION,
    *VELOCITY,
    *QUATERNION,
    *RATES,
    *ACCEL_BODY,
    "ad_mps2",
    "mode",
    "armed",
    "landed",
    *WIND,
    "boot_s",
]
MAX_MOTORS = 8
G_MPS2 = aero.G_MPS2  # (re-exported: the loaders' name for it)

# What each missing stream costs, for FlightLog.missing.
CONSEQUENCE = {
    "velocity": "velocity derived from position by differentiation",
    "attitude": "no blade-frame velocity: VRS exposure assumes level attitude",
    "rates": "no body-rate fluctuation",
    "imu": "vertical acceleration from differentiated velocity",
    "motors": "no motor-output spread (ΔT/T proxy)",
    "mode": "flight mode and armed state unknown",
    "wind": "the autopilot reports no wind estimate (the analysis takes flighttest's: flighttest.analysis.wind)",
}


HEIGHT_KINDS = ("estimator", "baro", "gps", "rangefinder")


@dataclass(frozen=True)
class HeightSource:
    """One height stream of a log, as the log has it.

    ``alt_m`` is up-positive metres above the source's own datum (home, the EKF origin, mean sea
    level, the pressure at boot, the ground below a rangefinder); ``home_relative`` says whether the
    source claims that datum is the take-off point, so that on the ground it should read ≈ 0.
    ``t_s`` is on the log's state clock (the same origin as ``state.t_s``)."""

    name: str  # the log's own name for it, e.g. "LOCAL_POSITION_NED.z", "BARO.Alt", "vehicle_air_data"
    kind: str  # one of HEIGHT_KINDS
    t_s: np.ndarray
    alt_m: np.ndarray
    home_relative: bool = False

    def __post_init__(self) -> None:
        if self.kind not in HEIGHT_KINDS:
            raise ValueError(f"height source kind must be one of {HEIGHT_KINDS} (got {self.kind!r})")


ISA_SEA_LEVEL_PA = 101_325.0


def pressure_altitude_m(pressure_pa: np.ndarray) -> np.ndarray:
    """Standard-atmosphere (ISA) altitude of a static pressure, m above the 1013.25 hPa level.

    Against the sea-level pressure rather than the first sample's: with the first sample as the
    base the same formula scales every height change by 1/(1 − h₀/44330.77), 1 % at a 500 m field,
    5 % at 2000 m; against 1013.25 hPa the differences are exact in the ISA (and it is the
    ``baro_alt_meter`` PX4 logs, with its default QNH)."""
    p = np.asarray(pressure_pa, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return 44330.77 * (1.0 - (p / ISA_SEA_LEVEL_PA) ** 0.190263)


def height_source(
    name: str, kind: str, t_s: np.ndarray, alt_m: np.ndarray, origin_s: float, home_relative: bool = False
) -> HeightSource | None:
    """A :class:`HeightSource` from a stream on the source's clock (``origin_s`` = the state's t_s = 0),
    finite samples only, time-sorted; None when fewer than two samples are left."""
    t = np.asarray(t_s, float) - origin_s
    a = np.asarray(alt_m, float)
    keep = np.isfinite(t) & np.isfinite(a)
    if keep.sum() < 2:
        return None
    t, a = t[keep], a[keep]
    order = np.argsort(t, kind="stable")
    return HeightSource(name=name, kind=kind, t_s=t[order], alt_m=a[order], home_relative=home_relative)


@dataclass(frozen=True)
class WindReport:
    """The autopilot's own wind estimate as the log has it, at its own rate on the state clock.

    ``ned_mps`` is the velocity of the air (n, 3); a sample of exact zeros is NaN (an estimator that
    does not estimate the wind sends zeros: not a calm), ``zero_samples`` counts them. ``sd_mps`` is
    the report's own horizontal 1 σ where it gives one (``WIND_COV.horiz_accuracy``, the ``wind``
    topic's variances), else NaN."""

    name: str  # the log's own name: "WIND_COV", "WIND", "XKF2", "wind", "estimator_wind", "wind_estimate"
    t_s: np.ndarray
    ned_mps: np.ndarray
    sd_mps: np.ndarray
    zero_samples: int = 0

    @property
    def estimating(self) -> bool:
        """Whether any sample is an estimate (not exact zeros, finite)."""
        return bool(np.isfinite(self.ned_mps).all(axis=1).any())


def wind_report(name: str, t_s: np.ndarray, ned_mps: np.ndarray, sd_mps: np.ndarray | None,
                origin_s: float) -> WindReport | None:  # fmt: skip
    """A :class:`WindReport` from a stream on the source's clock (``origin_s`` = the state's t_s = 0):
    time-sorted, samples without a finite time dropped, exact-zero samples NaN; None when empty."""
    t = np.asarray(t_s, float) - origin_s
    w = np.asarray(ned_mps, float).reshape(len(t), 3)
    sd = np.full(len(t), np.nan) if sd_mps is None else np.asarray(sd_mps, float).copy()
    keep = np.isfinite(t)
    if not keep.any():
        return None
    t, w, sd = t[keep], w[keep].copy(), sd[keep]
    order = np.argsort(t, kind="stable")
    t, w, sd = t[order], w[order], sd[order]
    zero = (w == 0.0).all(axis=1)
    w[zero | ~np.isfinite(w).all(axis=1)] = np.nan
    sd[~(np.isfinite(sd) & (sd > 0))] = np.nan
    return WindReport(name=name, t_s=t, ned_mps=w, sd_mps=sd, zero_samples=int(zero.sum()))


def state_wind(report: WindReport | None, t_state: np.ndarray, max_gap_s: float) -> dict[str, np.ndarray]:
    """The state's wind columns from the autopilot's report: its estimates (not its exact zeros)
    interpolated onto the state instants, NaN across gaps longer than ``max_gap_s``; {} for none."""
    if report is None or not report.estimating:
        return {}
    ok = np.isfinite(report.ned_mps).all(axis=1)
    wi = resample(report.t_s[ok], report.ned_mps[ok], t_state, max_gap_s)
    return {"wn_mps": wi[:, 0], "we_mps": wi[:, 1], "wd_mps": wi[:, 2]}


def param_value(v: float | int) -> float:
    """A parameter as the autopilot meant it: the shortest decimal that round-trips its float32
    (0.95, not 0.949999988), so one value logged by ULog, DataFlash and MAVLink compares equal.
    Integers pass unchanged (a float32 holds them exactly only up to 2²⁴)."""
    if isinstance(v, int | np.integer):
        return float(v)
    f = np.float32(v)
    return float(str(f)) if np.isfinite(f) else float(v)


def motor_columns(df: pd.DataFrame) -> list[str]:
    return [c for c in df.columns if c.startswith("motor_")]


@dataclass
class FlightLog:
    """A loaded log: the state table plus what the source had besides (see module docstring)."""

    path: Path
    source: str  # "flighttest-folder" | "tlog" | "dataflash" | "ulog"
    state: pd.DataFrame
    setpoints: pd.DataFrame | None = None
    guard: pd.DataFrame | None = None
    events: list[dict[str, Any]] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)
    missing: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    # every height stream the log carries, the estimator's first (see HeightSource)
    heights: list[HeightSource] = field(default_factory=list)
    # where the quaternion columns came from, e.g. "ATTITUDE_QUATERNION", "AHR2", "XKQ", "vehicle_attitude"
    attitude_source: str | None = None
    # autopilot parameters as the log has them (name → value), and where they came from
    params: dict[str, float] = field(default_factory=dict)
    params_source: str | None = None
    # the autopilot's own wind estimate as logged (WIND_COV, WIND, XKF2, wind topics), None when none
    wind_reported: WindReport | None = None
    # where the specific-force columns (ax/ay/az) came from, e.g. "HIGHRES_IMU", "IMU", "sensor_combined"
    accel_source: str | None = None
    # the wind the analysis judges the air with (flighttest.analysis.wind.LogWind), once resolved
    wind: Any = None

    @property
    def name(self) -> str:
        """The file or folder name as UTF-8 text (for messages, titles, tables)."""
        return display_path(self.path.name)

    @property
    def vehicle_name(self) -> str | None:
        v = self.meta.get("vehicle")
        if isinstance(v, dict):
            v = v.get("name")
        return v if isinstance(v, str) and v else None

    @property
    def mission_name(self) -> str | None:
        m = self.meta.get("mission")
        if isinstance(m, dict):
            m = m.get("name") or m.get("kind")
        m = m or self.meta.get("mission_name")
        return m if isinstance(m, str) and m else None

    @property
    def has(self) -> dict[str, bool]:
        s = self.state
        return {
            "attitude": bool(s["qw"].notna().any()),
            "rates": bool(s["p_radps"].notna().any()),
            "imu": bool(s["az_mps2"].notna().any()),
            "motors": bool(motor_columns(s)),
            "wind": bool(s["wn_mps"].notna().any()),
            "mode": bool(s["mode"].notna().any()),
        }


def resample(
    t_src: np.ndarray, values: np.ndarray, t_dst: np.ndarray, max_gap_s: float, hold: bool = False
) -> np.ndarray:
    """Values of a stream sampled at ``t_src`` at the instants ``t_dst``.

    Linear interpolation (``hold=False``) or last value (``hold=True``, for modes and flags). Where
    the nearest source sample is further than ``max_gap_s`` the result is NaN: a stream that
    stopped is not extrapolated. ``values`` may be 1-D or (n, k).
    """
    t_src = np.asarray(t_src, float)
    values = np.asarray(values)
    out_shape = (len(t_dst), *values.shape[1:])
    if len(t_src) == 0 or 0 in values.shape[1:]:  # no samples, or no columns (every motor output zero)
        return np.full(out_shape, np.nan)
    order = np.argsort(t_src, kind="stable")
    t_src, values = t_src[order], values[order]
    idx = np.searchsorted(t_src, t_dst, side="right")
    prev = np.clip(idx - 1, 0, len(t_src) - 1)
    nxt = np.clip(idx, 0, len(t_src) - 1)
    gap = np.minimum(np.abs(t_dst - t_src[prev]), np.abs(t_src[nxt] - t_dst))
    if hold:
        out = values[prev].astype(float) if values.dtype.kind != "O" else values[prev].copy()
        bad = (t_dst < t_src[0]) | (t_dst - t_src[prev] > max_gap_s)
    else:
        v = values.reshape(len(t_src), -1).astype(float)
        out = np.column_stack([np.interp(t_dst, t_src, v[:, k]) for k in range(v.shape[1])]).reshape(out_shape)
        bad = gap > max_gap_s
    if out.dtype.kind == "O":
        out[bad] = None
    else:
        out[bad] = np.nan
    return out


def continuous_quaternions(q: np.ndarray) -> np.ndarray:
    """Flip signs so consecutive quaternions lie in the same hemisphere (safe to interpolate)."""
    q = np.asarray(q, float).copy()
    if len(q) < 2:
        return q
    dots = np.einsum("ij,ij->i", q[1:], q[:-1])
    flips = np.concatenate([[False], dots < 0])
    sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
    return q * sign[:, None]


def normalise_quaternions(q: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return q / n


def build_state(t_s: np.ndarray, unix_s: np.ndarray | None, columns: dict[str, Any]) -> pd.DataFrame:
    """Assemble the state table: every schema column present (NaN when absent), sorted, deduplicated."""
    n = len(t_s)
    data: dict[str, Any] = {"t_s": np.asarray(t_s, float)}
    data["unix_s"] = np.full(n, np.nan) if unix_s is None else np.asarray(unix_s, float)
    for col in STATE_COLUMNS[2:]:
        if col == "mode":
            data[col] = columns.get(col, np.full(n, None, dtype=object))
        else:
            data[col] = np.asarray(columns.get(col, np.full(n, np.nan)), float)
    for col, val in columns.items():
        if col.startswith("motor_"):
            data[col] = np.asarray(val, float)
    df = pd.DataFrame(data)
    df = df[np.isfinite(df["t_s"]) & np.isfinite(df[POSITION]).all(axis=1)]
    df = df.sort_values("t_s", kind="stable").drop_duplicates("t_s", keep="last").reset_index(drop=True)
    if len(df) < 2:
        raise FlighttestError("no usable position samples (need at least 2)")
    origin = float(df["t_s"].iloc[0])
    df["t_s"] = df["t_s"] - origin
    df["mode"] = df["mode"].astype("string")
    # the source-clock time of t_s = 0, so a loader can put its other streams (heights) on this clock
    df.attrs["t_origin_s"] = origin
    return df


def stream_rate_hz(t_s: np.ndarray) -> float:
    t_s = np.asarray(t_s, float)
    return (len(t_s) - 1) / (t_s.max() - t_s.min()) if len(t_s) > 1 and t_s.max() > t_s.min() else 0.0


def fill_derived(df: pd.DataFrame, missing: dict[str, str], imu_fast: bool = True) -> pd.DataFrame:
    """Fill what can be derived from other columns and record what could not (in ``missing``).

    ``imu_fast``: the IMU stream is at least half the position rate (see ``ad_mps2``)."""
    t = df["t_s"].to_numpy()
    if df[VELOCITY].isna().all().all():
        for p, v in zip(POSITION, VELOCITY):
            df[v] = np.gradient(df[p].to_numpy(), t)
        missing["velocity"] = CONSEQUENCE["velocity"]
    if df["qw"].isna().all():
        missing["attitude"] = CONSEQUENCE["attitude"]
    if df["p_radps"].isna().all():
        missing["rates"] = CONSEQUENCE["rates"]
    if df["ad_mps2"].isna().all():
        q = df[QUATERNION].to_numpy()
        f = df[ACCEL_BODY].to_numpy()
        if imu_fast and np.isfinite(f).any() and np.isfinite(q).any():
            from flighttest.model.frames import body_to_ned

            _, _, fd = body_to_ned(f[:, 0], f[:, 1], f[:, 2], q[:, 0], q[:, 1], q[:, 2], q[:, 3])
            df["ad_mps2"] = fd + G_MPS2
        if df["ad_mps2"].isna().all():
            df["ad_mps2"] = np.gradient(df["vd_mps"].to_numpy(), t)
            if not imu_fast:
                missing["imu"] = "IMU stream slower than half the position rate: " + CONSEQUENCE["imu"]
            else:
                missing["imu"] = CONSEQUENCE["imu"]
    if not motor_columns(df):
        missing["motors"] = CONSEQUENCE["motors"]
    if df["mode"].isna().all() and df["armed"].isna().all():
        missing["mode"] = CONSEQUENCE["mode"]
    if df["wn_mps"].isna().all():
        missing["wind"] = CONSEQUENCE["wind"]
    return df
