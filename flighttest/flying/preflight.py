"""The preflight checklist: link and health, estimator, battery, abort-relevant PX4 parameters, room
for the planned trajectory, trajectory limits. Pure functions of what was measured; any ``fail``
stops the mission before arming, ``warn`` is shown at the go/no-go prompt.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np
from rich.table import Table

from flighttest.errors import FlighttestError
from flighttest.flying.autopilot import AutopilotRules
from flighttest.flying.guard import predicted_blade_velocity_mps
from flighttest.flying.link import TelemetryState
from flighttest.flying.live_limits import param_value
from flighttest.inputs import MAX_DURATION_S, MAX_HEIGHT_M
from flighttest.model.frames import GuardRegion
from flighttest.model.profiles import VehicleProfile
from flighttest.model.trajectory import LIMIT_REL_TOL, TILT_TOL_DEG, Trajectory
from flighttest.planner.autopilot_limits import AUTOPILOT_LIMIT_FRACTION

PASS, WARN, FAIL = "pass", "warn", "fail"

# COM_OBL_RC_ACT values (PX4): what the vehicle does when offboard setpoints stop
OBL_ACTIONS = {0: "Position", 1: "Altitude", 2: "Manual", 3: "Return", 4: "Land", 5: "Hold", 6: "Terminate",
               7: "Disarm"}  # fmt: skip
OBL_UNSAFE = {2, 6, 7}  # manual without a pilot, terminate and disarm drop the vehicle
RC_OVERRIDE_OFFBOARD_BIT = 2  # COM_RC_OVERRIDE bit 1: sticks take over from offboard
ABORT_PARAMS = {"COM_OF_LOSS_T": "float", "COM_OBL_RC_ACT": "int", "COM_RC_OVERRIDE": "int",
                "MPC_Z_VEL_MAX_DN": "float", "MPC_LAND_SPEED": "float", "MPC_Z_V_AUTO_DN": "float",
                "MPC_LAND_ALT1": "float", "MPC_LAND_ALT2": "float"}  # fmt: skip
GROUND_HEIGHT_OK_M = 0.5  # the estimate's height on the ground: within this of home is ordinary drift
GROUND_HEIGHT_MAX_M = 3.0  # beyond this the estimate is not fit to fly from (reset it, or set home)
LOG_BYTES_PER_S_PER_HZ = 1000.0  # a flight's log folder: ~45 kB/s at 50 Hz telemetry (../shared reference flights)
LOG_DISK_FACTOR = 2.0  # the free disk the preflight asks for, in estimated logs


@dataclass(frozen=True)
class Check:
    name: str
    status: str
    value: str
    requirement: str


@dataclass
class PreflightResult:
    checks: list[Check]

    @property
    def ok(self) -> bool:
        return all(c.status != FAIL for c in self.checks)

    @property
    def failures(self) -> list[Check]:
        return [c for c in self.checks if c.status == FAIL]

    def first_failure(self) -> str:
        f = self.failures
        return f"{f[0].name}: {f[0].value} (needs {f[0].requirement})" if f else ""

    def to_dict(self) -> dict:
        return {"ok": self.ok, "checks": [asdict(c) for c in self.checks]}

    def table(self, title: str = "Preflight") -> Table:
        t = Table(title=title)
        for col in ("check", "status", "value", "requirement"):
            t.add_column(col)
        colour = {PASS: "green", WARN: "yellow", FAIL: "bold red"}
        for c in self.checks:
            t.add_row(c.name, f"[{colour[c.status]}]{c.status}[/]", c.value, c.requirement)
        return t


# -- trajectory ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrajectoryStats:
    depth_max_m: float  # deepest point below the start (d_m max)
    radius_max_m: float  # largest horizontal distance from the start
    descent_max_mps: float  # largest vd
    speed_max_mps: float
    duration_s: float
    arrest_floor_m: float  # lowest height (above start - …) reached if the sink is arrested anywhere
    guard_margin_min_mps: float
    guard_margin_t_s: float
    rise_max_m: float = 0.0  # highest point above the start (-d_m min)
    problem: str = ""  # why the trajectory itself is not sound (re-checked here), "" if it is
    # what an autopilot that shapes its targets (ArduCopter's GUIDED) must allow for the plan to be flown
    climb_max_mps: float = 0.0  # largest -vd
    accel_z_max_mps2: float = 0.0  # largest |ad|
    accel_h_max_mps2: float = 0.0  # largest |(an, ae)|
    tilt_max_deg: float = 0.0  # the plan's own attitude, else where its specific force points


def trajectory_stats(
    traj: Trajectory, region: GuardRegion, arrest_accel_mps2: float, drag_per_s: float = 0.0,
    wind_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> TrajectoryStats:  # fmt: skip
    """``drag_per_s``: the vehicle's linear drag per unit mass; with it the disk is judged as the thrust
    will tilt it, against the plan's acceleration and the drag of the air (``wind_ned_mps``)."""
    # the loader checked the file; the preflight checks again what will actually be flown (a
    # trajectory built or edited in memory never went through the loader)
    rate = traj.meta.get("resampled_hz")
    if isinstance(rate, bool) or not isinstance(rate, int | float) or not math.isfinite(rate):
        rate = None
    try:
        traj.validate(where=f"trajectory resampled at {rate:g} Hz" if rate else "trajectory", coarse=bool(rate))
        problem = ""
    except FlighttestError as exc:
        problem = str(exc)
    df = traj.df
    n, e, d = (df[c].to_numpy(float) for c in ("n_m", "e_m", "d_m"))
    vn, ve, vd = (df[c].to_numpy(float) for c in ("vn_mps", "ve_mps", "vd_mps"))
    an, ae, ad = (df[c].to_numpy(float) for c in ("an_mps2", "ae_mps2", "ad_mps2"))
    # stopping a sink vd at arrest_accel costs vd²/2a of height below where it starts
    stop = np.where(vd > 0, vd * vd / (2.0 * arrest_accel_mps2), 0.0)
    if traj.has_attitude() and drag_per_s <= 0:
        q = traj.attitude_quat()
        _, _, _, margin = region.check(vn, ve, vd, q[:, 0], q[:, 1], q[:, 2], q[:, 3])
        margin = np.asarray(margin, float)
    else:  # attitude from the commanded acceleration (thrust along −z_body), as the guard predicts
        # a plan's own attitude is drag-free: the thrust also takes the drag, which tilts the disk further
        # (sih_quadx's helix: −0.34 m/s from the file, +0.53 tilted: bench/RESULTS.md, "The preflight judges …")
        wn, we, wd = (float(x) for x in wind_ned_mps)
        tn, te, td = (a + drag_per_s * (v - w) for a, v, w in ((an, vn, wn), (ae, ve, we), (ad, vd, wd)))
        wu = [predicted_blade_velocity_mps(a, b, c, x, y, z, wn, we, wd, horizon_s=0.0)
              for a, b, c, x, y, z in zip(vn, ve, vd, tn, te, td)]  # fmt: skip
        w, u = np.array(wu).T
        margin = np.asarray(region.margin(w, u), float)
    i = int(np.argmin(margin))
    return TrajectoryStats(
        depth_max_m=float(d.max()),
        radius_max_m=float(np.hypot(n, e).max()),
        descent_max_mps=float(vd.max()),
        speed_max_mps=float(np.sqrt(vn**2 + ve**2 + vd**2).max()),
        duration_s=traj.duration_s,
        arrest_floor_m=float((-(d + stop)).min()),
        guard_margin_min_mps=float(margin[i]),
        guard_margin_t_s=float(df["t_s"].iloc[i] - df["t_s"].iloc[0]),
        rise_max_m=float(max(0.0, -d.min())),
        problem=problem,
        climb_max_mps=float(max(0.0, -vd.min())),
        accel_z_max_mps2=float(np.abs(ad).max()),
        accel_h_max_mps2=float(np.hypot(an, ae).max()),
        tilt_max_deg=float(traj.tilt_deg().max()),
    )


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def trajectory_checks(
    stats: TrajectoryStats,
    profile: VehicleProfile,
    start_height_m: float,
    min_alt_m: float,
    geofence_radius_m: float,
    recovery_room_m: float = 0.0,
    observe_region: bool = False,
) -> list[Check]:
    """The trajectory against the vehicle and the room of this flight. Every comparison needs finite
    numbers: a start height of 1e308 m or a NaN anywhere fails (``1e308 − 3 ≥ 1`` would pass)."""
    speed_ok = _finite(stats.speed_max_mps, stats.descent_max_mps, stats.duration_s) and (
        stats.speed_max_mps <= profile.max_speed_mps * (1.0 + LIMIT_REL_TOL)
        and stats.duration_s <= MAX_DURATION_S
    )
    checks = [
        Check("trajectory limits", PASS if speed_ok and not stats.problem else FAIL,
              stats.problem or f"max speed {stats.speed_max_mps:.2f} m/s, max descent {stats.descent_max_mps:.2f} m/s, "
              f"{stats.duration_s:.2f} s",
              f"consistent, ≤ {MAX_DURATION_S:g} s, within '{profile.name}' tilt/speed/thrust limits"),
    ]  # fmt: skip
    low = start_height_m - stats.depth_max_m
    top = start_height_m + stats.rise_max_m
    height_ok = (
        _finite(start_height_m, min_alt_m, low, top)
        and 0.0 < start_height_m <= MAX_HEIGHT_M
        and low >= min_alt_m - 1e-6
        and top <= MAX_HEIGHT_M + 1e-6
    )
    checks.append(Check(
        "height", PASS if height_ok else FAIL,
        f"start {start_height_m:.2f} m, lowest point {low:.2f} m"
        + (f", highest {top:.2f} m" if stats.rise_max_m > 0.01 or top > MAX_HEIGHT_M else ""),
        f"lowest point ≥ --min-alt {min_alt_m:g} m, start and highest ≤ {MAX_HEIGHT_M:g} m",
    ))  # fmt: skip
    arrest_low = start_height_m + stats.arrest_floor_m
    checks.append(Check(
        "height to arrest the sink", PASS if _finite(arrest_low) and arrest_low >= min_alt_m - 1e-6 else FAIL,
        f"an abort anywhere bottoms out at {arrest_low:.2f} m",
        f"≥ --min-alt {min_alt_m:g} m",
    ))  # fmt: skip
    # the vehicle's tilt limit: its ATC_ANGLE_MAX or MPC_TILTMAX_AIR where the preflight read it
    # (flighttest.flying.live_limits), which its position control clips to
    tilt_ok = _finite(stats.tilt_max_deg) and stats.tilt_max_deg <= profile.max_tilt_deg + TILT_TOL_DEG
    checks.append(Check(
        "tilt", PASS if tilt_ok else FAIL, f"max {stats.tilt_max_deg:.1f}°",
        f"≤ {profile.max_tilt_deg:g}°, the vehicle's limit: a plan beyond it is flown clipped",
    ))  # fmt: skip
    room = stats.radius_max_m + recovery_room_m
    checks.append(Check(
        "horizontal room", PASS if _finite(room, geofence_radius_m) and room <= geofence_radius_m else FAIL,
        f"{stats.radius_max_m:.2f} m from start + {recovery_room_m:.2f} m recovery",
        f"≤ geofence radius {geofence_radius_m:g} m",
    ))  # fmt: skip
    if not _finite(stats.guard_margin_min_mps):
        status, value = FAIL, "margin not a number"
    elif stats.guard_margin_min_mps < 0:
        status, value = (
            WARN,
            f"plan enters the guard region at t={stats.guard_margin_t_s:.2f} s "
            f"(margin {stats.guard_margin_min_mps:.2f} m/s)"
            + ("; observed only (probe)" if observe_region else ": the guard will abort"),
        )
    else:
        status, value = PASS, f"min margin {stats.guard_margin_min_mps:.2f} m/s"
    checks.append(Check("plan vs guard region", status, value, "margin ≥ 0 along the plan"))
    return checks


# -- vehicle -------------------------------------------------------------------------------------------


RATE_NEEDED_FRACTION = 0.8  # of the telemetry rate asked for: the guard's debounce and horizon assume it


def telemetry_rates_ok(st: TelemetryState, now_s: float, telemetry_hz: float) -> bool:
    """Position-velocity and attitude both arrive at ``RATE_NEEDED_FRACTION`` of ``telemetry_hz`` or more."""
    need = RATE_NEEDED_FRACTION * telemetry_hz
    return all(st.rate_hz(s, now_s) >= need for s in ("posvel", "attitude"))


def vehicle_checks(
    st: TelemetryState, now_s: float, telemetry_hz: float, min_battery_percent: float
) -> list[Check]:
    out = []
    need = RATE_NEEDED_FRACTION * telemetry_hz
    rates = {s: st.rate_hz(s, now_s) for s in ("posvel", "attitude")}
    ok = st.connected and telemetry_rates_ok(st, now_s, telemetry_hz)
    out.append(Check(
        "link and telemetry rate", PASS if ok else FAIL,
        f"{'connected' if st.connected else 'DISCONNECTED'}, position-velocity {rates['posvel']:.0f} Hz, "
        f"attitude {rates['attitude']:.0f} Hz",
        f"connected, ≥ {need:.0f} Hz",
    ))  # fmt: skip
    bad = sorted(k.removeprefix("is_") for k, v in st.health.items() if not v)
    out.append(Check(
        "health", PASS if st.health and not bad else FAIL,
        "all ok" if st.health and not bad else (", ".join(bad) + " not ok" if bad else "not reported"),
        "every sensor and estimate ok, armable",
    ))  # fmt: skip
    est_ok = (st.health.get("is_local_position_ok", False) and st.health.get("is_home_position_ok", False)
              and all(math.isfinite(x) for x in (st.n_m, st.e_m, st.d_m, st.vn_mps, st.ve_mps, st.vd_mps))
              and all(math.isfinite(x) for x in st.q))  # fmt: skip
    out.append(Check(
        "estimator", PASS if est_ok else FAIL,
        f"local position ({st.n_m:.2f}, {st.e_m:.2f}, {st.d_m:.2f}) m" if est_ok else "no valid local position",
        "local position and home valid",
    ))  # fmt: skip
    if math.isfinite(st.battery_percent):
        pct = st.battery_percent * 100.0 if st.battery_percent <= 1.0 else st.battery_percent
        out.append(Check("battery", PASS if pct >= min_battery_percent else FAIL,
                         f"{pct:.0f} %, {st.battery_v:.2f} V", f"≥ {min_battery_percent:g} %"))  # fmt: skip
    else:
        out.append(Check("battery", WARN, "not reported", f"≥ {min_battery_percent:g} %"))
    on_ground = not st.armed and st.landed_state in ("ON_GROUND", "UNKNOWN") and not st.in_air
    out.append(Check("on the ground, disarmed", PASS if on_ground else FAIL,
                     f"armed={st.armed}, landed state {st.landed_state}", "disarmed on the ground"))  # fmt: skip
    return out


def wind_check(speed_mps: float, sd_mps: float, source: str, max_wind_mps: float) -> Check:
    """The wind known before takeoff (the operator's, the autopilot's) against ``max_wind_mps``; flighttest's
    own estimate is judged again at the start hover (``flighttest.flying.wind.hover_check``)."""
    value = f"{speed_mps:.1f} ± {sd_mps:.1f} m/s ({source})"
    need = f"≤ max_wind_mps {max_wind_mps:g} m/s (judged again in the start hover from flighttest's estimate)"
    if not math.isfinite(speed_mps):
        return Check("wind", FAIL, "not a number", need)
    return Check("wind", PASS if speed_mps <= max_wind_mps else FAIL, value, need)


def mode_check(mode: str, rules: AutopilotRules) -> Check:
    """The mode the vehicle will arm in: from the arm on, a pilot's mode is a takeover and flighttest sends
    nothing more, so a flight never starts in one (nor in a mode the autopilot will not arm in)."""
    why = ", a pilot's mode" if mode in rules.pilot_modes else ""
    why = why or (", not armable" if mode in rules.not_armable_modes else "")
    return Check("mode before arming", FAIL if why else PASS, f"{mode}{why}",
                 f"not a pilot's mode, armable: switch it to {rules.armable_mode}")  # fmt: skip


def ground_height_check(alt_m: float) -> Check:
    """The estimate's height on the ground: every height of the flight (start, floor) counts from it."""
    need = f"|height| ≤ {GROUND_HEIGHT_MAX_M:g} m; heights, the start and the floor count from it"
    if not math.isfinite(alt_m):
        return Check("height on the ground", FAIL, "not reported", need)
    status = PASS if abs(alt_m) <= GROUND_HEIGHT_OK_M else WARN if abs(alt_m) <= GROUND_HEIGHT_MAX_M else FAIL
    return Check("height on the ground", status, f"the estimate reads {alt_m:+.2f} m (offset from home)", need)


def disk_check(folder, flight_s: float, telemetry_hz: float) -> Check:
    """Free disk for this flight's log: a full disk mid-flight leaves it incomplete."""
    import shutil

    need_b = LOG_DISK_FACTOR * LOG_BYTES_PER_S_PER_HZ * telemetry_hz * max(flight_s, 0.0)
    try:
        free_b = shutil.disk_usage(folder).free
    except OSError as exc:
        return Check("free disk for the log", FAIL, f"unknown ({exc.strerror or exc})", f"≥ {need_b / 1e6:.0f} MB")
    return Check("free disk for the log", PASS if free_b >= need_b else FAIL, f"{free_b / 1e6:.0f} MB free",
                 f"≥ {need_b / 1e6:.0f} MB ({LOG_DISK_FACTOR:g}× the log of a {flight_s:.0f} s flight)")  # fmt: skip


def px4_land_speed_mps(params: dict[str, float | int | None], height_m: float) -> float | None:
    """The descent speed of PX4's Land at ``height_m``: MPC_LAND_SPEED below MPC_LAND_ALT2, MPC_Z_V_AUTO_DN
    above MPC_LAND_ALT1, linear between (FlightTaskAuto's speed_down); None without the parameters."""
    names = ("MPC_LAND_SPEED", "MPC_Z_V_AUTO_DN", "MPC_LAND_ALT1", "MPC_LAND_ALT2")
    if any(params.get(n) is None for n in names):
        return None
    slow, fast, alt1, alt2 = (float(params[n]) for n in names)
    if height_m <= alt2 or alt1 <= alt2:
        return slow
    if height_m >= alt1:
        return fast
    return slow + (height_m - alt2) / (alt1 - alt2) * (fast - slow)


def param_checks(params: dict[str, float | int | None], descent_max_mps: float, w_allow_mps: float,
                 height_max_m: float = 0.0) -> list[Check]:  # fmt: skip
    """PX4's parameters that decide what happens when offboard ends, and the Land the abort ladder flies
    from the flight's highest point (``height_max_m``)."""
    out = []
    t = params.get("COM_OF_LOSS_T")
    if t is None:
        out.append(Check("COM_OF_LOSS_T", WARN, "not reported", "≤ 2 s"))
    else:
        out.append(Check("COM_OF_LOSS_T", PASS if 0 < t <= 2.0 else FAIL, f"{t:g} s",
                         "0 < t ≤ 2 s: a dead link leaves offboard quickly"))  # fmt: skip
    a = params.get("COM_OBL_RC_ACT")
    if a is None:
        out.append(Check("COM_OBL_RC_ACT", WARN, "not reported", "Position/Altitude/Return/Land/Hold"))
    else:
        name = OBL_ACTIONS.get(int(a), f"unknown ({a})")
        out.append(Check("COM_OBL_RC_ACT", FAIL if int(a) in OBL_UNSAFE or int(a) not in OBL_ACTIONS else PASS,
                         f"{int(a)} = {name}", "offboard loss → Position/Altitude/Return/Land/Hold"))  # fmt: skip
    r = params.get("COM_RC_OVERRIDE")
    if r is None:
        out.append(Check("COM_RC_OVERRIDE", WARN, "not reported", "offboard bit (2) set"))
    else:
        on = bool(int(r) & RC_OVERRIDE_OFFBOARD_BIT)
        out.append(Check("COM_RC_OVERRIDE", PASS if on else WARN,
                         f"{int(r)} (offboard override {'on' if on else 'off'})",
                         "offboard bit (2) set: the pilot's sticks take over"))  # fmt: skip
    v = params.get("MPC_Z_VEL_MAX_DN")
    if v is None:
        out.append(Check("MPC_Z_VEL_MAX_DN", WARN, "not reported", f"≥ planned descent {descent_max_mps:.2f} m/s"))
    else:
        ok = v + 1e-6 >= descent_max_mps
        out.append(Check(
            "MPC_Z_VEL_MAX_DN", PASS if ok else FAIL, f"{v:g} m/s",
            f"≥ planned descent {descent_max_mps:.2f} m/s (PX4 clips offboard descents to it)",
        ))  # fmt: skip
    land = px4_land_speed_mps(params, height_max_m)
    need = f"≤ w_allow {w_allow_mps:.2f} m/s: the ladder's Land stays out of the vortex ring"
    if land is None:
        out.append(Check("PX4 Land after an abort", WARN, "MPC_LAND_* / MPC_Z_V_AUTO_DN not reported", need))
    else:
        ok = land <= w_allow_mps + 1e-6
        if not ok:
            need += (f": Land descends faster above MPC_LAND_ALT2 {float(params['MPC_LAND_ALT2']):g} m; raise "
                     f"MPC_LAND_ALT1/ALT2 above {height_max_m:.1f} m or lower MPC_Z_V_AUTO_DN")  # fmt: skip
        value = f"{land:.2f} m/s from {height_max_m:.1f} m (MPC_LAND_SPEED {float(params['MPC_LAND_SPEED']):g})"
        out.append(Check("PX4 Land after an abort", PASS if ok else WARN, value, need))
    return out


# ArduCopter's parameters the preflight reads (names of ArduPilot master, 2026: ../shared/ardupilot_sitl)
ARDUPILOT_PARAMS = {"GUID_TIMEOUT": "float", "FS_GCS_ENABLE": "int", "FS_GCS_TIMEOUT": "float",
                    "MAV_GCS_SYSID": "int", "WP_SPD_DN": "float", "WP_SPD_UP": "float", "WP_ACC_Z": "float",
                    "WP_ACC": "float", "WP_JERK": "float", "PSC_JERK_D": "float", "LAND_SPD_MS": "float",
                    "FENCE_ENABLE": "int", "DISARM_DELAY": "int"}  # fmt: skip
# FS_GCS_ENABLE values (ArduCopter): what the vehicle does when the ground station's heartbeats stop
GCS_FS_ACTIONS = {0: "off", 1: "RTL", 2: "continue the mission in AUTO, else RTL", 3: "SmartRTL or RTL",
                  4: "SmartRTL or Land", 5: "Land", 6: "Auto DO_LAND_START or RTL", 7: "Brake or Land"}  # fmt: skip
RIDES_LIMIT = 0.97  # a plan using this much of a limit's share is bounded by it
JERK_RAMP_MAX_S = 0.5  # an acceleration step smoothed over longer than this lags the plan noticeably
GUIDED_SHAPING = "GUIDED shapes the setpoints with it: the vehicle falls behind, then overshoots into the guard"


def _need(name: str, value: float | int | None, need: float, unit: str, why: str, scale: float = 1.0) -> Check:
    """``value`` ≥ ``need`` (both SI), else a failure that names the value to set (in the parameter's own unit:
    ``scale`` of it is one SI unit's, 0.01 for older ArduCopter's cm)."""
    if value is None:
        return Check(name, WARN, "not reported", f"≥ {need:.2f} {unit} ({why})")
    ok = float(value) + 1e-6 >= need
    to_set = f"{math.ceil(need * 10) / 10 / scale:g}"
    return Check(name, PASS if ok else FAIL, f"{float(value):g} {unit}",
                 f"≥ {need:.2f} {unit}" + ("" if ok else f": set {name} to {to_set}") + f" ({why})")  # fmt: skip


def ardupilot_param_checks(params: dict[str, float | int | None], stats: TrajectoryStats, w_allow_mps: float,
                           gcs_sysid: int, recovery_climb_mps: float) -> list[Check]:  # fmt: skip
    """ArduCopter's side of the preflight, in the spirit of PX4's (``param_checks``): its failsafes as they
    apply to flighttest's link, and the GUIDED limits the plan must fit within (each failure names the
    value to set). ArduCopter has no offboard-loss mode change: with setpoints gone for GUID_TIMEOUT it
    zeroes its targets and brakes in GUIDED."""
    out = []
    t = params.get("GUID_TIMEOUT")
    out.append(Check("GUID_TIMEOUT", WARN, "not reported", "≤ 3 s") if t is None else Check(
        "GUID_TIMEOUT", PASS if 0 < float(t) <= 3.0 else WARN, f"{float(t):g} s",
        "≤ 3 s: setpoints gone this long, GUIDED brakes and holds (no mode change)"))  # fmt: skip
    fs = params.get("FS_GCS_ENABLE")
    if fs is None:
        out.append(Check("FS_GCS_ENABLE", WARN, "not reported", "a GCS failsafe action"))
    else:
        action = GCS_FS_ACTIONS.get(int(fs), f"unknown ({fs})")
        out.append(Check("FS_GCS_ENABLE", PASS if int(fs) in (1, 3, 4, 5, 7) else WARN, f"{int(fs)} = {action}",
                         "on (RTL/SmartRTL/Land/Brake-Land): a lost link is not left holding in GUIDED"))  # fmt: skip
    ft = params.get("FS_GCS_TIMEOUT")
    if ft is not None:
        out.append(Check("FS_GCS_TIMEOUT", PASS if 0 < float(ft) <= 5.0 else WARN, f"{float(ft):g} s", "≤ 5 s"))
    sysid = params.get("MAV_GCS_SYSID")
    if sysid is None:
        out.append(Check("MAV_GCS_SYSID", WARN, "not reported", f"{gcs_sysid}, flighttest's system id"))
    else:
        match = int(sysid) == gcs_sysid
        fs_on = fs is not None and int(fs) != 0
        need = f"{gcs_sysid}, flighttest's system id: its GCS failsafe watches only that ground station"
        if not match:
            need += f"; set MAV_GCS_SYSID to {gcs_sysid} to have it watch flighttest"
        out.append(Check("MAV_GCS_SYSID", PASS if match else FAIL if fs_on else WARN, f"{int(sysid)}", need))
    # the GUIDED limits in whichever names the firmware has (older ones in cm: flighttest.flying.live_limits)
    for new, need, unit, why in (
        ("WP_SPD_DN", stats.descent_max_mps, "m/s", "GUIDED clips descents to it"),
        ("WP_SPD_UP", max(stats.climb_max_mps, recovery_climb_mps), "m/s",
         "GUIDED clips climbs to it; the recovery climbs"),
        ("WP_ACC_Z", stats.accel_z_max_mps2, "m/s²", f"the plan's vertical acceleration; {GUIDED_SHAPING}"),
        ("WP_ACC", stats.accel_h_max_mps2, "m/s²", f"the plan's horizontal acceleration; {GUIDED_SHAPING}"),
    ):  # fmt: skip
        name, value, scale = param_value(params, new)
        check = _need(name, value, need, unit, why, scale)
        if check.status == PASS and value and need >= RIDES_LIMIT * AUTOPILOT_LIMIT_FRACTION * value:
            # the plans keep AUTOPILOT_LIMIT_FRACTION of each limit: this one bounds the plan
            check = replace(check, requirement=f"{check.requirement}; the plan rides it: a higher {name} lets the "
                                                "plan go faster")  # fmt: skip
        out.append(check)
    jerk_name, jerk_d, _ = param_value(params, "PSC_JERK_D")
    if jerk_d is not None and float(jerk_d) > 0:
        # the position controller ramps each acceleration step at this jerk: a plan whose steps it smooths
        # over more than a few telemetry periods arrives late (a step plan, the vertical's, has no finite jerk)
        ramp_s = stats.accel_z_max_mps2 / float(jerk_d)
        out.append(Check(jerk_name, PASS if ramp_s <= JERK_RAMP_MAX_S else WARN, f"{float(jerk_d):g} m/s³",
                         f"ramps the plan's {stats.accel_z_max_mps2:.2f} m/s² in ≤ {JERK_RAMP_MAX_S:g} s "
                         f"(takes {ramp_s:.2f} s)"))  # fmt: skip
    jerk = params.get("WP_JERK")
    if jerk is not None:
        out.append(Check("WP_JERK", PASS, f"{float(jerk):g} m/s³", "waypoint jerk (AUTO; reported)"))
    land = params.get("LAND_SPD_MS")
    if land is not None:
        out.append(Check("LAND_SPD_MS", PASS if float(land) <= w_allow_mps else WARN, f"{float(land):g} m/s",
                         f"≤ w_allow {w_allow_mps:.2f} m/s: Land's final descent below the VRS onset"))  # fmt: skip
    fence = params.get("FENCE_ENABLE")
    if fence is not None:
        out.append(Check("FENCE_ENABLE", WARN if int(fence) else PASS, f"{int(fence)}",
                         "a fence breach takes the vehicle out of GUIDED mid-descent: check its limits"))  # fmt: skip
    delay = params.get("DISARM_DELAY")
    if delay is not None:
        out.append(Check("DISARM_DELAY", PASS, f"{int(delay)} s", "disarms this long after landing (reported)"))
    return out
