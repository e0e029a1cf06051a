"""What ArduCopter (master 2026, ``../shared/ardupilot_sitl``) says about itself: modes, parameters, streams.

Everything here is read off the reference flights of real ArduCopter SITL (ArduPilot master ``64a9c787``,
"ArduCopter V4.8.0-dev"): the DataFlash ``PARM`` records give the parameter names and defaults, the
``MODE`` records the mode numbers, the ``.tlog`` the HEARTBEAT, SYS_STATUS, AUTOPILOT_VERSION and the
stream groups. The parameter *types* are those of ArduPilot's declarations (``AP_Int8/16/32``,
``AP_Float``): MAVSDK's typed getters (``get_param_int`` / ``get_param_float``) depend on them.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from sitl_fakes.estimator import EstimateError
from sitl_fakes.link import mavlink as M

MEMINFO_ID = 152  # ardupilotmega.xml's MEMINFO (not in common.xml; built in ardupilot_telemetry)
WIND_ID = 168  # ardupilotmega.xml's WIND (direction the wind comes from, speed, vertical speed)


class CopterMode(IntEnum):
    """ArduCopter's ``custom_mode`` numbers (ArduCopter/mode.h, ``Mode::Number``)."""

    STABILIZE = 0
    ACRO = 1
    ALT_HOLD = 2
    AUTO = 3
    GUIDED = 4
    LOITER = 5
    RTL = 6
    CIRCLE = 7
    LAND = 9
    DRIFT = 11
    SPORT = 13
    FLIP = 14
    AUTOTUNE = 15
    POSHOLD = 16
    BRAKE = 17
    THROW = 18
    SMART_RTL = 21

    @property
    def custom_mode(self) -> int:
        return int(self.value)


# the modes the fake flies; the others exist on ArduCopter but are refused ("Mode change to X failed")
FLOWN_MODES = frozenset({
    CopterMode.STABILIZE, CopterMode.ALT_HOLD, CopterMode.GUIDED, CopterMode.LOITER, CopterMode.RTL,
    CopterMode.LAND, CopterMode.POSHOLD, CopterMode.BRAKE,
})  # fmt: skip
# modes whose position controller needs the EKF's position ("Mode change to GUIDED failed: requires position")
NEEDS_POSITION = frozenset({
    CopterMode.GUIDED, CopterMode.LOITER, CopterMode.RTL, CopterMode.POSHOLD, CopterMode.BRAKE, CopterMode.AUTO,
    CopterMode.CIRCLE, CopterMode.SMART_RTL,
})  # fmt: skip
# modes a pilot flies with the sticks (MAVSDK: STABILIZED, ALTCTL, HOLD, POSCTL)
PILOT_MODES = frozenset({CopterMode.STABILIZE, CopterMode.ALT_HOLD, CopterMode.LOITER, CopterMode.POSHOLD})
# HEARTBEAT base_mode sets MAV_MODE_FLAG_GUIDED_ENABLED while the horizontal position controller runs
# (GCS_MAVLINK_Copter::base_mode: ``pos_control->NE_is_active()``); the tlogs show 81 disarmed in
# STABILIZE, 217 armed in GUIDED / BRAKE / LAND, 89 disarmed in LAND
POSITION_CONTROLLED = frozenset({
    CopterMode.GUIDED, CopterMode.LOITER, CopterMode.RTL, CopterMode.LAND, CopterMode.POSHOLD, CopterMode.BRAKE,
})  # fmt: skip

# Timing of the reference flights' takeoffs (CTUN.ThO, three flights): the throttle stays at zero for
# 2.5 s after arming (ArduCopter's 2 s arming delay, then MOT_SPOOL_TIME 0.5 s of spool-up), then slews
# at 1/TKOFF_SLEW_TIME (0.5 per s) until the land detector sees the climb: lift-off at 3.3 s.
ARMING_DELAY_S = 2.0
# LAND: touchdown ("SIM Hit ground at 0.50 m/s") → LAND_COMPLETE_MAYBE after 0.8 s → LAND_COMPLETE after
# 1.6 s → "Disarming motors" 2.1 s after touchdown (the motors spool down to ground idle first)
LAND_COMPLETE_S = 1.6
LAND_DISARM_AFTER_TOUCHDOWN_S = 2.1
# a failsafe LAND waits this long before descending (Copter::set_mode_land_with_pause, LAND_WITH_DELAY_MS)
LAND_FAILSAFE_PAUSE_S = 4.0
# BRAKE (mode_brake.cpp, config.h): stop at 7.5 m/s² horizontally, vertical limits 2.5 m/s and 7.5 m/s²
BRAKE_DECEL_MPS2 = 7.5
BRAKE_SPEED_Z_MPS = 2.5
# ArduCopter SITL's EKF3 against its own truth (DataFlash XKF1 against SIM2 while airborne, three flights of
# ../shared/ardupilot_sitl and bench/RESULTS.md's vertical): height 0.08-0.09 m high (sd 0.025, drifting over
# 3-9 s), horizontal position within 0.01 m, horizontal velocity 0.015 m/s (over ~3 s), vertical velocity
# sd 0.008-0.015 m/s (decorrelating in 0.3 s). PX4 SIH's EKF2 of 2026-03 was 10-20 times further off
# (bench/RESULTS.md, "This change: the vertical ramps its acceleration at the jerk; the fake's vertical loop
# is ArduCopter's"); today's is as close as this (sitl_fakes.estimator)
SITL_ESTIMATE_ERROR = EstimateError(
    horizontal_sigma_m=0.012, horizontal_tau_s=2.5, height_sigma_m=0.09, height_tau_s=8.0, smoothing_s=0.5,
    horizontal_vel_sigma_mps=0.016, horizontal_vel_tau_s=3.0, vertical_vel_sigma_mps=0.012,
    vertical_vel_tau_s=0.3, velocity_smoothing_s=0.05,
)
# ArduCopter SITL's accelerometer is clean (SIM_ACC1_RND 0, no vibration): HIGHRES_IMU in ../shared/wind_sitl
# varies by 0.0006 m/s² per axis between samples
SITL_IMU_NOISE_MPS2 = 0.0006
# ArduCopter SITL took ~42 s from boot to "EKF3 IMU0 is using GPS" and prearm OK (../shared/ardupilot_sitl)
EKF_DELAY_S = 42.0
# the text ArduCopter answers an arm command with while its EKF has no origin yet (AP_Arming gps checks)
PREARM_EKF_TEXT = "PreArm: AHRS: waiting for home"
EKF_READY_TEXTS = ("EKF3 IMU0 is using GPS", "EKF3 IMU1 is using GPS")
# RC input as ArduPilot reads it: mode switch bands (RC_Channel::read_3pos / mode switch, PWM µs)
MODE_SWITCH_PWM = (1230, 1360, 1490, 1620, 1749)  # upper edges of FLTMODE1..5; ≥ 1750 is FLTMODE6
MODE_SWITCH_CENTRE_PWM = (1165, 1295, 1425, 1555, 1685, 1815)  # a PWM inside each band, for tests
RC_MID_PWM = 1500

# SITL home of the reference flights (GPS_GLOBAL_ORIGIN / HOME_POSITION in the tlogs: CMAC, Canberra)
HOME_LAT_DEG = -35.3632621
HOME_LON_DEG = 149.1652374
HOME_ALT_M = 584.09

# AUTOPILOT_VERSION of the reference firmware (tlog): 4.8.0-dev, git hash 64a9c787
FLIGHT_SW_VERSION = 67633152
CAPABILITIES = 64495  # MISSION/PARAM_FLOAT, MISSION/COMMAND_INT, FTP, SET_*_TARGET, TERRAIN, MAVLINK2, …
FLIGHT_CUSTOM_VERSION = list(b"64a9c787")
UID2 = [*b"3d1219c7c4c5404aaa", 0]
# SYS_STATUS of the reference flights once the EKF is ready (every health bit good, prearm included)
SENSORS_PRESENT = 1399979055
SENSORS_ENABLED = 1382128687
SENSORS_HEALTH = 1467063343
# what is not healthy before the EKF has its origin: GPS, AHRS, the position control and prearm bits
SENSORS_EKF_PENDING = (
    M.MAV_SYS_STATUS_SENSOR_GPS | M.MAV_SYS_STATUS_AHRS | M.MAV_SYS_STATUS_PREARM_CHECK
    | M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL | M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
)

# MAV_PARAM_TYPE of ArduPilot's AP_Param kinds
INT8, INT16 = M.MAV_PARAM_TYPE_INT8, M.MAV_PARAM_TYPE_INT16
INT32, REAL32 = M.MAV_PARAM_TYPE_INT32, M.MAV_PARAM_TYPE_REAL32
INT_TYPES = frozenset({INT8, INT16, INT32})


@dataclass
class Param:
    value: float | int
    type: int  # INT8, INT16, INT32 or REAL32


def _table() -> dict[str, tuple[float, int]]:
    # (default, type). Defaults: the reference flights' PARM records ("Default" column); MAV1_EXT_STAT
    # there was 2 from the boot file, ArduCopter's own default is 0 (vertical-refused-health)
    i8, i16, i32, f = INT8, INT16, INT32, REAL32
    return {
        # GUIDED
        "GUID_TIMEOUT": (3.0, f), "GUID_OPTIONS": (0, i32),
        # failsafes
        "FS_GCS_ENABLE": (0, i8), "FS_GCS_TIMEOUT": (5.0, f), "FS_OPTIONS": (16, i32),
        "FS_EKF_ACTION": (1, i8), "FS_EKF_THRESH": (0.8, f), "FS_THR_ENABLE": (1, i8), "FS_THR_VALUE": (975, i16),
        "FS_CRASH_CHECK": (1, i8), "FS_VIBE_ENABLE": (1, i8), "FS_DR_ENABLE": (2, i8),
        # identity
        "MAV_SYSID": (1, i16), "MAV_GCS_SYSID": (255, i16), "MAV_GCS_SYSID_HI": (0, i16), "MAV_OPTIONS": (0, i16),
        "MAV_TELEM_DELAY": (0, i8),
        # waypoint navigation limits, which GUIDED's position controller takes too
        "WP_SPD": (10.0, f), "WP_SPD_DN": (1.5, f), "WP_SPD_UP": (2.5, f), "WP_ACC": (2.5, f), "WP_ACC_Z": (1.0, f),
        "WP_ACC_CNR": (0.0, f), "WP_JERK": (1.0, f), "WP_RADIUS_M": (2.0, f), "WP_NAVALT_MIN": (0.0, f),
        "WP_YAW_BEHAVIOR": (2, i8), "WP_RFND_USE": (1, i8),
        # LAND
        "LAND_SPD_MS": (0.5, f), "LAND_SPD_HIGH_MS": (0.0, f), "LAND_ALT_LOW_M": (10.0, f), "LAND_REPOSITION": (1, i8),
        # fence
        "FENCE_ENABLE": (0, i8), "FENCE_TYPE": (7, i8), "FENCE_ACTION": (1, i8), "FENCE_ALT_MAX": (100.0, f),
        "FENCE_ALT_MIN": (-10.0, f), "FENCE_RADIUS": (150.0, f), "FENCE_MARGIN": (2.0, f),
        "FENCE_AUTOENABLE": (0, i8), "FENCE_TOTAL": (0, i8), "FENCE_OPTIONS": (0, i16),
        # arming
        "DISARM_DELAY": (10, i8), "ARMING_SKIPCHK": (0, i32), "ARMING_NEED_LOC": (0, i8), "ARMING_OPTIONS": (0, i32),
        # position controller (AC_PosControl; the 4.6 names PSC_POSZ_P, PSC_VELZ_P, … are gone on this master)
        "PSC_D_POS_P": (1.0, f), "PSC_D_VEL_P": (5.0, f), "PSC_D_VEL_I": (0.0, f), "PSC_D_VEL_D": (0.0, f),
        "PSC_D_VEL_IMAX": (10.0, f), "PSC_D_VEL_FLTE": (5.0, f), "PSC_D_ACC_P": (0.05, f), "PSC_D_ACC_I": (0.1, f),
        "PSC_D_ACC_D": (0.0, f),
        "PSC_D_ACC_IMAX": (0.8, f), "PSC_D_ACC_FLTE": (20.0, f), "PSC_D_ACC_FLTT": (0.0, f),
        "INS_ACCEL_FILTER": (20.0, f),
        "PSC_NE_POS_P": (1.0, f), "PSC_NE_VEL_P": (2.0, f), "PSC_NE_VEL_I": (1.0, f), "PSC_NE_VEL_D": (0.25, f),
        "PSC_NE_VEL_IMAX": (10.0, f), "PSC_JERK_D": (5.0, f), "PSC_JERK_NE": (5.0, f), "PSC_ANGLE_MAX": (0.0, f),
        # attitude controller (ANGLE_MAX is ATC_ANGLE_MAX in degrees on this master)
        "ATC_ANGLE_MAX": (30.0, f), "ATC_INPUT_TC": (0.15, f), "ATC_ANG_RLL_P": (4.5, f), "ATC_ANG_PIT_P": (4.5, f),
        "ATC_ANG_YAW_P": (4.5, f), "ATC_RAT_RLL_P": (0.135, f), "ATC_RAT_RLL_I": (0.135, f),
        "ATC_RAT_RLL_D": (0.0036, f), "ATC_RAT_PIT_P": (0.135, f), "ATC_RAT_PIT_I": (0.135, f),
        "ATC_RAT_PIT_D": (0.0036, f), "ATC_RAT_YAW_P": (0.3, f), "ATC_RAT_YAW_I": (0.02, f), "ATC_RAT_YAW_D": (0.0, f),
        "ATC_RATE_FF_ENAB": (1, i8), "ATC_ACC_R_MAX": (1100.0, f), "ATC_ACC_P_MAX": (1100.0, f),
        "ATC_ACC_Y_MAX": (270.0, f),
        # motors (MOT_THST_HOVER: the fake sets the vehicle's true hover thrust at boot, as ArduCopter learns it)
        "MOT_THST_HOVER": (0.39, f), "MOT_HOVER_LEARN": (2, i8), "MOT_SPOOL_TIME": (0.5, f),
        "MOT_SPIN_ARM": (0.1, f), "MOT_SPIN_MIN": (0.15, f),
        # takeoff
        "TKOFF_SLEW_TIME": (2.0, f), "TKOFF_THR_MAX": (0.9, f), "PILOT_TKO_ALT_M": (0.0, f),
        # pilot
        "PILOT_SPD_UP": (2.5, f), "PILOT_SPD_DN": (0.0, f), "PILOT_ACC_Z": (2.5, f), "PILOT_THR_BHV": (0, i16),
        "THR_DZ": (100, i16), "FLTMODE1": (7, i8), "FLTMODE2": (9, i8), "FLTMODE3": (6, i8), "FLTMODE4": (3, i8),
        "FLTMODE5": (5, i8), "FLTMODE6": (0, i8), "FLTMODE_CH": (5, i8), "RC_OVERRIDE_TIME": (3.0, f),
        "RCMAP_ROLL": (1, i8), "RCMAP_PITCH": (2, i8), "RCMAP_THROTTLE": (3, i8), "RCMAP_YAW": (4, i8),
        "INITIAL_MODE": (0, i8),
        # RTL, LOITER, POSHOLD
        "RTL_ALT_M": (15.0, f), "RTL_SPEED_MS": (0.0, f), "RTL_LOIT_TIME": (5000, i32), "RTL_ALT_FINAL_M": (0.0, f),
        "RTL_CLIMB_MIN_M": (0.0, f), "RTL_CONE_SLOPE": (3.0, f), "LOIT_SPEED_MS": (12.5, f),
        "LOIT_ACC_MAX_M": (5.0, f), "LOIT_BRK_ACC_M": (2.5, f), "LOIT_BRK_JRK_M": (5.0, f), "LOIT_BRK_DELAY": (1.0, f),
        # frame and estimator
        "FRAME_CLASS": (1, i8), "FRAME_TYPE": (0, i8), "AHRS_EKF_TYPE": (3, i8), "EK3_ENABLE": (1, i8),
        # EKF3's drag fusion: ballistic coefficients (kg/m²) and momentum drag (1/s), all 0 = off (no wind states)
        "EK3_DRAG_BCOEF_X": (0.0, f), "EK3_DRAG_BCOEF_Y": (0.0, f), "EK3_DRAG_MCOEF": (0.0, f),
        # stream rates of the GCS link (Hz; read at boot, as ArduCopter: changing them later does not restart
        # the streams on the link)
        "MAV1_RAW_SENS": (0, i16), "MAV1_EXT_STAT": (0, i16), "MAV1_RC_CHAN": (0, i16), "MAV1_RAW_CTRL": (0, i16),
        "MAV1_POSITION": (0, i16), "MAV1_EXTRA1": (0, i16), "MAV1_EXTRA2": (0, i16), "MAV1_EXTRA3": (0, i16),
        "MAV1_PARAMS": (0, i16), "MAV1_ADSB": (0, i16), "MAV1_OPTIONS": (0, i16),
        # statistics (int32 in the tlog's PARAM_VALUE)
        "STAT_RUNTIME": (0, i32), "STAT_FLTTIME": (0, i32), "STAT_FLTCNT": (0, i32),
    }  # fmt: skip


def default_params() -> dict[str, Param]:
    return {name: Param(value, kind) for name, (value, kind) in _table().items()}


def encode_param_value(p: Param) -> float:
    """ArduPilot sends every parameter as its value cast to float (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST)."""
    return float(p.value)


def decode_param_value(raw: float, param_type: int) -> float | int:
    return int(raw) if param_type in INT_TYPES else float(raw)


# Stream groups of the link's MAVn_* parameters (GCS_MAVLink_Copter.cpp, STREAM_*_msgs), as far as the
# fake builds the messages. EXT_STAT is what the reference tlogs show at MAV1_EXT_STAT 2: SYS_STATUS,
# POWER_STATUS, MEMINFO, MISSION_CURRENT, GPS_RAW_INT, NAV_CONTROLLER_OUTPUT, each at 2 Hz.
STREAM_GROUPS: dict[str, tuple[int, ...]] = {
    "MAV1_RAW_SENS": (M.MAVLINK_MSG_ID_RAW_IMU, M.MAVLINK_MSG_ID_SCALED_PRESSURE),
    "MAV1_EXT_STAT": (M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_POWER_STATUS, MEMINFO_ID,
                      M.MAVLINK_MSG_ID_MISSION_CURRENT, M.MAVLINK_MSG_ID_GPS_RAW_INT,
                      M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT),
    "MAV1_RC_CHAN": (M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, M.MAVLINK_MSG_ID_RC_CHANNELS),
    "MAV1_RAW_CTRL": (),
    "MAV1_POSITION": (M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    "MAV1_EXTRA1": (M.MAVLINK_MSG_ID_ATTITUDE,),
    "MAV1_EXTRA2": (M.MAVLINK_MSG_ID_VFR_HUD,),
    "MAV1_EXTRA3": (WIND_ID, M.MAVLINK_MSG_ID_BATTERY_STATUS, M.MAVLINK_MSG_ID_SYSTEM_TIME),
    "MAV1_PARAMS": (),
    "MAV1_ADSB": (),
}  # fmt: skip
# REQUEST_DATA_STREAM's req_stream_id → the group (MAV_DATA_STREAM_*); 0 = all of them
DATA_STREAM_GROUPS: dict[int, str] = {
    M.MAV_DATA_STREAM_RAW_SENSORS: "MAV1_RAW_SENS",
    M.MAV_DATA_STREAM_EXTENDED_STATUS: "MAV1_EXT_STAT",
    M.MAV_DATA_STREAM_RC_CHANNELS: "MAV1_RC_CHAN",
    M.MAV_DATA_STREAM_RAW_CONTROLLER: "MAV1_RAW_CTRL",
    M.MAV_DATA_STREAM_POSITION: "MAV1_POSITION",
    M.MAV_DATA_STREAM_EXTRA1: "MAV1_EXTRA1",
    M.MAV_DATA_STREAM_EXTRA2: "MAV1_EXTRA2",
    M.MAV_DATA_STREAM_EXTRA3: "MAV1_EXTRA3",
}


def mode_switch_pwm(slot: int) -> int:
    """A PWM (µs) on FLTMODE_CH that selects FLTMODE<slot> (1..6)."""
    if not 1 <= slot <= 6:
        raise ValueError(f"flight mode slot must be 1..6 (got {slot})")
    return MODE_SWITCH_CENTRE_PWM[slot - 1]


def mode_switch_slot(pwm: int) -> int | None:
    """The FLTMODE slot (1..6) a mode-switch PWM selects; None for no signal (0 / 65535 / < 900)."""
    if pwm < 900 or pwm >= 2200:
        return None
    for slot, edge in enumerate(MODE_SWITCH_PWM, start=1):
        if pwm <= edge:
            return slot
    return 6


def mode_by_name(name: str) -> CopterMode:
    try:
        return CopterMode[name.upper()]
    except KeyError:
        raise ValueError(f"unknown ArduCopter mode {name!r} (one of {', '.join(m.name for m in CopterMode)})") from None
