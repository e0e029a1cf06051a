"""Free-final-time optimal control by multiple shooting on CasADi ``nlpsol`` + IPOPT.

Transcription (shared by the planar and the 3D planner):

* ``N`` intervals of length ``h_k = T·mesh_k`` (uniform unless refined; ``mesh`` is an NLP parameter);
  ``T`` is a decision variable (free final time).
* States ``X[k]`` and controls ``U[k]`` at the ``N+1`` nodes; controls are **piecewise linear**
  (first-order hold), so what the re-simulation and the flying code interpolate is exactly what
  the optimiser saw.
* One RK4 step per interval with the linearly interpolated control gives the shooting defects.
* Path constraints hold at every node **and** at every interval midpoint (state from the cubic
  Hermite interpolant of the two nodes and their derivatives, control linear), which halves the
  gaps in which a constraint could be broken between nodes; the fine re-simulation measures what is
  left.
* Optional bound on the control rate ``|U[k+1] − U[k]| ≤ h·rate_max`` (linear in U and T).

The NLP is built once per problem shape and solved from several initial guesses.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

Dynamics = Callable[[ca.SX, ca.SX], ca.SX]
PathFn = Callable[[ca.SX, ca.SX], ca.SX]

IPOPT_QUIET = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"}
# IPOPT statuses that mean a usable local optimum.
SUCCESS_STATUSES = {"Solve_Succeeded", "Solved_To_Acceptable_Level"}


@dataclass
class OcpSpec:
    """A minimum-time problem ``min T`` s.t. ``ẋ = f(x, u)``, bounds and path constraints."""

    dynamics: Dynamics
    nx: int
    nu: int
    n_intervals: int
    x_lb: np.ndarray
    x_ub: np.ndarray
    u_lb: np.ndarray
    u_ub: np.ndarray
    x_initial: np.ndarray
    xf_lb: np.ndarray
    xf_ub: np.ndarray
    u_initial_lb: np.ndarray | None = None
    u_initial_ub: np.ndarray | None = None
    uf_lb: np.ndarray | None = None
    uf_ub: np.ndarray | None = None
    path: PathFn | None = None  # g(x, u) with path_lb ≤ g ≤ path_ub
    path_lb: np.ndarray | None = None
    path_ub: np.ndarray | None = None
    u_rate_max: np.ndarray | None = None  # per control, per second
    t_min_s: float = 0.05
    t_max_s: float = 60.0
    # Small penalty on control changes: minimum-time problems have bang-bang and singular arcs on
    # which the controls would otherwise chatter at the mesh frequency; the weight is far below
    # the solver tolerance on T (reported objective is T alone).
    smooth_weight: np.ndarray | None = None
    # Small penalty ``Σ h_k · w·u_k²`` on the controls' size (per control, per second): in a long
    # descent the optimum rides several bounds at once and the rates are left nearly free (the yaw
    # of a helix is a symmetry), which leaves IPOPT a flat, degenerate tail of iterations.
    control_weight: np.ndarray | None = None
    ipopt_options: dict = field(default_factory=dict)


@dataclass
class OcpResult:
    status: str
    success: bool
    t_f_s: float
    t_s: np.ndarray
    x: np.ndarray  # (N+1, nx)
    u: np.ndarray  # (N+1, nu)
    solve_s: float
    iterations: int
    max_defect: float
    mesh: np.ndarray
    guess: str = ""
    # IPOPT's multipliers at the solution (bounds, constraints): a warm start of the same NLP
    lam_x: np.ndarray | None = None
    lam_g: np.ndarray | None = None


class SolvedOcp:
    """What every planner's solution says about its solve; the dataclass provides ``result``."""

    result: OcpResult

    @property
    def success(self) -> bool:
        return self.result.success

    @property
    def status(self) -> str:
        return "optimal" if self.result.success else self.result.status

    @property
    def t_f_s(self) -> float:
        return self.result.t_f_s


class MinTimeOcp:
    """The transcribed NLP of one ``OcpSpec``; ``solve()`` it from any initial guess."""

    def __init__(self, spec: OcpSpec, verbose: bool = False, extra: dict | None = None):
        self.spec = spec
        s = spec
        n = s.n_intervals
        t_var = ca.SX.sym("T")
        xs = ca.SX.sym("X", s.nx, n + 1)
        us = ca.SX.sym("U", s.nu, n + 1)
        # Interval lengths are fractions of T given as a parameter, so mesh refinement (moving the
        # nodes) re-uses the same compiled NLP.
        mesh = ca.SX.sym("mesh", 1, n)
        h_row = t_var * mesh
        hx = ca.repmat(h_row, s.nx, 1)
        xk = ca.SX.sym("x", s.nx)
        uk = ca.SX.sym("u", s.nu)
        f = ca.Function("f", [xk, uk], [s.dynamics(xk, uk)])
        g_list, lbg, ubg = [], [], []

        x0s, x1s = xs[:, :-1], xs[:, 1:]
        u0s, u1s = us[:, :-1], us[:, 1:]
        um = 0.5 * (u0s + u1s)
        fmap = f.map(n)
        k1 = fmap(x0s, u0s)
        k2 = fmap(x0s + 0.5 * hx * k1, um)
        k3 = fmap(x0s + 0.5 * hx * k2, um)
        k4 = fmap(x0s + hx * k3, u1s)
        defects = x0s + hx / 6 * (k1 + 2 * k2 + 2 * k3 + k4) - x1s
        g_list.append(ca.vec(defects))
        lbg.append(np.zeros(s.nx * n))
        ubg.append(np.zeros(s.nx * n))
        self._defect_fn = ca.Function("defects", [t_var, xs, us, mesh], [defects])

        if s.path is not None:
            xsym = ca.SX.sym("xp", s.nx)
            usym = ca.SX.sym("up", s.nu)
            pfun = ca.Function("path", [xsym, usym], [s.path(xsym, usym)])
            g_nodes = pfun.map(n + 1)(xs, us)
            f_end = fmap(x1s, u1s)
            x_mid = 0.5 * (x0s + x1s) + hx / 8 * (k1 - f_end)
            g_mid = pfun.map(n)(x_mid, um)
            self._path_rows = slice(s.nx * n, s.nx * n + len(s.path_lb) * (2 * n + 1))
            g_list += [ca.vec(g_nodes), ca.vec(g_mid)]
            lbg += [np.tile(s.path_lb, n + 1), np.tile(s.path_lb, n)]
            ubg += [np.tile(s.path_ub, n + 1), np.tile(s.path_ub, n)]
            self.path_fn = pfun
        else:
            self.path_fn = None

        if s.u_rate_max is not None:
            rows = [i for i, r in enumerate(s.u_rate_max) if np.isfinite(r)]
            du = (u1s - u0s)[rows, :]
            lim = ca.DM(np.asarray(s.u_rate_max, float)[rows]) @ h_row
            nr = len(rows) * n
            g_list += [ca.vec(du - lim), ca.vec(du + lim)]
            lbg += [np.full(nr, -np.inf), np.zeros(nr)]
            ubg += [np.zeros(nr), np.full(nr, np.inf)]

        obj = t_var
        if s.smooth_weight is not None:
            du = u1s - u0s
            w = ca.DM(s.smooth_weight)
            obj = obj + ca.sum2(ca.sum1(w * du * du)) / n
        if s.control_weight is not None:
            w = ca.DM(s.control_weight)
            obj = obj + ca.sum2(ca.sum1(w * us[:, :-1] ** 2) * h_row)

        z = ca.vertcat(t_var, ca.vec(xs), ca.vec(us))
        opts = dict(IPOPT_QUIET)
        opts.update({"ipopt.max_iter": 3000, "ipopt.tol": 1e-7, "ipopt.acceptable_tol": 1e-5,
                     "ipopt.mu_strategy": "adaptive"})  # fmt: skip
        if verbose:
            opts.update({"ipopt.print_level": 5, "print_time": True})
        opts.update(s.ipopt_options)
        if extra:
            opts.update(extra)
        self.solver = ca.nlpsol(
            "mintime", "ipopt", {"x": z, "p": ca.vec(mesh), "f": obj, "g": ca.vertcat(*g_list)}, opts
        )
        self.lbg = np.concatenate(lbg)
        self.ubg = np.concatenate(ubg)
        self.lbz, self.ubz = self._bounds()

    def with_bounds_of(self, spec: OcpSpec) -> MinTimeOcp:
        """Solve ``spec``'s bounds with this compiled NLP (a problem of the same structure whose box
        bounds — start, end, state and control limits — differ): no new compilation."""
        self.spec = spec
        self.lbz, self.ubz = self._bounds()
        return self

    def _bounds(self) -> tuple[np.ndarray, np.ndarray]:
        s = self.spec
        n = s.n_intervals
        xl = np.tile(np.asarray(s.x_lb, float)[:, None], (1, n + 1))
        xu = np.tile(np.asarray(s.x_ub, float)[:, None], (1, n + 1))
        xl[:, 0] = xu[:, 0] = s.x_initial
        xl[:, -1], xu[:, -1] = s.xf_lb, s.xf_ub
        ul = np.tile(np.asarray(s.u_lb, float)[:, None], (1, n + 1))
        uu = np.tile(np.asarray(s.u_ub, float)[:, None], (1, n + 1))
        if s.u_initial_lb is not None:
            ul[:, 0], uu[:, 0] = s.u_initial_lb, s.u_initial_ub
        if s.uf_lb is not None:
            ul[:, -1], uu[:, -1] = s.uf_lb, s.uf_ub
        lb = np.concatenate([[s.t_min_s], xl.flatten(order="F"), ul.flatten(order="F")])
        ub = np.concatenate([[s.t_max_s], xu.flatten(order="F"), uu.flatten(order="F")])
        return lb, ub

    def solve(self, t_guess: float, x_guess: np.ndarray, u_guess: np.ndarray, name: str = "",
              xf_lb: np.ndarray | None = None, xf_ub: np.ndarray | None = None,
              mesh: np.ndarray | None = None, path_lb: np.ndarray | None = None,
              warm: OcpResult | None = None) -> OcpResult:  # fmt: skip
        """Solve from a guess: ``x_guess`` (N+1, nx), ``u_guess`` (N+1, nu) on the nodes of ``mesh``
        (interval fractions of T summing to 1; uniform by default); optionally other final state
        bounds than the spec's (e.g. another turn of a flip) or other lower bounds of the path
        constraints (tightened to keep the flown path inside between nodes) on the same NLP:
        ``path_lb`` one row for every point, or ``(2N+1, n_path)`` rows, the N+1 nodes then the N
        interval midpoints (tightened where the path breaks a bound only)."""
        s = self.spec
        n = s.n_intervals
        mesh = np.full(n, 1.0 / n) if mesh is None else np.asarray(mesh, float) / np.sum(mesh)
        lbz, ubz = self.lbz.copy(), self.ubz.copy()
        last = 1 + s.nx * n
        if xf_lb is not None:
            lbz[last : last + s.nx] = xf_lb
        if xf_ub is not None:
            ubz[last : last + s.nx] = xf_ub
        z0 = np.concatenate([[t_guess], np.asarray(x_guess).T.flatten(order="F"),
                             np.asarray(u_guess).T.flatten(order="F")])  # fmt: skip
        z0 = np.clip(z0, lbz, ubz)
        t0 = time.perf_counter()
        lbg = self.lbg
        if path_lb is not None:
            lbg = lbg.copy()
            plb = np.asarray(path_lb, float)
            lbg[self._path_rows] = np.tile(plb, 2 * n + 1) if plb.ndim == 1 else plb.ravel()
        kw = {}
        if warm is not None and warm.lam_x is not None and len(warm.lam_x) == len(z0):
            kw = {"lam_x0": warm.lam_x, "lam_g0": warm.lam_g}
        sol = self.solver(x0=z0, p=mesh, lbx=lbz, ubx=ubz, lbg=lbg, ubg=self.ubg, **kw)
        solve_s = time.perf_counter() - t0
        stats = self.solver.stats()
        z = np.asarray(sol["x"]).ravel()
        t_f = float(z[0])
        x = z[1 : 1 + s.nx * (n + 1)].reshape((n + 1, s.nx))
        u = z[1 + s.nx * (n + 1) :].reshape((n + 1, s.nu))
        defects = np.asarray(self._defect_fn(t_f, x.T, u.T, mesh))
        status = str(stats.get("return_status", "unknown"))
        return OcpResult(
            status=status,
            success=status in SUCCESS_STATUSES,
            t_f_s=t_f,
            t_s=t_f * np.concatenate([[0.0], np.cumsum(mesh)]),
            mesh=mesh,
            x=x,
            u=u,
            solve_s=solve_s,
            iterations=int(stats.get("iter_count", -1)),
            max_defect=float(np.abs(defects).max()) if defects.size else 0.0,
            guess=name,
            lam_x=np.asarray(sol["lam_x"]).ravel(),
            lam_g=np.asarray(sol["lam_g"]).ravel(),
        )


def resample_guess(t_src: np.ndarray, arr: np.ndarray, n_intervals: int, mesh: np.ndarray | None = None) -> np.ndarray:
    """Interpolate node values ``arr`` (M, k) on ``t_src`` onto the ``n_intervals+1`` nodes of
    ``mesh`` (interval fractions; uniform by default)."""
    if mesh is None:
        tn = np.linspace(t_src[0], t_src[-1], n_intervals + 1)
    else:
        tn = t_src[0] + (t_src[-1] - t_src[0]) * np.concatenate([[0.0], np.cumsum(mesh) / np.sum(mesh)])
    return np.stack([np.interp(tn, t_src, arr[:, j]) for j in range(arr.shape[1])], axis=1)


def refined_mesh(t_nodes: np.ndarray, t_hot: np.ndarray, gain: float = 6.0) -> np.ndarray:
    """Interval fractions for the same number of intervals, nodes crowded around the times
    ``t_hot`` (where the re-simulation found the constraint broken between nodes).

    Node density ``1 + gain·Σ exp(−((t − t_k)/σ)²)`` with σ two current intervals, equidistributed.
    """
    n = len(t_nodes) - 1
    t_f = t_nodes[-1]
    fine = np.linspace(0.0, t_f, 20 * n + 1)
    sigma = 2.0 * t_f / n
    dens = np.ones_like(fine)
    for tk in np.atleast_1d(t_hot):
        dens += gain * np.exp(-(((fine - tk) / sigma) ** 2))
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(fine))])
    nodes = np.interp(np.linspace(0.0, cum[-1], n + 1), cum, fine)
    return np.diff(nodes) / t_f


def _fine_clock(t_nodes: np.ndarray, u_nodes: np.ndarray, rate_hz: float):
    """The re-simulation clock and the linearly interpolated controls at its steps and midpoints."""
    t_f = float(t_nodes[-1])
    n = max(int(np.ceil(t_f * rate_hz)), 1)
    t = np.linspace(0.0, t_f, n + 1)
    h = t_f / n

    def u_at(tt):
        return np.stack([np.interp(tt, t_nodes, u_nodes[:, j]) for j in range(u_nodes.shape[1])], -1)

    return t, h, u_at(t), u_at(t[:-1] + 0.5 * h)


def violation_times(t: np.ndarray, margin: np.ndarray, tol: float) -> list[float]:
    """Times of the worst point of every stretch where ``margin < −tol``."""
    bad = margin < -tol
    out = []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(int), [0]])))
    for a, b in zip(edges[::2], edges[1::2]):
        out.append(float(t[a + int(np.argmin(margin[a:b]))]))
    return out


def rk4_resimulate(dynamics_np: Callable[[np.ndarray, np.ndarray], np.ndarray], t_nodes: np.ndarray,
                   x0: np.ndarray, u_nodes: np.ndarray, rate_hz: float = 1000.0):  # fmt: skip
    """Integrate ``ẋ = f(x, u)`` from ``x0`` with the linearly interpolated controls at ``rate_hz``.

    Returns ``(t, x, u)`` on the fine clock. This is an independent check of a solution: it does not
    use the solver's states at all, only its controls. Plain numpy, one Python step at a time: the
    reference that ``rk4_resimulate_compiled`` (what the planners use, ~30× faster) is tested against.
    """
    t, h, u, um = _fine_clock(t_nodes, u_nodes, rate_hz)
    n = len(t) - 1
    x = np.empty((n + 1, len(x0)))
    x[0] = x0
    for i in range(n):
        xi = x[i]
        k1 = dynamics_np(xi, u[i])
        k2 = dynamics_np(xi + 0.5 * h * k1, um[i])
        k3 = dynamics_np(xi + 0.5 * h * k2, um[i])
        k4 = dynamics_np(xi + h * k3, u[i + 1])
        x[i + 1] = xi + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return t, x, u


_RK4_CHUNK = 1000
_RK4_STEPPERS: dict[tuple, ca.Function] = {}


def _rk4_step(dynamics: Dynamics, nx: int, nu: int) -> ca.Function:
    """One RK4 step ``x_next = F(x, [u0; u_mid; u1; h])`` of ``ẋ = dynamics(x, u)``."""
    x = ca.SX.sym("x", nx)
    u0, um, u1 = ca.SX.sym("u0", nu), ca.SX.sym("um", nu), ca.SX.sym("u1", nu)
    h = ca.SX.sym("h")
    f = ca.Function("f", [x, u0], [dynamics(x, u0)])
    k1 = f(x, u0)
    k2 = f(x + 0.5 * h * k1, um)
    k3 = f(x + 0.5 * h * k2, um)
    k4 = f(x + h * k3, u1)
    return ca.Function("rk4", [x, ca.vertcat(u0, um, u1, h)], [x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])


def _rk4_stepper(dynamics: Dynamics, nx: int, nu: int) -> ca.Function:
    """``_RK4_CHUNK`` chained RK4 steps of ``ẋ = dynamics(x, u)`` as one compiled CasADi function
    ``x_end_all = F(x0, [u0; u_mid; u1; h] per step)``, built once per dynamics."""
    key = (dynamics, nx, nu)
    if key not in _RK4_STEPPERS:
        _RK4_STEPPERS[key] = _rk4_step(dynamics, nx, nu).mapaccum(_RK4_CHUNK)
    return _RK4_STEPPERS[key]


_INTERVAL_INTEGRATORS: dict[tuple, ca.Function] = {}


def _interval_integrator(dynamics: Dynamics, nx: int, nu: int, steps: int) -> ca.Function:
    """``steps`` chained RK4 steps across one interval: ``F(x0, [u0; u_mid; u1; h] per step)`` → the
    state after each step, built once per dynamics and step count (then mapped over intervals)."""
    key = (dynamics, nx, nu, steps)
    if key not in _INTERVAL_INTEGRATORS:
        _INTERVAL_INTEGRATORS[key] = _rk4_step(dynamics, nx, nu).mapaccum(steps)
    return _INTERVAL_INTEGRATORS[key]


@dataclass
class DenseSolution:
    """A solution re-simulated interval by interval from its own nodes (multiple-shooting style).

    ``t`` (M,), ``x`` (M, nx), ``u`` (M, nu): at least ``rate_hz`` samples per second, each interval
    integrated with RK4 from its start node with the linearly interpolated controls, then the gap to
    the next node (the integration error of the NLP's one RK4 step per interval) spread linearly
    over the interval so the path is continuous and ends on the solver's nodes. ``gaps`` (N, nx):
    that node-to-node integration error per interval, before spreading.
    """

    t: np.ndarray
    x: np.ndarray
    u: np.ndarray
    gaps: np.ndarray


def rk4_piecewise(dynamics: Dynamics, t_nodes: np.ndarray, x_nodes: np.ndarray, u_nodes: np.ndarray,
                  rate_hz: float = 1000.0) -> DenseSolution:  # fmt: skip
    """Re-simulate every interval from its own node (see ``DenseSolution``).

    Why not open loop from the first state only: the vehicle's dynamics with rate inputs integrate
    attitude errors twice into position, so over a long descent (10 s and more) an open-loop
    integration of the node controls drifts by metres from the planned path, although every
    interval follows the dynamics to integration accuracy. That drift is a numerical artefact (the
    autopilot's position loop removes it in flight), not the plan breaking a bound; what can break a
    bound is the path *between* nodes, which this re-simulation resolves at ``rate_hz``.
    """
    t_nodes = np.asarray(t_nodes, float)
    x_nodes = np.asarray(x_nodes, float)
    u_nodes = np.asarray(u_nodes, float)
    h = np.diff(t_nodes)
    n = len(h)
    nx, nu = x_nodes.shape[1], u_nodes.shape[1]
    m = max(int(np.ceil(h.max() * rate_hz - 1e-9)), 1)
    s0 = np.arange(m) / m  # substep start, mid and end as fractions of each interval
    sm = s0 + 0.5 / m
    s1 = s0 + 1.0 / m
    u0, u1 = u_nodes[:-1], u_nodes[1:]  # (n, nu)

    def lerp(s):  # (n·m, nu): controls at fractions s of every interval
        return (u0[:, None, :] + s[None, :, None] * (u1 - u0)[:, None, :]).reshape(n * m, nu)

    inputs = np.concatenate([lerp(s0), lerp(sm), lerp(s1), np.repeat(h / m, m)[:, None]], axis=1).T
    f = _interval_integrator(dynamics, nx, nu, m).map(n)
    xs = np.asarray(f(x_nodes[:-1].T, inputs)).T.reshape(n, m, nx)  # state after each substep
    gaps = xs[:, -1, :] - x_nodes[1:]
    xs = xs - s1[None, :, None] * gaps[:, None, :]
    t = np.concatenate([[t_nodes[0]], (t_nodes[:-1, None] + s1[None, :] * h[:, None]).ravel()])
    x = np.concatenate([x_nodes[:1], xs.reshape(n * m, nx)])
    u = np.concatenate([u_nodes[:1], lerp(s1)])
    return DenseSolution(t=t, x=x, u=u, gaps=gaps)


def rk4_resimulate_compiled(dynamics: Dynamics, t_nodes: np.ndarray, x0: np.ndarray, u_nodes: np.ndarray,
                            rate_hz: float = 1000.0):  # fmt: skip
    """``rk4_resimulate`` with the same steps evaluated by CasADi's virtual machine (``dynamics`` on
    CasADi symbols, as the NLP has it); steps run in chunks, the last padded with ``h = 0`` steps
    that leave the state unchanged."""
    t, h, u, um = _fine_clock(t_nodes, u_nodes, rate_hz)
    n = len(t) - 1
    nx, nu = len(x0), u.shape[1]
    chunks = -(-n // _RK4_CHUNK)
    inputs = np.zeros((3 * nu + 1, chunks * _RK4_CHUNK))
    inputs[:nu, :n] = u[:-1].T
    inputs[nu : 2 * nu, :n] = um.T
    inputs[2 * nu : 3 * nu, :n] = u[1:].T
    inputs[3 * nu, :n] = h
    stepper = _rk4_stepper(dynamics, nx, nu)
    x = np.empty((chunks * _RK4_CHUNK + 1, nx))
    x[0] = x0
    for c in range(chunks):
        sl = slice(c * _RK4_CHUNK, (c + 1) * _RK4_CHUNK)
        x[sl.start + 1 : sl.stop + 1] = np.asarray(stepper(x[sl.start], inputs[:, sl])).T
    return t, x[: n + 1], u
