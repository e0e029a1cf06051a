"""A scriptable in-process autopilot: the mission runner's link (``flighttest.flying.link.Link``) without
MAVLink, flying on the event loop's clock — virtual under ``sitl_fakes.virtual_time``.

The UDP fake (``sitl_fakes.app``) is PX4 as MAVSDK sees it, in real time; this one is PX4 as the runner
sees it, in virtual time, so that every way a flight ends can be tested deterministically and in a
fraction of a second (px4-ros2-interface-lib's ``fake_autopilot`` and RotorPy's ``simulate()`` are the
models). It keeps what the runner's decisions depend on, for PX4 (``autopilot=PX4``) or ArduCopter
(``autopilot=ARDUPILOT``), each with its own mode names and parameters (``flighttest.flying.autopilot``):

- the modes and their transitions: PX4's takeoff ends in HOLD and ``offboard stop`` goes to HOLD, and as it
  disarms after a landing PX4 goes back to the last mode asked for that it arms in (it will not arm in Land);
  ArduCopter takes off in GUIDED and stays there, and its hold is BRAKE; Land descends at
  ``land_speed_mps`` (ArduCopter's LAND_SPD_MS) and disarms on the ground; a pilot mode holds where the
  pilot is;
- offboard needs a setpoint before it starts; setpoints missing for ``COM_OF_LOSS_T`` send PX4 to HOLD
  (its offboard-loss failsafe), while ArduCopter only zeroes its targets after ``GUID_TIMEOUT`` and
  brakes, still in GUIDED;
- a position loop (P on position, velocity feed-forward, P on velocity, acceleration feed-forward,
  bounded acceleration) — not the dynamics: a level vehicle with yaw 0, so body axes are NED's;
- telemetry at ``telemetry_hz`` with a little seeded noise on rates and acceleration (the guard's hover
  baseline needs some), and MAVSDK's late "disconnected" after the heartbeats stop;
- what MAVSDK reads from the heartbeat (armed, the mode) at ``heartbeat_hz`` only, as PX4 and ArduCopter
  send it (1 Hz): an arm is acknowledged up to a second before the armed flag says so; the landed state
  (EXTENDED_SYS_STATE) at ``landed_state_hz``;
- an estimate that may read ``height_offset_m`` high on the ground, attitude samples stamped with the
  vehicle's own clock, and a wind report (WIND_COV) only where a script gives one.

A script is a list of rules, ``when(condition, action)`` or ``after(condition, delay_s, action)``,
checked every physics step, plus the switches below (``push``, ``pilot``, ``lose_link``,
``stop_telemetry``, ``stop_attitude``, ``delay_telemetry``, ``report_wind``, ``unanswered``, ``ignored``,
``refused``). ``commands`` records every command the vehicle heard, with its time.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flighttest.flying.autopilot import ARDUPILOT, PX4, rules_for
from flighttest.flying.link import TelemetryState

G_MPS2 = 9.80665
PX4_PARAMS: dict[str, float | int] = {
    "COM_OF_LOSS_T": 1.0, "COM_OBL_RC_ACT": 0, "COM_RC_OVERRIDE": 1, "MPC_Z_VEL_MAX_DN": 1.5, "MPC_Z_P": 1.0,
    "MPC_XY_P": 0.95, "MPC_ACC_DECOUPLE": 1, "MPC_LAND_SPEED": 0.7, "MPC_Z_V_AUTO_DN": 1.5, "MPC_LAND_ALT1": 10.0,
    "MPC_LAND_ALT2": 5.0,
}  # fmt: skip
# ArduCopter master's defaults (../shared/ardupilot_sitl, the DataFlash PARM records)
ARDUPILOT_PARAMS: dict[str, float | int] = {
    "GUID_TIMEOUT": 3.0, "FS_GCS_ENABLE": 0, "FS_GCS_TIMEOUT": 5.0, "MAV_GCS_SYSID": 255, "WP_SPD_DN": 1.5,
    "WP_SPD_UP": 2.5, "WP_ACC_Z": 1.0, "WP_ACC": 2.5, "WP_JERK": 1.0, "PSC_JERK_D": 5.0, "LAND_SPD_MS": 0.5,
    "FENCE_ENABLE": 0, "DISARM_DELAY": 10, "PSC_D_POS_P": 1.0,
}  # fmt: skip


HISTORY_S = 5.0  # how far back a delayed stream may reach (``delay_telemetry``)
# the modes PX4 will not arm in (ModeUtil/mode_requirements.cpp, mode_req_prevent_arming: "Mode not suitable for
# arming"); it leaves Land for the last mode asked for outside them as it disarms after a landing
PX4_PREVENT_ARMING = frozenset({"LAND", "RETURN_TO_LAUNCH", "FOLLOW_ME"})


@dataclass
class _Rule:
    condition: Callable[[], bool]
    action: Callable[[], None]
    delay_s: float = 0.0
    true_since_s: float | None = None
    fired: bool = False


@dataclass
class _Setpoint:
    p_ned: np.ndarray
    v_ned: np.ndarray
    a_ned: np.ndarray
    velocity_only: bool
    t_s: float


@dataclass
class ScriptedAutopilot:
    """One PX4-like vehicle on the ground at home, disarmed, in HOLD. See the module docstring."""

    telemetry_hz: float = 50.0
    physics_hz: float = 50.0
    answer_s: float = 0.05  # how long a command takes to be acknowledged
    takeoff_speed_mps: float = 1.0
    land_speed_mps: float = 0.7
    disarm_after_s: float = 0.5  # on the ground in Land, after a flight, PX4 disarms after this
    # from the takeoff command until the vehicle climbs: PX4 SITL spools up and ramps for seconds
    # (bench/RESULTS.md, "Flight-safety review on real firmware (issue 24)")
    spool_up_s: float = 1.0
    preflight_disarm_s: float = 10.0  # armed on the ground without a takeoff: COM_DISARM_PRFLT / DISARM_DELAY
    position_gain_per_s: float = 1.0
    velocity_gain_per_s: float = 4.0
    max_accel_mps2: float = 10.0
    disconnect_report_s: float = 3.0  # MAVSDK says "disconnected" this long after the heartbeats stop
    heartbeat_hz: float = 1.0  # armed and the mode reach the ground station with the heartbeat
    landed_state_hz: float = 10.0  # EXTENDED_SYS_STATE, as the link asks for it
    height_offset_m: float = 0.0  # the estimate's height reads this much high (on the ground too)
    # the air: its wind (NED, m/s) and the drag it exerts, which the IMU feels across the thrust axis (the
    # vehicle is level, so its body axes are NED's); deliberately not a profile's figures
    wind_ned_mps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mass_kg: float = 2.0
    drag_n_per_mps: float = 0.75  # x500's identified drag at 2-3 m/s within its ±8 %, linear at every thrust
    rate_noise_rps: float = 0.01
    accel_noise_mps2: float = 0.05
    seed: int = 0
    autopilot: str | None = PX4  # or ARDUPILOT: its modes, its parameters, no offboard-loss failsafe
    params: dict[str, float | int] | None = None  # None: the autopilot's defaults above
    offboard_loss_failsafe: bool = True  # False: a vehicle that stays in OFFBOARD with no setpoint (a test's)
    # switches a script sets
    unanswered: set[str] = field(default_factory=set)  # commands never acknowledged (the caller times out)
    ignored: set[str] = field(default_factory=set)  # commands acknowledged that change nothing
    refused: dict[str, str] = field(default_factory=dict)  # commands refused, with the error

    realtime = False  # its clock is the loop's, virtual in tests: no wall-clock watchdog may judge it

    def __post_init__(self) -> None:
        self.rules = rules_for(self.autopilot)
        ardupilot = self.rules.name == ARDUPILOT
        if self.params is None:
            self.params = dict(ARDUPILOT_PARAMS if ardupilot else PX4_PARAMS)
        # ArduCopter takes off in GUIDED and stays there; PX4 has a mode for it and holds after it
        self.takeoff_mode = self.rules.offboard_mode if ardupilot else "TAKEOFF"
        self.after_takeoff_mode = self.rules.offboard_mode if ardupilot else self.rules.hold_mode
        if ardupilot:
            self.land_speed_mps = float(self.params.get("LAND_SPD_MS", self.land_speed_mps))
        self.taking_off = False
        self.took_off = False  # since the last arm (PX4 disarms by itself after a landing only then)
        self._armed_t = 0.0
        self._takeoff_t = 0.0
        self.state = TelemetryState()
        self.on_posvel: list[Callable[[float], None]] = []
        self.on_attitude: list[Callable[[float], None]] = []
        self.on_imu: list[Callable[[float], None]] = []
        self.on_mode: list[Callable[[str, str], None]] = []
        self.on_connection: list[Callable[[bool], None]] = []
        self.commands: list[tuple[float, str]] = []
        self.listener_errors: list[str] = []
        self.p_ned = np.zeros(3)
        self.v_ned = np.zeros(3)
        self.a_ned = np.zeros(3)
        self.mode = "STABILIZE" if ardupilot else self.rules.hold_mode  # what each is in on the ground
        self._after_disarm = self.mode  # PX4: the last mode asked for that it arms in (UserModeIntention::onDisarm)
        self.armed = False
        self.hold_ned = np.zeros(3)
        self.takeoff_alt_m = 2.5
        self.setpoint: _Setpoint | None = None
        self.resending = False  # MAVSDK re-sends the last setpoint from offboard.start() to offboard.stop()
        self.link_up = True
        self.telemetry_on = True
        self.attitude_on = True
        self.telemetry_delay_s = 0.0
        self.telemetry_delay_growth = 0.0
        self._history: list[tuple[float, np.ndarray, np.ndarray]] = []  # (t, p, v): what a late stream shows
        self.wind_report: tuple[float, float, float] | None = None
        self.wind_accuracy_mps = math.nan
        self._boot_t: float | None = None
        self._next_heartbeat_t = 0.0
        self._next_landed_t = 0.0
        self._link_lost_t: float | None = None
        self._reported_connected = True
        self._push: tuple[np.ndarray, float] | None = None  # external acceleration, until
        self._ground_since: float | None = None
        self._rules: list[_Rule] = []
        self._rng = np.random.default_rng(self.seed)
        self._task: asyncio.Task | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    # -- the script ----------------------------------------------------------------------------------
    def when(self, condition: Callable[[], bool], action: Callable[[], None]) -> None:
        """Do ``action`` once, at the first physics step where ``condition()`` holds."""
        self._rules.append(_Rule(condition, action))

    def after(self, condition: Callable[[], bool], delay_s: float, action: Callable[[], None]) -> None:
        """Do ``action`` once, ``delay_s`` after ``condition()`` first held."""
        self._rules.append(_Rule(condition, action, delay_s))

    def push(self, a_ned_mps2: tuple[float, float, float], for_s: float) -> None:
        """An external acceleration for ``for_s`` (a downward one beyond the thrust margin: a sink the
        position loop cannot hold, as in the vortex ring state)."""
        self._push = (np.asarray(a_ned_mps2, float), self.now() + for_s)

    def pilot(self, mode: str = "POSCTL") -> None:
        """The pilot flips the mode switch: the vehicle holds where it is, under the sticks."""
        self.hold_ned = self.p_ned.copy()
        self.mode = mode
        self.taking_off = False

    def lose_link(self) -> None:
        """Nothing in either direction from now on: no telemetry, no setpoint, no command answered.
        MAVSDK reports the loss ``disconnect_report_s`` later."""
        self.link_up = False
        self._link_lost_t = self.now()

    def restore_link(self) -> None:
        self.link_up = True
        self._link_lost_t = None

    def stop_telemetry(self) -> None:
        """Telemetry stops (an overloaded link, a stuck stream); commands and setpoints still get through."""
        self.telemetry_on = False

    def resume_telemetry(self) -> None:
        self.telemetry_on = True

    def stop_attitude(self) -> None:
        """The attitude stream alone stops; position-velocity and the IMU keep coming."""
        self.attitude_on = False

    def delay_telemetry(self, growth_per_s: float) -> None:
        """From now on the link falls behind: each state sample arrives at the same steady rate, stamped with
        the vehicle's time of the state it carries, but the queue before it grows by ``growth_per_s`` seconds
        each second (a link that delivers less than the vehicle sends)."""
        self.telemetry_delay_growth = growth_per_s

    def report_wind(self, wind_ned_mps: tuple[float, float, float] | None, accuracy_mps: float = math.nan) -> None:
        """The autopilot's wind estimate (WIND_COV) from now on; None: it stops reporting one."""
        self.wind_report, self.wind_accuracy_mps = wind_ned_mps, accuracy_mps

    def heard(self, name: str) -> list[float]:
        """When the vehicle heard command ``name``."""
        return [t for t, c in self.commands if c == name]

    @property
    def on_ground(self) -> bool:
        return self.p_ned[2] >= 0.0 and self.v_ned[2] >= 0.0

    def now(self) -> float:
        return (self._loop or asyncio.get_running_loop()).time()

    # -- the link ------------------------------------------------------------------------------------
    async def open(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._boot_t = self.now() - 100.0  # the vehicle booted a while ago: its clock is not ours
        self._next_heartbeat_t = self.now()  # MAVSDK found the vehicle by a heartbeat: known before open returns
        self.state.health = {k: True for k in ("is_gyrometer_calibration_ok", "is_accelerometer_calibration_ok",
                                               "is_local_position_ok", "is_global_position_ok",
                                               "is_home_position_ok", "is_armable")}  # fmt: skip
        self.state.health_all_ok = True
        self.state.battery_percent, self.state.battery_v = 0.9, 16.2
        self._task = asyncio.create_task(self._run(), name="scripted-autopilot")
        await asyncio.sleep(self.answer_s)

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)
            self._task = None

    async def wait_for(self, predicate: Callable[[TelemetryState], bool], timeout_s: float,
                       poll_s: float = 0.05) -> bool:  # fmt: skip
        deadline = self.now() + timeout_s
        while self.now() < deadline:
            if predicate(self.state):
                return True
            await asyncio.sleep(poll_s)
        return predicate(self.state)

    def offboard_setters(self) -> Any:
        ap = self

        class Setters:
            @staticmethod
            def set_velocity_ned(v) -> None:
                ap.receive_setpoint(None, (v.north_m_s, v.east_m_s, v.down_m_s), None)

            @staticmethod
            def set_position_velocity_acceleration_ned(p, v, a) -> None:
                ap.receive_setpoint((p.north_m, p.east_m, p.down_m), (v.north_m_s, v.east_m_s, v.down_m_s),
                                     (a.north_m_s2, a.east_m_s2, a.down_m_s2))  # fmt: skip

        return Setters()

    def receive_setpoint(self, p, v, a) -> None:
        """A setpoint as MAVSDK's offboard plugin hands it over (position None: velocity only)."""
        if not self.link_up:
            return
        zero = np.zeros(3)
        if p is not None:  # the setpoint is in the estimate's frame, which reads height_offset_m high
            p = np.asarray(p, float) + np.array([0.0, 0.0, self.height_offset_m])
        self.setpoint = _Setpoint(zero if p is None else np.asarray(p, float), np.asarray(v, float),
                                  zero if a is None else np.asarray(a, float), p is None, self.now())  # fmt: skip

    async def get_param(self, name: str, kind: str = "float") -> float | int | None:
        if not self.link_up:
            await asyncio.sleep(5.0)
            return None
        await asyncio.sleep(self.answer_s)
        v = self.params.get(name)
        return None if v is None else (int(v) if kind == "int" else float(v))

    async def get_all_params(self, timeout_s: float = 3.0) -> dict[str, float | int]:
        await asyncio.sleep(self.answer_s)
        return dict(self.params)

    async def autopilot_name(self) -> str | None:
        return self.autopilot

    # -- commands ------------------------------------------------------------------------------------
    async def _command(self, name: str, what: str, timeout_s: float, effect: Callable[[], None]) -> None:
        if self.link_up:
            self.commands.append((self.now(), name))
            if name in ("start_offboard", "stop_offboard"):  # MAVSDK's side, whatever the vehicle answers
                self.resending = name == "start_offboard"
        if not self.link_up or name in self.unanswered:
            await asyncio.sleep(timeout_s)
            raise TimeoutError(f"{what}: no answer within {timeout_s:g} s")
        await asyncio.sleep(min(self.answer_s, timeout_s))
        if name in self.refused:
            raise RuntimeError(f"{what}: {self.refused[name]}")
        if name not in self.ignored:
            effect()

    async def arm(self, timeout_s: float, what: str = "arm") -> None:
        def effect() -> None:
            if not self.on_ground:
                raise RuntimeError(f"{what}: not on the ground")
            if self.rules.name == ARDUPILOT and self.mode in ("LAND", "RTL", "AUTO", "BRAKE"):
                # MAVSDK's arm switches LAND/RTL/AUTO to BRAKE first, where ArduCopter will not arm
                self.mode = "BRAKE"
                raise RuntimeError(f"{what}: denied (Arm: Mode not armable)")
            if self.rules.name != ARDUPILOT and self.mode in PX4_PREVENT_ARMING:
                raise RuntimeError(f"{what}: denied (Mode not suitable for arming)")
            self.armed = True
            self.took_off = False
            self._armed_t = self.now()
            self._ground_since = None

        await self._command("arm", what, timeout_s, effect)

    async def disarm(self, timeout_s: float, what: str = "disarm") -> None:
        def effect() -> None:
            if not (self.on_ground and abs(self.v_ned[2]) < 0.1):
                raise RuntimeError(f"{what}: denied (not landed)")
            self.armed = False

        await self._command("disarm", what, timeout_s, effect)

    async def set_takeoff_altitude(self, alt_m: float, timeout_s: float, what: str = "set takeoff altitude") -> None:
        await self._command("set_takeoff_altitude", what, timeout_s, lambda: setattr(self, "takeoff_alt_m", alt_m))

    async def takeoff(self, timeout_s: float, what: str = "takeoff") -> None:
        def effect() -> None:
            if not self.armed:
                raise RuntimeError(f"{what}: denied (disarmed)")
            self.hold_ned = np.array([self.p_ned[0], self.p_ned[1], -self.takeoff_alt_m])
            self.mode = self.takeoff_mode
            self.taking_off = True
            self._takeoff_t = self.now()

        await self._command("takeoff", what, timeout_s, effect)

    async def land(self, timeout_s: float, what: str = "land") -> None:
        def effect() -> None:
            self.hold_ned = self.p_ned.copy()
            self.mode = self.rules.land_mode
            self.taking_off = False

        await self._command("land", what, timeout_s, effect)

    async def hold(self, timeout_s: float, what: str = "hold") -> None:
        await self._command("hold", what, timeout_s, self._enter_hold)

    async def start_offboard(self, timeout_s: float, what: str = "offboard start") -> None:
        def effect() -> None:
            if self.setpoint is None:  # PX4 refuses offboard without a setpoint stream
                raise RuntimeError(f"{what}: no setpoint")
            self.mode = self.rules.offboard_mode
            self._asked(self.mode)
            self.taking_off = False

        await self._command("start_offboard", what, timeout_s, effect)

    async def stop_offboard(self, timeout_s: float, what: str = "offboard stop") -> None:
        await self._command("stop_offboard", what, timeout_s, self._enter_hold)

    async def set_mode(self, name: str, timeout_s: float) -> None:
        def effect() -> None:
            self.hold_ned = self.p_ned.copy()
            self.mode = name
            self._asked(name)
            self.taking_off = False

        await self._command("set_mode", f"mode {name}", timeout_s, effect)

    def _enter_hold(self) -> None:
        self.hold_ned = self.p_ned.copy()
        self.mode = self.rules.hold_mode
        self._asked(self.mode)
        self.taking_off = False

    def _asked(self, mode: str) -> None:
        if mode not in PX4_PREVENT_ARMING:
            self._after_disarm = mode

    # -- the vehicle ---------------------------------------------------------------------------------
    async def _run(self) -> None:
        dt = 1.0 / self.physics_hz
        every = max(round(self.physics_hz / self.telemetry_hz), 1)
        k = 0
        t0 = self.now()
        while True:
            k += 1
            await asyncio.sleep(max(t0 + k * dt - self.now(), 0.0))
            self._step(dt)
            self._script()
            if k % every == 0:
                self._telemetry()

    def _velocity_command(self) -> tuple[np.ndarray, np.ndarray]:
        """The velocity the position loop asks for, and the acceleration fed forward."""
        kp, zero = self.position_gain_per_s, np.zeros(3)
        sp = self.setpoint
        if self.mode == self.rules.offboard_mode and sp is not None and not self.taking_off:
            if sp.velocity_only:
                return sp.v_ned, zero
            return sp.v_ned + kp * (sp.p_ned - self.p_ned), sp.a_ned
        v = kp * (self.hold_ned - self.p_ned)
        if self.taking_off:
            spooled = self.now() >= self._takeoff_t + self.spool_up_s
            v[2] = max(v[2], -self.takeoff_speed_mps) if spooled else 0.0
        elif self.mode == self.rules.land_mode:
            v[2] = self.land_speed_mps
        return v, zero

    def _step(self, dt: float) -> None:
        now = self.now()
        sp = self.setpoint
        if sp is not None and self.resending and self.link_up:
            sp.t_s = now
        if self.mode == self.rules.offboard_mode and not self.taking_off:
            if self.rules.offboard_loss_failsafe:
                loss_s = float(self.params.get("COM_OF_LOSS_T", 1.0))
                if self.offboard_loss_failsafe and (sp is None or now - sp.t_s > loss_s):
                    self._enter_hold()  # PX4's offboard-loss failsafe (COM_OBL_RC_ACT 0 without RC: Hold)
            elif sp is not None and now - sp.t_s > float(self.params.get("GUID_TIMEOUT", 3.0)):
                # ArduCopter's GUID_TIMEOUT: targets zeroed, it brakes and holds, still in GUIDED
                self.setpoint = None
                self.hold_ned = self.p_ned.copy()
        if not self.armed:
            self.v_ned[:] = 0.0
            self.a_ned[:] = 0.0
            return
        v_cmd, a_ff = self._velocity_command()
        a = a_ff + self.velocity_gain_per_s * (v_cmd - self.v_ned)
        norm = float(np.linalg.norm(a))
        if norm > self.max_accel_mps2:
            a *= self.max_accel_mps2 / norm
        if self._push is not None:
            if now < self._push[1]:
                a = a + self._push[0]
            else:
                self._push = None
        self.a_ned = a
        self.v_ned = self.v_ned + a * dt
        self.p_ned = self.p_ned + self.v_ned * dt
        if self.p_ned[2] >= 0.0:  # the ground
            self.p_ned[2] = 0.0
            self.v_ned[2] = min(self.v_ned[2], 0.0)
            self.v_ned[:2] = 0.0
            if self.taking_off or self.v_ned[2] < 0:
                self._ground_since = None
            else:
                self._ground_since = now if self._ground_since is None else self._ground_since
                # PX4 disarms a landing by itself only after a flight; ArduCopter's LAND always does
                after_flight = self.took_off or self.rules.name == ARDUPILOT
                landed_s = now - self._ground_since
                if self.mode == self.rules.land_mode and after_flight and landed_s >= self.disarm_after_s:
                    self.armed = False
                    if self.rules.name != ARDUPILOT:  # PX4 leaves Land for it as it disarms, in the same heartbeat
                        self.mode = self._after_disarm
            if not self.took_off and now - self._armed_t >= self.preflight_disarm_s and not self.taking_off:
                self.armed = False  # armed this long without a takeoff
        else:
            self._ground_since = None
            if self.p_ned[2] < -0.1:
                self.took_off = True
        if self.taking_off and abs(self.p_ned[2] - self.hold_ned[2]) < 0.1:
            self.taking_off = False
            self.mode = self.after_takeoff_mode

    def _script(self) -> None:
        now = self.now()
        for r in self._rules:
            if r.fired:
                continue
            if r.true_since_s is None and r.condition():
                r.true_since_s = now
            if r.true_since_s is not None and now - r.true_since_s >= r.delay_s - 1e-9:
                r.fired = True
                r.action()

    def _telemetry(self) -> None:
        st, now = self.state, self.now()
        if not self.link_up:
            if self._reported_connected and now - self._link_lost_t >= self.disconnect_report_s:
                self._report_connection(False)
            return
        if not self._reported_connected:
            self._report_connection(True)
        climbing = self.taking_off and now >= self._takeoff_t + self.spool_up_s
        in_air = self.armed and not (self.p_ned[2] >= -0.05 and self._ground_since is not None) and (
            self.p_ned[2] < -0.05 or climbing)
        st.in_air = in_air
        if now >= self._next_landed_t - 1e-9:
            self._next_landed_t = now + 1.0 / self.landed_state_hz
            st.report_landed("IN_AIR" if in_air else "ON_GROUND", now)
        if now >= self._next_heartbeat_t - 1e-9:
            self._next_heartbeat_t += 1.0 / self.heartbeat_hz
            st.report_armed(self.armed, now)
            if st.flight_mode != self.mode:
                old, st.flight_mode = st.flight_mode, self.mode
                self._emit(self.on_mode, old, self.mode)
        if not self.telemetry_on:
            return
        self.telemetry_delay_s += self.telemetry_delay_growth / self.telemetry_hz
        self._history.append((now, self.p_ned.copy(), self.v_ned.copy()))
        while len(self._history) > 1 and self._history[0][0] < now - HISTORY_S:
            self._history.pop(0)
        t_state, p, v = now, self.p_ned, self.v_ned
        if self.telemetry_delay_s > 0:  # the newest state at least that old
            t_state, p, v = next((h for h in reversed(self._history) if h[0] <= now - self.telemetry_delay_s + 1e-9),
                                 self._history[0])  # fmt: skip
        st.n_m, st.e_m, st.d_m = float(p[0]), float(p[1]), float(p[2]) - self.height_offset_m
        st.vn_mps, st.ve_mps, st.vd_mps = (float(x) for x in v)
        st.t_posvel = now
        st.count("posvel", now)
        self._emit(self.on_posvel, now)
        if self.attitude_on:
            st.q = (1.0, 0.0, 0.0, 0.0)
            st.t_att = now
            st.t_att_vehicle_s = t_state - self._boot_t
            st.count("attitude", now)
            self._emit(self.on_attitude, now)
        if self.wind_report is not None:
            st.wind_ned_mps, st.wind_accuracy_mps, st.t_wind = self.wind_report, self.wind_accuracy_mps, now
        noise = self._rng.normal(size=6)
        st.rates_rps = tuple(float(x) for x in noise[:3] * self.rate_noise_rps)
        f = self.a_ned - np.array([0.0, 0.0, G_MPS2]) if self.armed else np.array([0.0, 0.0, -G_MPS2])
        # thrust is along body z: across it the IMU feels the drag of the air alone
        f[:2] = -self.drag_n_per_mps * (self.v_ned[:2] - np.asarray(self.wind_ned_mps[:2])) / self.mass_kg
        st.accel_frd_mps2 = tuple(float(x) for x in f + noise[3:] * self.accel_noise_mps2)
        st.t_imu = now
        st.count("imu", now)
        self._emit(self.on_imu, now)

    def _report_connection(self, connected: bool) -> None:
        self._reported_connected = connected
        self.state.connected = connected
        self._emit(self.on_connection, connected)

    def _emit(self, listeners: list[Callable[..., None]], *args: Any) -> None:
        """Each listener, as MAVSDK's subscriptions call them (``flighttest.flying.link``): one that raises is
        recorded in ``listener_errors`` and the stream goes on."""
        for cb in listeners:
            try:
                cb(*args)
            except Exception as exc:
                self.listener_errors.append(repr(exc))

    def heartbeat_now(self) -> None:
        """The next telemetry step sends a heartbeat (armed, the mode), whatever its phase."""
        self._next_heartbeat_t = self.now()

    @property
    def speed_mps(self) -> float:
        return float(math.sqrt(float(self.v_ned @ self.v_ned)))
