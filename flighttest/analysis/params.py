"""The autopilot parameters that shape a descent test, and how they differ between flights.

Two flights of the same trajectory descend differently when the autopilot was set up differently:
PX4 clips offboard descents to ``MPC_Z_VEL_MAX_DN`` and lands after an abort at ``MPC_LAND_SPEED``,
ArduPilot's ``WPNAV_SPEED_DN``/``LAND_SPEED`` do the same, the attitude and velocity gains decide
how hard the vehicle shakes near the vortex ring state, and the offboard/GCS-loss settings decide
what an abort does. A log carries hundreds of parameters; :func:`relevant` keeps these (the
``fnmatch`` patterns below, for PX4 and ArduPilot, newer ArduPilot names included) and
:func:`differences` says which of them were not the same across the flights compared.

The snapshot comes from the log itself (the ``.ulg`` parameters, DataFlash ``PARM``, a tlog's
``PARAM_VALUE``) or from the ``params.json`` flighttest writes into its log folder at preflight
(:func:`snapshot`; docs/CONTRACTS.md "Flight log folders").
"""

from __future__ import annotations

import math
from fnmatch import fnmatchcase
from typing import Any

PARAMS_FORMAT = "flighttest-params/1"
PARAMS_FILE = "params.json"
PREFLIGHT_SOURCE = "MAVLink PARAM_REQUEST_LIST at preflight"
FALLBACK_SOURCE = "MAVLink PARAM_REQUEST_READ at preflight (the preflight check's parameters only)"

RELEVANT: dict[str, tuple[str, ...]] = {
    "PX4": (
        # descent and landing speeds: offboard descents are clipped to MPC_Z_VEL_MAX_DN
        "MPC_Z_VEL_MAX_DN",
        "MPC_Z_V_AUTO_DN",
        "MPC_LAND_SPEED",
        "MPC_LAND_ALT*",
        "MPC_TILTMAX_AIR",
        "MPC_XY_P",
        "MPC_XY_VEL_*",
        "MPC_Z_*",
        "MPC_THR_MIN",
        "MPC_THR_HOVER",
        # attitude and rate gains, rate limits
        "MC_*_P",
        "MC_*RATE_MAX",
        # what an abort does: offboard loss, stick override
        "COM_OF_LOSS_T",
        "COM_OBL_RC_ACT",
        "COM_OBL_ACT",
        "COM_RC_OVERRIDE",
    ),
    "ArduPilot": (
        "WPNAV_SPEED_DN",
        "WPNAV_ACCEL_Z",
        "PILOT_SPEED_DN",
        "LAND_SPEED",
        "LAND_SPEED_HIGH",
        "ANGLE_MAX",
        "MOT_THST_HOVER",
        "ATC_*",
        "PSC_POSZ_P",
        "PSC_VELZ_P",
        "PSC_ACCZ_P",
        "PSC_ACCZ_I",
        "GUID_TIMEOUT",
        "FS_GCS_ENABLE",
        "FS_GCS_TIMEOUT",
        # names of newer ArduPilot (4.6+) for the same settings
        "WP_SPD_DN",
        "WP_ACC_Z",
        "WP_ACC",
        "WP_JERK",
        "LAND_SPD_MS",
        "LAND_SPD_HIGH_MS",
        "WP_SPD_UP",
        "WP_SPD",
        "PSC_D_*",
        "PSC_NE_POS_P",
        "PSC_JERK_*",
        "MAV_GCS_SYSID",
        "FENCE_ENABLE",
        "DISARM_DELAY",
    ),
}
_ALL_PATTERNS = tuple(p for patterns in RELEVANT.values() for p in patterns)
# parameters only one autopilot has, to tell which one wrote a snapshot
_MARKERS = {"PX4": ("MPC_", "COM_", "NAV_DLL_ACT", "SYS_AUTOSTART"), "ArduPilot": ("WPNAV_", "ATC_", "ARMING_CHECK")}


def is_relevant(name: str, autopilot: str | None = None) -> bool:
    patterns = RELEVANT.get(autopilot, _ALL_PATTERNS) if autopilot else _ALL_PATTERNS
    return any(fnmatchcase(name, p) for p in patterns)


def relevant(params: dict[str, Any] | None, autopilot: str | None = None) -> dict[str, Any]:
    """The parameters of ``params`` that shape these tests, sorted by name (values as given).

    ``autopilot`` ("PX4" or "ArduPilot") restricts the patterns to that autopilot's; by default
    both are used (their names do not collide)."""
    if not params:
        return {}
    return {k: params[k] for k in sorted(params) if isinstance(k, str) and is_relevant(k, autopilot)}


def guess_autopilot(params: dict[str, Any] | None) -> str | None:
    """Which autopilot wrote a snapshot, "PX4" or "ArduPilot", from its parameter names (None: cannot tell)."""
    if not params:
        return None
    votes = {ap: sum(any(k.startswith(m) for m in marks) for k in params) for ap, marks in _MARKERS.items()}
    best = max(votes, key=votes.get)
    return best if votes[best] > 0 else None


def same_value(a: Any, b: Any) -> bool:
    """Equal as parameters: a float32 read back over MAVLink (2.799999952) equals the 2.8 written."""
    if a is None or b is None:
        return a is b
    try:
        fa, fb = float(a), float(b)
    except (TypeError, ValueError):
        return a == b
    if math.isnan(fa) or math.isnan(fb):
        return math.isnan(fa) and math.isnan(fb)
    return math.isclose(fa, fb, rel_tol=1e-6, abs_tol=1e-9)


def differences(snapshots: list[dict[str, Any]]) -> dict[str, list[Any]]:
    """Names whose values are not the same in every snapshot, or missing from some: name → the
    value in each snapshot (None where that snapshot lacks it), sorted by name.

    An empty snapshot (a log without parameters) says nothing about any parameter: it takes no part
    in the decision (its entries are None), so a log without a snapshot does not list every
    parameter as "different". Fewer than two non-empty snapshots: no differences."""
    known = [s for s in snapshots if s]
    if len(known) < 2:
        return {}
    names = sorted({k for s in known for k in s})
    out: dict[str, list[Any]] = {}
    for name in names:
        vals = [s.get(name) for s in known]
        first = vals[0]
        if any(v is None for v in vals) or not all(same_value(first, v) for v in vals[1:]):
            out[name] = [s.get(name) if s else None for s in snapshots]
    return out


def format_value(v: Any) -> str:
    """A parameter value for a table: integers as integers, float32 noise removed (2.8, not 2.7999999)."""
    if v is None:
        return "–"
    if isinstance(v, bool):
        return str(int(v))
    if isinstance(v, int):
        return str(v)
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    if not math.isfinite(f):
        return str(f)
    if f.is_integer() and abs(f) < 1e15:
        return str(int(f))
    return f"{f:.6g}"


def clean_value(v: Any) -> Any:
    """A value for JSON: ints stay ints, floats lose their float32 noise (7 significant digits)."""
    if isinstance(v, bool):
        return int(v)
    if isinstance(v, int):
        return v
    try:
        f = float(v)
    except (TypeError, ValueError):
        return v
    return float(f"{f:.7g}") if math.isfinite(f) else None


def snapshot(
    all_params: dict[str, Any] | None,
    preflight_params: dict[str, Any] | None,
    autopilot: str | None,
    unix_s: float,
    note: str | None = None,
) -> dict[str, Any]:
    """The ``params.json`` document of a log folder (docs/CONTRACTS.md "Flight log folders").

    ``all_params``: every parameter the vehicle sent (None when reading them all failed: then the
    snapshot holds only ``preflight_params``, the ones the preflight check read one by one, and
    ``source`` says so). Kept: the relevant ones plus every one the preflight read."""
    pre = {k: v for k, v in (preflight_params or {}).items() if v is not None}
    kept = {**relevant(all_params, autopilot), **pre} if all_params is not None else pre
    return {
        "format": PARAMS_FORMAT,
        "source": PREFLIGHT_SOURCE if all_params is not None else FALLBACK_SOURCE,
        "autopilot": autopilot or guess_autopilot(all_params or pre),
        "unix_s": round(float(unix_s), 3),
        "params_read": len(all_params) if all_params is not None else len(pre),
        "note": note,
        "params": {k: clean_value(kept[k]) for k in sorted(kept)},
    }
