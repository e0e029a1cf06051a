"""MAVLink ``.tlog`` → :class:`FlightLog` (PX4 and ArduPilot telemetry).

Streams used, in order of preference (all MAVLink common, so PX4 and ArduPilot alike):

- position/velocity: ``LOCAL_POSITION_NED`` (m, m/s, NED); else ``ODOMETRY`` (velocity rotated to
  NED when its ``child_frame_id`` is body FRD, as PX4 sends it); else ``GLOBAL_POSITION_INT``
  (ArduPilot/PX4 integer units: lat/lon 1e-7 deg → flat-earth metres from the first fix,
  ``relative_alt`` mm up-positive → ``d_m = −relative_alt/1000``, ``vx vy vz`` cm/s NED → m/s).
- attitude and body rates: ``ATTITUDE_QUATERNION`` (q1..q4 = w,x,y,z), else ``ODOMETRY``, else
  ``ATTITUDE`` (Euler rad → quaternion); rates rad/s FRD.
- specific force: ``HIGHRES_IMU`` (m/s²), else ``SCALED_IMU`` (milli-g → m/s²), else ArduPilot's
  ``RAW_IMU`` (ArduPilot sends it in milli-g, as SCALED_IMU; other autopilots' raw units are their
  sensor's, so it is used only when the HEARTBEAT says ArduPilot). ``FlightLog.accel_source`` names it.
- motors: ``ACTUATOR_OUTPUT_STATUS`` (PX4; PWM µs when > 100, else taken as 0..1), else
  ``SERVO_OUTPUT_RAW`` (µs). Channels that are never non-zero are dropped.
- mode/armed: ``HEARTBEAT`` from the vehicle (not from a GCS), decoded by pymavlink's
  ``mode_string_v10``; armed = ``base_mode & MAV_MODE_FLAG_SAFETY_ARMED``.
- landed: ``EXTENDED_SYS_STATE.landed_state`` (``MAV_LANDED_STATE``: 1 on the ground → 1; 2–4 in the
  air, taking off, landing → 0; 0 undefined → NaN).
- wind: ``WIND_COV`` (NED m/s; 1 σ from ``horiz_accuracy``, else ``√var_horiz``), else ArduPilot's
  ``WIND`` (direction the wind comes *from*, deg, speed m/s → air velocity ``−speed·(cos, sin)``; its
  ``speed_z`` sign is undocumented, so wd = 0; no accuracy). Kept as ``FlightLog.wind_reported``; the
  state's wind columns hold its estimates only: reports of exact zeros (what PX4's EKF2 and
  ArduPilot's EKF3 send when they do not estimate the wind, their default on a multicopter) are NaN.

Height sources (``FlightLog.heights``, each at its own rate; up-positive metres):

- the position stream's own height first: ``LOCAL_POSITION_NED.z`` / ``ODOMETRY.z`` (negated; EKF
  origin, home-relative) or ``GLOBAL_POSITION_INT.relative_alt`` (mm above home);
- ``GLOBAL_POSITION_INT.relative_alt`` also when the local stream is the position (the same
  estimator, as the GCS shows it);
- ``ALTITUDE.altitude_monotonic`` (baro): MAVLink defines it as the uncorrected barometric altitude,
  never reset (PX4 sends ``vehicle_air_data.baro_alt_meter``). Its other fields repeat streams read
  already (``altitude_local`` = −``LOCAL_POSITION_NED.z``, ``altitude_relative`` = ``relative_alt``,
  ``altitude_amsl`` = ``GLOBAL_POSITION_INT.alt``), so they are not added again;
- ``SCALED_PRESSURE.press_abs`` / ``SCALED_PRESSURE2.press_abs`` (baro, hPa → ISA pressure altitude,
  see :func:`~flighttest.analysis.schema.pressure_altitude_m`; not home-relative);
- ``GPS_RAW_INT.alt`` (gps, mm above MSL, 3D fixes only: ``fix_type`` ≥ 3);
- ``DISTANCE_SENSOR.current_distance`` (rangefinder, cm; downward sensors only, orientation 25 =
  ``MAV_SENSOR_ROTATION_PITCH_270``, readings at or beyond ``min_distance``/``max_distance`` dropped).

``VFR_HUD.alt`` is not used: PX4 sends the AMSL estimate (the MAVLink definition), ArduCopter 3.x
sent the height above home — a loader cannot tell which, and either repeats an estimator stream.

Parameters: ``PARAM_VALUE`` (last value per ``param_id``). PX4 packs integer parameters byte-wise
into the float (``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE``: an INT32 1 arrives as the float
1.4e-45), ArduPilot casts them (1 arrives as 1.0); the vehicle's HEARTBEAT autopilot says which.

Each stream carries the autopilot's own clock (``time_boot_ms``/``time_usec``); it is mapped to UNIX
time with the median offset to the tlog's receive stamps, so radio jitter does not enter the
analysis. Streams on the same boot clock share the position stream's offset (a 1 Hz stream's own
median would carry its own latency). The position stream defines the sample instants and its boot
clock is the state's ``boot_s``; every other stream, at its own rate, is interpolated onto them
(last value for mode/armed; NaN across gaps longer than ``MAX_GAP_S``).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from pymavlink import mavutil

from flighttest.analysis.loaders.mavlink_frames import Decoded, decode, dialect, read_frames
from flighttest.analysis.schema import (
    G_MPS2,
    FlightLog,
    HeightSource,
    WindReport,
    build_state,
    continuous_quaternions,
    fill_derived,
    height_source,
    normalise_quaternions,
    param_value,
    pressure_altitude_m,
    resample,
    state_wind,
    stream_rate_hz,
    wind_report,
)
from flighttest.errors import FlighttestError
from flighttest.model.frames import EARTH_RADIUS_M, body_to_ned, quat_from_euler

MAX_GAP_S = 1.0
MAV_FRAME_BODY_FRD = 12
MAV_TYPE_GCS = 6
MAV_LANDED_STATE_ON_GROUND = 1
MAV_SENSOR_ROTATION_PITCH_270 = 25  # a downward-facing distance sensor
GPS_FIX_TYPE_3D = 3
BOOT_CLOCK_MAX_S = 1e9  # a "boot" clock beyond ~31 years is UNIX time
# MAV_PARAM_TYPE → how PX4 packs it byte-wise into the float (numpy dtype of the low bytes)
PARAM_BYTEWISE = {1: "<u1", 2: "<i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4"}


def _own_clock_s(d: Decoded) -> np.ndarray | None:
    """The autopilot's boot clock of each message, s; None when the stream has none usable (absent,
    zero, running backwards across a reboot, or UNIX time rather than time since boot)."""
    names = d.fields.dtype.names
    for field, scale in (("time_boot_ms", 1e-3), ("time_usec", 1e-6)):
        if field in names:
            own = d.fields[field].astype(float) * scale
            if len(own) < 2 or not np.all(np.diff(own) >= 0) or own[-1] <= own[0] or own[-1] > BOOT_CLOCK_MAX_S:
                return None
            return own
    return None


def _time(d: Decoded, ref_offset_s: float | None = None) -> np.ndarray:
    """UNIX seconds of each message from its autopilot timestamp (falls back to receive time).

    ``ref_offset_s``: the boot → UNIX offset of the position stream; used when this stream's own
    median offset is within a second of it (the same clock)."""
    recv_s = d.recv_us / 1e6
    own = _own_clock_s(d)
    if own is None:
        return recv_s
    offset = float(np.median(recv_s - own))
    if ref_offset_s is not None and abs(offset - ref_offset_s) < 1.0:
        offset = ref_offset_s
    return own + offset


STREAMS = (
    "LOCAL_POSITION_NED",
    "ODOMETRY",
    "GLOBAL_POSITION_INT",
    "ATTITUDE_QUATERNION",
    "ATTITUDE",
    "HIGHRES_IMU",
    "SCALED_IMU",
    "RAW_IMU",
    "ACTUATOR_OUTPUT_STATUS",
    "SERVO_OUTPUT_RAW",
    "HEARTBEAT",
    "EXTENDED_SYS_STATE",
    "WIND_COV",
    "WIND",
    "ALTITUDE",
    "SCALED_PRESSURE",
    "SCALED_PRESSURE2",
    "GPS_RAW_INT",
    "DISTANCE_SENSOR",
    "PARAM_VALUE",
)


def _heights(dec: dict[str, Decoded | None], first: str, when, origin_s: float) -> list[HeightSource]:
    """Every height stream of the log, ``first`` (the position stream's) leading; see module docstring."""
    out: list[HeightSource | None] = []
    add = out.append
    if first != "GLOBAL_POSITION_INT":
        d = dec[first]
        add(height_source(f"{first}.z", "estimator", when(d), -d.fields["z"].astype(float), origin_s, True))
    if (d := dec["GLOBAL_POSITION_INT"]) is not None:
        alt_m = d.fields["relative_alt"] / 1000.0
        add(height_source("GLOBAL_POSITION_INT.relative_alt", "estimator", when(d), alt_m, origin_s, True))
    if (d := dec["ALTITUDE"]) is not None:
        add(height_source("ALTITUDE.altitude_monotonic", "baro", when(d), d.fields["altitude_monotonic"], origin_s))
    for name in ("SCALED_PRESSURE", "SCALED_PRESSURE2"):
        if (d := dec[name]) is not None:
            p_pa = d.fields["press_abs"].astype(float) * 100.0
            p_pa[p_pa <= 0] = np.nan
            add(height_source(f"{name}.press_abs", "baro", when(d), pressure_altitude_m(p_pa), origin_s))
    if (d := dec["GPS_RAW_INT"]) is not None:
        fix = d.fields["fix_type"] >= GPS_FIX_TYPE_3D
        add(height_source("GPS_RAW_INT.alt", "gps", when(d)[fix], d.fields["alt"][fix] / 1000.0, origin_s))
    if (d := dec["DISTANCE_SENSOR"]) is not None:
        f = d.fields
        down = f["orientation"] == MAV_SENSOR_ROTATION_PITCH_270
        if down.any():
            sensor = np.bincount(f["id"][down]).argmax()  # one sensor: the downward one reporting most
            cur = f["current_distance"]
            ok = down & (f["id"] == sensor) & (cur > f["min_distance"]) & (cur < f["max_distance"])
            add(
                height_source("DISTANCE_SENSOR.current_distance", "rangefinder", when(d)[ok], cur[ok] / 100.0, origin_s)
            )
    return [h for h in out if h is not None]


def _params(pv: Decoded | None, bytewise: bool) -> dict[str, float]:
    """Last ``PARAM_VALUE`` per name (vectorised; the Python loop runs once per parameter)."""
    if pv is None:
        return {}
    f = pv.fields
    value = f["param_value"].astype("<f4")
    ids = np.char.decode(f["param_id"], "ascii", "replace")
    rev = slice(None, None, -1)
    names, last = np.unique(ids[rev], return_index=True)
    idx = len(ids) - 1 - last
    out: dict[str, float] = {}
    for name, i in zip(names, idx):
        if not name:
            continue
        code = PARAM_BYTEWISE.get(int(f["param_type"][i])) if bytewise else None
        if code is not None:  # the integer sits in the float's low bytes (little-endian)
            out[str(name)] = float(np.frombuffer(value[i : i + 1].tobytes()[: np.dtype(code).itemsize], code)[0])
        else:
            out[str(name)] = param_value(float(value[i]))
    return out


def load_tlog(path: Path) -> FlightLog:
    frames = read_frames(path)
    notes: list[str] = []
    if frames.bad_records:
        notes.append(f"{frames.bad_records} damaged record(s) skipped")
    if frames.truncated_bytes:
        notes.append(f"file truncated: last {frames.truncated_bytes} byte(s) are an incomplete record")

    # the vehicle is the system that reports its position most
    pos_ids = [
        dialect.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
        dialect.MAVLINK_MSG_ID_ODOMETRY,
        dialect.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    ]
    candidates = frames.sysid[np.isin(frames.msgid, pos_ids)]
    if len(candidates) == 0:
        if decode(frames, "HEARTBEAT") is None and decode(frames, "ATTITUDE") is None:
            raise FlighttestError(f"{path}: not a MAVLink telemetry log (no valid MAVLink messages)")
        raise FlighttestError(
            f"{path}: log has no position stream (LOCAL_POSITION_NED, ODOMETRY or GLOBAL_POSITION_INT)"
        )
    sysid = int(np.bincount(candidates).argmax())
    dec = {name: decode(frames, name, sysid) for name in STREAMS}
    crc_errors = sum(d.crc_errors for d in dec.values() if d is not None)
    if crc_errors:
        notes.append(f"{crc_errors} message(s) with a bad CRC skipped")

    cols: dict[str, np.ndarray] = {}
    odo = dec["ODOMETRY"]
    if (lp := dec["LOCAL_POSITION_NED"]) is not None and len(lp.fields) >= 2:
        pos, pos_name = lp, "LOCAL_POSITION_NED"
        f = lp.fields
        cols.update(n_m=f["x"], e_m=f["y"], d_m=f["z"], vn_mps=f["vx"], ve_mps=f["vy"], vd_mps=f["vz"])
    elif odo is not None and len(odo.fields) >= 2:
        pos, pos_name = odo, "ODOMETRY"
        f = odo.fields
        q = f["q"].astype(float)
        vel = np.column_stack([f["vx"], f["vy"], f["vz"]]).astype(float)
        body = f["child_frame_id"] == MAV_FRAME_BODY_FRD
        vn, ve, vd = body_to_ned(vel[:, 0], vel[:, 1], vel[:, 2], q[:, 0], q[:, 1], q[:, 2], q[:, 3])
        vel = np.where(body[:, None], np.column_stack([vn, ve, vd]), vel)
        cols.update(n_m=f["x"], e_m=f["y"], d_m=f["z"], vn_mps=vel[:, 0], ve_mps=vel[:, 1], vd_mps=vel[:, 2])
    elif (gp := dec["GLOBAL_POSITION_INT"]) is not None and len(gp.fields) >= 2:
        pos, pos_name = gp, "GLOBAL_POSITION_INT"
        f = gp.fields
        lat, lon = f["lat"] * 1e-7, f["lon"] * 1e-7
        cols.update(
            n_m=np.radians(lat - lat[0]) * EARTH_RADIUS_M,
            e_m=np.radians(lon - lon[0]) * EARTH_RADIUS_M * np.cos(np.radians(lat[0])),
            d_m=-f["relative_alt"] / 1000.0,
            vn_mps=f["vx"] / 100.0,
            ve_mps=f["vy"] / 100.0,
            vd_mps=f["vz"] / 100.0,
        )
        notes.append("position from GLOBAL_POSITION_INT (no local NED stream)")
    else:
        raise FlighttestError(
            f"{path}: log has no position stream (LOCAL_POSITION_NED, ODOMETRY or GLOBAL_POSITION_INT)"
        )
    boot = _own_clock_s(pos)
    ref_offset = None if boot is None else float(np.median(pos.recv_us / 1e6 - boot))

    def when(d: Decoded) -> np.ndarray:
        return _time(d, ref_offset)

    t = when(pos)
    if boot is not None:
        cols["boot_s"] = boot

    attitude_source = None
    if (aq := dec["ATTITUDE_QUATERNION"]) is not None:
        f = aq.fields
        q = np.column_stack([f["q1"], f["q2"], f["q3"], f["q4"]])
        att_t, rates = when(aq), np.column_stack([f["rollspeed"], f["pitchspeed"], f["yawspeed"]])
        attitude_source = "ATTITUDE_QUATERNION"
    elif odo is not None:
        f = odo.fields
        q, att_t = f["q"], when(odo)
        rates = np.column_stack([f["rollspeed"], f["pitchspeed"], f["yawspeed"]])
        attitude_source = "ODOMETRY"
    elif (at := dec["ATTITUDE"]) is not None:
        f = at.fields
        q = quat_from_euler(f["roll"].astype(float), f["pitch"].astype(float), f["yaw"].astype(float))
        att_t, rates = when(at), np.column_stack([f["rollspeed"], f["pitchspeed"], f["yawspeed"]])
        attitude_source = "ATTITUDE"
    else:
        q = None
    if q is not None:
        qi = resample(att_t, continuous_quaternions(q), t, MAX_GAP_S)
        qi = normalise_quaternions(qi)
        cols.update(qw=qi[:, 0], qx=qi[:, 1], qy=qi[:, 2], qz=qi[:, 3])
        ri = resample(att_t, rates, t, MAX_GAP_S)
        cols.update(p_radps=ri[:, 0], q_radps=ri[:, 1], r_radps=ri[:, 2])

    hb = dec["HEARTBEAT"]
    vehicle_hb = hb.fields[hb.fields["type"] != MAV_TYPE_GCS] if hb is not None else None
    autopilot = None
    if vehicle_hb is not None and len(vehicle_hb):
        autopilot = int(np.bincount(vehicle_hb["autopilot"]).argmax())
    ai, accel_source = None, None
    imu = None
    for name, scale in (("HIGHRES_IMU", 1.0), ("SCALED_IMU", G_MPS2 * 1e-3), ("RAW_IMU", G_MPS2 * 1e-3)):
        if name == "RAW_IMU" and autopilot != dialect.MAV_AUTOPILOT_ARDUPILOTMEGA:
            continue  # raw sensor units elsewhere
        if (imu := dec[name]) is not None:
            f = imu.fields
            acc = np.column_stack([f["xacc"], f["yacc"], f["zacc"]]).astype(float) * scale
            ai, accel_source = resample(when(imu), acc, t, MAX_GAP_S), name
            break
    imu_fast = imu is None or stream_rate_hz(when(imu)) >= 0.5 * stream_rate_hz(t)
    if ai is not None:
        cols.update(ax_mps2=ai[:, 0], ay_mps2=ai[:, 1], az_mps2=ai[:, 2])

    motors, motor_t = None, None
    if (ao := dec["ACTUATOR_OUTPUT_STATUS"]) is not None:
        motors, motor_t = ao.fields["actuator"].astype(float), when(ao)
    elif (so := dec["SERVO_OUTPUT_RAW"]) is not None:
        names = [f"servo{i}_raw" for i in range(1, 17)]
        motors = np.column_stack([so.fields[n] for n in names]).astype(float)
        motor_t = when(so)
    if motors is not None:
        used = np.flatnonzero(np.any(motors != 0, axis=0))[:8]
        m = motors[:, used]
        m = np.where(np.abs(m) > 100, (m - 1000.0) / 1000.0, m)
        mi = resample(motor_t, m, t, MAX_GAP_S)
        for k in range(mi.shape[1]):
            cols[f"motor_{k}"] = mi[:, k]

    if hb is not None:
        f = hb.fields
        keep = f["type"] != MAV_TYPE_GCS
        if keep.any():
            f, hb_t = f[keep], hb.recv_us[keep] / 1e6
            keys = np.stack([f["autopilot"], f["type"], f["base_mode"], f["custom_mode"]], axis=1).astype(np.int64)
            uniq, inv = np.unique(keys, axis=0, return_inverse=True)
            names = np.array(
                [
                    mavutil.mode_string_v10(
                        SimpleNamespace(
                            autopilot=int(a),
                            type=int(ty),
                            base_mode=int(b),
                            custom_mode=int(c),
                            get_type=lambda: "HEARTBEAT",
                        )
                    )
                    for a, ty, b, c in uniq
                ],
                dtype=object,
            )
            cols["mode"] = resample(hb_t, names[inv.ravel()], t, 5.0, hold=True)
            armed = (f["base_mode"] & dialect.MAV_MODE_FLAG_SAFETY_ARMED) != 0
            cols["armed"] = resample(hb_t, armed.astype(float), t, 5.0, hold=True)

    if (es := dec["EXTENDED_SYS_STATE"]) is not None:
        ls = es.fields["landed_state"].astype(float)
        landed = np.where(ls == MAV_LANDED_STATE_ON_GROUND, 1.0, np.where(ls > 0, 0.0, np.nan))
        cols["landed"] = resample(when(es), landed, t, 5.0, hold=True)

    reported: WindReport | None = None
    if (wc := dec["WIND_COV"]) is not None:
        f = wc.fields
        acc = f["horiz_accuracy"].astype(float)
        var = f["var_horiz"].astype(float)
        sd = np.where(np.isfinite(acc) & (acc > 0), acc, np.sqrt(np.where(var > 0, var, np.nan)))
        w = np.column_stack([f["wind_x"], f["wind_y"], f["wind_z"]])
        reported = wind_report("WIND_COV", when(wc), w, sd, 0.0)
    elif (wd := dec["WIND"]) is not None:
        f = wd.fields
        ang = np.radians(f["direction"].astype(float))
        w = np.column_stack([-f["speed"] * np.cos(ang), -f["speed"] * np.sin(ang), np.zeros(len(f))])
        reported = wind_report("WIND", wd.recv_us / 1e6, w, None, 0.0)
    cols.update(state_wind(reported, t, 5.0))

    missing: dict[str, str] = {}
    state = fill_derived(build_state(t, t, cols), missing, imu_fast)
    params = _params(dec["PARAM_VALUE"], bytewise=autopilot == dialect.MAV_AUTOPILOT_PX4)
    origin = state.attrs["t_origin_s"]
    if reported is not None:
        reported = replace(reported, t_s=reported.t_s - origin)
    return FlightLog(
        path=Path(path),
        source="tlog",
        state=state,
        missing=missing,
        notes=notes,
        heights=_heights(dec, pos_name, when, state.attrs["t_origin_s"]),
        attitude_source=attitude_source,
        params=params,
        params_source="tlog PARAM_VALUE" if params else None,
        wind_reported=reported,
        accel_source=accel_source,
    )
