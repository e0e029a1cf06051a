"""What a PX4 multicopter says about itself: custom modes, parameters and their defaults."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import Enum

# PX4 custom_mode = main << 16 | sub << 24 (px4_custom_mode.h)
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD, MAIN_STABILIZED = 1, 2, 3, 4, 5, 6, 7
SUB_AUTO_READY, SUB_AUTO_TAKEOFF, SUB_AUTO_LOITER, SUB_AUTO_MISSION = 1, 2, 3, 4
SUB_AUTO_RTL, SUB_AUTO_LAND = 5, 6


class Mode(Enum):
    """The flight modes the fake flies; value = (main, sub) of the PX4 custom mode."""

    HOLD = (MAIN_AUTO, SUB_AUTO_LOITER)
    TAKEOFF = (MAIN_AUTO, SUB_AUTO_TAKEOFF)
    LAND = (MAIN_AUTO, SUB_AUTO_LAND)
    RTL = (MAIN_AUTO, SUB_AUTO_RTL)
    OFFBOARD = (MAIN_OFFBOARD, 0)

    @property
    def custom_mode(self) -> int:
        main, sub = self.value
        return (main << 16) | (sub << 24)

    @classmethod
    def from_main_sub(cls, main: int, sub: int) -> Mode | None:
        for mode in cls:
            if mode.value == (main, sub) or (main == MAIN_OFFBOARD and mode is Mode.OFFBOARD):
                return mode
        return None


# MAV_PARAM_TYPE
PARAM_INT32 = 6
PARAM_REAL32 = 9


@dataclass
class Param:
    value: float | int
    type: int  # PARAM_INT32 or PARAM_REAL32


def default_params() -> dict[str, Param]:
    """PX4's defaults (SIH quadx airframe, PX4 main as in ../shared/px4_sih) of what flighttest reads or
    the fake itself flies with."""
    f, i = PARAM_REAL32, PARAM_INT32
    return {
        "MIS_TAKEOFF_ALT": Param(2.5, f),
        "COM_OF_LOSS_T": Param(1.0, f),
        "COM_OBL_RC_ACT": Param(0, i),  # 0 Position (no RC here → Hold), 3 Return, 4 Land, 5 Hold, 7 Disarm
        "COM_RC_OVERRIDE": Param(1, i),
        "COM_DISARM_PRFLT": Param(10.0, f),
        "COM_DISARM_LAND": Param(2.0, f),
        "MPC_Z_VEL_MAX_DN": Param(1.5, f),
        "MPC_Z_VEL_MAX_UP": Param(3.0, f),
        "MPC_XY_VEL_MAX": Param(12.0, f),
        "MPC_TILTMAX_AIR": Param(45.0, f),
        "MPC_TKO_SPEED": Param(1.5, f),
        "MPC_LAND_SPEED": Param(0.7, f),
        "MPC_LAND_ALT1": Param(10.0, f),
        "MPC_LAND_ALT2": Param(5.0, f),
        "MPC_XY_P": Param(0.95, f),
        "MPC_Z_P": Param(1.0, f),
        "MPC_XY_VEL_P_ACC": Param(1.8, f),
        "MPC_XY_VEL_I_ACC": Param(0.4, f),
        "MPC_Z_VEL_P_ACC": Param(4.0, f),
        "MPC_Z_VEL_I_ACC": Param(2.0, f),
        "MPC_ACC_HOR": Param(3.0, f),
        "MPC_XY_VEL_D_ACC": Param(0.2, f),
        "MPC_Z_VEL_D_ACC": Param(0.0, f),
        "MPC_VELD_LP": Param(5.0, f),
        "MPC_THR_HOVER": Param(0.5, f),  # the fake sets the vehicle's true hover thrust at boot
        "MPC_THR_MIN": Param(0.12, f),
        "MPC_THR_MAX": Param(1.0, f),
        "MPC_THR_XY_MARG": Param(0.3, f),
        "MPC_ACC_DECOUPLE": Param(1, i),
        "MPC_Z_V_AUTO_DN": Param(1.5, f),
        "MC_AIRMODE": Param(0, i),  # the fake's allocation is airmode-off only
        "MC_ROLL_P": Param(4.0, f),
        "MC_PITCH_P": Param(4.0, f),
        "MC_ROLLRATE_P": Param(0.15, f),
        "MC_PITCHRATE_P": Param(0.15, f),
        "MC_YAWRATE_P": Param(0.2, f),
        "MC_ROLLRATE_I": Param(0.2, f),
        "MC_PITCHRATE_I": Param(0.2, f),
        "MC_YAWRATE_I": Param(0.1, f),
        "MC_ROLLRATE_D": Param(0.003, f),
        "MC_PITCHRATE_D": Param(0.003, f),
        "MC_YAWRATE_D": Param(0.0, f),
        "MC_ROLLRATE_K": Param(1.0, f),
        "MC_PITCHRATE_K": Param(1.0, f),
        "MC_YAWRATE_K": Param(1.0, f),
        "MC_RR_INT_LIM": Param(0.3, f),
        "MC_PR_INT_LIM": Param(0.3, f),
        "MC_YR_INT_LIM": Param(0.3, f),
        "MC_YAW_P": Param(2.8, f),
        "MC_YAW_WEIGHT": Param(0.4, f),
        "MC_ROLLRATE_MAX": Param(220.0, f),
        "MC_PITCHRATE_MAX": Param(220.0, f),
        "MC_YAWRATE_MAX": Param(200.0, f),
        # EKF2's drag fusion (off by default: no wind estimate on a multicopter, no WIND_COV); its model's
        # ballistic coefficients (kg/m²) and momentum drag (1/s), PX4's defaults
        "EKF2_DRAG_CTRL": Param(0, i),
        "EKF2_BCOEF_X": Param(100.0, f),
        "EKF2_BCOEF_Y": Param(100.0, f),
        "EKF2_MCOEF": Param(0.15, f),
        "RTL_RETURN_ALT": Param(30.0, f),
        "NAV_DLL_ACT": Param(0, i),
        "SYS_AUTOSTART": Param(10040, i),  # sihsim_quadx
        "MAV_SYS_ID": Param(1, i),
    }


def encode_param_value(p: Param) -> float:
    """PX4 sends integers byte-wise inside the float field (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE)."""
    if p.type == PARAM_INT32:
        return struct.unpack("<f", struct.pack("<i", int(p.value)))[0]
    return float(p.value)


def decode_param_value(raw: float, param_type: int) -> float | int:
    if param_type == PARAM_INT32:
        return struct.unpack("<i", struct.pack("<f", raw))[0]
    return float(raw)
