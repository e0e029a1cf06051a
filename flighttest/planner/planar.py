"""Planar minimum-time descent (paper §IV-B, eq. 2Deom) with the body-frame VRS/WBS constraint.

Model (NED, Z down, roll φ about the north axis): states ``(Y, V_Y, Z, V_Z, φ)``, inputs
``(f_coll, ω)`` with ``f_coll`` the collective thrust per unit mass (m/s²) and ω the roll rate:

    Ẏ = V_Y,  V̇_Y = f_coll·sinφ,  Ż = V_Z,  V̇_Z = −f_coll·cosφ + g,  φ̇ = ω.

Hover to hover: everything zero at t = 0 except ``f_coll = g``; at ``t_f`` ``Z = height``, V = 0,
``φ ≡ 0`` (mod 2π when flips are allowed: a full roll ends level too), ``f_coll = g``, ``ω = 0``;
final Y fixed or free within its bound. Cost: ``t_f``.

Constraint: ``VelocityConstraint`` on the air-relative body-frame velocity (``cone.py`` explains the
smooth, sound formulation of both ``|u|`` branches). Non-convexity is handled by solving from
several kinematically consistent initial guesses (oblique either way, zig-zags with 1–3 reversals,
flips forward/backward and there-and-back) on a coarse mesh, and refining the best on a finer mesh
warm-started from it (the skeleton is ``multistart``'s; this module gives it the starts and the
mesh refinement). The winner is re-simulated at 1 kHz with the interpolated controls to
measure the true worst margin between the nodes.
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field, replace

import casadi as ca
import numpy as np

from flighttest.errors import FlighttestError
from flighttest.model.aero import G_MPS2
from flighttest.planner.cone import VelocityConstraint, planar_blade_velocity
from flighttest.planner.multistart import attempt_record, families_agree, multistart_refined
from flighttest.planner.ocp import (
    MinTimeOcp,
    OcpResult,
    OcpSpec,
    SolvedOcp,
    refined_mesh,
    resample_guess,
    rk4_resimulate_compiled,
    violation_times,
)

NX, NU = 5, 2
IY, IVY, IZ, IVZ, IPHI = range(NX)


@dataclass(frozen=True)
class PlanarProblem:
    """Inputs and bounds of one planar problem (m, m/s, m/s², rad, rad/s)."""

    height_m: float = 5.0
    y_bound_m: float = 15.0
    y_final: str = "fixed"  # "fixed" (= y_final_m) or "free" (anywhere within ±y_bound)
    y_final_m: float = 0.0
    phi_bound_rad: float | None = math.pi / 3  # None: free (flips allowed)
    v_bound_mps: float = 10.0
    z_bound_m: float = 15.0
    f_min_mps2: float = -20.0
    f_max_mps2: float = 20.0
    omega_max_rps: float = 1.0
    constraint: VelocityConstraint = field(default_factory=VelocityConstraint)
    wind_y_mps: float = 0.0
    wind_z_mps: float = 0.0
    n_intervals: int = 80
    n_coarse: int = 40
    # Extra margin (m/s) the NLP keeps from the constraint so that the flown, continuous trajectory
    # respects it *between* the mesh nodes too (riding the cone, the chord between two nodes cuts
    # the V of |u| where the side changes). Not part of the reported constraint.
    backoff_mps: float = 0.0

    def validate(self) -> None:
        def pos(name, v):
            if not (math.isfinite(v) and v > 0):
                raise FlighttestError(f"planar problem: {name} must be a positive number (got {v!r})")

        pos("height", self.height_m)
        pos("y bound", self.y_bound_m)
        pos("speed bound", self.v_bound_mps)
        pos("omega bound", self.omega_max_rps)
        if self.phi_bound_rad is not None:
            pos("phi bound", self.phi_bound_rad)
        if self.y_final not in ("fixed", "free"):
            raise FlighttestError(f"planar problem: y_final must be 'fixed' or 'free' (got {self.y_final!r})")
        if abs(self.y_final_m) > self.y_bound_m:
            raise FlighttestError("planar problem: final Y lies outside the Y bound")
        if not (self.f_min_mps2 < G_MPS2 < self.f_max_mps2):
            raise FlighttestError(
                f"planar problem: thrust range [{self.f_min_mps2:g}, {self.f_max_mps2:g}] m/s² must contain "
                f"hover (g = {G_MPS2:.2f})"
            )
        if self.height_m > self.z_bound_m + 1e-9:
            raise FlighttestError("planar problem: height exceeds the Z bound")
        if self.n_intervals < 10 or self.n_coarse < 10:
            raise FlighttestError("planar problem: need at least 10 mesh intervals")

    def summary(self) -> dict:
        return {
            "height_m": self.height_m,
            "y_bound_m": self.y_bound_m,
            "y_final": self.y_final,
            "y_final_m": self.y_final_m if self.y_final == "fixed" else None,
            "phi_bound_deg": None if self.phi_bound_rad is None else math.degrees(self.phi_bound_rad),
            "v_bound_mps": self.v_bound_mps,
            "z_bound_m": self.z_bound_m,
            "f_min_mps2": self.f_min_mps2,
            "f_max_mps2": self.f_max_mps2,
            "omega_max_rps": self.omega_max_rps,
            "wind_y_mps": self.wind_y_mps,
            "wind_z_mps": self.wind_z_mps,
            "n_intervals": self.n_intervals,
            **self.constraint.summary(),
        }


def dynamics(x, u, sin=ca.sin, cos=ca.cos):
    """Right-hand side of eq. (2Deom); works on CasADi symbols and (with numpy sin/cos) arrays."""
    f, om = u[0], u[1]
    phi = x[IPHI]
    out = [x[IVY], f * sin(phi), x[IVZ], -f * cos(phi) + G_MPS2, om]
    return ca.vertcat(*out) if isinstance(x, ca.SX | ca.MX) else np.array(out)


def _dynamics_np(x, u):
    return dynamics(x, u, np.sin, np.cos)


def resimulate(r: OcpResult, rate_hz: float = 1000.0):
    """``(t, x, u)`` of the solution's controls integrated from its first state at ``rate_hz``."""
    return rk4_resimulate_compiled(dynamics, r.t_s, r.x[0], r.u, rate_hz)


@dataclass
class PlanarSolution(SolvedOcp):
    problem: PlanarProblem
    result: OcpResult
    attempts: list[dict]
    solve_s: float
    check: dict  # fine re-simulation figures

    def blade_velocity(self, x: np.ndarray | None = None):
        x = self.result.x if x is None else x
        p = self.problem
        return planar_blade_velocity(x[:, IVY] - p.wind_y_mps, x[:, IVZ] - p.wind_z_mps, x[:, IPHI])

    def manoeuvre(self) -> dict:
        return classify(self.result.t_s, self.result.x, self.problem.height_m)


def classify(t_s: np.ndarray, x: np.ndarray, height_m: float) -> dict:
    """Manoeuvre class detected from a solution: flips, oblique, zig-zag (flags plus a label).

    * flips: the vehicle is upside down at some point (|φ| > 90°);
    * zig-zag: the horizontal motion reverses direction at least once with a swing of more than
      5 % of the height either side of the reversal (no flips);
    * oblique: a net sideways displacement of more than 10 % of the height, without reversals.
    """
    y = x[:, IY]
    flips = bool(np.max(np.abs(x[:, IPHI])) > math.pi / 2)
    swing = 0.05 * height_m
    # Turning points of Y that matter: extrema separated by more than `swing`.
    reversals = 0
    anchor, direction = y[0], 0
    for val in y[1:]:
        d = val - anchor
        if direction >= 0 and d < -swing:
            reversals += direction > 0
            direction, anchor = -1, val
        elif direction <= 0 and d > swing:
            reversals += direction < 0
            direction, anchor = 1, val
        elif (direction > 0 and val > anchor) or (direction < 0 and val < anchor):
            anchor = val
    oblique = abs(y[-1] - y[0]) > 0.1 * height_m and reversals == 0
    zigzag = reversals >= 1 and not flips
    parts = [n for n, on in (("oblique", oblique), ("zig-zag", zigzag), ("flips", flips)) if on]
    return {
        "oblique": oblique,
        "zigzag": zigzag,
        "flips": flips,
        "reversals": reversals,
        "label": "+".join(parts) if parts else "vertical",
    }


# -- initial guesses ---------------------------------------------------------------------------------


def _min_jerk(tau):
    return 10 * tau**3 - 15 * tau**4 + 6 * tau**5


def _guess(p: PlanarProblem, n: int, t_f: float, y_of_tau, phi_of_tau=None, name: str = ""):
    """Kinematically consistent guess from a path ``Y(τ)`` (τ ∈ [0, 1]) and min-jerk descent."""
    tau = np.linspace(0.0, 1.0, n + 1)
    t = tau * t_f
    y = y_of_tau(tau)
    z = p.height_m * _min_jerk(tau)
    vy = np.gradient(y, t)
    vz = np.gradient(z, t)
    ay = np.gradient(vy, t)
    az = np.gradient(vz, t)
    if phi_of_tau is None:
        phi = np.arctan2(ay, G_MPS2 - az)
        if p.phi_bound_rad is not None:
            phi = np.clip(phi, -p.phi_bound_rad, p.phi_bound_rad)
    else:
        phi = phi_of_tau(tau)
    f = ay * np.sin(phi) + (G_MPS2 - az) * np.cos(phi)
    f = np.clip(f, p.f_min_mps2, p.f_max_mps2)
    om = np.clip(np.gradient(phi, t), -p.omega_max_rps, p.omega_max_rps)
    x = np.stack([y, vy, z, vz, phi], axis=1)
    u = np.stack([f, om], axis=1)
    return name, t_f, x, u


# (name, T, X, U, final φ) of one start of the multi-start
PlanarGuess = tuple[str, float, np.ndarray, np.ndarray, float]


def initial_guesses(p: PlanarProblem, n: int) -> list[PlanarGuess]:
    """(name, T, X, U, final φ) for the multi-start search."""
    h = p.height_m
    # Oblique descent on the cone's edge needs about h/tan(20°) of sideways room.
    reach = min(0.9 * p.y_bound_m, h / math.tan(math.radians(20.0)))
    t_slow = max(2.0, 1.2 * h)
    out = []
    yf = p.y_final_m
    if p.phi_bound_rad is not None:
        if p.y_final == "free":
            for sgn in (1, -1):
                out.append(
                    (*_guess(p, n, t_slow, lambda s, sg=sgn: sg * reach * _min_jerk(s), name=f"oblique{sgn:+d}"), 0.0)
                )
        for k in (1, 2, 3):
            amp = min(0.8 * p.y_bound_m, reach / k)
            out.append((*_guess(p, n, t_slow * (1 + 0.2 * k),
                               lambda s, k=k, a=amp: a * np.sin(math.pi * k * s) + yf * _min_jerk(s),
                               name=f"zigzag{k}"), 0.0))  # fmt: skip
    else:
        t_flip = max(2.0, 2 * math.pi / p.omega_max_rps * 0.8)
        side = reach if p.y_final == "free" else 0.0

        def flip_full(s):
            return 2 * math.pi * _min_jerk(s)

        def flip_back(s):
            return math.pi * (1 - np.cos(2 * math.pi * s)) / 2

        def path(s):
            return side * _min_jerk(s) + (yf * _min_jerk(s) if p.y_final == "fixed" else 0.0)

        out.append((*_guess(p, n, t_flip, path, flip_back, "flip-there-and-back"), 0.0))
        out.append((*_guess(p, n, t_flip, path, flip_full, "flip-roll+"), 2 * math.pi))
        out.append((*_guess(p, n, t_flip, lambda s: -path(s), lambda s: -flip_full(s), "flip-roll-"), -2 * math.pi))
        # A non-flip start is also a candidate: the optimiser may find flips from it or not need them.
        out.append((*_guess(p, n, t_slow, lambda s: path(s) + 0.3 * reach * np.sin(math.pi * s), name="no-flip"), 0.0))
    return out


# -- the solve ---------------------------------------------------------------------------------------


def _spec(p: PlanarProblem, n: int) -> OcpSpec:
    inf = np.inf
    phi_b = p.phi_bound_rad if p.phi_bound_rad is not None else 3 * math.pi
    v = p.v_bound_mps
    z_lo, z_hi = -p.z_bound_m, max(p.z_bound_m, p.height_m)
    x_lb = np.array([-p.y_bound_m, -v, z_lo, -v, -phi_b])
    x_ub = np.array([p.y_bound_m, v, z_hi, v, phi_b])
    yf_lb, yf_ub = (p.y_final_m, p.y_final_m) if p.y_final == "fixed" else (-p.y_bound_m, p.y_bound_m)
    xf_lb = np.array([yf_lb, 0.0, p.height_m, 0.0, 0.0])
    xf_ub = np.array([yf_ub, 0.0, p.height_m, 0.0, 0.0])
    hover = np.array([G_MPS2, 0.0])
    con = replace(p.constraint, margin_mps=p.constraint.margin_mps + p.backoff_mps)

    def path(x, u):
        ub, wb = planar_blade_velocity(x[IVY] - p.wind_y_mps, x[IVZ] - p.wind_z_mps, x[IPHI], ca.cos, ca.sin)
        return con.slack_casadi(wb, ub)

    return OcpSpec(
        dynamics=dynamics,
        nx=NX,
        nu=NU,
        n_intervals=n,
        x_lb=x_lb,
        x_ub=x_ub,
        u_lb=np.array([p.f_min_mps2, -p.omega_max_rps]),
        u_ub=np.array([p.f_max_mps2, p.omega_max_rps]),
        x_initial=np.zeros(NX),
        xf_lb=xf_lb,
        xf_ub=xf_ub,
        u_initial_lb=hover,
        u_initial_ub=hover,
        uf_lb=hover,
        uf_ub=hover,
        path=path,
        path_lb=np.array([0.0]),
        path_ub=np.array([inf]),
        t_max_s=60.0,
        smooth_weight=np.array([1e-6, 1e-4]),
    )


_OCP_CACHE: dict[tuple, MinTimeOcp] = {}


def clear_ocp_cache() -> None:
    """Forget the compiled planar NLPs (a benchmark that times compilation starts cold)."""
    _OCP_CACHE.clear()


REFINE_TOL_MPS = 1e-3
REFINE_ROUNDS = 3
# The coarse multi-start stops once starts of two different guess families (oblique, zig-zag with
# k reversals, flip families, ...) reach the same best time (relative tolerance). Mirrored twins
# (``oblique+1``/``oblique-1``, ``flip-roll+``/``flip-roll-``) are one family: in a mirror-symmetric
# problem they agree by symmetry, which says nothing about other basins. Over Table II and the ω
# sweep this keeps every optimum of the exhaustive search and saves up to 2 of 5 coarse solves.
AGREE_REL = 1e-6


def _ocp(p: PlanarProblem, n: int, verbose: bool) -> MinTimeOcp:
    """The compiled NLP for this problem's structure (constraint, wind, mesh size), built once per
    process; bounds are plain numbers and are swapped in for each problem."""
    spec = _spec(p, n)
    key = (n, p.constraint, p.backoff_mps, p.wind_y_mps, p.wind_z_mps, verbose)
    ocp = _OCP_CACHE.get(key)
    if ocp is None:
        return _OCP_CACHE.setdefault(key, MinTimeOcp(spec, verbose=verbose))
    return ocp.with_bounds_of(spec)


def _final_bounds(ocp: MinTimeOcp, phi_f: float) -> tuple[np.ndarray, np.ndarray]:
    """The NLP's final-state bounds with the final roll of the start's family (a flip ends at ±2π)."""
    xf_lb = ocp.spec.xf_lb.copy()
    xf_ub = ocp.spec.xf_ub.copy()
    xf_lb[IPHI] = xf_ub[IPHI] = phi_f
    return xf_lb, xf_ub


def _family(guess: str) -> str:
    """A guess's family: mirrored twins (``oblique+1``/``oblique-1``) are one (see ``AGREE_REL``)."""
    return re.sub(r"[+-]\d*$", "", guess)


class _MeshRefinement:
    """The planar fine solve and its refinement rounds (a ``multistart.Refinement``): mesh nodes
    move to where the 1 kHz re-simulation still finds the constraint broken between nodes."""

    word = "refine"

    def __init__(self, p: PlanarProblem, fine: MinTimeOcp, phi_f: float):
        self.p = p
        self.fine = fine
        self.xf_lb, self.xf_ub = _final_bounds(fine, phi_f)
        self.mesh: np.ndarray | None = None  # uniform until a round finds a violation
        self.hot_s: list[float] = []  # every violation found so far: nodes stay crowded where they were

    def solve(self, current: OcpResult, label: str, round_: int) -> OcpResult:
        n = self.p.n_intervals
        xg = resample_guess(current.t_s, current.x, n, self.mesh)
        ug = resample_guess(current.t_s, current.u, n, self.mesh)
        return self.fine.solve(current.t_f_s, xg, ug, name=label, xf_lb=self.xf_lb, xf_ub=self.xf_ub,
                               mesh=self.mesh)  # fmt: skip

    def record(self, r: OcpResult) -> dict:
        return attempt_record(r)

    def again(self, r: OcpResult) -> bool:
        t_re, margin = _resim_margin(self.p, r)
        if margin.min() >= -REFINE_TOL_MPS:
            return False
        self.hot_s.extend(violation_times(t_re, margin, REFINE_TOL_MPS))
        self.mesh = refined_mesh(np.linspace(0.0, r.t_f_s, self.p.n_intervals + 1), np.array(self.hot_s))
        return True


def solve_planar(p: PlanarProblem, verbose: bool = False) -> PlanarSolution:
    """Multi-start on the coarse mesh, refine the best on the fine mesh, then move mesh nodes to
    where the 1 kHz re-simulation still finds the constraint broken between nodes (≤ 3 rounds)."""
    p.validate()
    t0 = time.perf_counter()
    coarse = _ocp(p, p.n_coarse, verbose)

    def solve_start(guess: PlanarGuess) -> OcpResult:
        name, t_g, xg, ug, phi_f = guess
        xf_lb, xf_ub = _final_bounds(coarse, phi_f)
        return coarse.solve(t_g, xg, ug, name=name, xf_lb=xf_lb, xf_ub=xf_ub)

    def refinement_for(guess: PlanarGuess) -> _MeshRefinement:
        return _MeshRefinement(p, _ocp(p, p.n_intervals, verbose), phi_f=guess[4])

    attempts: list[dict] = []
    result = multistart_refined(initial_guesses(p, p.n_coarse), solve_start, refinement_for, REFINE_ROUNDS,
                                attempts, stop=families_agree(_family, AGREE_REL))  # fmt: skip
    sol = PlanarSolution(problem=p, result=result, attempts=attempts, solve_s=0.0, check={})
    sol.check = resimulation_check(sol)
    sol.solve_s = time.perf_counter() - t0
    return sol


def _resim_margin(p: PlanarProblem, r: OcpResult, rate_hz: float = 1000.0):
    t, x, _ = resimulate(r, rate_hz)
    ub, wb = planar_blade_velocity(x[:, IVY] - p.wind_y_mps, x[:, IVZ] - p.wind_z_mps, x[:, IPHI])
    return t, p.constraint.margin(wb, ub)


def resimulation_check(sol: PlanarSolution, rate_hz: float = 1000.0) -> dict:
    """Integrate the dynamics at ``rate_hz`` with the interpolated controls; worst margins and
    end-point errors of what would actually be flown with those controls."""
    r = sol.result
    p = sol.problem
    t, x, _ = resimulate(r, rate_hz)
    ub, wb = planar_blade_velocity(x[:, IVY] - p.wind_y_mps, x[:, IVZ] - p.wind_z_mps, x[:, IPHI])
    margin = p.constraint.margin(wb, ub)
    u_nodes, w_nodes = sol.blade_velocity()
    i = int(np.argmin(margin))
    end = x[-1]
    target_y = p.y_final_m if p.y_final == "fixed" else r.x[-1, IY]
    phi_end = (end[IPHI] + math.pi) % (2 * math.pi) - math.pi
    return {
        "rate_hz": rate_hz,
        "worst_margin_mps": float(margin[i]),
        "worst_margin_t_s": float(t[i]),
        "node_worst_margin_mps": float(np.min(p.constraint.margin(w_nodes, u_nodes))),
        "end_position_error_m": float(math.hypot(end[IY] - target_y, end[IZ] - p.height_m)),
        "end_speed_mps": float(math.hypot(end[IVY], end[IVZ])),
        "end_phi_error_deg": float(abs(math.degrees(phi_end))),
    }


def with_omega(p: PlanarProblem, omega_max_rps: float) -> PlanarProblem:
    return replace(p, omega_max_rps=omega_max_rps)
