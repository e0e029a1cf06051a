"""Logs of known motion in every supported format, for tests and the benchmark.

A test helper, not part of the installed package (the wheel leaves ``tests/`` out): the tests import it as
``synthetic`` (pytest puts ``tests/`` on ``sys.path``), ``bench/bench_analysis.py`` adds ``tests/`` itself.

:class:`SyntheticFlight` is a closed-form flight: hover at ``start_alt_m``, then descents (a
raised-cosine vertical speed profile, so a descent of height H in D seconds peaks at πH/(2D); a
negative H is a climb, so a flight can take off from and land on the ground) or a probe
(``d = d0 + A sin(ω0 τ²)``, CONVENTIONS §3), level attitude at a fixed yaw, and "fluctuation" on body
rates, vertical acceleration and motors that grows once the descent speed passes ``onset_mps``, so
identification has a known answer. Every quantity is a function of time, so streams written at
different rates agree exactly.

Height faults of real logs (issue 14) are the estimator's, not the vehicle's: with ``ekf_offset_m``
the estimator's height runs a growing offset below the truth (an EKF that sits metres below home
on the ground), with ``ekf_excursion`` it dips below the truth and back (a hard landing), with
``ekf_error_knots`` it follows any piecewise-linear error (the ArduCopter 3.4 ``.tlog``'s estimator
sinking on for half a minute after its hard landing), with ``glitch`` it jumps 40 m below the
ground. The estimator streams (local/global position, EKF, POS/CTUN) carry the fault; the
barometer, GPS and rangefinder streams carry the truth with small deterministic noise
(``baro_noise_m``, ``gps_noise_m``), the GPS its own ``gps_error_knots`` too. Home is ``d = 0`` at
``HOME_AMSL_M``; ``disarm_s`` keeps a landed vehicle armed on the ground.

Writers: :func:`write_tlog` (pymavlink-packed frames with the tlog's 8-byte big-endian UNIX-µs
prefix), :func:`write_ulog` (PX4 ULog packed by hand per the ULog spec: pyulog 1.3 can only
re-write a ULog it parsed, it has no API to build one from data) and :func:`write_dataflash`
(ArduPilot FMT + records with ArduPilot's units: centidegrees, cm/s, up-positive altitudes). Each
also writes parameters (``PX4_PARAMS`` / ``ARDUPILOT_PARAMS`` unless given).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from flighttest.analysis.schema import ISA_SEA_LEVEL_PA
from flighttest.model.aero import G_MPS2
from flighttest.model.frames import EARTH_RADIUS_M, ned_to_body, quat_from_euler, quat_to_euler

G = G_MPS2
UNIX0 = 1_767_225_600.0  # 2026-01-01, the wall clock of synthetic tlogs
LAT0_DEG, LON0_DEG, HOME_AMSL_M = 47.3977, 8.5456, 488.0
M_PER_DEG = math.pi / 180 * EARTH_RADIUS_M
RANGEFINDER_MIN_M, RANGEFINDER_MAX_M = 0.2, 40.0
# parameters the writers log (ints are integer parameters: PX4 sends those byte-wise over MAVLink)
PX4_PARAMS: dict[str, float | int] = {
    "MPC_Z_VEL_MAX_DN": 1.5,
    "MPC_Z_V_AUTO_DN": 1.0,
    "MPC_LAND_SPEED": 0.7,
    "MPC_TILTMAX_AIR": 45.0,
    "MPC_XY_P": 0.95,
    "MC_ROLL_P": 6.5,
    "COM_OF_LOSS_T": 1.0,
    "COM_OBL_RC_ACT": 0,
    "COM_RC_OVERRIDE": 1,
    "NAV_RCL_ACT": 2,
}
ARDUPILOT_PARAMS: dict[str, float | int] = {
    "WPNAV_SPEED_DN": 150.0,
    "PILOT_SPEED_DN": 0,
    "LAND_SPEED": 50,
    "ATC_ANG_RLL_P": 4.5,
    "GUID_TIMEOUT": 3.0,
    "WP_YAW_BEHAVIOR": 2,
}


def isa_pressure_pa(alt_amsl_m: np.ndarray) -> np.ndarray:
    """Static pressure of the standard atmosphere at an altitude (inverse of ``pressure_altitude_m``)."""
    return ISA_SEA_LEVEL_PA * (1.0 - np.asarray(alt_amsl_m, float) / 44330.77) ** (1.0 / 0.190263)


def _noise(t: np.ndarray, k: int) -> np.ndarray:
    """Deterministic sensor noise of unit amplitude (incommensurate sines: the same at any rate)."""
    return sum(np.sin(2 * np.pi * f * t + 2.3 * k + i) for i, f in enumerate((0.43, 1.37, 3.11))) / 3.0


def _knots(t: np.ndarray, knots: tuple[tuple[float, float], ...]) -> tuple[np.ndarray, np.ndarray]:
    """(value, rate) of the piecewise-linear function through ``knots`` ((t_s, value), time-sorted),
    0 before the first knot and after the last."""
    kt = np.array([k[0] for k in knots], float)
    kv = np.array([k[1] for k in knots], float)
    inside = (t >= kt[0]) & (t <= kt[-1])
    value = np.where(inside, np.interp(t, kt, kv), 0.0)
    slope = np.diff(kv) / np.maximum(np.diff(kt), 1e-9)
    seg = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, max(len(slope) - 1, 0))
    rate = np.where(inside & (len(slope) > 0), slope[seg] if len(slope) else 0.0, 0.0)
    return value, rate


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
    # the IMU feels the air's drag across the thrust axis: −drag_per_s × the air-relative body velocity
    # (x500: 1 N per m/s on 2 kg), so flighttest's wind estimator finds the wind the flight flew in
    drag_per_s: float = 0.5
    # the autopilot's wind report (WIND_COV, WIND, the ulog's wind topic, DataFlash XKF2): its estimate (the
    # true wind), or exact zeros as an estimator that does not estimate the wind sends (PX4's EKF2 and
    # ArduPilot's EKF3 by default on a multicopter); its stated 1 σ (0: none given)
    wind_reported: bool = True
    wind_report_sd_mps: float = 0.0
    glitch: tuple[float, float] | None = None  # (t, seconds) altitude jumps 40 m below ground
    # estimator height below the truth, growing linearly from the first value (t = 0) to the second (end), m
    ekf_offset_m: tuple[float, float] | None = None
    # (t0_s, duration_s, depth_m): the estimator height dips depth below the truth and back (sin² shape)
    ekf_excursion: tuple[float, float, float] | None = None
    # ((t_s, below_truth_m), ...): the estimator's error at knots, linear between them, 0 outside
    ekf_error_knots: tuple[tuple[float, float], ...] | None = None
    # the same for the GPS altitude (an estimator fusing GPS vertical velocity drifts with it)
    gps_error_knots: tuple[tuple[float, float], ...] | None = None
    # when a flight that starts on the ground disarms; None: 1 s after its last move (inf: never)
    disarm_s: float | None = None
    baro_noise_m: float = 0.05
    gps_noise_m: float = 0.2

    @property
    def height_fault(self) -> bool:
        """The flight has an estimator height fault that other height sources reveal."""
        return self.ekf_offset_m is not None or self.ekf_excursion is not None or self.ekf_error_knots is not None

    def estimator_error(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Δd_m, Δvd_mps): how far the estimator's down position and down velocity run from the
        truth (positive: the estimator is below the truth / sinking faster). The glitch is not
        included (it is a jump of the position only)."""
        t = np.asarray(t, float)
        dd, dv = np.zeros_like(t), np.zeros_like(t)
        if self.ekf_offset_m is not None:
            a, b = self.ekf_offset_m
            rate = (b - a) / self.duration_s
            dd += a + rate * np.clip(t, 0.0, self.duration_s)
            dv += np.where((t >= 0) & (t <= self.duration_s), rate, 0.0)
        if self.ekf_excursion is not None:
            t0, dur, depth = self.ekf_excursion
            inside = (t >= t0) & (t <= t0 + dur)
            phase = np.pi * np.clip(t - t0, 0.0, dur) / dur
            dd += np.where(inside, depth * np.sin(phase) ** 2, 0.0)
            dv += np.where(inside, depth * np.pi / dur * np.sin(2 * phase), 0.0)
        if self.ekf_error_knots is not None:
            e, r = _knots(t, self.ekf_error_knots)
            dd += e
            dv += r
        return dd, dv

    def true_alt_m(self, t: np.ndarray) -> np.ndarray:
        """The vehicle's true height above home, m (up-positive)."""
        return -self.vertical(np.asarray(t, float))[0]

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

    def armed(self, t: np.ndarray) -> np.ndarray:
        """1 where the vehicle is armed, 0 where it stands disarmed at home. A flight that starts on the
        ground (``start_alt_m`` 0, no probe) arms 1 s before its first move and, when its moves bring it
        back to home height, disarms 1 s after the last one, as a real log has it: the ground before
        take-off and after landing is where a height source must read home (flighttest.analysis.heights).
        A flight that starts in the air is armed throughout."""
        t = np.asarray(t, float)
        if abs(self.start_alt_m) > 1e-9 or self.probe is not None or not self.descents:
            return np.ones_like(t)
        armed = t >= min(t0 for t0, _, _ in self.descents) - 1.0
        if self.disarm_s is not None:
            armed &= t < self.disarm_s
        elif abs(self.start_alt_m - sum(h for _, h, _ in self.descents)) < 1e-9:
            armed &= t <= max(t0 + dur for t0, _, dur in self.descents) + 1.0
        return armed.astype(float)

    def truth_descents(self) -> list[dict[str, float]]:
        return [
            {"start_s": t0, "duration_s": dur, "height_m": h, "max_rate_mps": math.pi * h / (2 * dur)}
            for t0, h, dur in self.descents
            if h > 0
        ]

    def fluctuation_amp(self, vd: np.ndarray) -> np.ndarray:
        w = vd - self.wind_ned_mps[2]
        return self.base_noise + self.fluct_gain * np.maximum(0.0, w - self.onset_mps)

    def states(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """Every stream's values at ``t``: ``d``/``vd`` are the estimator's (with its faults),
        ``d_true``/``vd_true`` the truth, ``alt_baro``/``alt_gps``/``alt_range`` the sensors' height
        above home (truth plus noise; the rangefinder's is NaN outside its range)."""
        t = np.asarray(t, float)
        d_true, vd_true, ad = self.vertical(t)
        moving = vd_true > 1e-9
        ve = np.where(moving, self.east_speed_mps, 0.0)
        e = np.cumsum(np.concatenate([[0.0], np.diff(t) * ve[1:]]))
        dd, dv = self.estimator_error(t)
        d, vd = d_true + dd, vd_true + dv
        gps_err = _knots(t, self.gps_error_knots)[0] if self.gps_error_knots is not None else 0.0
        if self.glitch is not None:
            g0, gdur = self.glitch
            d = np.where((t >= g0) & (t < g0 + gdur), d + self.start_alt_m + 40.0, d)
        amp = self.fluctuation_amp(vd_true)
        alt_range = -d_true + 0.01 * _noise(t, 2)
        alt_range[(alt_range <= RANGEFINDER_MIN_M) | (alt_range >= RANGEFINDER_MAX_M)] = np.nan

        # deterministic "noise": a sum of incommensurate sines, the same at any sample rate
        def wobble(k: int) -> np.ndarray:
            return sum(np.sin(2 * np.pi * f * t + k * 1.7 + i) for i, f in enumerate((7.3, 11.1, 13.7))) / 2.0

        q = quat_from_euler(np.zeros_like(t), np.zeros_like(t), np.full_like(t, math.radians(self.yaw_deg)))
        wn, we, wd = self.wind_ned_mps
        bx, by, _ = ned_to_body(-wn + 0.0 * t, ve - we, vd_true - wd, q[:, 0], q[:, 1], q[:, 2], q[:, 3])
        fx, fy = -self.drag_per_s * bx, -self.drag_per_s * by
        thrust = 0.5 * (1 - ad / G)
        out = {
            "t": t,
            "n": np.zeros_like(t),
            "e": e,
            "d": d,
            "vn": np.zeros_like(t),
            "ve": ve,
            "vd": vd,
            "d_true": d_true,
            "vd_true": vd_true,
            "alt_baro": -d_true + self.baro_noise_m * _noise(t, 0),
            "alt_gps": -d_true + self.gps_noise_m * _noise(t, 1) - gps_err,
            "alt_range": alt_range,
            "ad": ad,
            "q": q,
            "p": amp * wobble(0),
            "q_rate": amp * wobble(1),
            "r": 0.3 * amp * wobble(2),
            "fx": fx,
            "fy": fy,
            "fz": ad - G + 5 * amp * wobble(3),
        }
        out["armed"] = self.armed(t)
        # the land detector: at home height and still (taking off and landing are in the air)
        out["landed"] = ((-d_true < 0.05) & (np.abs(vd_true) < 0.05)).astype(float)
        # disarmed on the ground the motors stand still
        out["motors"] = np.column_stack([thrust + 0.2 * amp * wobble(4 + k) for k in range(4)]) * out["armed"][:, None]
        return out


# -- MAVLink .tlog -----------------------------------------------------------------------------------

TLOG_STREAMS = ("pos", "att", "imu", "servo", "heartbeat", "wind")
# what a height-fault flight adds by default: the streams that show the truth, and the parameters
TLOG_HEIGHT_STREAMS = ("global", "altitude", "baro", "gps", "params")
# every stream write_tlog knows ("att_euler": ATTITUDE; "range": DISTANCE_SENSOR, downward; "landed":
# EXTENDED_SYS_STATE at 1 Hz; "wind_ardupilot": ArduPilot's WIND at 1 Hz, the direction it comes from)
TLOG_ALL_STREAMS = (*TLOG_STREAMS, *TLOG_HEIGHT_STREAMS, "att_euler", "range", "landed", "wind_ardupilot")
_SENSOR_RATES_HZ = {"altitude": 10.0, "baro": 10.0, "gps": 5.0, "range": 10.0}


def _param_value_messages(mav, mavlink, params: dict[str, float | int], bytewise: bool) -> list:
    """PARAM_VALUE messages; integers byte-wise in the float as PX4 sends them, or cast as ArduPilot does."""
    out = []
    for index, (name, value) in enumerate(params.items()):
        if isinstance(value, int):
            ptype = mavlink.MAV_PARAM_TYPE_INT32
            wire = struct.unpack("<f", struct.pack("<i", value))[0] if bytewise else float(value)
        else:
            ptype, wire = mavlink.MAV_PARAM_TYPE_REAL32, float(value)
        out.append(mav.param_value_encode(name.encode(), wire, ptype, len(params), index))
    return out


def write_tlog(
    flight: SyntheticFlight,
    path: Path | str,
    rate_hz: float = 50.0,
    streams: tuple[str, ...] | None = None,
    jitter_s: float = 0.004,
    gcs_heartbeats: bool = True,
    autopilot: str = "px4",
    params: dict[str, float | int] | None = None,
) -> Path:
    """A tlog of ``flight`` as PX4 (or, ``autopilot="ardupilot"``, ArduCopter in GUIDED) would stream
    it (sysid 1) plus, optionally, a GCS heartbeat.

    ``streams`` (see ``TLOG_ALL_STREAMS``): by default ``TLOG_STREAMS``, plus ``TLOG_HEIGHT_STREAMS``
    when the flight has a height fault. "pos" is LOCAL_POSITION_NED, "global" GLOBAL_POSITION_INT
    (leave out "pos" for a log whose position is the global one, as ArduCopter 3.x streamed),
    "altitude" ALTITUDE, "baro" SCALED_PRESSURE, "gps" GPS_RAW_INT (the first fix is a no-fix),
    "range" DISTANCE_SENSOR, "landed" EXTENDED_SYS_STATE, "params" PARAM_VALUE of ``params`` (default
    ``PX4_PARAMS`` / ``ARDUPILOT_PARAMS``) before the first sample."""
    from pymavlink.dialects.v20 import common as mavlink

    if streams is None:
        streams = TLOG_STREAMS + (TLOG_HEIGHT_STREAMS if flight.height_fault else ())
    if autopilot not in ("px4", "ardupilot"):
        raise ValueError(f"autopilot must be 'px4' or 'ardupilot' (got {autopilot!r})")
    px4 = autopilot == "px4"
    path = Path(path)
    from pymavlink.dialects.v20 import ardupilotmega

    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    apm = ardupilotmega.MAVLink(None, srcSystem=1, srcComponent=1)  # its WIND message
    gcs = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    t = np.arange(0.0, flight.duration_s, 1.0 / rate_hz)
    s = flight.states(t)
    rng = np.random.default_rng(1)
    recv = UNIX0 + t + rng.uniform(0.0, jitter_s, len(t))
    pack_ts = struct.Struct(">Q").pack
    if px4:
        hb_autopilot, custom_mode = mavlink.MAV_AUTOPILOT_PX4, 6 << 16  # PX4 main mode OFFBOARD in custom_mode
    else:
        hb_autopilot, custom_mode = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, 4  # ArduCopter GUIDED
    base_armed = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    every = {k: max(1, round(rate_hz / hz)) for k, hz in _SENSOR_RATES_HZ.items()}
    chunks: list[bytes] = []
    add = chunks.append
    wind = flight.wind_ned_mps
    if "params" in streams:
        ts = pack_ts(int((recv[0] - 0.5) * 1e6))
        plist = params if params is not None else (PX4_PARAMS if px4 else ARDUPILOT_PARAMS)
        chunks.extend(ts + m.pack(mav) for m in _param_value_messages(mav, mavlink, plist, bytewise=px4))
    lat = LAT0_DEG + s["n"] / M_PER_DEG
    lon = LON0_DEG + s["e"] / (M_PER_DEG * math.cos(math.radians(LAT0_DEG)))
    alt_est = -s["d"]
    press_hpa = isa_pressure_pa(HOME_AMSL_M + s["alt_baro"]) / 100.0
    euler = np.column_stack(quat_to_euler(s["q"]))
    for i in range(len(t)):
        ms = round(t[i] * 1000) + 5000
        ts = pack_ts(int(recv[i] * 1e6))
        if "heartbeat" in streams and i % int(rate_hz) == 0:
            add(
                ts
                + mav.heartbeat_encode(
                    mavlink.MAV_TYPE_QUADROTOR,
                    hb_autopilot,
                    base_armed if s["armed"][i] else mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                    custom_mode,
                    mavlink.MAV_STATE_ACTIVE,
                ).pack(mav)
            )
            if gcs_heartbeats:
                add(ts + gcs.heartbeat_encode(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(gcs))
            if "landed" in streams:
                landed_state = mavlink.MAV_LANDED_STATE_ON_GROUND if s["landed"][i] else mavlink.MAV_LANDED_STATE_IN_AIR
                add(ts + mav.extended_sys_state_encode(0, landed_state).pack(mav))
            w = wind if flight.wind_reported else (0.0, 0.0, 0.0)
            if "wind" in streams:
                sd = flight.wind_report_sd_mps
                add(ts + mav.wind_cov_encode(ms * 1000, w[0], w[1], w[2], sd * sd, 0, 0, sd, 0).pack(mav))
            if "wind_ardupilot" in streams:
                from_deg = math.degrees(math.atan2(-w[1], -w[0])) if w[0] or w[1] else 0.0
                add(ts + apm.wind_encode(from_deg, math.hypot(w[0], w[1]), 0.0).pack(apm))
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
        if "att_euler" in streams:
            roll, pitch, yaw = euler[i]
            add(ts + mav.attitude_encode(ms, roll, pitch, yaw, s["p"][i], s["q_rate"][i], s["r"][i]).pack(mav))
        if "global" in streams:
            add(
                ts
                + mav.global_position_int_encode(
                    ms,
                    round(lat[i] * 1e7),
                    round(lon[i] * 1e7),
                    round((HOME_AMSL_M + alt_est[i]) * 1000),
                    round(alt_est[i] * 1000),
                    round(s["vn"][i] * 100),
                    round(s["ve"][i] * 100),
                    round(s["vd"][i] * 100),
                    round(flight.yaw_deg % 360 * 100),
                ).pack(mav)
            )
        if "altitude" in streams and i % every["altitude"] == 0:
            amsl = HOME_AMSL_M + alt_est[i]
            baro = HOME_AMSL_M + s["alt_baro"][i]
            add(ts + mav.altitude_encode(ms * 1000, baro, amsl, alt_est[i], alt_est[i], alt_est[i], -1.0).pack(mav))
        if "baro" in streams and i % every["baro"] == 0:
            add(ts + mav.scaled_pressure_encode(ms, press_hpa[i], 0.0, 2000).pack(mav))
        if "gps" in streams and i % every["gps"] == 0:
            fix, alt_mm = (1, 0) if i == 0 else (3, round((HOME_AMSL_M + s["alt_gps"][i]) * 1000))
            gps = mav.gps_raw_int_encode(
                ms * 1000, fix, round(lat[i] * 1e7), round(lon[i] * 1e7), alt_mm, 70, 110, 0, 0, 10
            )
            add(ts + gps.pack(mav))
        if "range" in streams and i % every["range"] == 0:
            r = s["alt_range"][i]
            cm = round(RANGEFINDER_MAX_M * 100) if not np.isfinite(r) else round(r * 100)
            sensor = mav.distance_sensor_encode(
                ms, round(RANGEFINDER_MIN_M * 100), round(RANGEFINDER_MAX_M * 100), cm, 0, 0, 25, 0
            )
            add(ts + sensor.pack(mav))
            forward = mav.distance_sensor_encode(ms, 20, 4000, 500, 0, 1, 0, 0)  # a forward sensor: not a height
            add(ts + forward.pack(mav))
    path.write_bytes(b"".join(chunks))
    return path


# -- PX4 ULog (spec: docs.px4.io "ULog File Format") --------------------------------------------------

_ULOG_TOPICS = {  # name: (format, rate Hz)
    "vehicle_local_position": ("uint64_t timestamp;float x;float y;float z;float vx;float vy;float vz;", 50.0),
    "vehicle_attitude": ("uint64_t timestamp;float[4] q;", 100.0),
    "vehicle_angular_velocity": ("uint64_t timestamp;float[3] xyz;", 200.0),
    "sensor_combined": ("uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;", 200.0),
    "actuator_outputs": ("uint64_t timestamp;uint32_t noutputs;float[16] output;", 50.0),
    "vehicle_status": ("uint64_t timestamp;uint8_t arming_state;uint8_t nav_state;", 2.0),
    "vehicle_global_position": ("uint64_t timestamp;double lat;double lon;float alt;", 50.0),
    "vehicle_air_data": ("uint64_t timestamp;float baro_alt_meter;float baro_pressure_pa;", 20.0),
    "sensor_baro": ("uint64_t timestamp;uint32_t device_id;float pressure;float temperature;", 20.0),
    "vehicle_gps_position": (
        "uint64_t timestamp;double latitude_deg;double longitude_deg;double altitude_msl_m;uint8_t fix_type;",
        5.0,
    ),
    "distance_sensor": (
        "uint64_t timestamp;float min_distance;float max_distance;float current_distance;uint8_t orientation;",
        10.0,
    ),
    "wind": (
        "uint64_t timestamp;float windspeed_north;float windspeed_east;float variance_north;float variance_east;",
        5.0,
    ),
}
# before PX4 1.14 the GPS topic carried integer lat/lon (1e-7 deg) and alt (mm)
_ULOG_GPS_OLD = "uint64_t timestamp;int32_t lat;int32_t lon;int32_t alt;uint8_t fix_type;"
ULOG_TOPICS = (
    "vehicle_local_position",
    "vehicle_attitude",
    "vehicle_angular_velocity",
    "sensor_combined",
    "actuator_outputs",
    "vehicle_status",
    "vehicle_global_position",
    "vehicle_air_data",
    "vehicle_gps_position",
)


def _ulog_msg(kind: bytes, body: bytes) -> bytes:
    return struct.pack("<HB", len(body), kind[0]) + body


def _ulog_body(name: str, ts: int, s: dict[str, np.ndarray], i: int, old_gps: bool) -> bytes:
    if name == "vehicle_local_position":
        return struct.pack("<Q6f", ts, s["n"][i], s["e"][i], s["d"][i], s["vn"][i], s["ve"][i], s["vd"][i])
    if name == "vehicle_attitude":
        return struct.pack("<Q4f", ts, *s["q"][i])
    if name == "vehicle_angular_velocity":
        return struct.pack("<Q3f", ts, s["p"][i], s["q_rate"][i], s["r"][i])
    if name == "sensor_combined":
        return struct.pack("<Q6f", ts, s["p"][i], s["q_rate"][i], s["r"][i], s["fx"][i], s["fy"][i], s["fz"][i])
    if name == "actuator_outputs":
        pwm = [1000 + 1000 * m for m in s["motors"][i]] + [0.0] * 12
        return struct.pack("<QI16f", ts, 4, *pwm)
    if name == "vehicle_global_position":
        return struct.pack("<Qddf", ts, s["lat"][i], s["lon"][i], HOME_AMSL_M - s["d"][i])
    if name == "vehicle_air_data":
        baro = HOME_AMSL_M + s["alt_baro"][i]
        return struct.pack("<Qff", ts, baro, isa_pressure_pa(baro))
    if name == "sensor_baro":
        return struct.pack("<QIff", ts, 6620172, isa_pressure_pa(HOME_AMSL_M + s["alt_baro"][i]), 20.0)
    if name == "vehicle_gps_position":
        fix, alt = (1, 0.0) if i == 0 else (3, HOME_AMSL_M + s["alt_gps"][i])  # the first sample has no fix
        if old_gps:
            return struct.pack("<QiiiB", ts, round(s["lat"][i] * 1e7), round(s["lon"][i] * 1e7), round(alt * 1000), fix)
        return struct.pack("<QdddB", ts, s["lat"][i], s["lon"][i], alt, fix)
    if name == "wind":
        return struct.pack("<Q4f", ts, s["wind_n"][i], s["wind_e"][i], s["wind_var"][i], s["wind_var"][i])
    if name == "distance_sensor":
        r = s["alt_range"][i]
        r = RANGEFINDER_MAX_M if not np.isfinite(r) else r
        return struct.pack("<QfffB", ts, RANGEFINDER_MIN_M, RANGEFINDER_MAX_M, r, 25)
    return struct.pack("<QBB", ts, 2 if s["armed"][i] else 1, 14)  # vehicle_status: armed (or standby), OFFBOARD


def _ulog_param(name: str, value: float | int) -> bytes:
    key = f"int32_t {name}" if isinstance(value, int) else f"float {name}"
    raw = struct.pack("<i", value) if isinstance(value, int) else struct.pack("<f", value)
    return _ulog_msg(b"P", bytes([len(key)]) + key.encode() + raw)


def write_ulog(
    flight: SyntheticFlight,
    path: Path | str,
    topics: tuple[str, ...] = ULOG_TOPICS,
    old_gps: bool = False,
    params: dict[str, float | int] | None = None,
) -> Path:
    """A PX4 ULog with ``topics`` (see ``_ULOG_TOPICS``; "sensor_baro" and "distance_sensor" on
    request), each at its own PX4-like rate (µs since boot), and ``params`` (default ``PX4_PARAMS``)
    as the initial parameters. ``old_gps``: the pre-1.14 GPS topic (``alt`` int mm)."""
    path = Path(path)
    out = [b"ULog\x01\x12\x35", struct.pack("<BQ", 1, 0)]
    out.append(_ulog_msg(b"B", bytes(16) + struct.pack("<3Q", 0, 0, 0)))
    key = b"char[8] sys_name"
    out.append(_ulog_msg(b"I", bytes([len(key)]) + key + b"PX4_SITL"))
    for name in topics:
        fmt = _ULOG_GPS_OLD if name == "vehicle_gps_position" and old_gps else _ULOG_TOPICS[name][0]
        out.append(_ulog_msg(b"F", f"{name}:{fmt}".encode()))
    out.extend(_ulog_param(k, v) for k, v in (PX4_PARAMS if params is None else params).items())
    for msg_id, name in enumerate(topics):
        out.append(_ulog_msg(b"A", struct.pack("<BH", 0, msg_id) + name.encode()))
    records: list[tuple[int, bytes]] = []
    boot_us = 5_000_000
    for msg_id, name in enumerate(topics):
        rate = _ULOG_TOPICS[name][1]
        t = np.arange(0.0, flight.duration_s, 1.0 / rate) + 0.37 / rate  # offset: streams do not coincide
        s = flight.states(t)
        reported = flight.wind_ned_mps if flight.wind_reported else (0.0, 0.0, 0.0)
        s["wind_n"], s["wind_e"] = np.full(len(t), reported[0]), np.full(len(t), reported[1])
        s["wind_var"] = np.full(len(t), flight.wind_report_sd_mps**2)
        s["lat"] = LAT0_DEG + s["n"] / M_PER_DEG
        s["lon"] = LON0_DEG + s["e"] / (M_PER_DEG * math.cos(math.radians(LAT0_DEG)))
        for i in range(len(t)):
            ts = round(t[i] * 1e6) + boot_us
            body = _ulog_body(name, ts, s, i, old_gps)
            records.append((ts, _ulog_msg(b"D", struct.pack("<H", msg_id) + body)))
    records.sort(key=lambda r: r[0])
    out.extend(r[1] for r in records)
    path.write_bytes(b"".join(out))
    return path


# -- ArduPilot DataFlash ------------------------------------------------------------------------------

_DF_HEAD = b"\xa3\x95"
_DF_STRUCT = {"Q": "Q", "c": "h", "C": "H", "L": "i", "f": "f", "h": "h", "B": "B", "M": "B", "I": "I", "N": "16s"}
_DF_MESSAGES = {  # name: (type id, format, columns)
    "ATT": (129, "QccC", "TimeUS,Roll,Pitch,Yaw"),
    "POS": (130, "QLLfff", "TimeUS,Lat,Lng,Alt,RelHomeAlt,RelOriginAlt"),
    "CTUN": (131, "Qffhh", "TimeUS,Alt,BAlt,DCRt,CRt"),
    "IMU": (132, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ"),
    "RCOU": (133, "Qhhhhhhhh", "TimeUS,C1,C2,C3,C4,C5,C6,C7,C8"),
    "MODE": (134, "QMBB", "TimeUS,Mode,ModeNum,Rsn"),
    "ARM": (135, "QBIBB", "TimeUS,ArmState,ArmChecks,Forced,Method"),
    "BARO": (136, "QBfff", "TimeUS,I,Alt,AltAMSL,Press"),
    "GPS": (137, "QBBLLf", "TimeUS,I,Status,Lat,Lng,Alt"),
    "PARM": (138, "QNf", "TimeUS,Name,Value"),
    "AHR2": (139, "QccCfLLffff", "TimeUS,Roll,Pitch,Yaw,Alt,Lat,Lng,Q1,Q2,Q3,Q4"),
    "XKQ": (140, "QBffff", "TimeUS,C,Q1,Q2,Q3,Q4"),
    "XKF1": (141, "QBffffff", "TimeUS,C,PN,PE,PD,VN,VE,VD"),
    "RFND": (142, "QBCBB", "TimeUS,Instance,Dist,Stat,Orient"),
    "XKF2": (143, "QBff", "TimeUS,C,VWN,VWE"),
}
# the default records; "AHR2", "XKQ" (attitude without ATT), "XKF1" (EKF position), "XKF2" (its wind) and
# "RFND" on request
DF_RECORDS = ("ATT", "POS", "CTUN", "IMU", "RCOU", "BARO", "GPS", "PARM")
ARDUCOPTER_GUIDED = 4
RFND_GOOD, RFND_OUT_OF_RANGE_LOW, RFND_OUT_OF_RANGE_HIGH = 4, 2, 3


def _df_fmt(type_id: int, name: str, fmt: str, cols: str) -> bytes:
    length = 3 + struct.calcsize("<" + "".join(_DF_STRUCT[c] for c in fmt))
    body = struct.pack("<BB4s16s64s", type_id, length, name.encode(), fmt.encode(), cols.encode())
    return _DF_HEAD + bytes([128]) + body


def write_dataflash(
    flight: SyntheticFlight,
    path: Path | str,
    rate_hz: float = 25.0,
    records: tuple[str, ...] = DF_RECORDS,
    params: dict[str, float | int] | None = None,
) -> Path:
    """An ArduCopter-style .bin: ATT/AHR2 in centidegrees, POS lat/lon 1e-7 deg and up-positive metres,
    CTUN climb rate in cm/s up-positive, IMU in SI, RCOU in µs, BARO m above home (the truth), GPS m
    AMSL (the first record has no fix), PARM ``params`` (default ``ARDUPILOT_PARAMS``). Without
    "XKF1" in ``records`` there are no EKF records, so the loader must use the ArduPilot-unit path.
    The second instance of BARO (I = 1) and of the EKF records (C = 1) is written too, wrong on
    purpose: loaders must keep instance 0. MODE and ARM are always written."""
    path = Path(path)
    unknown = set(records) - set(_DF_MESSAGES)
    if unknown:
        raise ValueError(f"unknown DataFlash records {sorted(unknown)}")
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
    if "PARM" in records:
        for name, value in (ARDUPILOT_PARAMS if params is None else params).items():
            out.append(rec("PARM", int(us[0]) - 100_000, name.encode(), float(value)))
    out.append(rec("MODE", int(us[0]), ARDUCOPTER_GUIDED, ARDUCOPTER_GUIDED, 0))
    armed = s["armed"] != 0
    for i in np.flatnonzero(np.concatenate([[True], armed[1:] != armed[:-1]])):  # ARM at the start and each change
        out.append(rec("ARM", int(us[i]), int(armed[i]), 0, 0, 0))
    euler = np.degrees(np.column_stack(quat_to_euler(s["q"])))
    lat_all = LAT0_DEG + s["n"] / M_PER_DEG
    lon_all = LON0_DEG + s["e"] / (M_PER_DEG * math.cos(math.radians(LAT0_DEG)))
    gps_every = max(1, round(rate_hz / 5.0))
    want = set(records)
    for i in range(len(t)):
        u = int(us[i])
        roll, pitch, yaw = euler[i]
        lat, lon = round(lat_all[i] * 1e7), round(lon_all[i] * 1e7)
        alt_up = -s["d"][i]
        if "ATT" in want:
            out.append(rec("ATT", u, round(roll * 100), round(pitch * 100), round((yaw % 360) * 100)))
        if "AHR2" in want:
            out.append(
                rec(
                    "AHR2",
                    u,
                    round(roll * 100),
                    round(pitch * 100),
                    round((yaw % 360) * 100),
                    HOME_AMSL_M + alt_up,
                    lat,
                    lon,
                    *s["q"][i],
                )
            )
        if "XKQ" in want:
            out.append(rec("XKQ", u, 0, *s["q"][i]))
            out.append(rec("XKQ", u, 1, 1.0, 0.0, 0.0, 0.0))  # core 1: a wrong attitude
        if "XKF1" in want:
            out.append(rec("XKF1", u, 0, s["n"][i], s["e"][i], s["d"][i], s["vn"][i], s["ve"][i], s["vd"][i]))
            out.append(rec("XKF1", u, 1, 0.0, 0.0, s["d"][i] + 50.0, 0.0, 0.0, 0.0))  # core 1: wrong
        if "XKF2" in want:
            w = flight.wind_ned_mps if flight.wind_reported else (0.0, 0.0, 0.0)
            out.append(rec("XKF2", u, 0, w[0], w[1]))
            out.append(rec("XKF2", u, 1, 9.0, 9.0))  # core 1: wrong
        if "POS" in want:
            out.append(rec("POS", u, lat, lon, HOME_AMSL_M + alt_up, alt_up, alt_up))
        if "CTUN" in want:
            out.append(rec("CTUN", u, alt_up, s["alt_baro"][i], 0, round(-s["vd"][i] * 100)))
        if "BARO" in want:
            baro = s["alt_baro"][i]
            press = float(isa_pressure_pa(HOME_AMSL_M + baro))
            out.append(rec("BARO", u, 0, baro, HOME_AMSL_M + baro, press))
            out.append(rec("BARO", u, 1, baro + 30.0, HOME_AMSL_M + baro + 30.0, press - 300.0))  # a wrong second baro
        if "GPS" in want and i % gps_every == 0:
            status, alt = (1, 0.0) if i == 0 else (3, HOME_AMSL_M + s["alt_gps"][i])
            out.append(rec("GPS", u, 0, status, lat, lon, alt))
        if "RFND" in want:
            r = s["alt_range"][i]
            if np.isfinite(r):
                out.append(rec("RFND", u, 0, round(r * 100), RFND_GOOD, 25))
            else:
                low = -s["d_true"][i] < RANGEFINDER_MIN_M
                out.append(rec("RFND", u, 0, 0, RFND_OUT_OF_RANGE_LOW if low else RFND_OUT_OF_RANGE_HIGH, 25))
        if "IMU" in want:
            out.append(rec("IMU", u, 0, s["p"][i], s["q_rate"][i], s["r"][i], s["fx"][i], s["fy"][i], s["fz"][i]))
        if "RCOU" in want:
            pwm = [round(1000 + 1000 * m) for m in s["motors"][i]] + [0] * 4
            out.append(rec("RCOU", u, *pwm))
    path.write_bytes(b"".join(out))
    return path
