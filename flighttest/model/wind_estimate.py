"""The horizontal wind, estimated from what every autopilot sends: specific force (``HIGHRES_IMU``),
attitude and velocity, with the airframe's drag model (``flighttest.model.drag``). The approach of PX4's
and ArduPilot's drag fusion: across the thrust axis the IMU feels only the air's drag, and the drag
says the air-relative velocity, so ``wind = v_ned − R·v_air``.

A two-state extended Kalman filter ``(wn, we)`` (the vertical wind is taken as zero): the wind wanders
as a random walk (``process_sd``), each sample's measurement is the body-frame specific force along x
and y against ``drag(Rᵀ(v − wind)) / m``. Its measurement noise adapts to the innovations it sees
(vibration differs by airframe by an order of magnitude), never below ``accel_sd_mps2``. The same class
runs live (``flighttest.flying.wind``) and over a log (``flighttest.analysis.wind``): one definition.

``sd_mps`` is honest about what the filter cannot see: its own covariance, plus what a drag model
wrong by ``drag.rel_sd`` and an accelerometer bias of ``accel_bias_mps2`` do to the airspeed it infers
— an error that no amount of averaging removes. A vehicle whose drag is small (ArduCopter SITL's quad
leans 1.2° in 3 m/s: ../shared/wind_sitl) senses the wind poorly, and says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from flighttest.model.drag import DragModel
from flighttest.model.frames import ned_to_body

ACCEL_SD_MPS2 = 0.05  # the least noise a sample's specific force is credited with
ACCEL_BIAS_MPS2 = 0.05  # an accelerometer's residual bias after calibration
PROCESS_SD_MPS = 0.3  # the wind's wander per √s (gusts are the guard's margin, not the filter's)
INITIAL_SD_MPS = 5.0  # before the first sample: nothing known
NOISE_TAU_S = 2.0  # the innovation variance's memory


@dataclass
class WindFilter:
    drag: DragModel
    mass_kg: float
    wn_mps: float = 0.0
    we_mps: float = 0.0
    initial_sd_mps: float = INITIAL_SD_MPS
    accel_sd_mps2: float = ACCEL_SD_MPS2
    accel_bias_mps2: float = ACCEL_BIAS_MPS2
    process_sd_mps: float = PROCESS_SD_MPS
    p: list[float] = field(default_factory=list)  # covariance [pnn, pne, pee]
    noise_var: float = 0.0  # the measurement variance the innovations show
    t_s: float | None = None
    samples: int = 0
    airspeed_mps: float = 0.0  # the horizontal air speed at the last sample (what the model floor scales with)
    slope_per_s: float = math.inf  # the drag's slope per unit mass there (the weakest axis): how well it sees

    def __post_init__(self) -> None:
        if not self.p:
            self.p = [self.initial_sd_mps**2, 0.0, self.initial_sd_mps**2]

    # -- the filter ------------------------------------------------------------------------------------
    def predict(self, t_s: float) -> None:
        if self.t_s is not None and t_s > self.t_s:
            q = self.process_sd_mps**2 * (t_s - self.t_s)
            self.p[0] += q
            self.p[2] += q
        self.t_s = t_s if self.t_s is None else max(self.t_s, t_s)

    def update(self, t_s: float, v_ned: tuple[float, float, float], q_wxyz: tuple[float, float, float, float],
               f_body_xy: tuple[float, float]) -> None:  # fmt: skip
        """One sample: velocity NED (m/s), attitude (body → NED), specific force along body x, y (m/s²)."""
        vals = (*v_ned, *q_wxyz, *f_body_xy)
        if not all(math.isfinite(x) for x in vals):
            return
        prev = self.t_s
        self.predict(t_s)
        qw, qx, qy, qz = q_wxyz
        m = self.mass_kg
        bx, by, _ = ned_to_body(v_ned[0] - self.wn_mps, v_ned[1] - self.we_mps, v_ned[2], qw, qx, qy, qz)
        fx, fy = self.drag.force_n(bx, by)
        sx, sy = self.drag.slope_n_per_mps(bx, by)
        # ∂(body x, y)/∂(wn, we) = −Rᵀ's first two columns' x, y rows: the NED axes' body components
        ax, ay, _ = ned_to_body(1.0, 0.0, 0.0, qw, qx, qy, qz)
        cx, cy, _ = ned_to_body(0.0, 1.0, 0.0, qw, qx, qy, qz)
        # h = F(v_b)/m; ∂h/∂w = (−slope/m)·(−∂v_b/∂v) = slope/m · (body components of the NED axes)
        h = ((sx / m) * ax, (sx / m) * cx, (sy / m) * ay, (sy / m) * cy)  # rows: body x, body y
        innov = (f_body_xy[0] - fx / m, f_body_xy[1] - fy / m)
        pnn, pne, pee = self.p
        # S = H P Hᵀ + R
        hp = ((h[0] * pnn + h[1] * pne, h[0] * pne + h[1] * pee), (h[2] * pnn + h[3] * pne, h[2] * pne + h[3] * pee))
        s00 = hp[0][0] * h[0] + hp[0][1] * h[1]
        s01 = hp[0][0] * h[2] + hp[0][1] * h[3]
        s11 = hp[1][0] * h[2] + hp[1][1] * h[3]
        seen = 0.5 * (innov[0] ** 2 + innov[1] ** 2) - 0.5 * (s00 + s11)
        dt = min(max(t_s - prev, 0.0), 1.0) if prev is not None else 0.0
        a = min(dt / NOISE_TAU_S, 1.0) if self.samples else 1.0
        self.noise_var = (1.0 - a) * self.noise_var + a * max(seen, 0.0)
        r = max(self.accel_sd_mps2**2, self.noise_var)
        s00 += r
        s11 += r
        det = s00 * s11 - s01 * s01
        if det <= 0 or not math.isfinite(det):
            return
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det
        # K = P Hᵀ S⁻¹ (2×2): P Hᵀ columns are hp rows
        k00 = hp[0][0] * i00 + hp[1][0] * i01
        k01 = hp[0][0] * i01 + hp[1][0] * i11
        k10 = hp[0][1] * i00 + hp[1][1] * i01
        k11 = hp[0][1] * i01 + hp[1][1] * i11
        self.wn_mps += k00 * innov[0] + k01 * innov[1]
        self.we_mps += k10 * innov[0] + k11 * innov[1]
        # P = (I − K H) P
        a00 = 1.0 - (k00 * h[0] + k01 * h[2])
        a01 = -(k00 * h[1] + k01 * h[3])
        a10 = -(k10 * h[0] + k11 * h[2])
        a11 = 1.0 - (k10 * h[1] + k11 * h[3])
        nn = a00 * pnn + a01 * pne
        ne = a00 * pne + a01 * pee
        ee = a10 * pne + a11 * pee
        self.p = [max(nn, 0.0), ne, max(ee, 0.0)]
        self.samples += 1
        self.airspeed_mps = math.hypot(v_ned[0] - self.wn_mps, v_ned[1] - self.we_mps)
        self.slope_per_s = float(min(sx, sy)) / m

    # -- what it knows ---------------------------------------------------------------------------------
    @property
    def filter_sd_mps(self) -> float:
        """The filter's own 1 σ along its worse axis."""
        pnn, pne, pee = self.p
        half = 0.5 * (pnn + pee)
        return math.sqrt(max(half + math.sqrt(max(0.25 * (pnn - pee) ** 2 + pne * pne, 0.0)), 0.0))

    @property
    def model_sd_mps(self) -> float:
        """What averaging cannot remove: the drag model's relative error on the airspeed it infers, and an
        accelerometer bias seen through the drag's slope."""
        bias = self.accel_bias_mps2 / self.slope_per_s if self.slope_per_s > 0 else math.inf
        return math.hypot(self.drag.rel_sd * self.airspeed_mps, bias)

    @property
    def sd_mps(self) -> float:
        if not self.samples:
            return self.initial_sd_mps
        return math.hypot(self.filter_sd_mps, self.model_sd_mps)

    @property
    def wind_ned_mps(self) -> tuple[float, float, float]:
        return (self.wn_mps, self.we_mps, 0.0)
