"""Each autopilot's own rules: the mode flighttest flies in, the hold rung's mode, Land, the modes that
mean a pilot has the sticks, and how long its estimator may take to be ready.

PX4's modes come through MAVSDK's ``FlightMode`` names (OFFBOARD, HOLD, POSCTL, …). ArduCopter's do not
survive that mapping — MAVSDK reports LOITER and BRAKE both as HOLD, yet LOITER is the pilot's mode and
BRAKE the ladder's — so for ArduPilot the link reads the mode from the heartbeat's ``custom_mode``
(``ARDUCOPTER_MODES``) and every name here is ArduCopter's own.
"""

from __future__ import annotations

from dataclasses import dataclass

PX4 = "PX4"
ARDUPILOT = "ArduPilot"

# ArduCopter's custom_mode numbers (ArduCopter/mode.h, Mode::Number)
ARDUCOPTER_MODES: dict[int, str] = {
    0: "STABILIZE", 1: "ACRO", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER", 6: "RTL", 7: "CIRCLE",
    9: "LAND", 11: "DRIFT", 13: "SPORT", 14: "FLIP", 15: "AUTOTUNE", 16: "POSHOLD", 17: "BRAKE", 18: "THROW",
    19: "AVOID_ADSB", 20: "GUIDED_NOGPS", 21: "SMART_RTL", 22: "FLOWHOLD", 23: "FOLLOW", 24: "ZIGZAG",
    25: "SYSTEMID", 26: "AUTOROTATE", 27: "AUTO_RTL", 28: "TURTLE",
}  # fmt: skip


@dataclass(frozen=True)
class AutopilotRules:
    name: str
    offboard_mode: str  # the mode flighttest's setpoints fly in
    hold_mode: str  # the abort ladder's hold rung: stops and holds, ignoring the sticks
    land_mode: str
    pilot_modes: frozenset[str]  # a person at the sticks: a takeover, never an unexpected mode
    # the modes the autopilot brings the vehicle down or home in by itself (its Land, its return, its
    # failsafes): entered by the autopilot, they are followed, never overridden by a Hold
    failsafe_modes: frozenset[str]
    # leaving offboard by "offboard stop" reaches the hold mode (PX4); else the ladder asks for it (ArduPilot,
    # whose MAVSDK "offboard stop" would leave it in a pilot's mode)
    hold_by_offboard_stop: bool
    # disarmed in one of these the vehicle will not arm (PX4: Offboard without a setpoint stream, and Land, Return,
    # Follow: "Mode not suitable for arming"; ArduCopter: LAND/RTL/AUTO, which MAVSDK's arm turns into BRAKE,
    # "Mode not armable"): the preflight sets armable_mode
    not_armable_modes: frozenset[str]
    armable_mode: str
    # it leaves the offboard mode by itself when setpoints stop (PX4's COM_OF_LOSS_T); ArduPilot stays in
    # GUIDED and only zeroes its targets after GUID_TIMEOUT
    offboard_loss_failsafe: bool
    # how long its estimator may take before the vehicle is healthy and armable: PX4 SITL a landing's
    # 10-odd s; ArduCopter SITL 42 s from boot to "EKF3 IMU0 is using GPS" (../shared/ardupilot_sitl)
    health_wait_s: float
    reads_mode_from_heartbeat: bool  # MAVSDK's FlightMode cannot tell its modes apart (module docstring)
    # its takeoff is asked for the handover height only (ArduCopter: it stops there, at rest, in GUIDED),
    # rather than the start height it would still be climbing towards at the handover (PX4)
    takeoff_to_handover: bool = False

    def describe(self) -> dict[str, object]:
        return {"autopilot": self.name, "offboard_mode": self.offboard_mode, "hold_mode": self.hold_mode,
                "land_mode": self.land_mode, "pilot_modes": sorted(self.pilot_modes),
                "failsafe_modes": sorted(self.failsafe_modes)}  # fmt: skip


PX4_RULES = AutopilotRules(
    name=PX4, offboard_mode="OFFBOARD", hold_mode="HOLD", land_mode="LAND",
    pilot_modes=frozenset({"MANUAL", "ALTCTL", "POSCTL", "ACRO", "STABILIZED", "RATTITUDE"}),
    failsafe_modes=frozenset({"LAND", "RETURN_TO_LAUNCH"}),
    hold_by_offboard_stop=True, not_armable_modes=frozenset({"OFFBOARD", "LAND", "RETURN_TO_LAUNCH", "FOLLOW_ME"}),
    armable_mode="HOLD",
    offboard_loss_failsafe=True,
    health_wait_s=30.0, reads_mode_from_heartbeat=False,
)  # fmt: skip

ARDUPILOT_RULES = AutopilotRules(
    name=ARDUPILOT, offboard_mode="GUIDED", hold_mode="BRAKE", land_mode="LAND",
    pilot_modes=frozenset({"STABILIZE", "ACRO", "ALT_HOLD", "LOITER", "POSHOLD", "DRIFT", "SPORT", "FLOWHOLD",
                           "ZIGZAG"}),
    failsafe_modes=frozenset({"LAND", "RTL", "SMART_RTL", "AUTO_RTL"}),
    hold_by_offboard_stop=False, not_armable_modes=frozenset({"LAND", "RTL", "AUTO", "BRAKE", "SMART_RTL", "AUTO_RTL"}),
    armable_mode="GUIDED", offboard_loss_failsafe=False,
    health_wait_s=90.0, reads_mode_from_heartbeat=True, takeoff_to_handover=True,
)  # fmt: skip


def rules_for(autopilot: str | None) -> AutopilotRules:
    """The rules of the autopilot the heartbeat names; PX4's where it names none (MAVSDK could not tell)."""
    return ARDUPILOT_RULES if autopilot == ARDUPILOT else PX4_RULES


def arducopter_mode_name(custom_mode: int) -> str:
    return ARDUCOPTER_MODES.get(int(custom_mode), f"MODE_{int(custom_mode)}")


def arducopter_mode_number(name: str) -> int:
    for number, mode in ARDUCOPTER_MODES.items():
        if mode == name:
            return number
    raise ValueError(f"no ArduCopter mode {name!r}")
