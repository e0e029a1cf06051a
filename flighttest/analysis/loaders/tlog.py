"""MAVLink ``.tlog`` → :class:`FlightLog` (PX4 and ArduPilot telemetry).

Streams used, in order of preference (all MAVLink common, so PX4 and ArduPilot alike):

- position/velocity: ``LOCAL_POSITION_NED`` (m, m/s, NED); else ``ODOMETRY`` (velocity rotated to
  NED when its ``child_frame_id`` is body FRD, as PX4 sends it); else ``GLOBAL_POSITION_INT``
  (ArduPilot/PX4 integer units: lat/lon 1e-7 deg → flat-earth metres from the first fix,
  ``relative_alt`` mm up-positive → ``d_m = −relative_alt/1000``, ``vx vy vz`` cm/s NED → m/s).
- attitude and body rates: ``ATTITUDE_QUATERNION`` (q1..q4 = w,x,y,z), else ``ODOMETRY``, else
  ``ATTITUDE`` (Euler rad → quaternion); rates rad/s FRD.
- specific force: ``HIGHRES_IMU`` (m/s²), else ``SCALED_IMU`` (milli-g → m/s²).
- motors: ``ACTUATOR_OUTPUT_STATUS`` (PX4; PWM µs when > 100, else taken as 0..1), else
  ``SERVO_OUTPUT_RAW`` (µs). Channels that are never non-zero are dropped.
- mode/armed: ``HEARTBEAT`` from the vehicle (not from a GCS), decoded by pymavlink's
  ``mode_string_v10``; armed = ``base_mode & MAV_MODE_FLAG_SAFETY_ARMED``.
- wind: ``WIND_COV`` (NED m/s), else ArduPilot's ``WIND`` (direction the wind comes *from*, deg,
  speed m/s → air velocity ``−speed·(cos, sin)``; its ``speed_z`` sign is undocumented, so wd = 0).

Each stream carries the autopilot's own clock (``time_boot_ms``/``time_usec``); it is mapped to UNIX
time with the median offset to the tlog's receive stamps, so radio jitter does not enter the
analysis. The position stream defines the sample instants; every other stream, at its own rate,
is interpolated onto them (last value for mode/armed; NaN across gaps longer than ``MAX_GAP_S``).
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
from pymavlink import mavutil

from flighttest.analysis.loaders.mavlink_frames import Decoded, decode, dialect, read_frames
from flighttest.analysis.schema import (
    FlightLog,
    build_state,
    continuous_quaternions,
    fill_derived,
    normalise_quaternions,
    resample,
    stream_rate_hz,
)
from flighttest.errors import FlighttestError
from flighttest.frames import body_to_ned, quat_from_euler

MAX_GAP_S = 1.0
EARTH_RADIUS_M = 6_378_137.0
MAV_FRAME_BODY_FRD = 12
MAV_TYPE_GCS = 6


def _clock_s(d: Decoded, field: str, scale: float) -> np.ndarray:
    """UNIX seconds of each message from its autopilot timestamp (falls back to receive time)."""
    recv_s = d.recv_us / 1e6
    if field not in d.fields.dtype.names:
        return recv_s
    own = d.fields[field].astype(float) * scale
    if len(own) < 2 or not np.all(np.diff(own) >= 0) or own[-1] <= own[0]:
        return recv_s
    return own + np.median(recv_s - own)


def _time(d: Decoded) -> np.ndarray:
    names = d.fields.dtype.names
    if "time_boot_ms" in names:
        return _clock_s(d, "time_boot_ms", 1e-3)
    if "time_usec" in names:
        return _clock_s(d, "time_usec", 1e-6)
    return d.recv_us / 1e6


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
    dec = {
        name: decode(frames, name, sysid)
        for name in (
            "LOCAL_POSITION_NED",
            "ODOMETRY",
            "GLOBAL_POSITION_INT",
            "ATTITUDE_QUATERNION",
            "ATTITUDE",
            "HIGHRES_IMU",
            "SCALED_IMU",
            "ACTUATOR_OUTPUT_STATUS",
            "SERVO_OUTPUT_RAW",
            "HEARTBEAT",
            "WIND_COV",
            "WIND",
        )
    }
    crc_errors = sum(d.crc_errors for d in dec.values() if d is not None)
    if crc_errors:
        notes.append(f"{crc_errors} message(s) with a bad CRC skipped")

    cols: dict[str, np.ndarray] = {}
    odo = dec["ODOMETRY"]
    if (lp := dec["LOCAL_POSITION_NED"]) is not None and len(lp.fields) >= 2:
        t = _time(lp)
        f = lp.fields
        cols.update(n_m=f["x"], e_m=f["y"], d_m=f["z"], vn_mps=f["vx"], ve_mps=f["vy"], vd_mps=f["vz"])
    elif odo is not None and len(odo.fields) >= 2:
        t = _time(odo)
        f = odo.fields
        q = f["q"].astype(float)
        vel = np.column_stack([f["vx"], f["vy"], f["vz"]]).astype(float)
        body = f["child_frame_id"] == MAV_FRAME_BODY_FRD
        vn, ve, vd = body_to_ned(vel[:, 0], vel[:, 1], vel[:, 2], q[:, 0], q[:, 1], q[:, 2], q[:, 3])
        vel = np.where(body[:, None], np.column_stack([vn, ve, vd]), vel)
        cols.update(n_m=f["x"], e_m=f["y"], d_m=f["z"], vn_mps=vel[:, 0], ve_mps=vel[:, 1], vd_mps=vel[:, 2])
    elif (gp := dec["GLOBAL_POSITION_INT"]) is not None and len(gp.fields) >= 2:
        t = _time(gp)
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

    if (aq := dec["ATTITUDE_QUATERNION"]) is not None:
        f = aq.fields
        q = np.column_stack([f["q1"], f["q2"], f["q3"], f["q4"]])
        att_t, rates = _time(aq), np.column_stack([f["rollspeed"], f["pitchspeed"], f["yawspeed"]])
    elif odo is not None:
        f = odo.fields
        q, att_t = f["q"], _time(odo)
        rates = np.column_stack([f["rollspeed"], f["pitchspeed"], f["yawspeed"]])
    elif (at := dec["ATTITUDE"]) is not None:
        f = at.fields
        q = quat_from_euler(f["roll"].astype(float), f["pitch"].astype(float), f["yaw"].astype(float))
        att_t, rates = _time(at), np.column_stack([f["rollspeed"], f["pitchspeed"], f["yawspeed"]])
    else:
        q = None
    if q is not None:
        qi = resample(att_t, continuous_quaternions(q), t, MAX_GAP_S)
        qi = normalise_quaternions(qi)
        cols.update(qw=qi[:, 0], qx=qi[:, 1], qy=qi[:, 2], qz=qi[:, 3])
        ri = resample(att_t, rates, t, MAX_GAP_S)
        cols.update(p_radps=ri[:, 0], q_radps=ri[:, 1], r_radps=ri[:, 2])

    if (imu := dec["HIGHRES_IMU"]) is not None:
        f = imu.fields
        acc = np.column_stack([f["xacc"], f["yacc"], f["zacc"]]).astype(float)
        ai = resample(_time(imu), acc, t, MAX_GAP_S)
    elif (imu := dec["SCALED_IMU"]) is not None:
        f = imu.fields
        acc = np.column_stack([f["xacc"], f["yacc"], f["zacc"]]).astype(float) * 9.80665e-3
        ai = resample(_time(imu), acc, t, MAX_GAP_S)
    else:
        ai = None
    imu_fast = imu is None or stream_rate_hz(_time(imu)) >= 0.5 * stream_rate_hz(t)
    if ai is not None:
        cols.update(ax_mps2=ai[:, 0], ay_mps2=ai[:, 1], az_mps2=ai[:, 2])

    motors, motor_t = None, None
    if (ao := dec["ACTUATOR_OUTPUT_STATUS"]) is not None:
        motors, motor_t = ao.fields["actuator"].astype(float), _time(ao)
    elif (so := dec["SERVO_OUTPUT_RAW"]) is not None:
        names = [f"servo{i}_raw" for i in range(1, 17)]
        motors = np.column_stack([so.fields[n] for n in names]).astype(float)
        motor_t = _time(so)
    if motors is not None:
        used = np.flatnonzero(np.any(motors != 0, axis=0))[:8]
        m = motors[:, used]
        m = np.where(np.abs(m) > 100, (m - 1000.0) / 1000.0, m)
        mi = resample(motor_t, m, t, MAX_GAP_S)
        for k in range(mi.shape[1]):
            cols[f"motor_{k}"] = mi[:, k]

    if (hb := dec["HEARTBEAT"]) is not None:
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

    if (wc := dec["WIND_COV"]) is not None:
        f = wc.fields
        wi = resample(_time(wc), np.column_stack([f["wind_x"], f["wind_y"], f["wind_z"]]), t, 5.0)
        cols.update(wn_mps=wi[:, 0], we_mps=wi[:, 1], wd_mps=wi[:, 2])
    elif (wd := dec["WIND"]) is not None:
        f = wd.fields
        ang = np.radians(f["direction"].astype(float))
        w = np.column_stack([-f["speed"] * np.cos(ang), -f["speed"] * np.sin(ang), np.zeros(len(f))])
        wi = resample(wd.recv_us / 1e6, w, t, 5.0)
        cols.update(wn_mps=wi[:, 0], we_mps=wi[:, 1], wd_mps=wi[:, 2])

    missing: dict[str, str] = {}
    state = fill_derived(build_state(t, t, cols), missing, imu_fast)
    return FlightLog(path=Path(path), source="tlog", state=state, missing=missing, notes=notes)
