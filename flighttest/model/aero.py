"""Rotor aerodynamics of descent: Peters' induced velocity, Onera's VRS/TWS criterion, WBS, the cone.

All functions are pure and vectorised over numpy arrays (scalars work too).

Conventions (CONVENTIONS §1-2): the aerodynamic formulas use the paper's *climb-positive* axial speed
``v_z = -w`` and in-plane speed ``v_H = u`` in the blade-disk (= body) frame. Quantities named
``*_n`` are normalised by the hover induced velocity ``v_h``; ``*_mps`` are in m/s.
"""

from __future__ import annotations

import math
from enum import IntEnum

import numpy as np

G_MPS2 = 9.80665

# Paper's values (§II-III). Every threshold below is a parameter with these as defaults.
ONERA_K = 6.0
ONERA_EPS_VRS = 0.4
ONERA_EPS_TWS = 0.2
CONE_DEG = 20.0


class Region(IntEnum):
    """Descent regime of one rotor disk (paper Fig. 1/9)."""

    NORMAL = 0
    VRS = 1
    TWS = 2
    WBS = 3


REGION_NAMES = {r: r.name for r in Region}


def hover_induced_velocity_mps(thrust_per_rotor_n, air_density_kgpm3, disk_area_m2):
    """Momentum-theory hover induced velocity ``v_h = sqrt(T / (2 rho A))`` (paper eq. 7), m/s."""
    return np.sqrt(np.asarray(thrust_per_rotor_n) / (2.0 * air_density_kgpm3 * disk_area_m2))


def induced_velocity_n(v_H_n, v_z_n, iterations: int = 64):
    """Normalised induced velocity ``λ = v_i/v_h`` solving Peters' equation ``λ·sqrt(μ² + (λ+η)²) = 1``.

    ``μ = v_H/v_h`` (in-plane), ``η = v_z/v_h`` (climb-positive). Vectorised bisection on a bracket
    that always holds exactly one root of the chosen branch, so the result is finite everywhere.

    Branch choice. Write ``g(λ) = λ·sqrt(μ² + (λ+η)²) − 1``; ``g(0) = −1`` and ``g → ∞``. For descent
    with ``η² ≥ 8μ²`` g has a local maximum at ``λ₁ = (−3η − sqrt(η² − 8μ²))/4`` and a local minimum
    at ``λ₂ = (−3η + sqrt(η² − 8μ²))/4``; when ``g(λ₁) ≥ 0 ≥ g(λ₂)`` there are up to three roots (the
    windmill region, e.g. ``η ≤ −2`` at ``μ = 0``). There we take the **smallest** root, the
    windmill-brake branch ``λ = (−η − sqrt(η² − 4))/2`` of classical momentum theory at ``μ = 0``: it is
    the branch that joins fast descent (``λ → 0`` as ``η → −∞``). Elsewhere the root is unique. The
    chosen branch jumps across the fold ``g(λ₁) = 0``; that fold lies far below the VRS (``η < −2``)
    so the Onera classification is unaffected by it.
    """
    mu = np.abs(np.asarray(v_H_n, dtype=float))
    eta = np.asarray(v_z_n, dtype=float)
    mu, eta = np.broadcast_arrays(mu, eta)

    def g(lam):
        return lam * np.sqrt(mu * mu + (lam + eta) ** 2) - 1.0

    disc = eta * eta - 8.0 * mu * mu
    has_fold = (eta < 0.0) & (disc >= 0.0)
    sq = np.sqrt(np.where(has_fold, disc, 0.0))
    lam1 = np.where(has_fold, (-3.0 * eta - sq) / 4.0, 0.0)
    lam2 = np.where(has_fold, (-3.0 * eta + sq) / 4.0, 0.0)
    windmill = has_fold & (g(lam1) >= 0.0)
    upper_any = np.maximum(-eta, 0.0) + 1.0  # g(upper_any) > 0 always (see docstring of tests)
    lo = np.where(windmill, 0.0, np.where(has_fold, lam2, 0.0))
    hi = np.where(windmill, lam1, upper_any)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        pos = g(mid) > 0.0
        hi = np.where(pos, mid, hi)
        lo = np.where(pos, lo, mid)
    return 0.5 * (lo + hi)


def onera_epsilon_n(v_H_n, v_z_n, k: float = ONERA_K, lam_n=None):
    """Onera tip-vortex speed ``ε = sqrt((v_H/k)² + (v_i/2 + v_z)²)``, normalised (paper eq. 8)."""
    if lam_n is None:
        lam_n = induced_velocity_n(v_H_n, v_z_n)
    return np.sqrt((np.asarray(v_H_n) / k) ** 2 + (0.5 * lam_n + np.asarray(v_z_n)) ** 2)


def classify_n(
    v_H_n,
    v_z_n,
    k: float = ONERA_K,
    eps_vrs: float = ONERA_EPS_VRS,
    eps_tws: float = ONERA_EPS_TWS,
    cone_deg: float = CONE_DEG,
):
    """Region (``Region`` codes as int array) of normalised blade-frame velocities.

    TWS where ``ε ≤ eps_tws``, VRS where ``ε ≤ eps_vrs``. Onera cannot see the WBS; following the
    paper's wind-tunnel finding (Fig. 9) we call WBS what lies inside the 20° forbidden cone
    (``−v_z > tan(cone)·|v_H|``) *below* the VRS (``v_i/2 + v_z < 0``, the tip vortices are blown
    up through the disk). Slow descent above the VRS is normal.
    """
    v_H_n = np.abs(np.asarray(v_H_n, dtype=float))
    v_z_n = np.asarray(v_z_n, dtype=float)
    lam = induced_velocity_n(v_H_n, v_z_n)
    eps = onera_epsilon_n(v_H_n, v_z_n, k, lam)
    in_cone = -v_z_n > math.tan(math.radians(cone_deg)) * v_H_n
    below = 0.5 * lam + v_z_n < 0.0
    out = np.full(np.shape(eps), int(Region.NORMAL), dtype=np.int8)
    out[in_cone & below] = Region.WBS
    out[eps <= eps_vrs] = Region.VRS
    out[eps <= eps_tws] = Region.TWS
    return out


def onera_vertical_boundary_n(eps_cr: float = ONERA_EPS_VRS) -> float:
    """Normalised descent rate ``w/v_h`` at which a straight-down descent (v_H = 0) enters the VRS.

    At ``μ = 0`` on the normal branch ``λ(λ + η) = 1``; the upper VRS edge ``λ/2 + η = ε_cr`` gives
    ``η² − 3ε_cr·η + 2ε_cr² − 1/2 = 0``; the root with ``η < 0`` is the entry point. For ε_cr = 0.4
    it is 0.1349: the Mambo (v_h = 4.36 m/s) meets the VRS at 0.59 m/s, the paper's observed 0.6 m/s.
    """
    b = 3.0 * eps_cr
    c = 2.0 * eps_cr * eps_cr - 0.5
    eta = 0.5 * (b - math.sqrt(b * b - 4.0 * c))
    return -eta


def guard_bound_mps(u_mps, w_allow_mps: float, cone_deg: float = CONE_DEG, margin_mps: float = 0.0):
    """Largest permitted descent-through-disk speed ``w`` for in-plane speed ``u`` (m/s).

    ``max(w_allow, tan(cone)·u) − margin``, never below 0: climbing (w ≤ 0) is always allowed.
    Works on floats and arrays with plain arithmetic so that the guard's per-sample call is cheap.
    """
    t = math.tan(math.radians(cone_deg))
    a = t * u_mps
    hi = 0.5 * (a + w_allow_mps + abs(a - w_allow_mps)) - margin_mps
    return 0.5 * (hi + abs(hi))


def guard_margin_mps(w_mps, u_mps, w_allow_mps: float, cone_deg: float = CONE_DEG, margin_mps: float = 0.0):
    """Signed margin (m/s) to the guard boundary along ``w``: ≥ 0 allowed, < 0 forbidden.

    Forbidden iff ``w > max(w_allow, tan(cone)·u) − margin`` while descending through the disk.
    """
    return guard_bound_mps(u_mps, w_allow_mps, cone_deg, margin_mps) - w_mps
