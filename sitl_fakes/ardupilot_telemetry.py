"""ArduCopter's telemetry: nothing but HEARTBEAT until a ground station asks.

As on real ArduCopter (``../shared/ardupilot_sitl``): streams come from the link's stream-rate parameters
(``MAV1_*``, read at boot; ``MAV1_EXT_STAT 2`` gives SYS_STATUS, POWER_STATUS, MEMINFO, MISSION_CURRENT,
GPS_RAW_INT and NAV_CONTROLLER_OUTPUT at 2 Hz), from REQUEST_DATA_STREAM (a whole group at a rate) and
from MAV_CMD_SET_MESSAGE_INTERVAL (one message; what MAVSDK's ``set_rate_*`` sends; −1 stops it, 0 returns
it to its group's rate). A message ArduPilot has no stream entry for is DENIED with "No ap_message for
mavlink id (N)". LOCAL_POSITION_NED, HOME_POSITION and GPS_GLOBAL_ORIGIN wait for the EKF's origin.
"""

from __future__ import annotations

import math
import time

from pymavlink.dialects.v20 import ardupilotmega as APM

from flighttest.model.aero import G_MPS2
from sitl_fakes import ardupilot as ap
from sitl_fakes.ardupilot import CopterMode
from sitl_fakes.link import mavlink
from sitl_fakes.telemetry import Telemetry

M = mavlink
# what MAVSDK's telemetry asks ArduPilot for but ArduPilot does not stream (no ap_message for it)
NOT_ON_ARDUPILOT = (M.MAVLINK_MSG_ID_ODOMETRY, M.MAVLINK_MSG_ID_WIND_COV, M.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS)
BATTERY_MV = 12600  # the SITL battery of the reference flights (SYS_STATUS / BATTERY_STATUS: 12.6 V, 100 %)


class ArduPilotTelemetry(Telemetry):
    def __init__(self, vehicle, main_hz: float, truth_rate_hz: float):
        super().__init__(vehicle, main_hz, truth_rate_hz)
        for msg_id in NOT_ON_ARDUPILOT:
            self.builders.pop(msg_id, None)
        self.builders.update({
            M.MAVLINK_MSG_ID_POWER_STATUS: self.power_status,
            APM.MAVLINK_MSG_ID_MEMINFO: self.meminfo,
            M.MAVLINK_MSG_ID_MISSION_CURRENT: self.mission_current,
            M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT: self.nav_controller_output,
            M.MAVLINK_MSG_ID_RAW_IMU: self.raw_imu,
            M.MAVLINK_MSG_ID_SCALED_PRESSURE: self.scaled_pressure,
            M.MAVLINK_MSG_ID_RC_CHANNELS: self.rc_channels,
            M.MAVLINK_MSG_ID_SYSTEM_TIME: self.system_time,
            M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: self.gps_global_origin,
            ap.WIND_ID: self.wind,
        })  # fmt: skip
        # group rates from the boot parameters; per-message overrides (None: follow the group)
        self.group_hz: dict[str, float] = {g: max(float(vehicle.p(g)), 0.0) for g in ap.STREAM_GROUPS}
        self.override_s: dict[int, float] = {}
        self.defaults = {k: 0.0 for k in self.builders}
        self.defaults[M.MAVLINK_MSG_ID_HEARTBEAT] = 1.0
        self.next_due = {k: vehicle.t0 for k in self.builders}
        self._recompute()

    # -- scheduling ----------------------------------------------------------------------------------
    def _group_interval_s(self, msg_id: int) -> float:
        rates = [hz for g, hz in self.group_hz.items() if msg_id in ap.STREAM_GROUPS[g] and hz > 0]
        if msg_id == M.MAVLINK_MSG_ID_HEARTBEAT:
            rates.append(1.0)
        return 1.0 / max(rates) if rates else 0.0

    def _recompute(self) -> None:
        old = dict(self.interval_s)
        self.interval_s = {}
        for msg_id in self.builders:
            interval = self.override_s.get(msg_id, self._group_interval_s(msg_id))
            self.interval_s[msg_id] = interval
            if interval > 0 and old.get(msg_id, 0.0) != interval:
                self.next_due[msg_id] = min(self.next_due.get(msg_id, self.v.now), self.v.now + interval)

    def set_group_rate(self, stream_id: int, rate_hz: float) -> None:
        """REQUEST_DATA_STREAM: a group (or all, MAV_DATA_STREAM_ALL) at ``rate_hz`` (0 stops it)."""
        groups = list(ap.DATA_STREAM_GROUPS.values()) if stream_id == M.MAV_DATA_STREAM_ALL else \
            [ap.DATA_STREAM_GROUPS[stream_id]] if stream_id in ap.DATA_STREAM_GROUPS else []  # fmt: skip
        for g in groups:
            self.group_hz[g] = max(float(rate_hz), 0.0)
        self._recompute()
        self.v.event("event", f"REQUEST_DATA_STREAM {stream_id} at {rate_hz} Hz: {', '.join(groups) or 'unknown'}")

    def set_interval(self, msg_id: int, interval_us: float) -> tuple[int, str]:
        if msg_id not in self.builders:
            self.v.statustext(M.MAV_SEVERITY_INFO, f"No ap_message for mavlink id ({msg_id})")
            return 2, f"message {msg_id} not streamed by ArduPilot"  # DENIED
        if interval_us < 0:
            self.override_s[msg_id] = 0.0
            note = "stream off"
        elif interval_us == 0:
            self.override_s.pop(msg_id, None)
            note = "back to the stream group's rate"
        else:
            self.override_s[msg_id] = max(interval_us * 1e-6, 0.004)
            note = f"interval {self.override_s[msg_id] * 1e3:.1f} ms"
        self._recompute()
        return 0, note

    def send_now(self, msg_id: int) -> None:
        builder = self.builders.get(msg_id)
        if builder is None:
            return
        msg = builder()
        if msg is not None:  # a message that needs the EKF's origin is not sent before it has one
            self.v.link.send(msg)
            self.sent += 1

    # -- builders ------------------------------------------------------------------------------------
    def heartbeat(self):
        v = self.v
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_STABILIZE_ENABLED
        base |= M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        if v.mode in ap.POSITION_CONTROLLED:
            base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        if v.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        # GCS_MAVLINK_Copter::vehicle_system_status: a failsafe is CRITICAL, landed STANDBY, else ACTIVE
        if v.crashed:
            status = M.MAV_STATE_EMERGENCY
        elif v.failsafe_gcs:
            status = M.MAV_STATE_CRITICAL
        elif v.land_complete:
            status = M.MAV_STATE_STANDBY
        else:
            status = M.MAV_STATE_ACTIVE
        return M.MAVLink_heartbeat_message(
            M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base, v.mode.custom_mode, status, 3
        )

    def sys_status(self):
        v = self.v
        health = ap.SENSORS_HEALTH if v.ekf_ready else ap.SENSORS_HEALTH & ~ap.SENSORS_EKF_PENDING
        if not v.armable():
            health &= ~M.MAV_SYS_STATUS_PREARM_CHECK
        return M.MAVLink_sys_status_message(ap.SENSORS_PRESENT, ap.SENSORS_ENABLED, health, 0, BATTERY_MV, 0, 100,
                                            0, 0, 0, 0, 0, 0)  # fmt: skip

    def extended_sys_state(self):
        v = self.v
        if v.land_complete:
            landed = M.MAV_LANDED_STATE_ON_GROUND
        elif v.mode is CopterMode.GUIDED and v.guided_sub == "takeoff" and not v.takeoff_complete:
            landed = M.MAV_LANDED_STATE_TAKEOFF
        elif v.mode is CopterMode.LAND or (v.mode is CopterMode.RTL and v.rtl_phase == "land"):
            landed = M.MAV_LANDED_STATE_LANDING
        else:
            landed = M.MAV_LANDED_STATE_IN_AIR
        return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_MC, landed)

    def local_position_ned(self):
        return super().local_position_ned() if self.v.ekf_ready else None

    def home_position(self):
        if not self.v.ekf_ready:
            return None
        cfg = self.v.cfg
        nan4 = (math.nan, math.nan, math.nan, math.nan)  # ArduPilot leaves the home attitude unset
        return M.MAVLink_home_position_message(
            round(cfg.home_lat_deg * 1e7), round(cfg.home_lon_deg * 1e7), int(cfg.home_alt_m * 1000),
            0.0, 0.0, 0.0, nan4, 0.0, 0.0, 0.0, self.boot_us(),
        )  # fmt: skip

    def gps_global_origin(self):
        if not self.v.ekf_ready:
            return None
        cfg = self.v.cfg
        return M.MAVLink_gps_global_origin_message(round(cfg.home_lat_deg * 1e7), round(cfg.home_lon_deg * 1e7),
                                                   int(cfg.home_alt_m * 1000), self.boot_us())  # fmt: skip

    def battery_status(self):
        cells = [BATTERY_MV] + [65535] * 9
        current_ca = int(sum(self.v.body.state.thrust_n) * 150)
        return M.MAVLink_battery_status_message(0, M.MAV_BATTERY_FUNCTION_UNKNOWN, M.MAV_BATTERY_TYPE_UNKNOWN, 32767,
                                                cells, current_ca, -1, -1, 100)  # fmt: skip

    def power_status(self):
        return M.MAVLink_power_status_message(5000, 0, 0)

    def meminfo(self):
        return APM.MAVLink_meminfo_message(0, 65535, 524288)

    def mission_current(self):
        return M.MAVLink_mission_current_message(0, 0, 1, 0)

    def nav_controller_output(self):
        v = self.v
        s = v.body.state
        roll = math.atan2(2 * (s.qw * s.qx + s.qy * s.qz), 1 - 2 * (s.qx**2 + s.qy**2))
        pitch = math.asin(max(-1.0, min(1.0, 2 * (s.qw * s.qy - s.qz * s.qx))))
        alt_error = -(v.pc.pos_ned[2] - v.est.d_m)
        yaw_deg = int(math.degrees(s.yaw_rad()))
        return M.MAVLink_nav_controller_output_message(math.degrees(roll), math.degrees(pitch), yaw_deg, 0, 0,
                                                       alt_error, 0.0, 0.0)  # fmt: skip

    def raw_imu(self):
        # ArduPilot's RAW_IMU: specific force in milli-g (GRAVITY_MSS), rates in mrad/s
        fx, fy, fz = self.specific_force_mps2()
        s = self.v.body.state
        return M.MAVLink_raw_imu_message(self.boot_us(), round(fx * 1000 / G_MPS2), round(fy * 1000 / G_MPS2),
                                         round(fz * 1000 / G_MPS2), int(s.p_radps * 1000), int(s.q_radps * 1000),
                                         int(s.r_radps * 1000), 0, 0, 0)  # fmt: skip

    def wind(self):
        """ArduCopter's WIND (GCS_MAVLINK_Copter::send_wind): sent while the EKF has a position (its airspeed
        vector); the direction the wind comes *from* (deg), its speed and vertical speed. EKF3's wind states stay
        at zero unless drag fusion runs (EK3_DRAG_*): then it is its lagging, noisy estimate."""
        w = self.v.wind_report()
        if w is None:
            return None
        wn, we, wd = w
        return APM.MAVLink_wind_message(math.degrees(math.atan2(-we, -wn)), math.sqrt(wn * wn + we * we + wd * wd),
                                        wd)  # fmt: skip

    def scaled_pressure(self):
        return M.MAVLink_scaled_pressure_message(self.boot_ms(), 1013.25 - (-self.v.body.state.d_m) * 0.12, 0.0, 2500)

    def rc_channels(self):
        pwm = [self.v.rc_pwm(i) for i in range(1, 19)]
        return M.MAVLink_rc_channels_message(self.boot_ms(), 16, *pwm, 255)

    def system_time(self):
        return M.MAVLink_system_time_message(int(time.time() * 1e6), self.boot_ms())

    def autopilot_version(self):
        return M.MAVLink_autopilot_version_message(
            ap.CAPABILITIES, ap.FLIGHT_SW_VERSION, 0, 0, 0, ap.FLIGHT_CUSTOM_VERSION, [0] * 8, [0] * 8, 0, 0, 0,
            ap.UID2,
        )  # fmt: skip
