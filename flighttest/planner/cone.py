"""The VRS/WBS velocity constraint as the optimiser sees it (smooth, sound) and as we check it (exact).

Physical statement (CONVENTIONS §2, paper Definition 1): in the blade-disk (= body) frame, with
``w = v_b,z`` (air flowing up through the disk) and ``u = |in-plane air speed|``, the state is
allowed iff ``w ≤ max(w_allow, tan(cone)·u) − margin`` or ``w ≤ 0``. The paper's optimisation used
the pure cone: ``w_allow = 0``, ``margin = 0``, i.e. ``w ≤ tan(20°)·|u|``.

**Formulation (why it is sound).** The set is non-convex and non-smooth: ``|u|`` has two branches
(the paper's ``C ≥ 0`` keeps only one), and ``max`` has a kink. We replace every kink by a smooth
function that lies *below* it, so the smooth constraint is a subset of the true one:

* ``|u| ≥ sabs(u) = sqrt(u² + δ²) − δ``  (equal at 0, within δ elsewhere),
* ``max(a, b) ≥ smax(a, b) = (a + b + sqrt((a−b)² + δ²))/2 − δ/2``,
* ``max(0, x) ≥ ppos(x)``: 0 for x ≤ 0, ``x²/(2δ)`` up to δ, ``x − δ/2`` above (C¹).

A point IPOPT accepts is therefore allowed by the exact test (up to the solver tolerance), and as
δ → 0 the smooth set fills the true one (the loss is at most ``tan(cone)·δ`` in ``w``). Both
branches of ``|u|`` live in one smooth function, so the optimiser can cross ``u = 0`` (where it
must have ``w ≤ 0``) instead of being locked to one sign as with the paper's one-branch ``C``. The
remaining non-convexity (which side to pass, how many reversals) is handled by solving from several
initial guesses and keeping the best (``planar.py``), not by binaries or complementarity
constraints, which IPOPT handles badly (degenerate multipliers at ``u⁺u⁻ = 0``).

The exact check of a finished trajectory uses ``flighttest.model.aero.guard_margin_mps`` — the same
function the flying guard uses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from flighttest.model.aero import CONE_DEG, guard_margin_mps

DEFAULT_SMOOTHING_MPS = 0.02


def sabs(x, delta: float):
    """Smooth lower bound of ``|x|``: ``sqrt(x² + δ²) − δ``."""
    return ca.sqrt(x * x + delta * delta) - delta


def smax(a, b, delta: float):
    """Smooth lower bound of ``max(a, b)``."""
    d = a - b
    return 0.5 * (a + b + ca.sqrt(d * d + delta * delta)) - 0.5 * delta


def ppos(x, delta: float):
    """C¹ lower bound of ``max(0, x)`` that is exactly 0 for ``x ≤ 0``."""
    return ca.if_else(x <= 0, 0, ca.if_else(x < delta, x * x / (2 * delta), x - 0.5 * delta))


@dataclass(frozen=True)
class VelocityConstraint:
    """Allowed iff ``w ≤ max(w_allow, tan(cone)·u) − margin`` or ``w ≤ 0`` (all m/s).

    ``w_allow_mps = 0`` and ``margin_mps = 0`` is the paper's pure cone; the guard's region uses the
    vehicle's ``w_allow`` and margin.
    """

    cone_deg: float = CONE_DEG
    w_allow_mps: float = 0.0
    margin_mps: float = 0.0
    smoothing_mps: float = DEFAULT_SMOOTHING_MPS

    @property
    def name(self) -> str:
        return "cone" if self.w_allow_mps <= 0 else "guard"

    def slack_casadi(self, w, u=None, u_sq=None):
        """Smooth expression that must be ``≥ 0``: a sound inner approximation of the exact set.

        Give the in-plane air speed as ``u`` (signed, planar) or as its square ``u_sq`` (3D, where
        ``u = hypot(v_b,x, v_b,y)``; ``sqrt(u² + δ²) − δ`` stays smooth at ``u = 0``).
        """
        d = self.smoothing_mps
        s = sabs(u, d) if u_sq is None else ca.sqrt(u_sq + d * d) - d
        b = math.tan(math.radians(self.cone_deg)) * s
        if self.w_allow_mps > 0:
            b = smax(self.w_allow_mps, b, d)
        if self.margin_mps > 0:
            b = ppos(b - self.margin_mps, d)
        return b - w

    def margin(self, w_mps, u_mps) -> np.ndarray:
        """Exact signed margin (m/s, ≥ 0 allowed), the guard's own formula."""
        return np.asarray(guard_margin_mps(w_mps, np.abs(u_mps), self.w_allow_mps, self.cone_deg, self.margin_mps))

    def summary(self) -> dict:
        return {
            "constraint": self.name,
            "cone_deg": self.cone_deg,
            "w_allow_mps": self.w_allow_mps,
            "margin_mps": self.margin_mps,
            "smoothing_mps": self.smoothing_mps,
        }


def planar_blade_velocity(vy, vz, phi, cos=np.cos, sin=np.sin):
    """Body-frame in-plane ``u = v_b,y`` and through-disk ``w = v_b,z`` for roll ``φ`` (CONVENTIONS §2).

    ``v_b,y = cosφ·V_Y + sinφ·V_Z``, ``v_b,z = −sinφ·V_Y + cosφ·V_Z`` (air-relative velocities).
    Pass ``cos=ca.cos, sin=ca.sin`` for symbolic use.
    """
    c, s = cos(phi), sin(phi)
    return c * vy + s * vz, -s * vy + c * vz
