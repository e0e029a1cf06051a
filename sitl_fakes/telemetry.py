"""Telemetry streams at PX4-like default rates, changeable with SET_MESSAGE_INTERVAL (511).

Position and velocity are the vehicle's *estimate* (``sitl_fakes.estimator``: offset from the truth as
PX4's EKF is); attitude, rates, GPS and the barometer are the truth's. Each builder reads the vehicle
and returns one MAVLink message.

Like a real link, the streams go quiet now and then: gaps of ``telemetry_gap_s`` (50–100 ms) at
``telemetry_gap_rate_hz`` (seeded), in which nothing is sent — what PX4 SITL on a loaded machine and
a flying process that stalls deliver (``../shared/px4_sih``: 60–85 ms gaps among 20 ms periods).
"""

from __future__ import annotations

import math
import random
import time

from sitl_fakes.link import mavlink
from sitl_fakes.physics import rotate_ned_to_body
from sitl_fakes.px4 import Mode

M = mavlink
EARTH_RADIUS_M = 6_378_137.0  # WGS-84 equatorial, as flighttest's loaders read it back
BARO_NOISE_M = 0.06  # SIH's barometer: ALTITUDE.altitude_monotonic's σ on the ground (../shared/px4_sih)
PX4_VERSION = (1 << 24) | (15 << 16) | (0 << 8) | 255  # v1.15.0 official
CAPABILITIES = (
    M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | M.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | M.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)
SENSORS = (
    M.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | M.MAV_SYS_STATUS_SENSOR_3D_MAG
    | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | M.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | M.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | M.MAV_SYS_STATUS_AHRS
    | M.MAV_SYS_STATUS_SENSOR_BATTERY
)
GPS = M.MAV_SYS_STATUS_SENSOR_GPS
PREARM = M.MAV_SYS_STATUS_PREARM_CHECK


def default_rates_hz(main_hz: float) -> dict[int, float]:
    """Message id → rate. The guard's inputs stream at ``main_hz``; the rest at PX4-like rates."""
    return {
        M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
        M.MAVLINK_MSG_ID_SYS_STATUS: 2.0,
        M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 2.0,
        M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: main_hz,
        M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: main_hz,
        M.MAVLINK_MSG_ID_ODOMETRY: main_hz,
        M.MAVLINK_MSG_ID_ATTITUDE: 10.0,
        M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 10.0,
        M.MAVLINK_MSG_ID_GPS_RAW_INT: 2.0,
        M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
        M.MAVLINK_MSG_ID_BATTERY_STATUS: 1.0,
        M.MAVLINK_MSG_ID_HIGHRES_IMU: 5.0,
        M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: 2.0,
        M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: 2.0,
        M.MAVLINK_MSG_ID_WIND_COV: 2.0,
        M.MAVLINK_MSG_ID_VFR_HUD: 4.0,
        M.MAVLINK_MSG_ID_ALTITUDE: 10.0,  # PX4 SITL's tlogs: 10 Hz (../shared/px4_sih)
        M.MAVLINK_MSG_ID_AUTOPILOT_VERSION: 0.0,  # on request only
    }


class Telemetry:
    def __init__(self, vehicle, main_hz: float, truth_rate_hz: float):
        self.v = vehicle
        self.defaults = default_rates_hz(main_hz)
        self.interval_s: dict[int, float] = {k: (1.0 / r if r > 0 else 0.0) for k, r in self.defaults.items()}
        self.next_due: dict[int, float] = {k: vehicle.t0 for k in self.defaults}
        self.builders = {
            M.MAVLINK_MSG_ID_HEARTBEAT: self.heartbeat,
            M.MAVLINK_MSG_ID_SYS_STATUS: self.sys_status,
            M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self.extended_sys_state,
            M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self.local_position_ned,
            M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: self.attitude_quaternion,
            M.MAVLINK_MSG_ID_ODOMETRY: self.odometry,
            M.MAVLINK_MSG_ID_ATTITUDE: self.attitude,
            M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self.global_position_int,
            M.MAVLINK_MSG_ID_GPS_RAW_INT: self.gps_raw_int,
            M.MAVLINK_MSG_ID_HOME_POSITION: self.home_position,
            M.MAVLINK_MSG_ID_BATTERY_STATUS: self.battery_status,
            M.MAVLINK_MSG_ID_HIGHRES_IMU: self.highres_imu,
            M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: self.servo_output_raw,
            M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: self.actuator_output_status,
            M.MAVLINK_MSG_ID_WIND_COV: self.wind_cov,
            M.MAVLINK_MSG_ID_VFR_HUD: self.vfr_hud,
            M.MAVLINK_MSG_ID_ALTITUDE: self.altitude,
            M.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self.autopilot_version,
        }
        self.truth_interval_s = 1.0 / truth_rate_hz if truth_rate_hz > 0 else 0.0
        self.truth_next = vehicle.t0
        self.sent = 0
        cfg = vehicle.cfg
        self._gap_rng = random.Random(cfg.seed * 104729 + 3)
        self._gap_rate_hz = cfg.telemetry_gap_rate_hz
        self._gap_s = cfg.telemetry_gap_s
        self._gap_until = -math.inf
        self._last_tick = vehicle.t0
        self.gaps = 0
        self._imu_rng = random.Random(cfg.seed * 15485863 + 11)
        self._imu_noise = cfg.imu_noise_mps2
        self._imu_bias = cfg.imu_bias_mps2
        self._baro_rng = random.Random(cfg.seed * 32452843 + 5)

    # -- scheduling ----------------------------------------------------------------------------------
    def can_send(self, msg_id: int) -> bool:
        return msg_id in self.builders

    def set_interval(self, msg_id: int, interval_us: float) -> tuple[int, str]:
        if msg_id not in self.builders:
            return 3, f"message {msg_id} not streamed by the fake"  # UNSUPPORTED
        if interval_us < 0:
            self.interval_s[msg_id] = 0.0
            return 0, "stream off"
        if interval_us == 0:
            r = self.defaults[msg_id]
            self.interval_s[msg_id] = 1.0 / r if r > 0 else 0.0
            return 0, "default rate"
        # nothing faster than the physics
        self.interval_s[msg_id] = max(interval_us * 1e-6, 0.004)
        self.next_due[msg_id] = min(self.next_due[msg_id], self.v.now + self.interval_s[msg_id])
        return 0, f"interval {self.interval_s[msg_id] * 1e3:.1f} ms"

    def send_now(self, msg_id: int) -> None:
        builder = self.builders.get(msg_id)
        if builder is None:
            return
        msg = builder()
        if msg is not None:  # a message with nothing to say this time (WIND_COV without an estimate) is not sent
            self.v.link.send(msg)
            self.sent += 1

    def truth_due(self, now: float) -> bool:
        if now + 1e-9 >= self.truth_next:
            self.truth_next = max(self.truth_next + self.truth_interval_s, now - self.truth_interval_s)
            return True
        return False

    def _in_gap(self, now: float) -> bool:
        dt = now - self._last_tick
        self._last_tick = now
        if now < self._gap_until:
            return True
        if self._gap_rate_hz > 0 and self._gap_rng.random() < self._gap_rate_hz * dt:
            self._gap_until = now + self._gap_rng.uniform(*self._gap_s)
            self.gaps += 1
            return True
        return False

    def tick(self, now: float) -> None:
        v = self.v
        if self._in_gap(now):
            return
        if v.heartbeat_due:
            v.heartbeat_due = False
            self.send_now(M.MAVLINK_MSG_ID_HEARTBEAT)
            self.next_due[M.MAVLINK_MSG_ID_HEARTBEAT] = now + 1.0
        for msg_id, interval in self.interval_s.items():
            if interval <= 0.0:
                continue
            due = self.next_due[msg_id]
            if now >= due:
                self.send_now(msg_id)
                # keep the cadence; after a stall do not burst
                self.next_due[msg_id] = due + interval if now - due < interval else now + interval

    # -- builders ------------------------------------------------------------------------------------
    def boot_ms(self) -> int:
        return int((self.v.now - self.v.t0) * 1000) & 0xFFFFFFFF

    def boot_us(self) -> int:
        return int((self.v.now - self.v.t0) * 1e6)

    def heartbeat(self):
        v = self.v
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
        if v.mode in (Mode.HOLD, Mode.TAKEOFF, Mode.LAND, Mode.RTL):
            base |= M.MAV_MODE_FLAG_AUTO_ENABLED | M.MAV_MODE_FLAG_GUIDED_ENABLED
        elif v.mode is Mode.OFFBOARD:
            base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        if v.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        if v.crashed:
            status = M.MAV_STATE_EMERGENCY
        else:
            status = M.MAV_STATE_ACTIVE if v.armed else M.MAV_STATE_STANDBY
        return M.MAVLink_heartbeat_message(
            M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, base, v.mode.custom_mode, status, 3
        )

    def sys_status(self):
        v = self.v
        present = SENSORS | GPS | PREARM
        health = SENSORS
        if v.position_valid():
            health |= GPS
        if v.armable():
            health |= PREARM
        return M.MAVLink_sys_status_message(present, present, health, 250, 16200, 500, 90, 0, 0, 0, 0, 0, 0)

    def extended_sys_state(self):
        v = self.v
        if v.body.state.on_ground:
            landed = M.MAV_LANDED_STATE_ON_GROUND
        elif v.mode is Mode.TAKEOFF:
            landed = M.MAV_LANDED_STATE_TAKEOFF
        elif v.mode is Mode.LAND:
            landed = M.MAV_LANDED_STATE_LANDING
        else:
            landed = M.MAV_LANDED_STATE_IN_AIR
        return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_MC, landed)

    def local_position_ned(self):
        s = self.v.est
        return M.MAVLink_local_position_ned_message(self.boot_ms(), s.n_m, s.e_m, s.d_m, s.vn_mps, s.ve_mps, s.vd_mps)

    def attitude_quaternion(self):
        s = self.v.body.state
        return M.MAVLink_attitude_quaternion_message(
            self.boot_ms(), s.qw, s.qx, s.qy, s.qz, s.p_radps, s.q_radps, s.r_radps, (0.0, 0.0, 0.0, 0.0)
        )

    def odometry(self):
        s = self.v.est
        # PX4 sends pose in LOCAL_NED and velocity in the body frame (child frame BODY_FRD)
        bx, by, bz = rotate_ned_to_body(s.vn_mps, s.ve_mps, s.vd_mps, s.qw, s.qx, s.qy, s.qz)
        nan21 = [math.nan] * 21
        return M.MAVLink_odometry_message(
            self.boot_us(), M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_BODY_FRD, s.n_m, s.e_m, s.d_m,
            (s.qw, s.qx, s.qy, s.qz), bx, by, bz, s.p_radps, s.q_radps, s.r_radps, nan21, nan21, 0,
            M.MAV_ESTIMATOR_TYPE_GPS_INS, 100,
        )  # fmt: skip

    def attitude(self):
        s = self.v.body.state
        roll = math.atan2(2 * (s.qw * s.qx + s.qy * s.qz), 1 - 2 * (s.qx**2 + s.qy**2))
        pitch = math.asin(max(-1.0, min(1.0, 2 * (s.qw * s.qy - s.qz * s.qx))))
        return M.MAVLink_attitude_message(self.boot_ms(), roll, pitch, s.yaw_rad(), s.p_radps, s.q_radps, s.r_radps)

    def _global(self, n_m: float, e_m: float) -> tuple[int, int]:
        cfg = self.v.cfg
        lat = cfg.home_lat_deg + math.degrees(n_m / EARTH_RADIUS_M)
        lon = cfg.home_lon_deg + math.degrees(e_m / (EARTH_RADIUS_M * math.cos(math.radians(cfg.home_lat_deg))))
        return round(lat * 1e7), round(lon * 1e7)

    def global_position_int(self):
        s = self.v.est
        lat, lon = self._global(s.n_m, s.e_m)
        hdg = round(math.degrees(s.yaw_rad()) % 360.0 * 100) % 36000
        return M.MAVLink_global_position_int_message(
            self.boot_ms(), lat, lon, int((self.v.cfg.home_alt_m - s.d_m) * 1000), int(-s.d_m * 1000),
            int(s.vn_mps * 100), int(s.ve_mps * 100), int(s.vd_mps * 100), hdg,
        )  # fmt: skip

    def gps_raw_int(self):
        s = self.v.body.state
        lat, lon = self._global(s.n_m, s.e_m)
        ok = self.v.position_valid()
        vel = int(math.hypot(s.vn_mps, s.ve_mps) * 100)
        cog = int(math.degrees(math.atan2(s.ve_mps, s.vn_mps)) % 360.0 * 100) if vel > 0 else 0
        return M.MAVLink_gps_raw_int_message(
            self.boot_us(), 3 if ok else 1, lat, lon, int((self.v.cfg.home_alt_m - s.d_m) * 1000),
            80, 120, vel, cog, 14 if ok else 0, 0, 500, 800, 200, 0, 0,
        )  # fmt: skip

    def home_position(self):
        cfg = self.v.cfg
        return M.MAVLink_home_position_message(
            round(cfg.home_lat_deg * 1e7), round(cfg.home_lon_deg * 1e7), int(cfg.home_alt_m * 1000),
            0.0, 0.0, 0.0, (1.0, 0.0, 0.0, 0.0), 0.0, 0.0, 0.0, self.boot_us(),
        )  # fmt: skip

    def battery_status(self):
        v = self.v
        cells = [4050] * 4 + [65535] * 6
        current_ca = int(sum(v.body.state.thrust_n) * 150)  # ~1.5 A per newton: a plausible x500 draw
        return M.MAVLink_battery_status_message(
            0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 2500, cells, current_ca, -1, -1, 90
        )

    def specific_force_mps2(self) -> tuple[float, float, float]:
        """The accelerometer: the body's specific force (thrust and drag over the mass, −g on the ground) with
        the autopilot's noise and the IMU's bias."""
        s = self.v.body.state
        n = self._imu_noise
        bx, by, bz = self._imu_bias
        if n <= 0.0:
            return s.fx_mps2 + bx, s.fy_mps2 + by, s.fz_mps2 + bz
        g = self._imu_rng.gauss
        return s.fx_mps2 + bx + n * g(0.0, 1.0), s.fy_mps2 + by + n * g(0.0, 1.0), s.fz_mps2 + bz + n * g(0.0, 1.0)

    def highres_imu(self):
        s = self.v.body.state
        fx, fy, fz = self.specific_force_mps2()
        return M.MAVLink_highres_imu_message(
            self.boot_us(), fx, fy, fz, s.p_radps, s.q_radps, s.r_radps, 0.21, 0.01, 0.42,
            1013.25 - (-s.d_m) * 0.12, 0.0, -s.d_m, 25.0, 0x1FFF,
        )  # fmt: skip

    def _motor_outputs(self) -> list[float]:
        """Motor commands normalised 0..1 of max thrust (what PX4 calls actuator outputs)."""
        tmax = self.v.profile.max_thrust_per_rotor_n
        return [min(max(t / tmax, 0.0), 1.0) for t in self.v.thrust_cmd]

    def servo_output_raw(self):
        pwm = [int(1000 + 1000 * u) if self.v.armed else 900 for u in self._motor_outputs()]
        return M.MAVLink_servo_output_raw_message(self.boot_us() & 0xFFFFFFFF, 0, *pwm, 0, 0, 0, 0)

    def actuator_output_status(self):
        out = self._motor_outputs() + [0.0] * 28
        return M.MAVLink_actuator_output_status_message(self.boot_us(), 4, out)

    def wind_cov(self):
        """PX4's WIND_COV (mavlink/streams/WIND_COV.hpp): only once EKF2 estimates the wind (EKF2_DRAG_CTRL), its
        estimate, var_horiz = the north and east variances summed (m²/s², as PX4 fills it), no vertical wind,
        the altitude AMSL; PX4 leaves var_vert and both accuracies 0."""
        w = self.v.wind_report()
        if w is None:
            return None
        var_n, var_e = self.v.wind_estimate.var_mps2
        return M.MAVLink_wind_cov_message(self.boot_us(), w[0], w[1], 0.0, var_n + var_e, 0.0,
                                          self.v.cfg.home_alt_m - self.v.est.d_m, 0.0, 0.0)  # fmt: skip

    def vfr_hud(self):
        s = self.v.est
        throttle = int(100 * sum(self._motor_outputs()) / 4)
        hdg = int(math.degrees(s.yaw_rad()) % 360.0)
        return M.MAVLink_vfr_hud_message(
            math.hypot(s.vn_mps, s.ve_mps), math.hypot(s.vn_mps, s.ve_mps), hdg, throttle,
            self.v.cfg.home_alt_m - s.d_m, -s.vd_mps,
        )  # fmt: skip

    def altitude(self):
        """PX4's ALTITUDE: ``altitude_monotonic`` the barometer's (the truth with SIH's noise, 0.06 m σ in
        ../shared/px4_sih's hovers), the others the estimate's."""
        est, amsl = self.v.est, self.v.cfg.home_alt_m
        baro = amsl - self.v.body.state.d_m + self._baro_rng.gauss(0.0, BARO_NOISE_M)
        return M.MAVLink_altitude_message(self.boot_us(), baro, amsl - est.d_m, -est.d_m, -est.d_m, -est.d_m,
                                          float("nan"))  # fmt: skip

    def autopilot_version(self):
        return M.MAVLink_autopilot_version_message(
            CAPABILITIES, PX4_VERSION, PX4_VERSION, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0x26AC, 0x0011,
            int(time.time()) & 0xFFFF, [0] * 18,
        )  # fmt: skip
