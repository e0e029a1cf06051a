"""The setpoint-shaping limits the vehicle's own parameters set, read at the preflight, and a profile that
carries them, so a plan is made within what the autopilot will impose today, not within a profile's copy.

ArduCopter's GUIDED mode shapes its setpoints with its position controller's limits
(``flighttest.planner.autopilot_limits``). Firmware names them two ways: ArduCopter master since 2025 in SI
units (``WP_ACC_Z`` m/s², ``PSC_JERK_D``), earlier firmware in cm (``WPNAV_ACCEL_Z`` cm/s², ``PSC_JERK_Z``);
ArduCopter SITL 90700977 still had the older names beside the newer ``MAV_GCS_SYSID`` (bench/RESULTS.md,
"Parameter files on real firmware"). PX4's offboard control takes the setpoints as sent: its profiles
carry no such table.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from flighttest.model.profiles import AutopilotLimits, VehicleProfile

# a profile's [autopilot] field: (the parameter, its scale to SI) in the names of each firmware, newest first
ARDUPILOT_LIMITS: dict[str, tuple[tuple[str, float], ...]] = {
    "accel_z_max_mps2": (("WP_ACC_Z", 1.0), ("WPNAV_ACCEL_Z", 0.01)),
    "accel_h_max_mps2": (("WP_ACC", 1.0), ("WPNAV_ACCEL", 0.01)),
    "descent_max_mps": (("WP_SPD_DN", 1.0), ("WPNAV_SPEED_DN", 0.01)),
    "climb_max_mps": (("WP_SPD_UP", 1.0), ("WPNAV_SPEED_UP", 0.01)),
    "jerk_h_max_mps3": (("PSC_JERK_NE", 1.0), ("PSC_JERK_XY", 1.0)),
    "jerk_z_max_mps3": (("PSC_JERK_D", 1.0), ("PSC_JERK_Z", 1.0)),
}
# two limits this close are the same (a float32 parameter read back; a cm value scaled)
SAME_REL = 1e-4


@dataclass(frozen=True)
class LiveLimit:
    field: str  # the profile's [autopilot] field
    param: str  # the vehicle's parameter it came from
    value: float  # SI (m/s, m/s², m/s³)
    raw: float  # as the parameter holds it

    def describe(self) -> str:
        unit = {"accel": "m/s²", "jerk": "m/s³"}.get(self.field.split("_")[0], "m/s")
        return f"{self.param} {self.raw:g}" + ("" if self.raw == self.value else f" ({self.value:g} {unit})")


def ardupilot_limits(params: dict[str, float | int | None] | None) -> dict[str, LiveLimit]:
    """The GUIDED limits the parameters hold (field → ``LiveLimit``), in whichever names the firmware uses;
    a limit the vehicle does not report, or reports as 0 or less, is left out."""
    out: dict[str, LiveLimit] = {}
    for f, names in ARDUPILOT_LIMITS.items():
        for name, scale in names:
            v = (params or {}).get(name)
            if isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v > 0:
                out[f] = LiveLimit(f, name, float(v) * scale, float(v))
                break
    return out


def param_value(params: dict[str, float | int | None], new_name: str) -> tuple[str, float | None, float]:
    """(the name the vehicle uses, its value in SI or None, that name's scale to SI) for a limit known by its
    newest name (``WP_ACC_Z``): the older name's, scaled, where the firmware has that one instead."""
    names = next((n for n in ARDUPILOT_LIMITS.values() if n[0][0] == new_name), ((new_name, 1.0),))
    for name, scale in names:
        v = params.get(name)
        if v is not None:
            return name, float(v) * scale, scale
    return new_name, None, 1.0


def with_live_limits(profile: VehicleProfile, live: dict[str, LiveLimit]) -> tuple[VehicleProfile, list[str]]:
    """``profile`` with its ``[autopilot]`` table the vehicle's own (the fields the vehicle reports; the others
    as they were), and what changed ("WP_ACC_Z 2 (the profile's 1)"). Unchanged where nothing differs."""
    ap = profile.autopilot or AutopilotLimits(name="ArduPilot")
    updates, diffs = {}, []
    for f, lim in live.items():
        old = getattr(ap, f)
        if old is None or abs(lim.value - old) > SAME_REL * max(abs(old), 1e-9):
            updates[f] = lim.value
            diffs.append(f"{lim.describe()} (the profile's {'none' if old is None else f'{old:g}'})")
    if not updates:
        return profile, []
    return dataclasses.replace(profile, autopilot=dataclasses.replace(ap, **updates)), diffs
