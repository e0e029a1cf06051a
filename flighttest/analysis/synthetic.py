"""Logs of known motion in every supported format, for tests and the benchmark.

:class:`SyntheticFlight` is a closed-form flight: hover at ``start_alt_m``, then descents (a
raised-cosine vertical speed profile, so a descent of height H in D seconds peaks at πH/(2D)) or a
probe (``d = d0 + A sin(ω0 τ²)``, NOTES §3), level attitude at a fixed yaw, and "fluctuation" on
body rates, vertical acceleration and motors that grows once the descent speed passes
``onset_mps``, so identification has a known answer. Every quantity is a function of time, so
streams written at different rates agree exactly.

Writers: :func:`write_tlog` (pymavlink-packed frames with the tlog's 8-byte big-endian UNIX-µs
prefix), :func:`write_ulog` (PX4 ULog packed by hand per the ULog spec: pyulog 1.3 can only
re-write a ULog it parsed, it has no API to build one from data) and :func:`write_dataflash`
(ArduPilot FMT + records with ArduPilot's units: centidegrees, cm/s, up-positive altitudes).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flighttest.frames import quat_from_euler

G = 9.80665
UNIX0 = 1_767_225_600.0  # 2026-01-01, the wall clock of synthetic tlogs


@dataclass
class SyntheticFlight:
    duration_s: float = 30.0
    start_alt_m: float = 10.0
    descents: list[tuple[float, float, float]] = field(default_factory=lambda: [(10.0, 5.0, 2.5)])  # (t0, H, D)
    probe: tuple[float, float, float, float] | None = None  # (t0, A_m, omega0_radps2, T_s)
    yaw_deg: float = 30.0
    east_speed_mps: float = 0.0  # horizontal drift during descents
    onset_mps: float = math.inf
    fluct_gain: float = 2.0  # rate-noise amplitude per m/s beyond the onset, rad/s
    base_noise: float = 0.01
    wind_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    glitch: tuple[float, float] | None = None  # (t, seconds) altitude jumps 40 m below ground

    def vertical(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(d_m, vd_mps, ad_mps2) of the true motion."""
        d = np.full_like(t, -self.start_alt_m)
        vd = np.zeros_like(t)
        ad = np.zeros_like(t)
        for t0, h, dur in self.descents:
            tau = np.clip(t - t0, 0.0, dur)
            inside = (t >= t0) & (t <= t0 + dur)
            d += h * (1 - np.cos(np.pi * tau / dur)) / 2
            vd += np.where(inside, h * np.pi / (2 * dur) * np.sin(np.pi * tau / dur), 0.0)
            ad += np.where(inside, h * (np.pi / dur) ** 2 / 2 * np.cos(np.pi * tau / dur), 0.0)
        if self.probe is not None:
            t0, a, w0, dur = self.probe
            tau = np.clip(t - t0, 0.0, dur)
            inside = (t >= t0) & (t <= t0 + dur)
            end_d = a * np.sin(w0 * dur**2)
            d += np.where(t < t0 + dur, a * np.sin(w0 * tau**2), end_d)
            vd += np.where(inside, a * 2 * w0 * tau * np.cos(w0 * tau**2), 0.0)
            ad += np.where(inside, a * (2 * w0 * np.cos(w0 * tau**2) - 4 * w0**2 * tau**2 * np.sin(w0 * tau**2)), 0.0)
        return d, vd, ad

    def truth_descents(self) -> list[dict[str, float]]:
        return [
            {"start_s": t0, "duration_s": dur, "height_m": h, "max_rate_mps": math.pi * h / (2 * dur)}
            for t0, h, dur in self.descents
        ]

    def fluctuation_amp(self, vd: np.ndarray) -> np.ndarray:
        w = vd - self.wind_ned_mps[2]
        return self.base_noise + self.fluct_gain * np.maximum(0.0, w - self.onset_mps)

    def states(self, t: np.ndarray) -> dict[str, np.ndarray]:
        t = np.asarray(t, float)
        d, vd, ad = self.vertical(t)
        moving = vd > 1e-9
        ve = np.where(moving, self.east_speed_mps, 0.0)
        e = np.cumsum(np.concatenate([[0.0], np.diff(t) * ve[1:]]))
        if self.glitch is not None:
            g0, gdur = self.glitch
            d = np.where((t >= g0) & (t < g0 + gdur), d + self.start_alt_m + 40.0, d)
        amp = self.fluctuation_amp(vd)

        # deterministic "noise": a sum of incommensurate sines, the same at any sample rate
        def wobble(k: int) -> np.ndarray:
            return sum(np.sin(2 * np.pi * f * t + k * 1.7 + i) for i, f in enumerate((7.3, 11.1, 13.7))) / 2.0

        q = quat_from_euler(np.zeros_like(t), np.zeros_like(t), np.full_like(t, math.radians(self.yaw_deg)))
        thrust = 0.5 * (1 - ad / G)
        out = {
            "t": t,
            "n": np.zeros_like(t),
            "e": e,
            "d": d,
            "vn": np.zeros_like(t),
            "ve": ve,
            "vd": vd,
            "ad": ad,
            "q": q,
            "p": amp * wobble(0),
            "q_rate": amp * wobble(1),
            "r": 0.3 * amp * wobble(2),
            "fx": np.zeros_like(t),
            "fy": np.zeros_like(t),
            "fz": ad - G + 5 * amp * wobble(3),
        }
        out["motors"] = np.column_stack([thrust + 0.2 * amp * wobble(4 + k) for k in range(4)])
        return out


# -- MAVLink .tlog -----------------------------------------------------------------------------------


def write_tlog(
    flight: SyntheticFlight,
    path: Path | str,
    rate_hz: float = 50.0,
    streams: tuple[str, ...] = ("pos", "att", "imu", "servo", "heartbeat", "wind"),
    jitter_s: float = 0.004,
    gcs_heartbeats: bool = True,
) -> Path:
    """A tlog of ``flight`` as PX4 would stream it (sysid 1) plus, optionally, a GCS heartbeat."""
    from pymavlink.dialects.v20 import common as mavlink

    path = Path(path)
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    t = np.arange(0.0, flight.duration_s, 1.0 / rate_hz)
    s = flight.states(t)
    rng = np.random.default_rng(1)
    recv = UNIX0 + t + rng.uniform(0.0, jitter_s, len(t))
    pack_ts = struct.Struct(">Q").pack
    px4_offboard = 6 << 16  # PX4 main mode OFFBOARD in custom_mode
    base_armed = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    chunks: list[bytes] = []
    add = chunks.append
    wind = flight.wind_ned_mps
    for i in range(len(t)):
        ms = round(t[i] * 1000) + 5000
        ts = pack_ts(int(recv[i] * 1e6))
        if "heartbeat" in streams and i % int(rate_hz) == 0:
            add(
                ts
                + mav.heartbeat_encode(
                    mavlink.MAV_TYPE_QUADROTOR,
                    mavlink.MAV_AUTOPILOT_PX4,
                    base_armed,
                    px4_offboard,
                    mavlink.MAV_STATE_ACTIVE,
                ).pack(mav)
            )
            if gcs_heartbeats:
                add(ts + gcs.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(gcs))
            if "wind" in streams:
                add(ts + mav.wind_cov_encode(ms * 1000, wind[0], wind[1], wind[2], 0, 0, 0, 0, 0).pack(mav))
        if "pos" in streams:
            add(
                ts
                + mav.local_position_ned_encode(
                    ms, s["n"][i], s["e"][i], s["d"][i], s["vn"][i], s["ve"][i], s["vd"][i]
                ).pack(mav)
            )
        if "att" in streams:
            q = s["q"][i]
            add(
                ts
                + mav.attitude_quaternion_encode(ms, q[0], q[1], q[2], q[3], s["p"][i], s["q_rate"][i], s["r"][i]).pack(
                    mav
                )
            )
        if "imu" in streams:
            add(
                ts
                + mav.highres_imu_encode(
                    ms * 1000,
                    s["fx"][i],
                    s["fy"][i],
                    s["fz"][i],
                    s["p"][i],
                    s["q_rate"][i],
                    s["r"][i],
                    0,
                    0,
                    0,
                    1013,
                    0,
                    0,
                    20,
                    0,
                ).pack(mav)
            )
        if "servo" in streams:
            pwm = [int(1000 + 1000 * m) for m in s["motors"][i]] + [0] * 4
            add(ts + mav.servo_output_raw_encode(ms * 1000, 0, *pwm).pack(mav))
    path.write_bytes(b"".join(chunks))
    return path


# -- PX4 ULog (spec: docs.px4.io "ULog File Format") --------------------------------------------------

_ULOG_TOPICS = {
    "vehicle_local_position": ("uint64_t timestamp;float x;float y;float z;float vx;float vy;float vz;", 50.0),
    "vehicle_attitude": ("uint64_t timestamp;float[4] q;", 100.0),
    "vehicle_angular_velocity": ("uint64_t timestamp;float[3] xyz;", 200.0),
    "sensor_combined": ("uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;", 200.0),
    "actuator_outputs": ("uint64_t timestamp;uint32_t noutputs;float[16] output;", 50.0),
    "vehicle_status": ("uint64_t timestamp;uint8_t arming_state;uint8_t nav_state;", 2.0),
}


def _ulog_msg(kind: bytes, body: bytes) -> bytes:
    return struct.pack("<HB", len(body), kind[0]) + body


def write_ulog(flight: SyntheticFlight, path: Path | str) -> Path:
    """A PX4 ULog with the topics above, each at its own PX4-like rate (µs since boot)."""
    path = Path(path)
    out = [b"ULog\x01\x12\x35", struct.pack("<BQ", 1, 0)]
    out.append(_ulog_msg(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0)))
    key = b"char[8] sys_name"
    out.append(_ulog_msg(b"I", bytes([len(key)]) + key + b"PX4_SITL"))
    for name, (fmt, _) in _ULOG_TOPICS.items():
        out.append(_ulog_msg(b"F", f"{name}:{fmt}".encode()))
    for msg_id, name in enumerate(_ULOG_TOPICS):
        out.append(_ulog_msg(b"A", struct.pack("<BH", 0, msg_id) + name.encode()))
    records: list[tuple[int, bytes]] = []
    boot_us = 5_000_000
    for msg_id, (name, (_, rate)) in enumerate(_ULOG_TOPICS.items()):
        t = np.arange(0.0, flight.duration_s, 1.0 / rate) + 0.37 / rate  # offset: streams do not coincide
        s = flight.states(t)
        for i in range(len(t)):
            ts = round(t[i] * 1e6) + boot_us
            if name == "vehicle_local_position":
                body = struct.pack("<Q6f", ts, s["n"][i], s["e"][i], s["d"][i], s["vn"][i], s["ve"][i], s["vd"][i])
            elif name == "vehicle_attitude":
                body = struct.pack("<Q4f", ts, *s["q"][i])
            elif name == "vehicle_angular_velocity":
                body = struct.pack("<Q3f", ts, s["p"][i], s["q_rate"][i], s["r"][i])
            elif name == "sensor_combined":
                body = struct.pack("<Q6f", ts, s["p"][i], s["q_rate"][i], s["r"][i], s["fx"][i], s["fy"][i], s["fz"][i])
            elif name == "actuator_outputs":
                pwm = [1000 + 1000 * m for m in s["motors"][i]] + [0.0] * 12
                body = struct.pack("<QI16f", ts, 4, *pwm)
            else:
                body = struct.pack("<QBB", ts, 2, 14)  # armed, OFFBOARD
            records.append((ts, _ulog_msg(b"D", struct.pack("<H", msg_id) + body)))
    records.sort(key=lambda r: r[0])
    out.extend(r[1] for r in records)
    path.write_bytes(b"".join(out))
    return path


# -- ArduPilot DataFlash ------------------------------------------------------------------------------

_DF_HEAD = b"\xa3\x95"
_DF_STRUCT = {"Q": "Q", "c": "h", "C": "H", "L": "i", "f": "f", "h": "h", "B": "B", "M": "B", "I": "I"}
_DF_MESSAGES = {  # name: (type id, format, columns)
    "ATT": (129, "QccC", "TimeUS,Roll,Pitch,Yaw"),
    "POS": (130, "QLLfff", "TimeUS,Lat,Lng,Alt,RelHomeAlt,RelOriginAlt"),
    "CTUN": (131, "Qfhh", "TimeUS,Alt,DCRt,CRt"),
    "IMU": (132, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
    "RCOU": (133, "Qhhhhhhhh", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8"),
    "MODE": (134, "QMBB", "TimeUS,Mode,ModeNum,Rsn"),
    "ARM": (135, "QBIBB", "TimeUS,ArmState,ArmChecks,Forced,Method"),
}
LAT0_DEG, LON0_DEG, HOME_AMSL_M = 47.3977, 8.5456, 488.0
ARDUCOPTER_GUIDED = 4


def _df_fmt(type_id: int, name: str, fmt: str, cols: str) -> bytes:
    length = 3 + struct.calcsize("<" + "".join(_DF_STRUCT[c] for c in fmt))
    body = struct.pack("<BB4s16s64s", type_id, length, name.encode(), fmt.encode(), cols.encode())
    return _DF_HEAD + bytes([128]) + body


def write_dataflash(flight: SyntheticFlight, path: Path | str, rate_hz: float = 25.0) -> Path:
    """An ArduCopter-style .bin: ATT in centidegrees, POS lat/lon 1e-7 deg and up-positive metres,
    CTUN climb rate in cm/s up-positive, IMU in SI, RCOU in µs. No EKF (XKF1) records, so the
    loader must use the ArduPilot-unit path."""
    path = Path(path)
    out = [
        _DF_HEAD
        + bytes([128])
        + struct.pack("<BB4s16s64s", 128, 89, b"FMT", b"BBnNZ", b"Type,Length,Name,Format,Columns")
    ]
    packers = {}
    for name, (tid, fmt, cols) in _DF_MESSAGES.items():
        out.append(_df_fmt(tid, name, fmt, cols))
        packers[name] = (tid, struct.Struct("<" + "".join(_DF_STRUCT[c] for c in fmt)))

    def rec(name: str, *values) -> bytes:
        tid, st = packers[name]
        return _DF_HEAD + bytes([tid]) + st.pack(*values)

    t = np.arange(0.0, flight.duration_s, 1.0 / rate_hz)
    s = flight.states(t)
    us = (t * 1e6).astype(np.int64) + 20_000_000
    out.append(rec("MODE", int(us[0]), ARDUCOPTER_GUIDED, ARDUCOPTER_GUIDED, 0))
    out.append(rec("ARM", int(us[0]), 1, 0, 0, 0))
    m_per_deg = math.pi / 180 * 6_378_137.0
    for i in range(len(t)):
        from flighttest.frames import quat_to_euler

        roll, pitch, yaw = (math.degrees(float(a)) for a in quat_to_euler(s["q"][i]))
        out.append(rec("ATT", int(us[i]), round(roll * 100), round(pitch * 100), round((yaw % 360) * 100)))
        lat = LAT0_DEG + s["n"][i] / m_per_deg
        lon = LON0_DEG + s["e"][i] / (m_per_deg * math.cos(math.radians(LAT0_DEG)))
        alt_up = -s["d"][i]
        out.append(rec("POS", int(us[i]), round(lat * 1e7), round(lon * 1e7), HOME_AMSL_M + alt_up, alt_up, alt_up))
        out.append(rec("CTUN", int(us[i]), alt_up, 0, round(-s["vd"][i] * 100)))
        out.append(rec("IMU", int(us[i]), 0, s["p"][i], s["q_rate"][i], s["r"][i], s["fx"][i], s["fy"][i], s["fz"][i]))
        pwm = [round(1000 + 1000 * m) for m in s["motors"][i]] + [0] * 4
        out.append(rec("RCOU", int(us[i]), *pwm))
    path.write_bytes(b"".join(out))
    return path
