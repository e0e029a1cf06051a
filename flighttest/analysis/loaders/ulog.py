"""PX4 ``.ulg`` → :class:`FlightLog` via pyulog.

PX4 topics used (each at its own rate, µs since boot):

- ``vehicle_local_position``: ``x y z`` (m NED), ``vx vy vz`` (m/s NED) → the sample instants;
- ``vehicle_attitude``: ``q[0..3]`` = w, x, y, z (body FRD → NED);
- ``vehicle_angular_velocity``: ``xyz[0..2]`` rad/s FRD (else ``sensor_combined.gyro_rad``);
- ``sensor_combined``: ``accelerometer_m_s2[0..2]`` (specific force FRD: what the accelerometer measures,
  ≈ (0, 0, −g) level at rest; calibrated, not bias-corrected by the estimator. ``vehicle_acceleration``
  is the same specific force with EKF2's bias removed and filtered, but PX4 logs it at ~20 Hz, too
  slow for the fluctuation measures);
- ``actuator_motors``: ``control[i]`` (0..1), else ``actuator_outputs``: ``output[i]`` (PWM µs);
- ``vehicle_status``: ``nav_state`` (PX4 navigation state → name), ``arming_state`` (2 = armed);
- ``vehicle_land_detected``: ``landed`` (the state's ``landed``);
- ``wind`` (PX4 1.13 on), else ``estimator_wind`` (instance 0), else ``wind_estimate`` (older):
  ``windspeed_north/east`` (m/s; vertical wind 0; 1 σ from ``variance_north/east``) as
  ``FlightLog.wind_reported``, in the state's wind columns only where it is an estimate (EKF2 without
  drag fusion or airspeed, the multicopter default, publishes none, or zeros);
- ``vehicle_local_position_setpoint`` / ``trajectory_setpoint``: the setpoints table.

Height sources (up-positive m): ``vehicle_local_position.z`` (negated; the EKF origin, home-relative)
first, ``vehicle_global_position.alt`` (the same estimator, m AMSL), ``vehicle_air_data.baro_alt_meter``
(baro; else ``sensor_baro.pressure`` Pa → ISA pressure altitude), ``vehicle_gps_position`` (else
``sensor_gps``) ``altitude_msl_m`` (m; older PX4: ``alt``, int mm) for 3D fixes (``fix_type`` ≥ 3),
and ``distance_sensor.current_distance`` (m; downward sensors, orientation 25, readings strictly
inside ``min_distance``..``max_distance``). Instance 0 of every topic.

Parameters: the log's initial parameter set (``ulog.initial_parameters``; changes logged later in
flight are not applied).

The data carry only the boot clock (the state's ``boot_s``), so ``unix_s`` is NaN.
"""

from __future__ import annotations

import contextlib
import io
import os
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from flighttest.analysis.schema import (
    FlightLog,
    HeightSource,
    build_state,
    continuous_quaternions,
    fill_derived,
    height_source,
    normalise_quaternions,
    param_value,
    pressure_altitude_m,
    resample,
    state_wind,
    wind_report,
)
from flighttest.errors import FlighttestError

MAX_GAP_S = 1.0
ULOG_MAGIC = b"ULog\x01\x12\x35"
# PX4 vehicle_status.nav_state
NAV_STATE = {
    0: "MANUAL",
    1: "ALTCTL",
    2: "POSCTL",
    3: "AUTO_MISSION",
    4: "AUTO_LOITER",
    5: "AUTO_RTL",
    10: "ACRO",
    12: "DESCEND",
    13: "TERMINATION",
    14: "OFFBOARD",
    15: "STAB",
    17: "AUTO_TAKEOFF",
    18: "AUTO_LAND",
    19: "AUTO_FOLLOW_TARGET",
    20: "AUTO_PRECLAND",
    21: "ORBIT",
}
ARMED = 2

TOPICS = [
    "vehicle_local_position",
    "vehicle_attitude",
    "vehicle_angular_velocity",
    "sensor_combined",
    "actuator_motors",
    "actuator_outputs",
    "vehicle_status",
    "vehicle_land_detected",
    "wind",
    "estimator_wind",
    "wind_estimate",
    "vehicle_local_position_setpoint",
    "trajectory_setpoint",
    "vehicle_global_position",
    "vehicle_air_data",
    "sensor_baro",
    "vehicle_gps_position",
    "sensor_gps",
    "distance_sensor",
]
GPS_FIX_3D = 3
ROTATION_DOWNWARD_FACING = 25


def _topic(ulog, name: str) -> dict[str, np.ndarray] | None:
    """Instance 0 of a topic, its numeric fields only (a damaged format can make a field text)."""
    for d in ulog.data_list:
        if d.name == name and d.multi_id == 0 and len(d.data.get("timestamp", ())) > 0:
            data = {k: v for k, v in d.data.items() if getattr(v, "dtype", None) is not None and v.dtype.kind in "biuf"}
            return data if "timestamp" in data else None
    return None


class _ReadBudgetExceeded(Exception):
    """Raised inside pyulog when a damaged file makes it re-read without end (see :class:`_BoundedFile`)."""


class _BoundedFile(io.FileIO):
    """The ULog file for pyulog, with a bound on the bytes it may read.

    pyulog resynchronises after damage in its definitions section one byte at a time, reading the
    whole (garbage) message length again each time: a few flipped bytes cost minutes. A sound parse
    reads the file about once; ``READ_BUDGET`` times its size (plus a floor for small files) leaves
    room for genuine resyncs and stops the pathological ones with a clear error."""

    READ_BUDGET = 8
    READ_FLOOR = 16_000_000

    def __init__(self, path: Path) -> None:
        super().__init__(path, "r")
        self._left = self.READ_BUDGET * os.fstat(self.fileno()).st_size + self.READ_FLOOR

    def read(self, size: int = -1) -> bytes:  # type: ignore[override]
        data = super().read(size)
        self._left -= len(data) + 64  # a call costs too: many tiny reads are as slow as big ones
        if self._left < 0:
            raise _ReadBudgetExceeded()
        return data


def _cols(d: dict[str, np.ndarray], base: str, n: int) -> np.ndarray | None:
    names = [f"{base}[{i}]" for i in range(n)]
    if not all(k in d for k in names):
        return None
    return np.column_stack([d[k] for k in names]).astype(float)


def _heights(ulog, origin_s: float) -> list[HeightSource]:
    """Every height topic of the log, the estimator's local height first; see module docstring."""
    out: list[HeightSource | None] = []

    def add(topic: str, field: str, kind: str, d: dict, alt_m, keep=None, home: bool = False) -> None:
        t = d["timestamp"] / 1e6
        alt_m = np.asarray(alt_m, float)
        if keep is not None:
            t, alt_m = t[keep], alt_m[keep]
        out.append(height_source(f"{topic}.{field}", kind, t, alt_m, origin_s, home))

    if (lp := _topic(ulog, "vehicle_local_position")) is not None:
        add("vehicle_local_position", "z", "estimator", lp, -lp["z"].astype(float), home=True)
    if (gp := _topic(ulog, "vehicle_global_position")) is not None and "alt" in gp:
        add("vehicle_global_position", "alt", "estimator", gp, gp["alt"])
    if (ad := _topic(ulog, "vehicle_air_data")) is not None and "baro_alt_meter" in ad:
        add("vehicle_air_data", "baro_alt_meter", "baro", ad, ad["baro_alt_meter"])
    elif (sb := _topic(ulog, "sensor_baro")) is not None and "pressure" in sb:
        p = sb["pressure"].astype(float)
        add("sensor_baro", "pressure", "baro", sb, pressure_altitude_m(np.where(p > 0, p, np.nan)))
    for topic in ("vehicle_gps_position", "sensor_gps"):
        if (g := _topic(ulog, topic)) is None:
            continue
        fix = g["fix_type"] >= GPS_FIX_3D if "fix_type" in g else None
        if "altitude_msl_m" in g:
            add(topic, "altitude_msl_m", "gps", g, g["altitude_msl_m"], fix)
        elif "alt" in g:
            add(topic, "alt", "gps", g, g["alt"] / 1000.0, fix)  # int32 mm before PX4 1.14
        break
    if (ds := _topic(ulog, "distance_sensor")) is not None and "current_distance" in ds:
        cur = ds["current_distance"].astype(float)
        ok = np.isfinite(cur)
        if "orientation" in ds:
            ok &= ds["orientation"] == ROTATION_DOWNWARD_FACING
        if "min_distance" in ds and "max_distance" in ds:
            ok &= (cur > ds["min_distance"]) & (cur < ds["max_distance"])
        add("distance_sensor", "current_distance", "rangefinder", ds, cur, ok)
    return [h for h in out if h is not None]


def load_ulog(path: Path) -> FlightLog:
    from pyulog import ULog

    with open(path, "rb") as fh:
        head = fh.read(len(ULOG_MAGIC))
    if head != ULOG_MAGIC:
        raise FlighttestError(f"{path}: not a PX4 ULog file (bad header)")
    chatter = io.StringIO()
    try:
        # pyulog prints its damage reports (print(), on stdout: they broke --json) and may warn; both
        # are caught here and become one note
        with (
            _BoundedFile(path) as fh,
            contextlib.redirect_stdout(chatter),
            contextlib.redirect_stderr(chatter),
            warnings.catch_warnings(record=True) as caught,
        ):
            warnings.simplefilter("always")
            ulog = ULog(fh, TOPICS, disable_str_exceptions=True)
    except _ReadBudgetExceeded:
        raise FlighttestError(
            f"{path}: cannot parse ULog: damaged beyond what the reader can resynchronise on (it kept re-reading "
            "the same bytes)"
        ) from None
    except Exception as exc:  # pyulog raises assorted errors on damaged files
        raise FlighttestError(f"{path}: cannot parse ULog ({type(exc).__name__}: {exc})") from None
    notes = []
    said = [ln.strip() for ln in chatter.getvalue().splitlines() if ln.strip()] + [str(w.message) for w in caught]
    if ulog.file_corruption or said:
        note = "ULog reports corruption: data after the damage may be missing"
        if said:
            more = f"; and {len(said) - 1} more line(s)" if len(said) > 1 else ""
            note += f" (the reader said: {said[0][:120]}{more})"
        notes.append(note)
    lp = _topic(ulog, "vehicle_local_position")
    if lp is None or not all(k in lp for k in ("x", "y", "z")):
        raise FlighttestError(f"{path}: log has no position (vehicle_local_position)")
    t = lp["timestamp"] / 1e6
    cols: dict[str, np.ndarray] = {"n_m": lp["x"], "e_m": lp["y"], "d_m": lp["z"], "boot_s": t}
    if all(k in lp for k in ("vx", "vy", "vz")):
        cols.update(vn_mps=lp["vx"], ve_mps=lp["vy"], vd_mps=lp["vz"])

    attitude_source = None
    if (att := _topic(ulog, "vehicle_attitude")) is not None and (q := _cols(att, "q", 4)) is not None:
        qi = normalise_quaternions(resample(att["timestamp"] / 1e6, continuous_quaternions(q), t, MAX_GAP_S))
        cols.update(qw=qi[:, 0], qx=qi[:, 1], qy=qi[:, 2], qz=qi[:, 3])
        attitude_source = "vehicle_attitude"
    sc = _topic(ulog, "sensor_combined")
    av = _topic(ulog, "vehicle_angular_velocity")
    rates = (av["timestamp"], _cols(av, "xyz", 3)) if av is not None else (None, None)
    if rates[1] is None and sc is not None:
        rates = (sc["timestamp"], _cols(sc, "gyro_rad", 3))
    if rates[1] is not None:
        ri = resample(rates[0] / 1e6, rates[1], t, MAX_GAP_S)
        cols.update(p_radps=ri[:, 0], q_radps=ri[:, 1], r_radps=ri[:, 2])
    if sc is not None and (acc := _cols(sc, "accelerometer_m_s2", 3)) is not None:
        ai = resample(sc["timestamp"] / 1e6, acc, t, MAX_GAP_S)
        cols.update(ax_mps2=ai[:, 0], ay_mps2=ai[:, 1], az_mps2=ai[:, 2])

    motors = None
    if (am := _topic(ulog, "actuator_motors")) is not None:
        m = _cols(am, "control", 4)
        motors = (am["timestamp"], m) if m is not None else None
    if motors is None and (ao := _topic(ulog, "actuator_outputs")) is not None:
        nout = np.asarray(ao.get("noutputs", [4]), float)
        n = int(np.nanmax(nout)) if np.isfinite(nout).any() and np.nanmax(nout) < 256 else 4
        n = n or 4
        m = _cols(ao, "output", min(max(n, 1), 8))
        if m is not None:
            motors = (ao["timestamp"], np.where(np.abs(m) > 100, (m - 1000.0) / 1000.0, m))
    if motors is not None:
        used = np.flatnonzero(np.any(motors[1] != 0, axis=0))[:8]
        mi = resample(motors[0] / 1e6, motors[1][:, used], t, MAX_GAP_S)
        for k in range(mi.shape[1]):
            cols[f"motor_{k}"] = mi[:, k]

    if (vs := _topic(ulog, "vehicle_status")) is not None:
        ts = vs["timestamp"] / 1e6
        if "nav_state" in vs:
            nav = vs["nav_state"].astype(float)
            ok = np.isfinite(nav) & (np.abs(nav) < 2**31)  # a damaged format can make it a float, NaN
            names = np.array([NAV_STATE.get(int(s), f"NAV_STATE({int(s)})") for s in nav[ok]], dtype=object)
            cols["mode"] = resample(ts[ok], names, t, 1e9, hold=True)
        if "arming_state" in vs:
            cols["armed"] = resample(ts, (vs["arming_state"] == ARMED).astype(float), t, 1e9, hold=True)
    if (ld := _topic(ulog, "vehicle_land_detected")) is not None and "landed" in ld:
        cols["landed"] = resample(ld["timestamp"] / 1e6, (ld["landed"] != 0).astype(float), t, 1e9, hold=True)
    reported = None
    for name in ("wind", "estimator_wind", "wind_estimate"):
        wind = _topic(ulog, name)
        if wind is None or not {"windspeed_north", "windspeed_east"} <= wind.keys():
            continue
        w = np.column_stack([wind["windspeed_north"], wind["windspeed_east"], np.zeros(len(wind["timestamp"]))])
        var = [wind[k].astype(float) for k in ("variance_north", "variance_east") if k in wind]
        sd = np.sqrt(np.maximum(*var)) if len(var) == 2 else None
        reported = wind_report(name, wind["timestamp"] / 1e6, w, sd, 0.0)
        cols.update(state_wind(reported, t, 5.0))
        break

    missing: dict[str, str] = {}
    state = fill_derived(build_state(t, None, cols), missing)
    t0 = state.attrs["t_origin_s"]
    if reported is not None:
        reported = replace(reported, t_s=reported.t_s - t0)

    setpoints = None
    sp = _topic(ulog, "trajectory_setpoint") or _topic(ulog, "vehicle_local_position_setpoint")
    if sp is not None:
        spd = {"t_s": sp["timestamp"] / 1e6 - t0}
        if _cols(sp, "position", 3) is not None:
            p, v = _cols(sp, "position", 3), _cols(sp, "velocity", 3)
            spd.update(n_m=p[:, 0], e_m=p[:, 1], d_m=p[:, 2])
            if v is not None:
                spd.update(vn_mps=v[:, 0], ve_mps=v[:, 1], vd_mps=v[:, 2])
        else:
            for src, dst in (
                ("x", "n_m"),
                ("y", "e_m"),
                ("z", "d_m"),
                ("vx", "vn_mps"),
                ("vy", "ve_mps"),
                ("vz", "vd_mps"),
            ):
                if src in sp:
                    spd[dst] = sp[src]
        setpoints = pd.DataFrame(spd)
    params = {
        str(k): param_value(v)
        for k, v in sorted(ulog.initial_parameters.items(), key=lambda kv: str(kv[0]))
        if isinstance(v, int | float | np.integer | np.floating) and not isinstance(v, bool) and np.isfinite(v)
    }
    return FlightLog(
        path=Path(path),
        source="ulog",
        state=state,
        setpoints=setpoints,
        missing=missing,
        notes=notes,
        heights=_heights(ulog, t0),
        attitude_source=attitude_source,
        params=params,
        params_source="ulog" if params else None,
        wind_reported=reported,
        accel_source="sensor_combined" if "ax_mps2" in cols else None,
    )
