"""The horizontal wind, estimated from what every autopilot sends: specific force (``HIGHRES_IMU``),
attitude and velocity, with the airframe's drag model (``flighttest.model.drag``). The approach of PX4's
and ArduPilot's drag fusion: across the thrust axis the IMU feels only the air's drag, and the drag
says the air-relative velocity, so ``wind = v_ned − R·v_air``.

An extended Kalman filter ``(wn, we, ε, bx, by)``: the horizontal wind (the vertical wind is taken as
zero), which wanders as a random walk (``process_sd``), and the drag's scale error ε — the vehicle drags
(1 + ε) times its model, ε known to ``drag.rel_sd`` beforehand and constant. (Only a drag known to
``SCALE_STATE_MAX_REL_SD``: beyond it the product ε·wind the linearisation drops is as large as what it keeps;
an assumed drag's scale stays out of the state and its share of ``sd_mps`` is ``rel_sd`` times the airspeed.)
Each sample's measurement is the body-frame specific force along x and y against
``(1 + ε)·drag(Rᵀ(v − wind)) / m``. A drag model wrong by a factor moves every sample the same way,
which no averaging removes: as a state, the filter learns ε where the airspeed changes under a steady wind
(a helix turns it through every direction) and otherwise carries its uncertainty into the wind's, so a fast
leg flown on a wind found in the hover neither trusts its own samples more than the model allows nor throws
the hover's estimate away. Its measurement noise adapts to the innovations it sees (vibration differs by
airframe by an order of magnitude), never below ``accel_sd_mps2``. The same class runs live
(``flighttest.flying.wind``) and over a log (``flighttest.analysis.wind``): one definition.

The accelerometer's bias along body x, y is two more states (prior ``accel_bias_mps2``): at one heading it
reads as wind, and a turn of the heading tells them apart (the runner's climb turns it: bench/RESULTS.md, "The
climb looks around").

``sd_mps`` is honest about what the filter cannot see: its own covariance (the scale error's and the bias's
shares included; with ``bias_states`` off, what a bias of ``accel_bias_mps2`` does to the airspeed it infers).
A vehicle whose drag is small (ArduCopter SITL's quad leans 1.2° in 3 m/s: ../shared/wind_sitl) senses the wind
poorly, and says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from flighttest.model.aero import G_MPS2
from flighttest.model.drag import DragModel
from flighttest.model.frames import ned_to_body

ACCEL_SD_MPS2 = 0.05  # the least noise a sample's specific force is credited with
ACCEL_BIAS_MPS2 = 0.05  # an accelerometer's residual bias after calibration
# the wind's wander per √s, between PX4's EKF2_WIND_NSD (0.05) and ArduPilot's EK3_WIND_P_NSE (0.2); gusts
# faster than this are the guard's margin (bench/RESULTS.md, "The wind filter's scale state")
PROCESS_SD_MPS = 0.1
INITIAL_SD_MPS = 5.0  # before the first sample: nothing known
NOISE_TAU_S = 2.0  # the innovation variance's memory
# a sample's noise until the innovations have shown it (a multicopter's IMU at hover: 0.05-0.5 m/s²): the first
# samples must not be trusted to the floor (tests/test_wind_estimate.py)
NOISE_INITIAL_MPS2 = 0.3
SCALE_MIN = -0.9  # ε is kept above: a drag of a tenth of the model's is another vehicle
SCALE_STATE_MAX_REL_SD = 0.2
# ε is only considered (its uncertainty carried, its value kept: a Schmidt filter) for this long after the
# first sample, where the first updates overshoot, and while the velocity stays within this of its recent
# mean: a steady velocity in a steady wind cannot tell wind from scale, and the linearised filter would drift
# along what it cannot see (tests/test_runner_safety.py, tests/test_wind_estimate.py)
SCALE_LEARN_AFTER_S = 3.0
SCALE_LEARN_EXCITATION_MPS = 1.0
V_MEAN_TAU_S = 5.0  # the recent mean's memory
N_STATES = 5  # wn, we, ε, bx, by
ITERATIONS_FIRST = 4  # the first sample's relinearisations (Gauss-Newton: 4 meet a 3 m/s wind from calm)


def scale_in_state(drag: DragModel) -> bool:
    return drag.rel_sd <= SCALE_STATE_MAX_REL_SD


def model_sd(drag: DragModel, airspeed_mps, accel_bias_mps2, slope_per_s):
    """What no filter state covers (m/s): an accelerometer bias over the drag's slope per unit mass, and
    for a drag whose scale is not a state, its relative error on the airspeed; numpy-vectorised."""
    slope = np.asarray(slope_per_s, float)
    if accel_bias_mps2 > 0:
        out = np.where(slope > 0, accel_bias_mps2 / np.where(slope > 0, slope, 1.0), np.inf)
    else:  # the bias is the filter's state
        out = np.zeros_like(slope)
    if not scale_in_state(drag):
        out = np.hypot(out, drag.rel_sd * np.asarray(airspeed_mps, float))
    return float(out) if out.ndim == 0 else out


def worse_axis_sd(pnn, pne, pee):
    """The 1 σ along the worse axis of a 2×2 covariance; numpy-vectorised."""
    half = 0.5 * (np.asarray(pnn) + pee)
    return np.sqrt(np.maximum(half + np.sqrt(np.maximum(0.25 * (np.asarray(pnn) - pee) ** 2 + np.asarray(pne) ** 2,
                                                        0.0)), 0.0))  # fmt: skip


@dataclass
class WindFilter:
    drag: DragModel
    mass_kg: float
    wn_mps: float = 0.0
    we_mps: float = 0.0
    scale_error: float = 0.0  # ε: the vehicle drags (1 + ε) times the model
    initial_sd_mps: float = INITIAL_SD_MPS
    accel_sd_mps2: float = ACCEL_SD_MPS2
    accel_bias_mps2: float = ACCEL_BIAS_MPS2
    # the accelerometer's bias along body x, y as states (its prior ``accel_bias_mps2``): learned where the heading
    # turns under the wind (the runner's climb), else carried in the wind's uncertainty as before; off, the
    # bias is held at 0 and ``model_sd`` covers it
    bias_states: bool = True
    process_sd_mps: float = PROCESS_SD_MPS
    p: list[list[float]] = field(default_factory=list)  # covariance of (wn, we, ε, bx, by), 5×5
    bx_mps2: float = 0.0
    by_mps2: float = 0.0
    noise_var: float = NOISE_INITIAL_MPS2**2  # the measurement variance the innovations show
    t_s: float | None = None
    t_first_s: float | None = None  # the first sample's time
    samples: int = 0
    airspeed_mps: float = 0.0  # the horizontal air speed at the last sample
    v_mean_ned: tuple[float, float] | None = None  # the horizontal velocity's recent mean
    slope_per_s: float = math.inf  # the drag's slope per unit mass there (the weakest axis): how well it sees

    def __post_init__(self) -> None:
        if not self.p:
            self.seed(self.wn_mps, self.we_mps, self.initial_sd_mps)

    def seed(self, wn_mps: float, we_mps: float, sd_mps: float) -> None:
        """Start from a wind known to ``sd_mps`` (an operator's measurement), the drag's scale to its rel_sd,
        the accelerometer's bias to its prior."""
        self.wn_mps, self.we_mps = wn_mps, we_mps
        # a drag known exactly still gets a state; one whose scale is not a state holds ε at 0
        e = max(self.drag.rel_sd, 1e-3) ** 2 if scale_in_state(self.drag) else 0.0
        b = self.accel_bias_mps2**2 if self.bias_states else 0.0
        diag = (sd_mps**2, sd_mps**2, e, b, b)
        self.p = [[diag[i] if i == j else 0.0 for j in range(N_STATES)] for i in range(N_STATES)]

    # -- the filter ------------------------------------------------------------------------------------
    def predict(self, t_s: float) -> None:
        if self.t_s is not None and t_s > self.t_s:
            q = self.process_sd_mps**2 * (t_s - self.t_s)
            self.p[0][0] += q
            self.p[1][1] += q
        self.t_s = t_s if self.t_s is None else max(self.t_s, t_s)

    def update(self, t_s: float, v_ned: tuple[float, float, float], q_wxyz: tuple[float, float, float, float],
               f_body: tuple[float, ...]) -> None:  # fmt: skip
        """One sample: velocity NED (m/s), attitude (body → NED), specific force along body x, y and, where
        known, z (m/s²: the thrust, which the rotors' momentum drag grows with)."""
        f_body_xy = f_body[:2]
        thrust_ratio = abs(f_body[2]) / G_MPS2 if len(f_body) > 2 and math.isfinite(f_body[2]) else 1.0
        vals = (*v_ned, *q_wxyz, *f_body_xy)
        if not all(math.isfinite(x) for x in vals):
            return
        prev = self.t_s
        self.predict(t_s)
        if self.t_first_s is None:
            self.t_first_s = t_s
        m = self.mass_kg
        n = N_STATES
        x0 = (self.wn_mps, self.we_mps, self.scale_error, self.bx_mps2, self.by_mps2)
        p = self.p
        # ∂(body x, y)/∂(wn, we) = −Rᵀ's first two columns' x, y rows: the NED axes' body components
        ax, ay, _ = ned_to_body(1.0, 0.0, 0.0, *q_wxyz)
        cx, cy, _ = ned_to_body(0.0, 1.0, 0.0, *q_wxyz)
        # the first sample relinearises (an iterated EKF): at an unknown wind the drag's slope, and the
        # scale's share (∂h/∂ε = F/m, zero at zero air) are taken where the air is not
        mean = self.v_mean_ned or (v_ned[0], v_ned[1])
        dt_s = min(max(t_s - prev, 0.0), 1.0) if prev is not None else 0.0
        w_mean = min(dt_s / V_MEAN_TAU_S, 1.0)
        self.v_mean_ned = (mean[0] + w_mean * (v_ned[0] - mean[0]), mean[1] + w_mean * (v_ned[1] - mean[1]))
        learn = (scale_in_state(self.drag) and t_s - self.t_first_s >= SCALE_LEARN_AFTER_S
                 and math.hypot(v_ned[0] - mean[0], v_ned[1] - mean[1]) > SCALE_LEARN_EXCITATION_MPS)  # fmt: skip
        x = x0
        for _ in range(ITERATIONS_FIRST if not self.samples else 1):
            k = 1.0 + x[2]
            bx, by, _ = ned_to_body(v_ned[0] - x[0], v_ned[1] - x[1], v_ned[2], *q_wxyz)
            fx, fy = self.drag.force_n(bx, by, thrust_ratio)
            sx, sy = self.drag.slope_n_per_mps(bx, by, thrust_ratio)
            # h = (1 + ε)·F(v_b)/m + b; ∂h/∂w = (1 + ε)·slope/m · (the NED axes' body components); ∂h/∂ε = F/m;
            # ∂h/∂b = I
            h = ((k * sx / m * ax, k * sx / m * cx, fx / m, 1.0, 0.0),
                 (k * sy / m * ay, k * sy / m * cy, fy / m, 0.0, 1.0))
            dx = tuple(x0[i] - x[i] for i in range(n))
            innov = (f_body_xy[0] - k * fx / m - x[3] - sum(h[0][j] * dx[j] for j in range(n)),
                     f_body_xy[1] - k * fy / m - x[4] - sum(h[1][j] * dx[j] for j in range(n)))  # fmt: skip
            # P Hᵀ (n×2) and S = H P Hᵀ + R (2×2)
            pht = [[sum(p[i][j] * h[r][j] for j in range(n)) for r in range(2)] for i in range(n)]
            s00 = sum(h[0][i] * pht[i][0] for i in range(n))
            s01 = sum(h[0][i] * pht[i][1] for i in range(n))
            s11 = sum(h[1][i] * pht[i][1] for i in range(n))
            if x is x0:
                seen = 0.5 * (innov[0] ** 2 + innov[1] ** 2) - 0.5 * (s00 + s11)
                a = min(dt_s / NOISE_TAU_S, 1.0)
                self.noise_var = (1.0 - a) * self.noise_var + a * max(seen, 0.0)
            r = max(self.accel_sd_mps2**2, self.noise_var)
            s00 += r
            s11 += r
            det = s00 * s11 - s01 * s01
            if det <= 0 or not math.isfinite(det):
                return
            i00, i01, i11 = s11 / det, -s01 / det, s00 / det
            # K = P Hᵀ S⁻¹ (n×2); ε's row zero while it is only considered
            kg = [(row[0] * i00 + row[1] * i01, row[0] * i01 + row[1] * i11) for row in pht]
            if not learn:
                kg[2] = (0.0, 0.0)
            x = tuple(x0[i] + kg[i][0] * innov[0] + kg[i][1] * innov[1] for i in range(n))
        self.wn_mps, self.we_mps, self.scale_error = x[0], x[1], max(x[2], SCALE_MIN)
        self.bx_mps2, self.by_mps2 = x[3], x[4]
        # P ← P − K (P Hᵀ)ᵀ − (P Hᵀ) Kᵀ + K S Kᵀ: right for any gain (the optimal one reduces it to P − K H P)
        ks = [(g[0] * s00 + g[1] * s01, g[0] * s01 + g[1] * s11) for g in kg]
        new = [[p[i][j] - (kg[i][0] * pht[j][0] + kg[i][1] * pht[j][1]) - (pht[i][0] * kg[j][0] + pht[i][1] * kg[j][1])
                + (ks[i][0] * kg[j][0] + ks[i][1] * kg[j][1]) for j in range(n)] for i in range(n)]  # fmt: skip
        for i in range(n):
            new[i][i] = max(new[i][i], 0.0)
            for j in range(i):
                new[i][j] = new[j][i] = 0.5 * (new[i][j] + new[j][i])
        self.p = new
        self.samples += 1
        self.airspeed_mps = math.hypot(v_ned[0] - self.wn_mps, v_ned[1] - self.we_mps)
        self.slope_per_s = float(min(sx, sy)) / m

    # -- what it knows ---------------------------------------------------------------------------------
    @property
    def filter_sd_mps(self) -> float:
        """The filter's own 1 σ along its worse axis (the scale error's share included)."""
        return float(worse_axis_sd(self.p[0][0], self.p[0][1], self.p[1][1]))

    @property
    def scale_sd(self) -> float:
        return math.sqrt(max(self.p[2][2], 0.0))

    @property
    def model_sd_mps(self) -> float:
        """What the filter's states do not cover: an accelerometer bias seen through the drag's slope (and an
        assumed drag's error on the airspeed)."""
        bias = 0.0 if self.bias_states else self.accel_bias_mps2
        return model_sd(self.drag, self.airspeed_mps, bias, self.slope_per_s)

    @property
    def sd_mps(self) -> float:
        if not self.samples:
            return self.initial_sd_mps
        return math.hypot(self.filter_sd_mps, self.model_sd_mps)

    @property
    def wind_ned_mps(self) -> tuple[float, float, float]:
        return (self.wn_mps, self.we_mps, 0.0)
