"""The fake PX4: arming, modes, offboard rules, commands, parameters and failsafes around the physics.

One object, stepped by the main loop (``sitl_fakes.app``): ``handle(msg, addr)`` for every MAVLink
message received, ``step(dt)`` for every physics step. It never blocks and owns no threads.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from flighttest.model.aero import G_MPS2
from flighttest.model.profiles import VehicleProfile
from sitl_fakes import px4
from sitl_fakes.control import NAN, Controller, Limits, Target, finite
from sitl_fakes.disturbance import Disturbance, VrsTruth
from sitl_fakes.drag import TruthDrag
from sitl_fakes.drag_fusion import DragFusionModel, DragFusionWind
from sitl_fakes.estimator import EstimateError, Estimator
from sitl_fakes.link import Link, mavlink
from sitl_fakes.physics import QuadBody
from sitl_fakes.px4 import Mode
from sitl_fakes.truthlog import TruthLog
from sitl_fakes.wind import Wind

# PX4 offboard: the mode is available while setpoints arrive; a > 2 Hz stream means one within 0.5 s.
OFFBOARD_SIGNAL_FRESH_S = 0.5
# PX4 will not arm in these (ModeUtil/mode_requirements.cpp: mode_req_prevent_arming, "Mode not suitable for
# arming"): disarmed in Land after an abort, PX4 SITL reported not armable until the mode changed
PREVENT_ARMING = frozenset({Mode.LAND, Mode.RTL})
TAKEOFF_ACCEPT_M = 0.05
RTL_ACCEPT_M = 1.0
RTL_SPEED_MPS = 5.0
IDLE_THRUST_FRACTION = 0.05
FORCE_ARM_MAGIC = 21196
# PX4 SIH's accelerometer as HIGHRES_IMU carries it (../shared/wind_sitl: 0.068 m/s² per axis, white, in the air
# and on the ground; SIH adds 0.1 m/s² of Gaussian noise to the specific force and PX4 filters it)
PX4_IMU_NOISE_MPS2 = 0.07
# a calibrated accelerometer's residual bias along body x, y, z (both SITLs have none; a real IMU keeps a few
# hundredths of a m/s² after calibration): flighttest's wind filter must learn it, not assume it away
IMU_BIAS_MPS2 = (0.04, -0.03, 0.0)

# MAV_RESULT
ACCEPTED, TEMP_REJECTED, DENIED, UNSUPPORTED, FAILED = 0, 1, 2, 3, 4

POSITION_IGNORE = 0b111
VELOCITY_IGNORE = 0b111 << 3
ACCEL_IGNORE = 0b111 << 6
FORCE_SET = 1 << 9
YAW_IGNORE = 1 << 10
YAW_RATE_IGNORE = 1 << 11


@dataclass
class FakeConfig:
    profile: VehicleProfile
    truth: VrsTruth
    wind_ned: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gust_mps: float = 0.0
    gust_tau_s: float | None = None  # one correlation time for the turbulence; None: Dryden's (sitl_fakes.wind)
    truth_drag: TruthDrag | None = None  # None: the airframe's (sitl_fakes.drag.TRUTH_DRAG)
    imu_noise_mps2: float = PX4_IMU_NOISE_MPS2  # HIGHRES_IMU's accelerometer noise, 1 σ per axis
    imu_bias_mps2: tuple[float, float, float] = IMU_BIAS_MPS2  # … and its constant bias, body x, y, z
    seed: int = 0
    crash_speed_mps: float = 2.5
    crash_tilt_deg: float = 60.0
    gps_delay_s: float = 0.0
    home_lat_deg: float = 47.397742  # PX4 SITL default home (Zurich)
    home_lon_deg: float = 8.545594
    home_alt_m: float = 488.0
    telemetry_hz: float = 50.0
    estimate_error: EstimateError = field(default_factory=EstimateError)
    # telemetry gaps as a loaded machine and PX4's own scheduling make them (sitl_fakes.telemetry)
    telemetry_gap_rate_hz: float = 0.1
    telemetry_gap_s: tuple[float, float] = (0.05, 0.1)


class FakePx4:
    def __init__(self, cfg: FakeConfig, link: Link, log: TruthLog, t0: float):
        self.cfg = cfg
        self.link = link
        self.log = log
        self.t0 = t0
        self.now = t0
        self.profile = cfg.profile
        self.body = QuadBody(cfg.profile, cfg.truth_drag)
        self.ctrl = Controller(cfg.profile)
        self.estimator = Estimator(cfg.estimate_error, cfg.seed)
        self.est = self.estimator.estimate(self.body.state)
        self.dist = Disturbance(cfg.truth)
        self.wind = Wind(cfg.wind_ned, cfg.gust_mps, cfg.seed, cfg.gust_tau_s)
        self.wind_estimate = DragFusionWind(cfg.seed)  # the autopilot's own, with drag fusion on
        self.params = px4.default_params()
        self.params["MPC_TILTMAX_AIR"].value = min(45.0, cfg.profile.max_tilt_deg)
        # PX4's hover-thrust estimator converges within seconds: start it at the vehicle's truth
        prof = cfg.profile
        self.params["MPC_THR_HOVER"].value = prof.mass_kg * G_MPS2 / (prof.n_rotors * prof.max_thrust_per_rotor_n)
        self.param_names = sorted(self.params)
        self.mode = Mode.HOLD
        # the last mode asked for (DO_SET_MODE) that PX4 arms in: it returns to it when it disarms after a landing
        self.user_mode = Mode.HOLD
        self.armed = False
        self.crashed = False
        self.crash_reason = ""
        self.arm_time = 0.0
        self.has_flown = False
        self.ground_since = t0
        self.target = Target()
        self.hold_target = Target()
        self.takeoff_alt_m = 0.0
        self.offboard_sp: Target | None = None
        self.offboard_mask = 0
        self.offboard_source = ""
        self.offboard_attitude: tuple[tuple[float, float, float, float], float] | None = None
        self.last_sp_time = -math.inf
        self.thrust_cmd = [0.0, 0.0, 0.0, 0.0]
        self.active_sp: tuple[str, int, Target] | None = None
        self.heartbeat_due = True  # extra heartbeat on arm / mode change
        self.telemetry = None  # set by the app (sitl_fakes.telemetry.Telemetry)
        self._hold_here()

    # -- helpers -------------------------------------------------------------------------------------
    @property
    def t_s(self) -> float:
        return self.now - self.t0

    def position_valid(self) -> bool:
        return self.t_s >= self.cfg.gps_delay_s

    def armable(self) -> bool:
        """PX4's prearm check as far as the fake models it: a position, no crash, not Offboard without a live
        setpoint stream, and not in a mode PX4 will not arm in (Land, Return: ``PREVENT_ARMING``)."""
        offboard_dead = self.mode is Mode.OFFBOARD and self.now_wall() - self.last_sp_time > OFFBOARD_SIGNAL_FRESH_S
        return self.position_valid() and not self.crashed and not offboard_dead and self.mode not in PREVENT_ARMING

    def landed(self) -> bool:
        return self.body.state.on_ground

    def p(self, name: str) -> float:
        return float(self.params[name].value)

    def limits(self) -> Limits:
        return Limits.from_params(self.p, self.profile)

    def drag_fusion_model(self) -> DragFusionModel:
        """EKF2's drag model, used only with EKF2_DRAG_CTRL set (its wind states run only then)."""
        if int(self.p("EKF2_DRAG_CTRL")) <= 0:
            return DragFusionModel(0.0, 0.0, 0.0)
        return DragFusionModel(self.p("EKF2_MCOEF"), self.p("EKF2_BCOEF_X"), self.p("EKF2_BCOEF_Y"))

    def wind_report(self) -> tuple[float, float, float] | None:
        """The wind the autopilot reports (PX4: WIND_COV, only once EKF2 estimates it), else None."""
        est = self.wind_estimate
        return est.wind_ned_mps if est.started and self.drag_fusion_model().used else None

    def event(self, kind: str, detail: str, severity: int | None = None) -> None:
        self.log.row(self.now, kind, self.mode.name, self.armed, self.landed(), self.body.state,
                     wind=self.wind.ned, detail=detail, gust=self.wind.gust)  # fmt: skip
        if severity is not None:
            self.statustext(severity, detail)

    def statustext(self, severity: int, text: str) -> None:
        self.link.send(mavlink.MAVLink_statustext_message(severity, text[:50].encode()))

    def set_mode(self, mode: Mode, why: str) -> None:
        if mode is self.mode:
            return
        old = self.mode
        self.mode = mode
        self.heartbeat_due = True
        if mode is Mode.HOLD:
            self._hold_here()
        elif mode is Mode.TAKEOFF:
            s = self.est
            self.target = Target(pos=[s.n_m, s.e_m, -self.takeoff_alt_m], yaw_rad=s.yaw_rad())
        self.event("mode", f"{old.name}->{mode.name} ({why})")

    def _hold_here(self) -> None:
        s = self.est
        # stop where braking at a moderate deceleration ends, as PX4's hold does
        brake = 0.5 / 2.0
        self.hold_target = Target(
            pos=[s.n_m + s.vn_mps * brake, s.e_m + s.ve_mps * brake, min(s.d_m + s.vd_mps * brake, 0.0)],
            yaw_rad=s.yaw_rad(),
        )

    def arm(self, why: str) -> None:
        if not self.armed:
            self.armed = True
            self.arm_time = self.now
            self.has_flown = False
            self.ctrl.reset(self.body.state)
            self.heartbeat_due = True
            if self.mode is Mode.HOLD:
                self._hold_here()
            self.event("mode", f"armed ({why})")

    def disarm(self, why: str) -> None:
        if self.armed:
            self.armed = False
            self.heartbeat_due = True
            self.event("mode", f"disarmed ({why})")

    # -- physics step --------------------------------------------------------------------------------
    def step(self, dt_s: float, now: float) -> None:
        self.now = now
        s = self.body.state
        self.estimator.step(dt_s)
        self.est = self.estimator.estimate(s)
        self._supervise()
        if self.armed and not self.crashed:
            self.thrust_cmd = self._control(dt_s)
        else:
            self.thrust_cmd = [0.0, 0.0, 0.0, 0.0]
        wind = self.wind.step(dt_s, -s.d_m, (s.vn_mps, s.ve_mps, s.vd_mps))
        factors = self.dist.step(dt_s, s.vn_mps, s.ve_mps, s.vd_mps, s.qw, s.qx, s.qy, s.qz, *wind)
        if self.log.fh is not None and self.telemetry is not None and self.telemetry.truth_due(now):
            # the state at ``now``, with the wind and the air-relative velocity the disturbance sees in it
            self.log.row(now, "state", self.mode.name, self.armed, s.on_ground, s, self.dist, wind, self.active_sp,
                         gust=self.wind.gust, est_wind=self.wind_report())  # fmt: skip
        was_airborne = not s.on_ground
        tilt_deg = math.degrees(s.tilt_rad())
        contact = self.body.step(dt_s, self.thrust_cmd, factors, wind)
        self.wind_estimate.step(dt_s, self.drag_fusion_model(), not s.on_ground, s)
        if not s.on_ground:
            self.has_flown = True
        if was_airborne and contact > 0.0:
            self._touchdown(contact, tilt_deg)
        if s.on_ground and was_airborne:
            self.ground_since = now
        if self.crashed:
            self.body.state.thrust_n[:] = [0.0, 0.0, 0.0, 0.0]

    def _touchdown(self, speed_mps: float, tilt_deg: float) -> None:
        if speed_mps > self.cfg.crash_speed_mps or tilt_deg > self.cfg.crash_tilt_deg:
            self.crashed = True
            self.crash_reason = f"crash: touchdown at {speed_mps:.2f} m/s, tilt {tilt_deg:.0f} deg"
            self.armed = False
            self.heartbeat_due = True
            self.log.row(self.now, "crash", self.mode.name, False, True, self.body.state, self.dist, self.wind.ned,
                         detail=self.crash_reason, gust=self.wind.gust)  # fmt: skip
            self.statustext(mavlink.MAV_SEVERITY_CRITICAL, self.crash_reason)
        else:
            self.event("event", f"touchdown at {speed_mps:.2f} m/s")

    def _supervise(self) -> None:
        """Failsafes and automatic transitions: offboard loss, takeoff done, auto-disarm."""
        s = self.est
        if self.armed and self.mode is Mode.OFFBOARD and self.now - self.last_sp_time > self.p("COM_OF_LOSS_T"):
            self._offboard_lost()
        if self.mode is Mode.TAKEOFF and -s.d_m >= self.takeoff_alt_m - TAKEOFF_ACCEPT_M:
            self.set_mode(Mode.HOLD, "takeoff complete")
            self.hold_target = Target(pos=[s.n_m, s.e_m, -self.takeoff_alt_m], yaw_rad=s.yaw_rad())
        if self.mode is Mode.RTL and self.rtl_phase == "return" and math.hypot(s.n_m, s.e_m) < RTL_ACCEPT_M:
            self.set_mode(Mode.LAND, "RTL: home reached")
        if self.armed and self.body.state.on_ground:
            if not self.has_flown and self.now - self.arm_time > self.p("COM_DISARM_PRFLT") > 0:
                self.disarm("no takeoff within COM_DISARM_PRFLT")
            elif self.has_flown and self.now - self.ground_since > self.p("COM_DISARM_LAND") > 0:
                self.disarm("landed")
                if self.user_mode is not self.mode:
                    # PX4 goes back to the last mode asked for that it arms in (UserModeIntention::onDisarm):
                    # Offboard after a flight, which without a setpoint stream is not armable either
                    # (../shared/px4_sih: "reports the last mode (OFFBOARD) on the ground"); Hold after an abort
                    self.set_mode(self.user_mode, "landed: back to the mode last asked for")

    def _offboard_lost(self) -> None:
        action = int(self.p("COM_OBL_RC_ACT"))
        loss_s = self.p("COM_OF_LOSS_T")
        self.event(
            "failsafe",
            f"offboard lost: no setpoint for {loss_s:.2f} s (COM_OBL_RC_ACT={action})",
            mavlink.MAV_SEVERITY_CRITICAL,
        )
        if action == 3:
            self._start_rtl("offboard loss failsafe")
        elif action == 4:
            self.set_mode(Mode.LAND, "offboard loss failsafe")
        elif action in (6, 7):
            self.set_mode(Mode.HOLD, "offboard loss failsafe")
            self.disarm("offboard loss failsafe: " + ("terminate" if action == 6 else "disarm"))
        else:  # 0-2 need RC, which the fake has not: PX4 falls back to Hold; 5 is Hold
            self.set_mode(Mode.HOLD, "offboard loss failsafe")

    rtl_phase = ""

    def _land_speed_mps(self, height_m: float) -> float:
        """PX4's Land descends at MPC_Z_V_AUTO_DN above MPC_LAND_ALT1, at MPC_LAND_SPEED below MPC_LAND_ALT2,
        linearly between (its FlightTaskAuto; PX4 SITL's Land from 7.3 m ran at 1.0 m/s at 6 m, ../shared/px4_sih)."""
        slow, fast = self.p("MPC_LAND_SPEED"), self.p("MPC_Z_V_AUTO_DN")
        alt1, alt2 = self.p("MPC_LAND_ALT1"), self.p("MPC_LAND_ALT2")
        if height_m <= alt2 or alt1 <= alt2:
            return slow
        return slow + (min(height_m, alt1) - alt2) / (alt1 - alt2) * (fast - slow)

    def _start_rtl(self, why: str) -> None:
        self.rtl_phase = "return"
        s = self.est
        self.set_mode(Mode.RTL, why)
        self.target = Target(pos=[0.0, 0.0, min(s.d_m, -2.0)], yaw_rad=s.yaw_rad())

    def _control(self, dt_s: float) -> list[float]:
        s = self.est  # PX4 flies its estimate; attitude and rates are the truth's
        lim = self.limits()
        mode = self.mode
        idle = IDLE_THRUST_FRACTION * self.profile.max_thrust_per_rotor_n
        if mode is Mode.OFFBOARD and self.offboard_attitude is not None:
            (qw, qx, qy, qz), thrust = self.offboard_attitude
            bz = (2 * (qx * qz + qw * qy), 2 * (qy * qz - qw * qx), 1 - 2 * (qx * qx + qy * qy))
            yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
            self.active_sp = None
            if s.on_ground and thrust < lim.thr_hover:
                return [max(idle, thrust * self.profile.max_thrust_per_rotor_n)] * 4
            return self.ctrl.rotor_thrusts(dt_s, s, bz, thrust, yaw, lim)
        if mode is Mode.OFFBOARD and self.offboard_sp is not None:
            target = self.offboard_sp
            self.active_sp = (self.offboard_source, self.offboard_mask, target)
        elif mode is Mode.HOLD:
            if s.on_ground:
                self.ctrl.reset(s)
                return [idle] * 4
            target = self.hold_target
            self.active_sp = ("hold", 0, target)
        elif mode is Mode.TAKEOFF:
            target = self.target
            lim.vel_up_max_mps = min(lim.vel_up_max_mps, self.p("MPC_TKO_SPEED"))
            self.active_sp = ("takeoff", 0, target)
        elif mode is Mode.LAND:
            if s.on_ground:
                self.ctrl.reset(s)
                return [idle] * 4
            if not finite(self.hold_target.pos[0]):
                self._hold_here()
            target = Target(pos=[self.hold_target.pos[0], self.hold_target.pos[1], NAN],
                            vel=[NAN, NAN, self._land_speed_mps(-s.d_m)], yaw_rad=self.hold_target.yaw_rad)  # fmt: skip
            self.active_sp = ("land", 0, target)
        elif mode is Mode.RTL:
            target = self.target
            lim.vel_xy_max_mps = min(lim.vel_xy_max_mps, RTL_SPEED_MPS)
            self.active_sp = ("rtl", 0, target)
        else:
            target = self.hold_target
        bz, collective = self.ctrl.thrust_setpoint(dt_s, s, target, lim)
        yaw = target.yaw_rad
        if finite(target.yaw_rate_radps) and not finite(yaw):
            self.ctrl.yaw_hold_rad += target.yaw_rate_radps * dt_s
            yaw = self.ctrl.yaw_hold_rad
        elif finite(yaw):
            self.ctrl.yaw_hold_rad = yaw
        else:
            yaw = self.ctrl.yaw_hold_rad
        return self.ctrl.rotor_thrusts(dt_s, s, bz, collective, yaw, lim)

    # -- MAVLink input -------------------------------------------------------------------------------
    def handle(self, msg, addr) -> None:
        t = msg.get_type()
        if t == "HEARTBEAT":
            return
        handler = getattr(self, f"_on_{t.lower()}", None)
        if handler is not None:
            try:
                handler(msg, addr)
            except (ValueError, TypeError, OverflowError) as exc:  # a malformed message must not stop the vehicle
                self.event("event", f"ignored malformed {t} from {addr[0]}:{addr[1]}: {exc}")

    def _targets_me(self, msg) -> bool:
        ts = getattr(msg, "target_system", 0)
        tc = getattr(msg, "target_component", 0)
        return ts in (0, getattr(self.link, "sysid", 1)) and tc in (0, 1)

    def _ack(self, msg, command: int, result: int) -> None:
        self.link.send(
            mavlink.MAVLink_command_ack_message(command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())
        )

    def _on_command_long(self, msg, addr) -> None:
        if not self._targets_me(msg):
            return
        p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7)
        self._command(msg, addr, msg.command, p)

    def _on_command_int(self, msg, addr) -> None:
        if not self._targets_me(msg):
            return
        p = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x * 1e-7, msg.y * 1e-7, msg.z)
        self._command(msg, addr, msg.command, p)

    def _command(self, msg, addr, cmd: int, p) -> None:
        result, note = self._execute(cmd, p)
        self.log.row(self.now, "command", self.mode.name, self.armed, self.landed(), None,
                     detail=f"cmd={cmd} params={[round(x, 4) if x == x else 'nan' for x in p]} "
                            f"from={msg.get_srcSystem()}/{msg.get_srcComponent()}@{addr[0]}:{addr[1]} "
                            f"result={result} {note}".strip())  # fmt: skip
        self._ack(msg, cmd, result)
        if cmd == mavlink.MAV_CMD_REQUEST_MESSAGE and result == ACCEPTED and self.telemetry is not None:
            self.telemetry.send_now(int(p[0]))
        elif cmd in (mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,) and result == ACCEPTED:
            self.telemetry.send_now(mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        elif cmd == mavlink.MAV_CMD_GET_HOME_POSITION and result == ACCEPTED:
            self.telemetry.send_now(mavlink.MAVLINK_MSG_ID_HOME_POSITION)

    def _execute(self, cmd: int, p) -> tuple[int, str]:
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            return self._cmd_arm(p)
        if cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            return self._cmd_takeoff(p)
        if cmd == mavlink.MAV_CMD_NAV_LAND:
            # accepted disarmed too: PX4 SITL then sat in Land, where it does not arm (PREVENT_ARMING)
            self.set_mode(Mode.LAND, "NAV_LAND")
            return ACCEPTED, ""
        if cmd == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            if not self.armed:
                return TEMP_REJECTED, "not armed"
            if self.mode is not Mode.RTL:
                self._start_rtl("NAV_RETURN_TO_LAUNCH")
            return ACCEPTED, ""
        if cmd == mavlink.MAV_CMD_DO_SET_MODE:
            return self._cmd_set_mode(p)
        if cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            if not (finite(p[0]) and finite(p[1])):
                return DENIED, "message id and interval must be numbers"
            return self.telemetry.set_interval(int(p[0]), p[1])
        if cmd == mavlink.MAV_CMD_REQUEST_MESSAGE:
            ok = finite(p[0]) and self.telemetry.can_send(int(p[0]))
            return (ACCEPTED, "") if ok else (UNSUPPORTED, "unknown message")
        if cmd in (mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, mavlink.MAV_CMD_GET_HOME_POSITION):
            return ACCEPTED, ""
        return UNSUPPORTED, "not implemented by the fake"

    def _cmd_arm(self, p) -> tuple[int, str]:
        want = finite(p[0]) and p[0] >= 0.5
        force = finite(p[1]) and int(p[1]) == FORCE_ARM_MAGIC
        if want:
            if self.armed:
                return ACCEPTED, "already armed"
            if self.crashed:
                self.statustext(mavlink.MAV_SEVERITY_CRITICAL, "Arming denied: vehicle crashed")
                return DENIED, "crashed"
            if not self.position_valid() and not force:
                self.statustext(mavlink.MAV_SEVERITY_CRITICAL, "Arming denied: no valid position")
                return TEMP_REJECTED, "no position"
            if self.mode is Mode.OFFBOARD and self.now - self.last_sp_time > OFFBOARD_SIGNAL_FRESH_S:
                return TEMP_REJECTED, "offboard without setpoints"
            if self.mode in PREVENT_ARMING:
                self.statustext(mavlink.MAV_SEVERITY_CRITICAL, "Arming denied: Mode not suitable for arming")
                return DENIED, f"{self.mode.name} not armable"
            self.arm("ARM_DISARM")
            return ACCEPTED, ""
        if not self.armed:
            return ACCEPTED, "already disarmed"
        if not self.landed() and not force:
            self.statustext(mavlink.MAV_SEVERITY_CRITICAL, "Disarming denied: not landed")
            return TEMP_REJECTED, "in air"
        self.disarm("ARM_DISARM" + (" forced" if force else ""))
        return ACCEPTED, ""

    def _cmd_takeoff(self, p) -> tuple[int, str]:
        if not self.armed:
            self.statustext(mavlink.MAV_SEVERITY_CRITICAL, "Takeoff denied: disarmed")
            return TEMP_REJECTED, "not armed"
        if self.mode is Mode.TAKEOFF:
            return ACCEPTED, "already taking off"
        alt_amsl = p[6]
        if finite(alt_amsl):
            alt = alt_amsl - self.cfg.home_alt_m
        else:
            alt = self.p("MIS_TAKEOFF_ALT")
        s = self.est
        self.takeoff_alt_m = max(alt, -s.d_m, 0.5)
        self.set_mode(Mode.TAKEOFF, "NAV_TAKEOFF")
        return ACCEPTED, f"alt={self.takeoff_alt_m:.2f}"

    def _cmd_set_mode(self, p) -> tuple[int, str]:
        main = int(p[1]) if finite(p[1]) else -1
        sub = int(p[2]) if finite(p[2]) else 0
        mode = Mode.from_main_sub(main, sub)
        if main == px4.MAIN_AUTO and sub == px4.SUB_AUTO_TAKEOFF:
            return self._cmd_takeoff((NAN,) * 7)
        if mode is None:
            self.statustext(mavlink.MAV_SEVERITY_CRITICAL, "Mode switch denied: no RC / not supported")
            return TEMP_REJECTED, f"mode {main}/{sub} not available"
        if mode is self.mode:
            return ACCEPTED, "already in mode"
        if mode is Mode.OFFBOARD:
            if self.now - self.last_sp_time > OFFBOARD_SIGNAL_FRESH_S:
                self.statustext(mavlink.MAV_SEVERITY_CRITICAL, "Switching to Offboard denied: no setpoints")
                return TEMP_REJECTED, "no offboard setpoint stream"
            self.ctrl.yaw_hold_rad = self.body.state.yaw_rad()
        if mode is Mode.RTL:
            if not self.armed:
                return TEMP_REJECTED, "not armed"
            self._start_rtl("DO_SET_MODE")
            return ACCEPTED, ""
        if mode not in PREVENT_ARMING:  # PX4 keeps the last one it arms in, for after the disarm
            self.user_mode = mode
        self.set_mode(mode, "DO_SET_MODE")
        return ACCEPTED, ""

    def _on_set_position_target_local_ned(self, msg, addr) -> None:
        if not self._targets_me(msg):
            return
        mask = msg.type_mask
        frame = msg.coordinate_frame
        s = self.est
        pos = [msg.x, msg.y, msg.z] if not mask & POSITION_IGNORE else [NAN, NAN, NAN]
        vel = [msg.vx, msg.vy, msg.vz] if not mask & VELOCITY_IGNORE else [NAN, NAN, NAN]
        acc = [msg.afx, msg.afy, msg.afz] if not (mask & ACCEL_IGNORE or mask & FORCE_SET) else [NAN, NAN, NAN]
        for i in range(3):  # per-axis ignore bits
            if mask & (1 << i):
                pos[i] = NAN
            if mask & (1 << (3 + i)):
                vel[i] = NAN
            if mask & (1 << (6 + i)):
                acc[i] = NAN
        if frame in (mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED):
            yaw = s.yaw_rad()
            c, sn = math.cos(yaw), math.sin(yaw)
            for v in (pos, vel, acc):
                v[0], v[1] = c * v[0] - sn * v[1], sn * v[0] + c * v[1]
        if frame in (mavlink.MAV_FRAME_LOCAL_OFFSET_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED, mavlink.MAV_FRAME_BODY_NED):
            pos = [pos[0] + s.n_m, pos[1] + s.e_m, pos[2] + s.d_m]
        elif frame != mavlink.MAV_FRAME_LOCAL_NED:
            self.log.row(self.now, "setpoint", self.mode.name, self.armed, self.landed(), None,
                         detail=f"ignored: frame {frame} not supported")  # fmt: skip
            return
        target = Target(
            pos=pos,
            vel=vel,
            acc=acc,
            yaw_rad=msg.yaw if not mask & YAW_IGNORE else NAN,
            yaw_rate_radps=msg.yaw_rate if not mask & YAW_RATE_IGNORE else NAN,
        )
        source = f"{msg.get_srcSystem()}/{msg.get_srcComponent()}@{addr[1]}"
        self.offboard_sp = target
        self.offboard_mask = mask
        self.offboard_source = source
        self.offboard_attitude = None
        self.last_sp_time = self.now_wall()
        self.log.row(self.last_sp_time, "setpoint", self.mode.name, self.armed, self.landed(), None,
                     sp=(source, mask, target), detail=f"frame={frame}")  # fmt: skip

    def _on_set_attitude_target(self, msg, addr) -> None:
        if not self._targets_me(msg):
            return
        if msg.type_mask & 0x80:  # attitude ignored: body-rate setpoints are not flown by the fake
            self.log.row(self.now, "setpoint", self.mode.name, self.armed, self.landed(), None,
                         detail="ignored: SET_ATTITUDE_TARGET without attitude")  # fmt: skip
            return
        q = tuple(msg.q)
        self.offboard_attitude = (q, min(max(msg.thrust, 0.0), 1.0))
        self.offboard_sp = None
        self.last_sp_time = self.now_wall()
        self.log.row(self.last_sp_time, "setpoint", self.mode.name, self.armed, self.landed(), None,
                     detail=f"attitude q={[round(x, 4) for x in q]} thrust={msg.thrust:.3f}")  # fmt: skip

    def now_wall(self) -> float:
        """Arrival time of a message: the monotonic clock now, not the last physics step."""
        return time.monotonic()

    def _on_param_request_read(self, msg, addr) -> None:
        if not self._targets_me(msg):
            return
        name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
        if msg.param_index >= 0:
            if msg.param_index < len(self.param_names):
                self._send_param(self.param_names[msg.param_index])
            return
        if name in self.params:
            self._send_param(name)

    def _on_param_request_list(self, msg, addr) -> None:
        if not self._targets_me(msg):
            return
        for name in self.param_names:
            self._send_param(name)

    def _on_param_set(self, msg, addr) -> None:
        if not self._targets_me(msg):
            return
        name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
        if name not in self.params:
            self.log.row(self.now, "param", self.mode.name, self.armed, self.landed(), None, detail=f"unknown {name}")
            return
        param = self.params[name]
        value = px4.decode_param_value(msg.param_value, msg.param_type)
        if param.type == px4.PARAM_INT32:
            value = int(value)
        elif not math.isfinite(value):
            self._send_param(name)
            return
        param.value = value
        self.log.row(self.now, "param", self.mode.name, self.armed, self.landed(), None, detail=f"{name}={value}")
        self._send_param(name)

    def _send_param(self, name: str) -> None:
        param = self.params[name]
        self.link.send(
            mavlink.MAVLink_param_value_message(
                name.encode(),
                px4.encode_param_value(param),
                param.type,
                len(self.param_names),
                self.param_names.index(name),
            )
        )

    def _on_timesync(self, msg, addr) -> None:
        if msg.tc1 == 0:
            self.link.send(mavlink.MAVLink_timesync_message(int((time.monotonic() - self.t0) * 1e9), msg.ts1))
