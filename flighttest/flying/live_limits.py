"""The setpoint-shaping limits the vehicle's own parameters set, read at the preflight, and a profile that
carries them, so a plan is made within what the autopilot will impose today, not within a profile's copy.

ArduCopter's GUIDED mode shapes its setpoints with its position controller's limits
(``flighttest.planner.autopilot_limits``). Firmware names them two ways: ArduCopter master since 2025 in SI
units (``WP_ACC_Z`` m/s², ``PSC_JERK_D``), earlier firmware in cm (``WPNAV_ACCEL_Z`` cm/s², ``PSC_JERK_Z``);
ArduCopter SITL 90700977 still had the older names beside the newer ``MAV_GCS_SYSID`` (bench/RESULTS.md,
"Parameter files on real firmware"). PX4's offboard control takes the setpoints as sent but clips its vertical
velocity setpoint to ``MPC_Z_VEL_MAX_DN`` and ``MPC_Z_VEL_MAX_UP`` (PositionControl). Both clip the tilt (ArduCopter's
``ATC_ANGLE_MAX``, PX4's ``MPC_TILTMAX_AIR``): a plan made for more is flown late.

PX4's speed limits never bound a flown plan (``flighttest.planner.autopilot_limits``): where only they differ
(:func:`plans_bound`), the plans stand and only their optimum is made again, within the vehicle's own limits.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from flighttest.model.profiles import AutopilotLimits, VehicleProfile
from flighttest.planner.autopilot_limits import plan_limits

# a profile's [autopilot] field: (the parameter, its scale to SI) in the names of each firmware, newest first
ARDUPILOT_LIMITS: dict[str, tuple[tuple[str, float], ...]] = {
    "accel_z_max_mps2": (("WP_ACC_Z", 1.0), ("WPNAV_ACCEL_Z", 0.01)),
    "accel_h_max_mps2": (("WP_ACC", 1.0), ("WPNAV_ACCEL", 0.01)),
    "descent_max_mps": (("WP_SPD_DN", 1.0), ("WPNAV_SPEED_DN", 0.01)),
    "climb_max_mps": (("WP_SPD_UP", 1.0), ("WPNAV_SPEED_UP", 0.01)),
    "jerk_h_max_mps3": (("PSC_JERK_NE", 1.0), ("PSC_JERK_XY", 1.0)),
    "jerk_z_max_mps3": (("PSC_JERK_D", 1.0), ("PSC_JERK_Z", 1.0)),
}
PX4_LIMITS: dict[str, tuple[tuple[str, float], ...]] = {
    "descent_max_mps": (("MPC_Z_VEL_MAX_DN", 1.0),),
    "climb_max_mps": (("MPC_Z_VEL_MAX_UP", 1.0),),
}
# the tilt the position control allows (the profile's ``max_tilt_deg``, not its [autopilot] table), in degrees:
# ArduCopter's attitude controller's ATC_ANGLE_MAX (ANGLE_MAX in cdeg on older firmware), and its position
# controller's PSC_ANGLE_MAX where that is set lower (0: unset); PX4's MPC_TILTMAX_AIR, which its offboard
# position and velocity control clip to
TILT_FIELD = "max_tilt_deg"
ARDUPILOT_TILT = (("ATC_ANGLE_MAX", 1.0), ("ANGLE_MAX", 0.01))
ARDUPILOT_POS_TILT = (("PSC_ANGLE_MAX", 1.0),)
PX4_TILT = (("MPC_TILTMAX_AIR", 1.0),)
# two limits this close are the same (a float32 parameter read back; a cm value scaled)
SAME_REL = 1e-4


@dataclass(frozen=True)
class LiveLimit:
    field: str  # the profile's [autopilot] field
    param: str  # the vehicle's parameter it came from
    value: float  # SI (m/s, m/s², m/s³)
    raw: float  # as the parameter holds it

    def describe(self) -> str:
        unit = {"accel": "m/s²", "jerk": "m/s³", "max": "°"}.get(self.field.split("_")[0], "m/s")
        return f"{self.param} {self.raw:g}" + ("" if self.raw == self.value else f" ({self.value:g} {unit})")


def ardupilot_limits(params: dict[str, float | int | None] | None) -> dict[str, LiveLimit]:
    """The GUIDED limits the parameters hold (field → ``LiveLimit``), in whichever names the firmware uses;
    a limit the vehicle does not report, or reports as 0 or less, is left out; the tilt as ``TILT_FIELD``."""
    out = _limits(params, {**ARDUPILOT_LIMITS, TILT_FIELD: ARDUPILOT_TILT})
    pos = _limits(params, {TILT_FIELD: ARDUPILOT_POS_TILT}).get(TILT_FIELD)
    if pos is not None and (TILT_FIELD not in out or pos.value < out[TILT_FIELD].value):
        out[TILT_FIELD] = pos
    return out


def px4_limits(params: dict[str, float | int | None] | None) -> dict[str, LiveLimit]:
    """The vertical speeds and the tilt PX4's position control clips offboard setpoints to, as the parameters hold
    them."""
    return _limits(params, {**PX4_LIMITS, TILT_FIELD: PX4_TILT})


def _limits(params: dict[str, float | int | None] | None,
            table: dict[str, tuple[tuple[str, float], ...]]) -> dict[str, LiveLimit]:  # fmt: skip
    out: dict[str, LiveLimit] = {}
    for f, names in table.items():
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


def with_live_limits(profile: VehicleProfile, live: dict[str, LiveLimit],
                     autopilot: str = "ArduPilot") -> tuple[VehicleProfile, list[str]]:  # fmt: skip
    """``profile`` with its ``[autopilot]`` table the vehicle's own (the fields the vehicle reports; the others
    as they were) and its ``max_tilt_deg`` the vehicle's where that is lower, and what changed ("WP_ACC_Z 2 (the
    profile's 1)"). Unchanged where nothing differs. A
    profile whose table is another autopilot's (an x500 profile on ArduPilot firmware) gets one of
    ``autopilot``'s own, made of what the vehicle reports."""
    same = profile.autopilot is not None and profile.autopilot.name == autopilot
    ap = profile.autopilot if same and profile.autopilot is not None else AutopilotLimits(name=autopilot)
    updates, top, diffs = {}, {}, []
    for f, lim in live.items():
        old = getattr(profile if f == TILT_FIELD else ap, f)
        if f == TILT_FIELD and lim.value >= old:
            # only a lower tilt: the profile's is the airframe's as the operator states it. ArduCopter SITL with
            # ATC_ANGLE_MAX 35 planned its helix at 25° and the guard's prediction stopped it at the flare, the
            # truth 0.36 m/s clear (bench/RESULTS.md, "The tilt the vehicle allows")
            continue
        if old is None or abs(lim.value - old) > SAME_REL * max(abs(old), 1e-9):
            (top if f == TILT_FIELD else updates)[f] = lim.value
            diffs.append(f"{lim.describe()} (the profile's {'none' if old is None else f'{old:g}'})")
    if not diffs:
        return profile, []
    if updates:
        top["autopilot"] = dataclasses.replace(ap, **updates)
    return dataclasses.replace(profile, **top), diffs


def plans_bound(old: VehicleProfile, new: VehicleProfile) -> bool:
    """Whether plans made for ``old`` must be made again for ``new``: the limits a flown plan keeps within
    (``plan_limits``, the tilt) differ. PX4's speeds never bound a flown plan, so they change only the optimum."""
    return plan_limits(old) != plan_limits(new) or old.max_tilt_deg != new.max_tilt_deg
