"""The fake's ArduCopter personality (``--autopilot ardupilot``): ArduCopter's modes, commands, GUIDED shaping,
parameters, EKF start-up, RC and GCS failsafe around the shared physics, estimate, wind and VRS truth.

As real ArduCopter (master 2026, ``../shared/ardupilot_sitl``) behaves towards MAVSDK 4 and pymavlink:

- boots in STABILIZE (the SITL transmitter's mode switch sits on FLTMODE6); modes change with
  DO_SET_MODE / SET_MODE (base_mode with CUSTOM_MODE_ENABLED, custom_mode = ArduCopter's number), NAV_LAND
  (LAND), NAV_RETURN_TO_LAUNCH (RTL), a failsafe, or the RC mode switch (RC_CHANNELS_OVERRIDE from the
  ground station's sysid on FLTMODE_CH, through FLTMODE1..6);
- GUIDED flies SET_POSITION_TARGET_LOCAL_NED through ``AC_PosControl``'s input shaping
  (``sitl_fakes.ardupilot_control``); setpoints missing for GUID_TIMEOUT zero the velocity and acceleration
  targets and it stays in GUIDED; NAV_TAKEOFF in GUIDED spools up, slews the throttle, climbs to the
  altitude and stays in GUIDED;
- BRAKE stops at 7.5 m/s² and holds, ignoring the sticks; LAND descends at LAND_SPD_MS below
  LAND_ALT_LOW_M (LAND_SPD_HIGH_MS, or WP_SPD_DN, above it) and disarms after touchdown;
- until its EKF has an origin (``ekf_delay_s``) arming fails with "PreArm: AHRS: waiting for home";
- the GCS failsafe (FS_GCS_ENABLE) watches only MAV_GCS_SYSID: heartbeats (and RC overrides) from other
  sysids are remembered (``gcs_seen``) but keep nothing alive.
"""

from __future__ import annotations

import math
import time

from flighttest.model.aero import G_MPS2
from sitl_fakes import ardupilot as ap
from sitl_fakes.ardupilot import CopterMode
from sitl_fakes.ardupilot_control import THR_MIN, PosControl, VerticalAccelPid, copter_limits, sqrt_controller
from sitl_fakes.control import NAN, Limits, Target, finite, lowpass_alpha
from sitl_fakes.drag_fusion import DragFusionModel
from sitl_fakes.link import Link, mavlink
from sitl_fakes.physics import rotate_body_to_ned
from sitl_fakes.truthlog import TruthLog
from sitl_fakes.vehicle import ACCEPTED, DENIED, FAILED, FORCE_ARM_MAGIC, IDLE_THRUST_FRACTION, UNSUPPORTED, FakeConfig
from sitl_fakes.vehicle import FakePx4 as _FakeVehicleBase

M = mavlink
POS_IGNORE = 0b111
VEL_IGNORE = 0b111 << 3
ACC_IGNORE = 0b111 << 6
FORCE_SET = 1 << 9
YAW_IGNORE = 1 << 10
YAW_RATE_IGNORE = 1 << 11
FRAMES = (M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_LOCAL_OFFSET_NED, M.MAV_FRAME_BODY_NED, M.MAV_FRAME_BODY_OFFSET_NED)
# the SITL transmitter of the reference flights (DataFlash RCIN): sticks centred, throttle low, mode switch
# on FLTMODE6 (1800 µs), channel 8 high
SITL_RC_PWM = (1500, 1500, 1000, 1500, 1800, 1000, 1000, 1800) + (0,) * 10
# D_update_controller hands its throttle to the motors through a 2 Hz low-pass (POSCONTROL_THROTTLE_CUTOFF_FREQ_HZ):
# the reference's vertical acceleration follows its target 0.1-0.2 s late (PSCD.TAD vs AD), and the descent
# runs on past the shaped velocity (VD 0.99 against DVD 0.92 in vertical-guard-abort)
THROTTLE_CUTOFF_HZ = 2.0
SWITCH_DEBOUNCE_S = 0.2  # RC_Channel mode switch debounce (SWITCH_DEBOUNCE_TIME_MS)
TAKEOFF_DONE_VEL_FRACTION = 0.1  # _AutoTakeoff: complete within 10 % of WP_SPD_UP and its stopping distance
LOITER_BRAKE_DECEL_MPS2 = 2.5  # LOIT_BRK_ACC_M (used directly: the fake's pilot never moves the sticks sideways)
RTL_ALT_REACHED_M = 0.2
RTL_HOME_REACHED_M = 0.5
# what a failsafe does for FS_GCS_ENABLE (ArduCopter/events.cpp: SmartRTL and DO_LAND_START fall back to RTL)
GCS_FS_ACTIONS = {1: CopterMode.RTL, 2: CopterMode.RTL, 3: CopterMode.RTL, 4: CopterMode.LAND, 5: CopterMode.LAND,
                  6: CopterMode.RTL, 7: CopterMode.BRAKE}  # fmt: skip
FS_OPTION_CONTINUE_LANDING = 1 << 3
FS_OPTION_CONTINUE_PILOT_GCS = 1 << 4
MAV_OPTION_GCS_SYSID_ENFORCE = 1 << 0
# modes ArduCopter will not arm in (Mode::allows_arming false): "Arm: Mode not armable"
NOT_ARMABLE = frozenset({CopterMode.LAND, CopterMode.RTL, CopterMode.BRAKE, CopterMode.AUTO, CopterMode.CIRCLE,
                         CopterMode.SMART_RTL})  # fmt: skip
# NAV_TAKEOFF is flown in GUIDED (what MAVSDK switches to first); ArduCopter's pilot-assisted takeoff in
# LOITER / ALT_HOLD / POSHOLD is not in the fake: there the command fails
USER_TAKEOFF_MODES = frozenset({CopterMode.GUIDED})


class FakeArduCopter(_FakeVehicleBase):
    """The vehicle with ArduCopter's rules; shares the body, estimate, wind, disturbance and truth log."""

    autopilot = "ardupilot"

    def __init__(self, cfg: FakeConfig, link: Link, log: TruthLog, t0: float, ekf_delay_s: float = ap.EKF_DELAY_S):
        super().__init__(cfg, link, log, t0)
        self.params = ap.default_params()
        prof = cfg.profile
        # ArduCopter learns its hover throttle in flight (MOT_HOVER_LEARN 2): start at the vehicle's truth
        self.params["MOT_THST_HOVER"].value = prof.mass_kg * G_MPS2 / (prof.n_rotors * prof.max_thrust_per_rotor_n)
        self.params["MAV_SYSID"].value = getattr(link, "sysid", 1)
        self.param_names = list(self.params)  # ArduPilot's own order, not sorted
        self.ekf_delay_s = ekf_delay_s
        self.ekf_ready = False
        self.mode = CopterMode.STABILIZE
        self.mode_reason = "RC_COMMAND"
        self.pc = PosControl(self.p)
        self.land_complete = True
        self.land_maybe_since: float | None = None
        self.touchdown_time: float | None = None
        self.ever_flown_since_arm = False
        self.takeoff_pending = False  # NAV_TAKEOFF accepted, still on the ground (spool-up, throttle slew)
        self.throttle = 0.0  # the takeoff throttle slew, 0..1 of full thrust
        self.takeoff_alt_d_m = 0.0
        self.takeoff_complete = False
        self.guided_sub = "velaccel"
        self.guided_pos = [0.0, 0.0, 0.0]
        self.guided_vel = [0.0, 0.0, 0.0]
        self.guided_acc = [0.0, 0.0, 0.0]
        self.guided_yaw_rad = NAN
        self.guided_yaw_rate_radps = NAN
        self.guided_update_time = -math.inf
        self.guided_timed_out = False
        self.land_pause_until = -math.inf
        self.rtl_phase = "climb"
        self.rtl_alt_d_m = 0.0
        self.rtl_loiter_until = math.inf
        self.rc_override = [0] * 18  # 0: no override on that channel
        self.rc_override_time = [-math.inf] * 18
        self.switch_slot: int | None = ap.mode_switch_slot(SITL_RC_PWM[4])
        self.switch_pending: tuple[int, float] | None = None
        self.gcs_seen: dict[int, float] = {}  # sysid → last heartbeat (monotonic s), every ground station heard
        self.gcs_last_seen: float | None = None  # MAV_GCS_SYSID's last heartbeat / RC override / MANUAL_CONTROL
        self.failsafe_gcs = False
        self.collective_filtered = 0.0  # the motors' throttle filter (THROTTLE_CUTOFF_HZ)
        self.accel_pid = VerticalAccelPid(self.p)

    # -- helpers -------------------------------------------------------------------------------------
    def position_valid(self) -> bool:
        return self.t_s >= max(self.cfg.gps_delay_s, self.ekf_delay_s)

    def drag_fusion_model(self) -> DragFusionModel:
        """EKF3's drag model: on as soon as a ballistic or the momentum coefficient is set."""
        return DragFusionModel(self.p("EK3_DRAG_MCOEF"), self.p("EK3_DRAG_BCOEF_X"), self.p("EK3_DRAG_BCOEF_Y"))

    def wind_report(self) -> tuple[float, float, float] | None:
        """EKF3's wind states (ArduCopter's WIND): zero until drag fusion has run in the air (its wind states are
        inhibited), then its estimate, kept on the ground; None before the EKF has its origin."""
        if not self.ekf_ready:
            return None
        return self.wind_estimate.wind_ned_mps if self.wind_estimate.started else (0.0, 0.0, 0.0)

    def armable(self) -> bool:
        return self.position_valid() and not self.crashed

    def landed(self) -> bool:
        return self.land_complete

    def limits(self) -> Limits:
        return copter_limits(self.p, self.profile)

    def is_gcs(self, sysid: int) -> bool:
        lo = int(self.p("MAV_GCS_SYSID"))
        hi = int(self.p("MAV_GCS_SYSID_HI"))
        return lo <= sysid <= hi if hi > lo else sysid == lo

    def rc_pwm(self, channel: int) -> int:
        """Channel 1..18 as ArduCopter reads it: the GCS's override while fresh, else the SITL transmitter."""
        i = channel - 1
        if not 0 <= i < len(SITL_RC_PWM):
            return 0
        fresh = self.now - self.rc_override_time[i] <= self.p("RC_OVERRIDE_TIME")
        if fresh and self.rc_override[i] > 0:
            return self.rc_override[i]
        return SITL_RC_PWM[i]

    def throttle_stick(self) -> float:
        """Throttle stick 0..1 (RCMAP_THROTTLE; 1000..2000 µs); 0 without a signal."""
        pwm = self.rc_pwm(int(self.p("RCMAP_THROTTLE")))
        return min(max((pwm - 1000) / 1000.0, 0.0), 1.0) if pwm >= 900 else 0.0

    def pilot_climb_rate_mps(self) -> float:
        """Mode::get_pilot_desired_climb_rate: a dead zone THR_DZ around mid stick, PILOT_SPD_UP/DN beyond."""
        stick = self.throttle_stick() * 1000.0
        dz = self.p("THR_DZ")
        mid = 500.0
        up = self.p("PILOT_SPD_UP")
        dn = self.p("PILOT_SPD_DN") or up
        if stick < mid - dz:
            return -dn * (mid - dz - stick) / (mid - dz)
        if stick > mid + dz:
            return up * (stick - mid - dz) / (1000.0 - mid - dz)
        return 0.0

    def pilot_throttle(self) -> float:
        """Mode::get_pilot_desired_throttle: mid stick is MOT_THST_HOVER, with ArduCopter's expo curve."""
        thr_mid = min(max(self.p("MOT_THST_HOVER"), 0.1), 0.9)
        x = self.throttle_stick()
        expo = min(max(-(thr_mid - 0.5) / 0.375, -0.5), 1.0)
        return x * (1.0 - expo) + expo * x**3

    # -- modes ---------------------------------------------------------------------------------------
    def set_mode(self, mode, why: str, reason: str = "GCS_COMMAND") -> None:  # type: ignore[override]
        """Enter ``mode`` unconditionally (checks are ``try_set_mode``'s); re-entering keeps the state."""
        if mode is self.mode:
            self.mode_reason = reason
            return
        old = self.mode
        self.mode = mode
        self.mode_reason = reason
        self.heartbeat_due = True
        self._mode_init(mode)
        self.event("mode", f"{old.name}->{mode.name} ({why})")

    def try_set_mode(self, mode: int, why: str, reason: str = "GCS_COMMAND") -> tuple[bool, str]:
        """Copter::set_mode: the mode must exist and be flown by the fake, and have a position if it needs one."""
        try:
            target = CopterMode(mode)
        except ValueError:
            return False, f"no mode {mode}"
        if target is self.mode:
            self.mode_reason = reason
            return True, "already in mode"
        if target not in ap.FLOWN_MODES:
            self.statustext(M.MAV_SEVERITY_WARNING, f"Mode change to {target.name} failed: not in the fake")
            return False, f"{target.name} not flown by the fake"
        if target in ap.NEEDS_POSITION and not self.position_valid():
            self.statustext(M.MAV_SEVERITY_WARNING, f"Mode change to {target.name} failed: requires position")
            return False, "requires position"
        self.set_mode(target, why, reason)
        return True, ""

    def _mode_init(self, mode: CopterMode) -> None:
        s = self.est
        pos, vel = (s.n_m, s.e_m, s.d_m), (s.vn_mps, s.ve_mps, s.vd_mps)
        accel_d = self.body.state.ad_mps2 if not self.body.state.on_ground else 0.0
        if mode is CopterMode.GUIDED:
            # ModeGuided::init: velocity-acceleration control of zero (stop where the shaping ends)
            self.guided_sub = "velaccel"
            self.guided_vel = [0.0, 0.0, 0.0]
            self.guided_acc = [0.0, 0.0, 0.0]
            self.guided_yaw_rad = NAN
            self.guided_yaw_rate_radps = NAN
            self.guided_update_time = self.now
            self._pva_start()
        elif mode is CopterMode.BRAKE:
            speed = math.hypot(vel[0], vel[1])
            self.pc.set_ne_limits(speed, ap.BRAKE_DECEL_MPS2)
            self._init_ne(pos, vel)
            self.pc.set_d_limits(ap.BRAKE_SPEED_Z_MPS, ap.BRAKE_SPEED_Z_MPS, ap.BRAKE_DECEL_MPS2)
            self.pc.init_d(pos[2], vel[2], accel_d)
        elif mode is CopterMode.LAND:
            self.pc.set_ne_limits(self.p("WP_SPD"), self.p("WP_ACC"))
            self._init_ne(pos, vel)
            self.pc.set_d_limits(self.p("WP_SPD_DN"), self.p("WP_SPD_UP"), self.p("WP_ACC_Z"))
            self.pc.init_d(pos[2], vel[2], accel_d)
            self.land_pause_until = -math.inf
        elif mode is CopterMode.RTL:
            self.pc.set_ne_limits(self.p("RTL_SPEED_MS") or self.p("WP_SPD"), self.p("WP_ACC"))
            self._init_ne(pos, vel)
            self.pc.set_d_limits(self.p("WP_SPD_DN"), self.p("WP_SPD_UP"), self.p("WP_ACC_Z"))
            self.pc.init_d(pos[2], vel[2], accel_d)
            self.rtl_phase = "climb"
            self.rtl_alt_d_m = min(s.d_m, -max(self.p("RTL_ALT_M"), -s.d_m + self.p("RTL_CLIMB_MIN_M")))
            self.rtl_loiter_until = math.inf
        elif mode in (CopterMode.LOITER, CopterMode.POSHOLD, CopterMode.ALT_HOLD):
            self.pc.set_ne_limits(self.p("LOIT_SPEED_MS"), LOITER_BRAKE_DECEL_MPS2)
            self._init_ne(pos, vel)
            self.pc.set_d_limits(self.p("PILOT_SPD_DN") or self.p("PILOT_SPD_UP"), self.p("PILOT_SPD_UP"),
                                 self.p("PILOT_ACC_Z"))  # fmt: skip
            self.pc.init_d(pos[2], vel[2], accel_d)

    def _init_ne(self, pos_ned, vel_ned) -> None:
        """NE_init_controller: desired state := estimate, and the velocity loop's integrator takes over the
        acceleration the present tilt gives (so the attitude does not jump). That integrator then decays
        only at PSC_NE_VEL_I: the reference helix kept accelerating at ~3 m/s² for 0.3 s after its
        recover command re-initialised the controller (PSCN.TAN 2.1 m/s² with DAN -0.3)."""
        self.pc.init_ne(pos_ned, vel_ned)
        s = self.body.state
        zx, zy, zz = rotate_body_to_ned(0.0, 0.0, 1.0, s.qw, s.qx, s.qy, s.qz)
        if zz > 0.1 and not s.on_ground:
            lim = math.tan(self.limits().tilt_max_rad) * G_MPS2
            an, ae = -G_MPS2 * zx / zz, -G_MPS2 * zy / zz
            norm = math.hypot(an, ae)
            if norm > lim:
                an, ae = an / norm * lim, ae / norm * lim
            self.ctrl.vel_int[0], self.ctrl.vel_int[1] = an, ae

    def _pva_start(self) -> None:
        """ModeGuided::pva_control_start: WP limits, and the desired state reset to the estimate."""
        s = self.est
        self.pc.set_ne_limits(self.p("WP_SPD"), self.p("WP_ACC"))
        self.pc.set_d_limits(self.p("WP_SPD_DN"), self.p("WP_SPD_UP"), self.p("WP_ACC_Z"))
        self._init_ne((s.n_m, s.e_m, s.d_m), (s.vn_mps, s.ve_mps, s.vd_mps))
        accel_d = self.body.state.ad_mps2 if not self.body.state.on_ground else 0.0
        self.pc.init_d(s.d_m, s.vd_mps, accel_d)

    def arm(self, why: str) -> None:
        if not self.armed:
            super().arm(why)
            self.statustext(M.MAV_SEVERITY_INFO, "Arming motors")
            self.land_complete = True
            self.ever_flown_since_arm = False
            self.takeoff_pending = False
            self.takeoff_complete = False
            self.throttle = 0.0

    def disarm(self, why: str) -> None:
        if self.armed:
            super().disarm(why)
            self.statustext(M.MAV_SEVERITY_INFO, "Disarming motors")
            self.takeoff_pending = False

    # -- supervision ---------------------------------------------------------------------------------
    def _supervise(self) -> None:
        now = self.now
        if not self.ekf_ready and self.position_valid():
            self.ekf_ready = True
            for text in ap.EKF_READY_TEXTS:
                self.statustext(M.MAV_SEVERITY_INFO, text)
            self.event("event", "EKF3 using GPS: origin and home set, prearm ok")
            if self.telemetry is not None:
                self.telemetry.send_now(M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
                self.telemetry.send_now(M.MAVLINK_MSG_ID_HOME_POSITION)
        self._read_mode_switch()
        self._gcs_failsafe_check()
        body = self.body.state
        # land detector: airborne once the body leaves the ground; land complete after LAND_COMPLETE_S on it
        if not body.on_ground:
            if self.land_complete:
                self.land_complete = False
                self.event("event", "land detector: airborne")
            self.land_maybe_since = None
        elif not self.land_complete and self.armed:
            if self.land_maybe_since is None:
                self.land_maybe_since = now
            elif now - self.land_maybe_since >= ap.LAND_COMPLETE_S:
                self.land_complete = True
                self.event("event", "land detector: landed")
        elif not self.armed:
            self.land_complete = True
        if self.mode is CopterMode.GUIDED and self.guided_sub == "takeoff" and not self.takeoff_complete \
                and not self.land_complete:  # fmt: skip
            vmax = self.pc.vel_max_up_mps
            stop_m = 0.5 * (TAKEOFF_DONE_VEL_FRACTION * vmax) ** 2 / max(self.pc.accel_max_d_mps2, 1e-3)
            if self.pc.pos_ned[2] <= self.takeoff_alt_d_m + stop_m and -self.pc.vel_ned[2] < vmax * 0.1:
                self.takeoff_complete = True
                self.event("event", f"takeoff complete at {-self.est.d_m:.2f} m (stays in GUIDED)")
        if not self.armed:
            return
        # LAND (and RTL's final descent) disarms once the land detector and the spool-down are through
        landing = self.mode is CopterMode.LAND or (self.mode is CopterMode.RTL and self.rtl_phase == "land")
        if landing and body.on_ground:
            touched = self.touchdown_time if self.ever_flown_since_arm else None
            if touched is None and self.land_complete and now - self.arm_time > ap.ARMING_DELAY_S:
                self.disarm("LAND on the ground")  # ModeLand::gps_run: landed and at ground idle
                return
            if touched is not None and now - touched >= ap.LAND_DISARM_AFTER_TOUCHDOWN_S:
                self.disarm("landed (LAND)")
                return
        # auto-disarm: on the ground, not taking off, for DISARM_DELAY s (Copter::auto_disarm_check)
        delay = self.p("DISARM_DELAY")
        idle = self.land_complete and not self.takeoff_pending and (
            self.mode not in (CopterMode.STABILIZE, CopterMode.ACRO) or self.throttle_stick() <= 0.0)
        if delay > 0 and idle:
            since = max(self.arm_time, self.ground_since if self.ever_flown_since_arm else self.arm_time)
            if now - since > delay:
                self.disarm(f"auto-disarm: on the ground for DISARM_DELAY {delay:g} s")

    def _touchdown(self, speed_mps: float, tilt_deg: float) -> None:
        super()._touchdown(speed_mps, tilt_deg)
        self.touchdown_time = self.now

    def step(self, dt_s: float, now: float) -> None:
        was_on_ground = self.body.state.on_ground
        super().step(dt_s, now)
        if was_on_ground and not self.body.state.on_ground:
            self.ever_flown_since_arm = True
            self.touchdown_time = None

    def _read_mode_switch(self) -> None:
        """RC_Channels::read_mode_switch: a new FLTMODE_CH position, held SWITCH_DEBOUNCE_S, selects FLTMODEn."""
        slot = ap.mode_switch_slot(self.rc_pwm(int(self.p("FLTMODE_CH"))))
        if slot is None or slot == self.switch_slot:
            self.switch_pending = None
            return
        if self.switch_pending is None or self.switch_pending[0] != slot:
            self.switch_pending = (slot, self.now)
            return
        if self.now - self.switch_pending[1] < SWITCH_DEBOUNCE_S:
            return
        self.switch_slot = slot
        self.switch_pending = None
        mode = int(self.p(f"FLTMODE{slot}"))
        ok, note = self.try_set_mode(mode, f"RC mode switch FLTMODE{slot}", "RC_COMMAND")
        self.event("event", f"RC mode switch to FLTMODE{slot} ({mode}): {'ok' if ok else note}")

    def _gcs_failsafe_check(self) -> None:
        """Copter::failsafe_gcs_check: only MAV_GCS_SYSID keeps the link alive, and only once it was seen."""
        enable = int(self.p("FS_GCS_ENABLE"))
        if enable == 0 or self.gcs_last_seen is None:
            return
        silent_s = time.monotonic() - self.gcs_last_seen
        timeout_s = self.p("FS_GCS_TIMEOUT")
        if self.failsafe_gcs and silent_s < timeout_s:
            self.failsafe_gcs = False
            self.heartbeat_due = True
            self.event("failsafe", "GCS failsafe cleared", M.MAV_SEVERITY_WARNING)
            return
        if self.failsafe_gcs or silent_s <= timeout_s:
            return
        self.failsafe_gcs = True
        self.heartbeat_due = True
        sysid = int(self.p("MAV_GCS_SYSID"))
        self.event("failsafe", f"GCS Failsafe: no heartbeat from sysid {sysid} for {silent_s:.1f} s "
                               f"(FS_GCS_ENABLE={enable})", M.MAV_SEVERITY_WARNING)  # fmt: skip
        if not self.armed:
            return
        if self.land_complete:
            self.disarm("GCS failsafe on the ground")
            return
        options = int(self.p("FS_OPTIONS"))
        landing = self.mode is CopterMode.LAND or (self.mode is CopterMode.RTL and self.rtl_phase == "land")
        if landing and options & FS_OPTION_CONTINUE_LANDING:
            return
        if self.mode in ap.PILOT_MODES and options & FS_OPTION_CONTINUE_PILOT_GCS:
            self.event("failsafe", "GCS failsafe: pilot in control, continuing (FS_OPTIONS bit 4)")
            return
        action = GCS_FS_ACTIONS.get(enable, CopterMode.LAND)
        ok, _ = self.try_set_mode(action, "GCS failsafe", "GCS_FAILSAFE")
        if not ok and action is not CopterMode.LAND:
            self.try_set_mode(CopterMode.LAND, "GCS failsafe (fallback)", "GCS_FAILSAFE")
        if self.mode is CopterMode.LAND:
            self.land_pause_until = self.now + ap.LAND_FAILSAFE_PAUSE_S

    # -- control -------------------------------------------------------------------------------------
    def _fly(self, dt_s: float, target: Target, lim: Limits) -> list[float]:
        s = self.est
        bz, _ = self.ctrl.thrust_setpoint(dt_s, s, target, lim)
        # the cascade gives the tilt; the collective is ArduCopter's acceleration PID, boosted for the tilt
        # flown (AC_AttitudeControl_Multi::get_throttle_boosted)
        cos_tilt = 1.0 - 2.0 * (s.qx * s.qx + s.qy * s.qy)
        limited = not THR_MIN < self.collective_filtered < 1.0
        thr = self.accel_pid.throttle(-self.ctrl.acc_setpoint_ned[2], -self.body.state.ad_mps2, lim.thr_hover,
                                      limited, dt_s)  # fmt: skip
        collective = min(max(thr / min(max(cos_tilt, 0.1), 1.0), THR_MIN), 1.0)
        self.collective_filtered += lowpass_alpha(THROTTLE_CUTOFF_HZ, dt_s) * (collective - self.collective_filtered)
        collective = self.collective_filtered
        yaw = target.yaw_rad
        if finite(target.yaw_rate_radps) and not finite(yaw):
            self.ctrl.yaw_hold_rad += target.yaw_rate_radps * dt_s
            yaw = self.ctrl.yaw_hold_rad
        elif finite(yaw):
            self.ctrl.yaw_hold_rad = yaw
        else:
            yaw = self.ctrl.yaw_hold_rad
        return self.ctrl.rotor_thrusts(dt_s, s, bz, collective, yaw, lim)

    def _level(self, dt_s: float, collective: float, lim: Limits) -> list[float]:
        """Level attitude at a collective (0..1): the takeoff throttle slew and STABILIZE (unfiltered)."""
        self.collective_filtered = collective
        return self.ctrl.rotor_thrusts(dt_s, self.est, (0.0, 0.0, 1.0), collective, self.ctrl.yaw_hold_rad, lim)

    def _idle(self) -> list[float]:
        self.ctrl.reset(self.est)
        self.collective_filtered = 0.0
        self.accel_pid.reset()
        return [IDLE_THRUST_FRACTION * self.profile.max_thrust_per_rotor_n] * 4

    def _control(self, dt_s: float) -> list[float]:
        lim = self.limits()
        mode = self.mode
        pc = self.pc
        if mode is CopterMode.GUIDED:
            return self._guided(dt_s, lim)
        if mode is CopterMode.STABILIZE:
            throttle = self.pilot_throttle()
            if self.land_complete and throttle <= 0.0:
                return self._idle()
            self.active_sp = ("pilot", 0, Target())
            return self._level(dt_s, throttle, lim)
        if self.land_complete and mode is not CopterMode.LAND:
            if mode in (CopterMode.LOITER, CopterMode.POSHOLD, CopterMode.ALT_HOLD) and self.pilot_climb_rate_mps() > 0:
                return self._user_takeoff(dt_s, lim)
            return self._idle()
        if mode is CopterMode.BRAKE:
            pc.input_vel_accel_ne((0.0, 0.0), (0.0, 0.0), dt_s)
            pc.input_vel_accel_d(0.0, 0.0, dt_s)
            target = pc.target()
            self.active_sp = ("brake", 0, target)
            return self._fly(dt_s, target, lim)
        if mode is CopterMode.LAND:
            return self._land(dt_s, lim, "land")
        if mode is CopterMode.RTL:
            return self._rtl(dt_s, lim)
        # LOITER / POSHOLD / ALT_HOLD with the sticks centred sideways: the throttle stick is the climb rate
        pc.input_vel_accel_d(-self.pilot_climb_rate_mps(), 0.0, dt_s)
        if mode is CopterMode.ALT_HOLD:
            target = pc.target(ne=False)
        else:
            pc.input_vel_accel_ne((0.0, 0.0), (0.0, 0.0), dt_s)
            target = pc.target()
        self.active_sp = (mode.name.lower(), 0, target)
        return self._fly(dt_s, target, lim)

    def _user_takeoff(self, dt_s: float, lim: Limits) -> list[float]:
        """A pilot's takeoff (throttle above the dead zone in LOITER/ALT_HOLD/POSHOLD): the throttle slews up."""
        if self.now < self.arm_time + ap.ARMING_DELAY_S + self.p("MOT_SPOOL_TIME"):
            return self._idle()
        self.throttle = min(self.throttle + dt_s / max(self.p("TKOFF_SLEW_TIME"), 0.1), 1.0)
        self._liftoff_check()
        return self._level(dt_s, self.throttle, lim)

    def _liftoff_check(self) -> None:
        """_AutoTakeoff::run on the ground: throttle ≥ 90 %, or climbing/accelerating up as it detects it."""
        s = self.est
        accel_up = -self.body.state.ad_mps2
        if (self.throttle >= min(self.p("TKOFF_THR_MAX"), 0.9) or accel_up >= 0.5 * self.pc.accel_max_d_mps2
                or -s.vd_mps >= 0.1 * self.pc.vel_max_up_mps):  # fmt: skip
            self.land_complete = False
            self.event("event", f"liftoff detected (throttle {self.throttle:.2f})")
            self._init_ne((s.n_m, s.e_m, s.d_m), (s.vn_mps, s.ve_mps, s.vd_mps))
            self.pc.init_d(s.d_m, s.vd_mps, 0.0)
            self.ctrl.reset(s)
            self.accel_pid.reset(self.throttle - self.limits().thr_hover)

    def _guided(self, dt_s: float, lim: Limits) -> list[float]:
        pc = self.pc
        if self.guided_sub == "takeoff":
            if self.land_complete:
                if not self.takeoff_pending:
                    return self._idle()
                # motors spool up after the arming delay, then the throttle slews until the climb is seen
                if self.now < self.arm_time + ap.ARMING_DELAY_S + self.p("MOT_SPOOL_TIME"):
                    return self._idle()
                self.throttle = min(self.throttle + dt_s / max(self.p("TKOFF_SLEW_TIME"), 0.1), 1.0)
                self._liftoff_check()
                if self.land_complete:
                    self.active_sp = ("takeoff", 0, Target())
                    return self._level(dt_s, self.throttle, lim)
            self.takeoff_pending = False
            pc.input_vel_accel_ne((0.0, 0.0), (0.0, 0.0), dt_s)
            pc.input_pos_vel_accel_d(self.takeoff_alt_d_m, 0.0, 0.0, dt_s)
            target = pc.target(yaw_rad=self.ctrl.yaw_hold_rad)
            self.active_sp = ("takeoff", 0, target)
            return self._fly(dt_s, target, lim)
        if self.land_complete:
            return self._idle()  # is_disarmed_or_landed: GUIDED targets do not lift a landed vehicle
        timed_out = self.now - self.guided_update_time > max(self.p("GUID_TIMEOUT"), 0.1)
        if timed_out and not self.guided_timed_out and self.guided_sub != "pos":
            self.event("failsafe", f"GUIDED: no target for GUID_TIMEOUT {self.p('GUID_TIMEOUT'):g} s: velocity and "
                                   "acceleration targets zeroed, staying in GUIDED")  # fmt: skip
        self.guided_timed_out = timed_out
        sub = self.guided_sub
        if sub == "posvelaccel":
            if timed_out:
                self.guided_vel = [0.0, 0.0, 0.0]
                self.guided_acc = [0.0, 0.0, 0.0]
            pos, vel = pc.input_pos_vel_accel_ne(self.guided_pos[:2], self.guided_vel[:2], self.guided_acc[:2], dt_s)
            self.guided_pos[0], self.guided_pos[1] = pos
            self.guided_vel[0], self.guided_vel[1] = vel
            self.guided_pos[2], self.guided_vel[2] = pc.input_pos_vel_accel_d(
                self.guided_pos[2], self.guided_vel[2], self.guided_acc[2], dt_s)
        elif sub == "velaccel":
            if timed_out:
                self.guided_vel = [0.0, 0.0, 0.0]
                self.guided_acc = [0.0, 0.0, 0.0]
            vel = pc.input_vel_accel_ne(self.guided_vel[:2], self.guided_acc[:2], dt_s)
            self.guided_vel[0], self.guided_vel[1] = vel
            self.guided_vel[2] = pc.input_vel_accel_d(self.guided_vel[2], self.guided_acc[2], dt_s)
        elif sub == "accel":
            if timed_out:
                self.guided_acc = [0.0, 0.0, 0.0]
                pc.input_vel_accel_ne((0.0, 0.0), (0.0, 0.0), dt_s)
                pc.input_vel_accel_d(0.0, 0.0, dt_s)
            else:
                pc.input_accel_ne(self.guided_acc[:2], dt_s)
                pc.input_accel_d(self.guided_acc[2], dt_s)
        else:  # pos
            pc.input_pos_ned(self.guided_pos, dt_s)
        yaw_rate = NAN if timed_out else self.guided_yaw_rate_radps
        target = pc.target(yaw_rad=self.guided_yaw_rad, yaw_rate_radps=yaw_rate)
        self.active_sp = (self.offboard_source or "guided", self.offboard_mask, target)
        return self._fly(dt_s, target, lim)

    def _land_descent_rate_mps(self) -> float:
        """Mode::land_run_vertical_control: down to LAND_ALT_LOW_M at LAND_SPD_HIGH_MS (0: WP_SPD_DN), then
        LAND_SPD_MS — no rangefinder, so the height is the estimate's above home."""
        alt_m = -self.est.d_m
        low_m = max(self.p("LAND_ALT_LOW_M"), 1.0)
        slow = abs(self.p("LAND_SPD_MS"))
        high = self.p("LAND_SPD_HIGH_MS") if self.p("LAND_SPD_HIGH_MS") > 0 else self.pc.vel_max_down_mps
        fast = max(high, slow)
        climb = sqrt_controller(low_m - alt_m, self.p("PSC_D_POS_P"), self.pc.accel_max_d_mps2, 0.0)
        return -min(max(climb, -fast), -slow)

    def _land(self, dt_s: float, lim: Limits, label: str) -> list[float]:
        if self.body.state.on_ground and self.ever_flown_since_arm:
            return self._idle()
        descent = 0.0 if self.now < self.land_pause_until else self._land_descent_rate_mps()
        self.pc.input_vel_accel_ne((0.0, 0.0), (0.0, 0.0), dt_s)
        self.pc.input_vel_accel_d(descent, 0.0, dt_s)
        target = self.pc.target()
        self.active_sp = (label, 0, target)
        return self._fly(dt_s, target, lim)

    def _rtl(self, dt_s: float, lim: Limits) -> list[float]:
        """RTL as ModeRTL flies it here: climb to RTL_ALT_M, return home, loiter RTL_LOIT_TIME, land."""
        pc = self.pc
        s = self.est
        if self.rtl_phase == "land":
            return self._land(dt_s, lim, "rtl")
        if self.rtl_phase == "climb":
            pc.input_vel_accel_ne((0.0, 0.0), (0.0, 0.0), dt_s)
            pc.input_pos_vel_accel_d(self.rtl_alt_d_m, 0.0, 0.0, dt_s)
            if abs(s.d_m - self.rtl_alt_d_m) < RTL_ALT_REACHED_M:
                self.rtl_phase = "return"
                self.event("event", "RTL: altitude reached, returning")
        else:
            pc.input_pos_ned((0.0, 0.0, self.rtl_alt_d_m), dt_s)
            if self.rtl_phase == "return" and math.hypot(s.n_m, s.e_m) < RTL_HOME_REACHED_M \
                    and math.hypot(s.vn_mps, s.ve_mps) < 0.2:  # fmt: skip
                self.rtl_phase = "loiter"
                self.rtl_loiter_until = self.now + self.p("RTL_LOIT_TIME") / 1000.0
            if self.rtl_phase == "loiter" and self.now >= self.rtl_loiter_until:
                self.rtl_phase = "land"
                self.event("event", "RTL: final descent")
        target = pc.target()
        self.active_sp = ("rtl", 0, target)
        return self._fly(dt_s, target, lim)

    # -- MAVLink input -------------------------------------------------------------------------------
    def handle(self, msg, addr) -> None:
        t = msg.get_type()
        sysid = msg.get_srcSystem()
        if t == "HEARTBEAT":
            self._on_heartbeat(msg, addr)
            return
        if int(self.p("MAV_OPTIONS")) & MAV_OPTION_GCS_SYSID_ENFORCE and not self.is_gcs(sysid):
            return  # MAV_OPTIONS bit 0: only the ground station's sysid is listened to
        super().handle(msg, addr)

    def _on_heartbeat(self, msg, addr) -> None:
        if msg.type != M.MAV_TYPE_GCS and not self.is_gcs(msg.get_srcSystem()):
            return
        sysid = msg.get_srcSystem()
        now = time.monotonic()
        if sysid not in self.gcs_seen:
            role = "MAV_GCS_SYSID: keeps the GCS failsafe alive" if self.is_gcs(sysid) else \
                f"not MAV_GCS_SYSID {int(self.p('MAV_GCS_SYSID'))}: ignored by the GCS failsafe"  # fmt: skip
            self.event("event", f"ground station sysid {sysid} heard from {addr[0]}:{addr[1]} ({role})")
        self.gcs_seen[sysid] = now
        if self.is_gcs(sysid):
            self.gcs_last_seen = now

    def _on_rc_channels_override(self, msg, addr) -> None:
        if not self.is_gcs(msg.get_srcSystem()):
            return  # "Only accept control from our gcs"
        if not self._targets_me(msg):
            return
        self.gcs_last_seen = time.monotonic()  # an RC override counts as the GCS's heartbeat
        values = [getattr(msg, f"chan{i}_raw", 0) for i in range(1, 19)]
        for i, v in enumerate(values):
            # GCS_MAVLINK::handle_rc_channels_override: UINT16_MAX ignores a channel; 0 releases 1-8 back to
            # the transmitter and ignores 9-18
            if v == 65535 or (v == 0 and i >= 8):
                continue
            self.rc_override[i] = v
            self.rc_override_time[i] = self.now

    def _on_manual_control(self, msg, addr) -> None:
        if self.is_gcs(msg.get_srcSystem()):
            self.gcs_last_seen = time.monotonic()  # counts as the GCS's heartbeat; the sticks are not flown

    def _on_request_data_stream(self, msg, addr) -> None:
        if not self._targets_me(msg) or self.telemetry is None:
            return
        rate = msg.req_message_rate if msg.start_stop else 0
        self.telemetry.set_group_rate(msg.req_stream_id, rate)

    def _on_set_mode(self, msg, addr) -> None:
        if msg.target_system not in (0, getattr(self.link, "sysid", 1)):
            return
        if msg.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            ok, note = self.try_set_mode(msg.custom_mode, "SET_MODE")
            self.log.row(self.now, "command", self.mode.name, self.armed, self.landed(), None,
                         detail=f"SET_MODE custom_mode={msg.custom_mode} ok={ok} {note}".strip())  # fmt: skip

    # commands ---------------------------------------------------------------------------------------
    def _execute(self, cmd: int, p) -> tuple[int, str]:
        if cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
            return self._cmd_arm(p)
        if cmd == M.MAV_CMD_NAV_TAKEOFF:
            return self._cmd_takeoff(p)
        if cmd == M.MAV_CMD_NAV_LAND:
            ok, note = self.try_set_mode(CopterMode.LAND, "NAV_LAND")
            return (ACCEPTED, note) if ok else (FAILED, note)
        if cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            ok, note = self.try_set_mode(CopterMode.RTL, "NAV_RETURN_TO_LAUNCH")
            return (ACCEPTED, note) if ok else (FAILED, note)
        if cmd == M.MAV_CMD_DO_SET_MODE:
            base = int(p[0]) if finite(p[0]) else 0
            if not base & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED or not finite(p[1]):
                return FAILED, "base_mode without CUSTOM_MODE_ENABLED"
            ok, note = self.try_set_mode(int(p[1]), "DO_SET_MODE")
            return (ACCEPTED, note) if ok else (FAILED, note)
        if cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
            if not (finite(p[0]) and finite(p[1])):
                return DENIED, "message id and interval must be numbers"
            return self.telemetry.set_interval(int(p[0]), p[1])
        if cmd == M.MAV_CMD_REQUEST_MESSAGE:
            ok = finite(p[0]) and self.telemetry.can_send(int(p[0]))
            return (ACCEPTED, "") if ok else (DENIED, "unknown message")
        if cmd == M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return ACCEPTED, ""
        if cmd == M.MAV_CMD_GET_HOME_POSITION:
            return (ACCEPTED, "") if self.ekf_ready else (FAILED, "home not set")
        return UNSUPPORTED, "not implemented by the fake"

    def _cmd_arm(self, p) -> tuple[int, str]:
        want = finite(p[0]) and p[0] >= 0.5
        force = finite(p[1]) and int(p[1]) == FORCE_ARM_MAGIC
        if want:
            if self.armed:
                return ACCEPTED, "already armed"
            if self.crashed:
                self.statustext(M.MAV_SEVERITY_CRITICAL, "PreArm: Crash detected")
                return FAILED, "crashed"
            if self.mode in NOT_ARMABLE:
                self.statustext(M.MAV_SEVERITY_CRITICAL, "Arm: Mode not armable")
                return FAILED, f"{self.mode.name} not armable"
            # the EKF's origin is a mandatory check: the force magic does not bypass it
            if not self.position_valid():
                self.statustext(M.MAV_SEVERITY_CRITICAL, ap.PREARM_EKF_TEXT)
                return FAILED, "EKF not ready"
            self.arm("ARM_DISARM" + (" forced" if force else ""))
            return ACCEPTED, ""
        if not self.armed:
            return ACCEPTED, "already disarmed"
        if not self.land_complete and not force:
            return FAILED, "in air"
        self.disarm("ARM_DISARM" + (" forced" if force else ""))
        return ACCEPTED, ""

    def _cmd_takeoff(self, p) -> tuple[int, str]:
        """Mode::do_user_takeoff_U_m: armed, landed, a mode with user takeoff, above the current altitude."""
        alt_m = p[6]
        if not self.armed:
            return FAILED, "not armed"
        if not self.land_complete:
            return FAILED, "already flying"
        if self.mode not in USER_TAKEOFF_MODES:
            return FAILED, f"{self.mode.name} has no user takeoff"
        if not finite(alt_m) or alt_m <= -self.est.d_m:
            return FAILED, "takeoff altitude not above the vehicle"
        s = self.est
        if self.mode is CopterMode.GUIDED:
            self.guided_sub = "takeoff"
        self.takeoff_alt_d_m = s.d_m - alt_m  # altitude above the current position (_TakeOff::start_m)
        self.takeoff_pending = True
        self.takeoff_complete = False
        self.throttle = 0.0
        self.ctrl.yaw_hold_rad = s.yaw_rad()
        self.event("event", f"takeoff to {alt_m:.2f} m")
        return ACCEPTED, f"alt={alt_m:.2f}"

    def _on_set_position_target_local_ned(self, msg, addr) -> None:
        if not self._targets_me(msg):
            return
        source = f"{msg.get_srcSystem()}/{msg.get_srcComponent()}@{addr[1]}"
        if self.mode is not CopterMode.GUIDED:
            self.log.row(self.now, "setpoint", self.mode.name, self.armed, self.landed(), None,
                         detail=f"ignored: not in GUIDED (from {source})")  # fmt: skip
            return
        mask = msg.type_mask
        frame = msg.coordinate_frame
        pos_ignore, vel_ignore = bool(mask & POS_IGNORE), bool(mask & VEL_IGNORE)
        acc_ignore = bool(mask & ACC_IGNORE)
        arrival = self.now_wall()
        if frame not in FRAMES or (mask & FORCE_SET and not acc_ignore):
            self._guided_stop(f"frame {frame} / force not supported")
            return
        s = self.est
        yaw = s.yaw_rad()
        c, sn = math.cos(yaw), math.sin(yaw)
        body = frame in (M.MAV_FRAME_BODY_NED, M.MAV_FRAME_BODY_OFFSET_NED)

        def rot(v: list[float]) -> list[float]:
            return [c * v[0] - sn * v[1], sn * v[0] + c * v[1], v[2]] if body else v

        pos = rot([msg.x, msg.y, msg.z]) if not pos_ignore else [0.0, 0.0, 0.0]
        if not pos_ignore and frame != M.MAV_FRAME_LOCAL_NED:
            pos = [pos[0] + s.n_m, pos[1] + s.e_m, pos[2] + s.d_m]
        vel = rot([msg.vx, msg.vy, msg.vz]) if not vel_ignore else [0.0, 0.0, 0.0]
        acc = rot([msg.afx, msg.afy, msg.afz]) if not acc_ignore else [0.0, 0.0, 0.0]
        if not pos_ignore and not vel_ignore:
            sub = "posvelaccel"
        elif pos_ignore and not vel_ignore:
            sub = "velaccel"
        elif pos_ignore and vel_ignore and not acc_ignore:
            sub = "accel"
        elif not pos_ignore and vel_ignore and acc_ignore:
            sub = "pos"
        else:
            self._guided_stop(f"type_mask {mask} not supported")
            return
        if sub != self.guided_sub:
            self.guided_sub = sub
            self._pva_start()
        self.guided_pos, self.guided_vel, self.guided_acc = pos, vel, acc
        yaw_sp = msg.yaw if not mask & YAW_IGNORE else NAN
        if finite(yaw_sp) and body:
            yaw_sp += yaw
        self.guided_yaw_rad = yaw_sp
        self.guided_yaw_rate_radps = msg.yaw_rate if not mask & YAW_RATE_IGNORE else NAN
        self.guided_update_time = arrival
        self.offboard_source = source
        self.offboard_mask = mask
        self.last_sp_time = arrival
        t = Target(pos=pos if not pos_ignore else [NAN] * 3, vel=vel if not vel_ignore else [NAN] * 3,
                   acc=acc if not acc_ignore else [NAN] * 3, yaw_rad=yaw_sp,
                   yaw_rate_radps=self.guided_yaw_rate_radps)  # fmt: skip
        self.log.row(arrival, "setpoint", self.mode.name, self.armed, self.landed(), None, sp=(source, mask, t),
                     detail=f"frame={frame} {sub}")  # fmt: skip

    def _guided_stop(self, why: str) -> None:
        """An invalid target: ModeGuided::init(true) — stop with zero velocity and acceleration."""
        self.guided_sub = "velaccel"
        self.guided_vel = [0.0, 0.0, 0.0]
        self.guided_acc = [0.0, 0.0, 0.0]
        self.guided_update_time = self.now_wall()
        self._pva_start()
        self.log.row(self.now, "setpoint", self.mode.name, self.armed, self.landed(), None,
                     detail=f"GUIDED stop: {why}")  # fmt: skip

    def _on_set_attitude_target(self, msg, addr) -> None:
        self.log.row(self.now, "setpoint", self.mode.name, self.armed, self.landed(), None,
                     detail="ignored: SET_ATTITUDE_TARGET (GUIDED angle control not in the fake)")  # fmt: skip

    # parameters (ArduPilot: values cast to float, types of its declarations, PARAM_SET echoed with index -1)
    def _on_param_set(self, msg, addr) -> None:
        if not self._targets_me(msg):
            return
        name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
        if name not in self.params:
            self.log.row(self.now, "param", self.mode.name, self.armed, self.landed(), None, detail=f"unknown {name}")
            return
        param = self.params[name]
        if not math.isfinite(msg.param_value):
            self._send_param(name, index=-1)
            return
        param.value = int(msg.param_value) if param.type in ap.INT_TYPES else float(msg.param_value)
        self.log.row(self.now, "param", self.mode.name, self.armed, self.landed(), None,
                     detail=f"{name}={param.value}")  # fmt: skip
        self._send_param(name, index=-1)

    def _send_param(self, name: str, index: int | None = None) -> None:  # type: ignore[override]
        param = self.params[name]
        idx = self.param_names.index(name) if index is None else index
        self.link.send(M.MAVLink_param_value_message(name.encode(), ap.encode_param_value(param), param.type,
                                                     len(self.param_names), idx & 0xFFFF))  # fmt: skip
