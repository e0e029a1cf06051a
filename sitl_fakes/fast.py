"""Either personality in-process, faster than real time: the same vehicle code as the UDP fake, with no link
and no clock. For tests and benchmarks of the physics, the wind and what the autopilot makes of it.

    v = vehicle("x500", wind_ned=(0, 3, 0))          # PX4; autopilot="ardupilot" for ArduCopter
    hover_at(v, (0, 0, -7))                           # armed, airborne, holding there (PX4 Hold, ArduCopter GUIDED)
    advance(v, 30.0)                                  # 30 s of the vehicle's own clock
    v.body.state, v.wind.ned, v.wind_report(), v.telemetry.highres_imu()

The estimate is the truth unless ``estimate_error`` is given; the VRS disturbance is off unless ``severity``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

from flighttest.model.profiles import VehicleProfile, load_profile
from sitl_fakes import ardupilot as ap
from sitl_fakes.ardupilot import CopterMode
from sitl_fakes.ardupilot_telemetry import ArduPilotTelemetry
from sitl_fakes.ardupilot_vehicle import FakeArduCopter
from sitl_fakes.control import Target
from sitl_fakes.disturbance import VrsTruth, default_onset_mps
from sitl_fakes.drag import TruthDrag
from sitl_fakes.estimator import EstimateError
from sitl_fakes.px4 import Mode
from sitl_fakes.telemetry import Telemetry
from sitl_fakes.truthlog import TruthLog
from sitl_fakes.vehicle import FakeConfig, FakePx4

PHYSICS_DT_S = 0.004


class Silent:
    """A link that sends nowhere."""

    sysid = 1

    def send(self, msg) -> None:
        pass


class FastPx4(FakePx4):
    def now_wall(self) -> float:  # messages arrive on the vehicle's clock
        return self.now


class FastCopter(FakeArduCopter):
    def now_wall(self) -> float:
        return self.now


def vehicle(profile: VehicleProfile | str, autopilot: str = "px4", *, wind_ned=(0.0, 0.0, 0.0),
            gust_mps: float = 0.0, gust_tau_s: float | None = None, truth_drag: TruthDrag | None = None,
            seed: int = 0, params: Mapping[str, float] | None = None, estimate_error: EstimateError | None = None,
            severity: float = 0.0, imu_noise_mps2: float | None = None,
            truth_log: Path | None = None) -> FakePx4:  # fmt: skip
    """A vehicle on the ground at home, ready to arm (ArduCopter: EKF ready), with its telemetry builders;
    ``truth_log``: a truth-log CSV with a state row every step (``v.log.close()`` when done)."""
    prof = load_profile(profile) if isinstance(profile, str) else profile
    error = estimate_error if estimate_error is not None else EstimateError().scaled(0.0)
    extra = {}
    if imu_noise_mps2 is not None:
        extra["imu_noise_mps2"] = imu_noise_mps2
    elif autopilot == "ardupilot":
        extra["imu_noise_mps2"] = ap.SITL_IMU_NOISE_MPS2
    cfg = FakeConfig(profile=prof, truth=VrsTruth(default_onset_mps(prof.v_h_mps), 20.0, severity, seed, prof.v_h_mps),
                     wind_ned=tuple(wind_ned), gust_mps=gust_mps, gust_tau_s=gust_tau_s, truth_drag=truth_drag,
                     seed=seed, estimate_error=error, telemetry_gap_rate_hz=0.0, **extra)  # fmt: skip
    log = TruthLog(truth_log, 0.0)
    if autopilot == "ardupilot":
        v: FakePx4 = FastCopter(cfg, Silent(), log, 0.0, ekf_delay_s=0.0)  # type: ignore[arg-type]
        telemetry: Telemetry = ArduPilotTelemetry(v, cfg.telemetry_hz, 0.0)
    elif autopilot == "px4":
        v = FastPx4(cfg, Silent(), log, 0.0)  # type: ignore[arg-type]
        telemetry = Telemetry(v, cfg.telemetry_hz, 0.0)
    else:
        raise ValueError(f"autopilot must be px4 or ardupilot (got {autopilot!r})")
    for name, value in (params or {}).items():
        v.params[name].value = value
    v.telemetry = telemetry
    return v


def hover_at(v: FakePx4, pos_ned: tuple[float, float, float], yaw_rad: float = 0.0) -> FakePx4:
    """Put ``v`` armed and airborne at ``pos_ned`` at hover thrust, holding that position: PX4 in Hold,
    ArduCopter in GUIDED (no setpoints: it holds where its shaping ends)."""
    s = v.body.state
    s.n_m, s.e_m, s.d_m = pos_ned
    s.qw, s.qx, s.qy, s.qz = math.cos(0.5 * yaw_rad), 0.0, 0.0, math.sin(0.5 * yaw_rad)
    s.on_ground = False
    prof = v.profile
    hover = prof.mass_kg * 9.80665 / prof.n_rotors
    s.thrust_n = [hover] * 4
    v.est = v.estimator.estimate(s)
    if isinstance(v, FakeArduCopter):
        v.collective_filtered = v.p("MOT_THST_HOVER")
        v.armed = True
        v.arm_time = v.now
        v.land_complete = False
        v.ever_flown_since_arm = True
        v.ekf_ready = True
        v.set_mode(CopterMode.GUIDED, "test")
        v.guided_pos = list(pos_ned)
        return v
    v.arm("test")
    v.has_flown = True
    v.set_mode(Mode.HOLD, "test")
    v.hold_target = Target(pos=list(pos_ned), yaw_rad=yaw_rad)
    v.ctrl.yaw_hold_rad = yaw_rad
    return v


def advance(v: FakePx4, duration_s: float, dt_s: float = PHYSICS_DT_S, each=None) -> None:
    """Step ``v`` for ``duration_s`` of its own clock; ``each(v)`` after every step."""
    for _ in range(math.ceil(duration_s / dt_s)):
        v.step(dt_s, v.now + dt_s)
        if each is not None:
            each(v)


__all__ = ["PHYSICS_DT_S", "FastCopter", "FastPx4", "Silent", "advance", "hover_at", "vehicle"]
