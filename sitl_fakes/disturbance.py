"""The fake's VRS/WBS truth: where rotor thrust drops and fluctuates, and by how much.

Geometry comes from ``flighttest.model.frames`` (air-relative blade-frame velocity ``w``, ``u``) and region
labels from ``flighttest.model.aero``; the *truth parameters* come from the command line and are independent
of what flighttest believes about the vehicle:

- ``onset_mps``: straight-down descent rate ``w`` (m/s, through the disk) at which the disturbance
  starts. Default: Onera's VRS boundary at ``v_H = 0`` for the vehicle's physical ``v_h``.
- ``cone_deg``: with in-plane speed ``u`` the disturbed region is ``w > max(onset, tan(cone)·u)``
  (the paper's forbidden cone, with the onset as the vertical floor).
- ``severity``: multiplies thrust loss and fluctuation (1 = nominal, 0 = no disturbance).
- ``seed``: the fluctuation noise.

Model, with ``depth_n = (w − max(onset, tan(cone)·u)) / v_h`` (> 0 inside):
- VRS/TWS: every rotor loses ``L = severity·min(0.5, 0.8·depth_n)`` of its thrust and fluctuates by
  ``σ = severity·min(0.6, depth_n)`` (relative, one standard deviation), as coloured noise
  (correlation time 0.1 s, i.e. the few-Hz buffeting of a ring vortex) half shared by all rotors and
  half per rotor, so the vehicle is both dropped and rocked. Loss raises the sink rate, which
  deepens the state: deep enough the rotors cannot hold attitude and the vehicle departs.
- WBS band (Onera's windmill side of the cone, see ``aero.classify_n``): fluctuation
  ``σ = severity·0.15`` with no mean loss.
- Outside: exactly no disturbance (factor 1).

Labels (``aero.Region``) come from ``aero.classify_n`` on velocities rescaled along ``w`` so that its
vertical VRS entry falls on the truth onset, clipped to the truth region (outside → NORMAL, inside
but Onera-normal → VRS). ``classify_n`` is tabulated once at start-up: the step costs a lookup.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import numpy as np

from flighttest.model import aero

CORRELATION_TIME_S = 0.1
SHARED_FRACTION = 0.5
_MU_MAX, _ETA_MIN, _ETA_MAX, _STEP = 4.0, -4.0, 1.0, 0.02


@dataclass(frozen=True)
class VrsTruth:
    onset_mps: float
    cone_deg: float
    severity: float
    seed: int
    v_h_mps: float

    def __post_init__(self):
        for name in ("onset_mps", "v_h_mps"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number (got {v})")
        if not 0.0 < self.cone_deg < 90.0:
            raise ValueError(f"cone must lie in (0, 90) degrees (got {self.cone_deg})")
        if not (math.isfinite(self.severity) and self.severity >= 0):
            raise ValueError(f"severity must be ≥ 0 (got {self.severity})")


def blade_velocity_mps(vn, ve, vd, qw, qx, qy, qz, wn=0.0, we=0.0, wd=0.0) -> tuple[float, float]:
    """The air's velocity through the rotor disk, in the body frame: ``w`` (m/s, > 0 when the air
    flows up through the disk, i.e. the vehicle sinks into it) and ``u`` (in the disk's plane).

    The quaternion (w, x, y, z) turns body FRD into NED; its conjugate turns the air-relative NED
    velocity into the body: ``v' = v + 2 r × (r × v + w v)`` with ``r`` the conjugate's vector part.
    """
    ax, ay, az = vn - wn, ve - we, vd - wd
    rx, ry, rz = -qx, -qy, -qz
    cx = ry * az - rz * ay + qw * ax
    cy = rz * ax - rx * az + qw * ay
    cz = rx * ay - ry * ax + qw * az
    bx = ax + 2.0 * (ry * cz - rz * cy)
    by = ay + 2.0 * (rz * cx - rx * cz)
    bz = az + 2.0 * (rx * cy - ry * cx)
    return bz, math.hypot(bx, by)


def default_onset_mps(v_h_mps: float) -> float:
    """Onera's straight-down VRS entry for this ``v_h`` (what the physics says, not the profile)."""
    return aero.onera_vertical_boundary_n(aero.ONERA_EPS_VRS) * v_h_mps


class Disturbance:
    """Per-step thrust factors for the four rotors, plus what the truth log records."""

    def __init__(self, truth: VrsTruth):
        self.truth = truth
        self.tan_cone = math.tan(math.radians(truth.cone_deg))
        self.rng = random.Random(truth.seed)
        self.noise = [0.0] * 5  # shared + four rotors
        # stretch along w so Onera's vertical VRS entry lands on the truth onset
        self.w_scale = aero.onera_vertical_boundary_n(aero.ONERA_EPS_VRS) * truth.v_h_mps / truth.onset_mps
        mu = np.arange(0.0, _MU_MAX + _STEP / 2, _STEP)
        eta = np.arange(_ETA_MIN, _ETA_MAX + _STEP / 2, _STEP)
        m, e = np.meshgrid(mu, eta, indexing="ij")
        self._table = aero.classify_n(m, e, cone_deg=truth.cone_deg).tolist()
        self._n_mu, self._n_eta = len(mu), len(eta)
        # outputs of the last step
        self.w_mps = self.u_mps = self.depth_n = 0.0
        self.region = int(aero.Region.NORMAL)
        self.loss = 0.0
        self.sigma = 0.0
        self.dT_T = 0.0  # collective relative thrust change (mean over rotors)
        self.factors = [1.0, 1.0, 1.0, 1.0]

    def label(self, w_mps: float, u_mps: float) -> int:
        v_h = self.truth.v_h_mps
        i = min(max(round(u_mps / v_h / _STEP), 0), self._n_mu - 1)
        j = min(max(round((-w_mps * self.w_scale / v_h - _ETA_MIN) / _STEP), 0), self._n_eta - 1)
        return self._table[i][j]

    def step(self, dt_s, vn, ve, vd, qw, qx, qy, qz, wn, we, wd) -> list[float]:
        w, u = blade_velocity_mps(vn, ve, vd, qw, qx, qy, qz, wn, we, wd)
        self.w_mps, self.u_mps = w, u
        bound = max(self.truth.onset_mps, self.tan_cone * u)
        depth = (w - bound) / self.truth.v_h_mps
        self.depth_n = depth
        f = self.factors
        if depth <= 0.0 or self.truth.severity == 0.0:
            self.region = int(aero.Region.NORMAL)
            self.loss = self.sigma = self.dT_T = 0.0
            f[0] = f[1] = f[2] = f[3] = 1.0
            return f
        region = self.label(w, u)
        if region == aero.Region.NORMAL:
            region = int(aero.Region.VRS)
        self.region = region
        sev = self.truth.severity
        if region == aero.Region.WBS:
            loss, sigma = 0.0, 0.15 * sev
        else:
            loss, sigma = sev * min(0.5, 0.8 * depth), sev * min(0.6, depth)
        self.loss, self.sigma = loss, sigma
        decay = math.exp(-dt_s / CORRELATION_TIME_S)
        kick = math.sqrt(1.0 - decay * decay)
        n = self.noise
        g = self.rng.gauss
        for k in range(5):
            n[k] = decay * n[k] + kick * g(0.0, 1.0)
        a, b = math.sqrt(SHARED_FRACTION), math.sqrt(1.0 - SHARED_FRACTION)
        total = 0.0
        for i in range(4):
            fi = 1.0 - loss + sigma * (a * n[0] + b * n[i + 1])
            fi = max(fi, 0.0)
            f[i] = fi
            total += fi
        self.dT_T = total / 4.0 - 1.0
        return f
