"""The wind the live guard judges with: every estimate flighttest has, each with its uncertainty, fused.

- flighttest's own (``flighttest.model.wind_estimate.WindFilter``, from the IMU's specific force, the
  attitude and the velocity with the profile's drag model), fed while the vehicle flies; it starts from
  the operator's wind where there is one;
- the operator's (``--wind-ned``, a measurement on the ground): a prior, with its standard deviation;
- the autopilot's report (``WIND_COV``), used while fresh and only when it is an estimate: a report of
  exactly zero is what an estimator that does not estimate the wind sends, not a calm;
- nothing known: calm, with ``UNKNOWN_SD_MPS``.

The fused wind is the inverse-variance mean, and its uncertainty carries the estimates' disagreement too
(the variance of the mixture), so two sources that contradict each other widen the guard's margin rather
than narrow it. The guard judges the worst air within ``WIND_COVERAGE_SIGMAS`` of it
(``flighttest.model.frames.worst_blade_velocity_mps``).

No estimator reports the air's vertical motion, and an updraft moves ``w`` one for one. The guard allows an
updraft of ``UPDRAFT_SIGMAS`` × the gusts' 1 σ: the larger of the operator's (``[guard] gust_sd_mps``) and
``GustMeter``'s, the spread of flighttest's own horizontal estimate while the vehicle holds still (climb,
settle, hover; not the descent, whose manoeuvres move the estimate too) less the spread it shows in steady air.
That measure sees only the slow part of the gusts, which the estimate follows: on the fake it covered 37-91 % of
the updrafts (bench/RESULTS.md, "Updrafts in the guard"); on a gusty day the operator's figure is the guard's.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from flighttest.model.aero import G_MPS2
from flighttest.model.drag import DragModel
from flighttest.model.frames import GuardRegion, worst_blade_velocity_mps
from flighttest.model.trajectory import Trajectory
from flighttest.model.wind_estimate import WindFilter

# a horizontal wind within this many σ of the estimate covers 95 % of a 2-D normal distribution
WIND_COVERAGE_SIGMAS = 2.45
WIND_REPORT_MAX_AGE_S = 2.0  # PX4 and the fake send WIND_COV at 2 Hz or more: older is not the wind now
REPORT_SD_UNKNOWN_MPS = 1.0  # a report that gives no accuracy
PRIOR_SD_MPS = 1.0  # a wind measured on the ground, at the vehicle's height: shear and gusts
MIN_SD_MPS = 0.05  # no estimate of the wind is better than this
UNKNOWN_SD_MPS = 1.0  # no drag model, no prior, no report: calm assumed, this unsure
FRESH_STATE_S = 0.1  # a specific-force sample is paired only with a velocity and attitude this fresh
# the gusts: the spread of flighttest's own estimate over the last GUST_WINDOW_S of its settled samples (its
# 1 σ below GUST_SETTLED_SD_MPS: not the converging start), less GUST_FLOOR_MPS, above the most it spread in
# still or steady air (0.002-0.043 m/s on both SITLs and the fakes); the guard allows an updraft of
# UPDRAFT_SIGMAS × that (one-sided 97.5 %; bench/RESULTS.md, "Updrafts in the guard")
GUST_WINDOW_S = 5.0
GUST_SETTLED_SD_MPS = 0.3
GUST_FLOOR_MPS = 0.05
GUST_MIN_SAMPLES = 25
UPDRAFT_SIGMAS = 1.96


@dataclass(frozen=True)
class WindEstimate:
    ned_mps: tuple[float, float, float]
    sd_mps: float  # horizontal, 1 σ per axis
    source: str
    gust_sd_mps: float = 0.0  # the gusts' 1 σ (GustMeter): the updraft the guard allows

    @property
    def radius_mps(self) -> float:
        """How far from ``ned_mps`` the guard looks for the worst air."""
        return WIND_COVERAGE_SIGMAS * self.sd_mps

    @property
    def updraft_mps(self) -> float:
        """The updraft the guard allows: no estimator reports one."""
        return UPDRAFT_SIGMAS * self.gust_sd_mps

    def describe(self) -> dict[str, object]:
        return {"wind_ned_mps": [round(x, 3) for x in self.ned_mps], "wind_sd_mps": round(self.sd_mps, 3),
                "wind_source": self.source, "gust_sd_mps": round(self.gust_sd_mps, 3)}  # fmt: skip


def fuse(estimates: Sequence[WindEstimate]) -> WindEstimate:
    """Inverse-variance mean; its variance (1 / the summed precision) widened by the weighted spread of the
    estimates about it, the larger horizontal axis's."""
    if len(estimates) == 1:
        return estimates[0]
    weights = [1.0 / max(e.sd_mps, MIN_SD_MPS) ** 2 for e in estimates]
    total = sum(weights)
    mean = tuple(sum(w * e.ned_mps[i] for w, e in zip(weights, estimates)) / total for i in range(3))
    spread = max(sum(w * (e.ned_mps[i] - mean[i]) ** 2 for w, e in zip(weights, estimates)) / total for i in (0, 1))
    return WindEstimate(mean, math.sqrt(1.0 / total + spread), "+".join(e.source for e in estimates))


class WindReport(Protocol):
    wind_ned_mps: tuple[float, float, float] | None
    wind_accuracy_mps: float
    t_wind: float | None


def autopilot_report(st: WindReport, now_s: float) -> WindEstimate | None:
    """The autopilot's wind while it is a fresh estimate, else None."""
    w = st.wind_ned_mps
    if w is None or st.t_wind is None or now_s - st.t_wind > WIND_REPORT_MAX_AGE_S:
        return None
    if not all(math.isfinite(x) for x in w) or all(x == 0.0 for x in w):
        return None
    acc = st.wind_accuracy_mps
    sd = acc if math.isfinite(acc) and acc > 0 else REPORT_SD_UNKNOWN_MPS
    return WindEstimate(tuple(float(x) for x in w), sd, "autopilot")


class FlightState(Protocol):
    """What the filter is fed from (``flighttest.flying.link.TelemetryState``)."""

    vn_mps: float
    ve_mps: float
    vd_mps: float
    t_posvel: float | None
    q: tuple[float, float, float, float]
    t_att: float | None
    accel_frd_mps2: tuple[float, float, float]


@dataclass
class GustMeter:
    """The gusts' 1 σ from the spread of flighttest's own wind estimate while the vehicle holds still."""

    window_s: float = GUST_WINDOW_S
    samples: deque = field(default_factory=deque)  # (t_s, wn_mps, we_mps)

    def add(self, t_s: float, wn_mps: float, we_mps: float) -> None:
        self.samples.append((t_s, wn_mps, we_mps))
        while self.samples and self.samples[0][0] < t_s - self.window_s:
            self.samples.popleft()

    @property
    def sd_mps(self) -> float:
        """The worse axis's standard deviation over the window less ``GUST_FLOOR_MPS`` (0 with too few samples:
        the wind's own uncertainty covers a vehicle that has not yet held still)."""
        if len(self.samples) < GUST_MIN_SAMPLES:
            return 0.0
        a = np.asarray(self.samples, float)
        return max(float(max(a[:, 1].std(), a[:, 2].std())) - GUST_FLOOR_MPS, 0.0)


@dataclass
class WindSources:
    """The estimates available to one flight; ``current`` fuses those valid now."""

    prior: WindEstimate | None = None  # the operator's
    estimator: WindFilter | None = None  # flighttest's own (None: the profile has no drag model)
    unknown_sd_mps: float = UNKNOWN_SD_MPS
    gusts: GustMeter = field(default_factory=GustMeter)
    stated_gust_sd_mps: float = 0.0  # the operator's (``[guard] gust_sd_mps``): the gusts are never less

    @classmethod
    def for_flight(cls, drag: DragModel | None, mass_kg: float, prior: WindEstimate | None,
                   gust_sd_mps: float = 0.0) -> WindSources:  # fmt: skip
        estimator = None
        if drag is not None:
            estimator = WindFilter(drag, mass_kg)
            if prior is not None:  # the filter starts from the operator's wind, so the prior counts once
                estimator.seed(prior.ned_mps[0], prior.ned_mps[1], prior.sd_mps)
        return cls(prior, estimator, stated_gust_sd_mps=gust_sd_mps)

    @property
    def gust_sd_mps(self) -> float:
        """The gusts' 1 σ: the larger of the operator's and the measured."""
        return max(self.stated_gust_sd_mps, self.gusts.sd_mps)

    def on_imu(self, t_s: float, st: FlightState, measure_gusts: bool = False) -> None:
        """A specific-force sample, while the vehicle flies (the caller judges that): into the filter,
        paired with the latest velocity and attitude if both are fresh; with ``measure_gusts`` (the vehicle
        holds still) its estimate into the gust meter once it has settled."""
        f = self.estimator
        if f is None or st.t_posvel is None or st.t_att is None:
            return
        if t_s - st.t_posvel > FRESH_STATE_S or t_s - st.t_att > FRESH_STATE_S:
            return
        f.update(t_s, (st.vn_mps, st.ve_mps, st.vd_mps), st.q, st.accel_frd_mps2)
        if measure_gusts and f.samples and f.sd_mps < GUST_SETTLED_SD_MPS:
            self.gusts.add(t_s, f.wn_mps, f.we_mps)

    def own(self, now_s: float) -> WindEstimate | None:
        """flighttest's estimate, its uncertainty grown by the time since its last sample."""
        f = self.estimator
        if f is None or not f.samples:
            return None
        age = max(now_s - (f.t_s or now_s), 0.0)
        sd = math.sqrt(f.sd_mps**2 + f.process_sd_mps**2 * age)
        return WindEstimate(f.wind_ned_mps, sd, "flighttest")

    def current(self, st: WindReport, now_s: float) -> WindEstimate:
        own = self.own(now_s)
        found = [e for e in (own, autopilot_report(st, now_s), None if own else self.prior) if e is not None]
        if not found:
            return WindEstimate((0.0, 0.0, 0.0), self.unknown_sd_mps, "assumed calm", self.gust_sd_mps)
        return replace(fuse(found), gust_sd_mps=self.gust_sd_mps)


# -- the plan in the wind that blows ---------------------------------------------------------------------


def plan_margin_in_wind(traj: Trajectory, region: GuardRegion, drag: DragModel | None, mass_kg: float,
                        wind: WindEstimate) -> tuple[float, float]:  # fmt: skip
    """The plan's smallest guard margin (m/s) and its time (s, from the plan's start) in this wind, at the
    worst air its uncertainty and gusts allow, as the guard will judge it: the air-relative velocity, and the disk
    tilted as the plan's acceleration *and the drag of that air* need (thrust along −z_body balances
    both), whatever attitude the plan was made with."""
    df = traj.df
    v = df[["vn_mps", "ve_mps", "vd_mps"]].to_numpy(float)
    a = df[["an_mps2", "ae_mps2", "ad_mps2"]].to_numpy(float)
    v_air = v - np.asarray(wind.ned_mps, float)
    drag_per_kg = drag.mean_linear_n_per_mps(float(np.hypot(*v_air[:, :2].T).max())) / mass_kg if drag else 0.0
    # m·a = T + D + m·g  →  thrust direction −z_b ∥ a − g − D/m, with D = −drag·v_air
    z_b = np.column_stack([-a[:, 0] - drag_per_kg * v_air[:, 0], -a[:, 1] - drag_per_kg * v_air[:, 1],
                           G_MPS2 - a[:, 2] - drag_per_kg * v_air[:, 2]])  # fmt: skip
    z_b /= np.maximum(np.linalg.norm(z_b, axis=1, keepdims=True), 1e-9)
    w = np.einsum("ij,ij->i", v_air, z_b)
    u = np.linalg.norm(v_air - w[:, None] * z_b, axis=1)
    tilt_sin = np.hypot(z_b[:, 0], z_b[:, 1])
    margin = np.asarray(region.margin(*worst_blade_velocity_mps(w, u, tilt_sin, wind.radius_mps, wind.updraft_mps)),
                        float)  # fmt: skip
    i = int(np.argmin(margin))
    return float(margin[i]), float(df["t_s"].iloc[i] - df["t_s"].iloc[0])


def rotate_plan(traj: Trajectory, angle_rad: float) -> Trajectory:
    """The plan turned about the vertical by ``angle_rad`` (north towards east): a plan made for a wind from
    one direction, for the same wind from another (gravity is the same whichever way the wind blows)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    df = traj.df.copy()
    for x, y in (("n_m", "e_m"), ("vn_mps", "ve_mps"), ("an_mps2", "ae_mps2")):
        n, e = df[x].to_numpy(float), df[y].to_numpy(float)
        df[x], df[y] = c * n - s * e, s * n + c * e
    df["yaw_deg"] = (df["yaw_deg"] + math.degrees(angle_rad) + 180.0) % 360.0 - 180.0
    if traj.has_attitude():  # q' = q_z(angle) ⊗ q
        hw, hz = math.cos(angle_rad / 2), math.sin(angle_rad / 2)
        qw, qx, qy, qz = (df[k].to_numpy(float) for k in ("qw", "qx", "qy", "qz"))
        df["qw"], df["qx"] = hw * qw - hz * qz, hw * qx - hz * qy
        df["qy"], df["qz"] = hw * qy + hz * qx, hw * qz + hz * qw
    meta = dict(traj.meta)
    meta["rotated_deg"] = round(math.degrees(angle_rad), 3)
    return Trajectory(df, meta)
