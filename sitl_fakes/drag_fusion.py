"""The autopilot's own wind estimate, as its EKF makes it with drag fusion on: lagging, noisy, and as wrong as
its drag coefficients.

Neither PX4 nor ArduCopter estimates the wind on a multicopter by default. PX4's EKF2 does with
``EKF2_DRAG_CTRL`` set (its model: ``EKF2_BCOEF_X/Y`` ballistic coefficients in kg/m², ``EKF2_MCOEF`` momentum
drag in 1/s; ``ekf2/EKF/aid_sources/drag/drag_fusion.cpp``), ArduCopter's EKF3 with ``EK3_DRAG_BCOEF_X/Y`` or
``EK3_DRAG_MCOEF`` set (``SampleDragData``: a ballistic coefficient counts above 1, the momentum coefficient
above 0.001). Both model the specific force across the thrust axis as
``a = −(mcoef·v + ρ/(2·bcoef)·|v|·v)`` per body axis and estimate the wind that makes it fit.

The fake does the same in one line: it inverts the autopilot's model (its parameters, not the fake's truth)
on the true specific force, giving the air-relative body velocity the autopilot would infer, and the wind
that goes with it (``v − R·v_air``, horizontal). Its estimate follows that with a first-order lag of
``LAG_S`` (EKF2 and EKF3 take tens of seconds to converge on a wind) and carries an error that wanders
(``ERROR_SD_MPS`` over ``ERROR_TAU_S``: attitude and accelerometer errors, vibration). With coefficients that
fit the airframe the estimate is a few tenths off once converged; with coefficients that do not (PX4's
defaults on an airframe they were not identified on) it is off by their ratio, as the autopilot's is.
It learns only in the air, and keeps its last estimate on the ground.

``var_mps2``: what the estimator can know of its own error, per axis: the wandering error's variance plus the
gap between its lagged estimate and what its measurements say now (smoothed over ``GAP_TAU_S``), which is
large while it converges and after the wind changes. A wrong drag model is not in it: no EKF knows that.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

from sitl_fakes.physics import rotate_body_to_ned, rotate_ned_to_body

AIR_DENSITY_KGPM3 = 1.225
LAG_S = 10.0
ERROR_SD_MPS = 0.3
ERROR_TAU_S = 20.0
GAP_TAU_S = 1.0
BCOEF_MIN = 1.0  # a ballistic coefficient at or below this is "not used" (both autopilots)
MCOEF_MIN = 0.001  # likewise the momentum coefficient


@dataclass(frozen=True)
class DragFusionModel:
    """The autopilot's drag model (its parameters)."""

    mcoef_per_s: float
    bcoef_x_kgpm2: float
    bcoef_y_kgpm2: float

    @property
    def used(self) -> bool:
        return self.mcoef_per_s > MCOEF_MIN or self.bcoef_x_kgpm2 > BCOEF_MIN or self.bcoef_y_kgpm2 > BCOEF_MIN

    def airspeed_mps(self, f_mps2: float, bcoef: float) -> float | None:
        """The air-relative velocity along one body axis this model infers from the specific force along it;
        None if the model has no drag on that axis."""
        m = self.mcoef_per_s if self.mcoef_per_s > MCOEF_MIN else 0.0
        q = 0.5 * AIR_DENSITY_KGPM3 / bcoef if bcoef > BCOEF_MIN else 0.0
        mag = abs(f_mps2)
        if q > 0.0:
            speed = (-m + math.sqrt(m * m + 4.0 * q * mag)) / (2.0 * q)
        elif m > 0.0:
            speed = mag / m
        else:
            return None
        return -math.copysign(speed, f_mps2)  # drag opposes the air-relative velocity


class DragFusionWind:
    def __init__(self, seed: int, lag_s: float = LAG_S, error_sd_mps: float = ERROR_SD_MPS,
                 error_tau_s: float = ERROR_TAU_S):  # fmt: skip
        self.lag_s = lag_s
        self.error_sd = error_sd_mps
        self.error_tau_s = error_tau_s
        self.rng = random.Random(seed * 7 + 104723)
        self.started = False  # has estimated the wind (drag fusion on, in the air) at least once
        self.learning = False  # estimating this step
        self.wn = self.we = 0.0  # the lagged estimate, without the wandering error
        self.err = [error_sd_mps * self.rng.gauss(0.0, 1.0), error_sd_mps * self.rng.gauss(0.0, 1.0)]
        self.meas = [0.0, 0.0]  # the measurement, smoothed over GAP_TAU_S
        self.airborne_s = 0.0

    def step(self, dt_s: float, model: DragFusionModel, airborne: bool, state) -> None:
        """One physics step with the true state (velocity, attitude, specific force after its step)."""
        self.learning = model.used and airborne
        if not self.learning:
            return
        s = state
        qw, qx, qy, qz = s.qw, s.qx, s.qy, s.qz
        # the body velocity against the air the estimate believes in now, for the axes the model cannot see
        px, py, pz = rotate_ned_to_body(s.vn_mps - self.wn, s.ve_mps - self.we, s.vd_mps, qw, qx, qy, qz)
        vx = model.airspeed_mps(s.fx_mps2, model.bcoef_x_kgpm2)
        vy = model.airspeed_mps(s.fy_mps2, model.bcoef_y_kgpm2)
        an, ae, _ = rotate_body_to_ned(px if vx is None else vx, py if vy is None else vy, pz, qw, qx, qy, qz)
        mn, me = s.vn_mps - an, s.ve_mps - ae
        if not self.started:
            self.started = True
            self.meas = [mn, me]
        a_gap = min(dt_s / GAP_TAU_S, 1.0)
        self.meas[0] += a_gap * (mn - self.meas[0])
        self.meas[1] += a_gap * (me - self.meas[1])
        a = min(dt_s / self.lag_s, 1.0)
        self.wn += a * (mn - self.wn)
        self.we += a * (me - self.we)
        decay = math.exp(-dt_s / self.error_tau_s)
        kick = math.sqrt(1.0 - decay * decay) * self.error_sd
        for i in range(2):
            self.err[i] = decay * self.err[i] + kick * self.rng.gauss(0.0, 1.0)
        self.airborne_s += dt_s

    @property
    def wind_ned_mps(self) -> tuple[float, float, float]:
        """The estimate the autopilot reports (no vertical wind: neither estimates one)."""
        return (self.wn + self.err[0], self.we + self.err[1], 0.0)

    @property
    def var_mps2(self) -> tuple[float, float]:
        """Its honest variance per horizontal axis (north, east)."""
        base = self.error_sd**2
        return (base + (self.meas[0] - self.wn) ** 2, base + (self.meas[1] - self.we) ** 2)
