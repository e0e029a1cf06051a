"""PNG of a planned trajectory: path, height, speeds, attitude, and its blade-frame velocity against
the guard region, over time and in velocity space.

The region shaded is the one the live guard aborts on (``guard``: the vehicle's ``w_allow``, cone and
margin), on its forbidden side only; the plan's own bound, when it is tighter (a tracking margin, the
paper's pure cone), is the dashed line the plan keeps under. Every axis is fitted to the plan with the
region in view, and every line drawn against space starts at a circle and ends at a square.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from flighttest.errors import FlighttestError
from flighttest.model.aero import guard_bound_mps
from flighttest.model.frames import blade_velocity_mps
from flighttest.model.trajectory import Trajectory
from flighttest.planner.cone import VelocityConstraint

MOVES_SIDEWAYS_M = 1e-3  # a plan with less horizontal travel than this is drawn from the side
MIN_U_SPAN_MPS = 1.0  # the velocity-space panel shows at least this much in-plane speed
REGION_BAND = 0.45  # of the plan's own span: how much of the forbidden side is shown above the boundary


def blade_series(traj: Trajectory, wind_ned_mps=(0.0, 0.0, 0.0)):
    """(w, u) over the trajectory's samples; level attitude where the file has none."""
    q = traj.attitude_quat()
    if q is None:
        q = np.tile([1.0, 0.0, 0.0, 0.0], (len(traj.df), 1))
    return blade_velocity_mps(traj.column("vn_mps"), traj.column("ve_mps"), traj.column("vd_mps"),
                              q[:, 0], q[:, 1], q[:, 2], q[:, 3], *wind_ned_mps)  # fmt: skip


def _bound(c: VelocityConstraint, u) -> np.ndarray:
    return guard_bound_mps(np.asarray(u, float), c.w_allow_mps, c.cone_deg, c.margin_mps)


def _describe(c: VelocityConstraint) -> str:
    allow = f"w_allow {c.w_allow_mps:.2f} m/s, " if c.w_allow_mps > 0 else "pure "
    return f"{allow}{c.cone_deg:g}° cone, margin {c.margin_mps:g} m/s"


def _same(a: VelocityConstraint, b: VelocityConstraint) -> bool:
    return (a.w_allow_mps, a.cone_deg, a.margin_mps) == (b.w_allow_mps, b.cone_deg, b.margin_mps)


def _region_limits(w: np.ndarray, bound: np.ndarray) -> tuple[float, float]:
    """A w axis holding the plan's w and the boundary, with a band of the forbidden side above it."""
    from flighttest.model.chart import fitted_range

    lo, hi = fitted_range(w, bound, 0.0, min_span=0.5)
    top = max(hi, float(np.nanmax(bound)) + REGION_BAND * (hi - lo))
    return lo, top


def _draw_path(fig, a, traj: Trajectory) -> None:
    from flighttest.model.chart import mark_ends

    n, e, d = traj.column("n_m"), traj.column("e_m"), traj.column("d_m")
    if np.ptp(n) > MOVES_SIDEWAYS_M:
        sc = a.scatter(e, n, c=-d, s=4, cmap="viridis", zorder=2)
        fig.colorbar(sc, ax=a, label="height relative to the start, m")
        mark_ends(a, e, n)
        a.set_ylabel("north, m")
        a.set_title("path, seen from above")
        a.set_aspect("equal", adjustable="datalim")
    else:  # in the east-down plane (planar, straight down): a side view says more than a line seen from above
        a.plot(e, -d, color="tab:blue", lw=1.5)
        mark_ends(a, e, -d)
        if np.ptp(e) <= MOVES_SIDEWAYS_M:
            a.set_xlim(-0.5, 0.5)
        a.set_ylabel("height relative to the start, m")
        a.set_title("path, seen from the side")
    a.set_xlabel("east, m")
    a.legend(loc="best", fontsize=8)


def plot_trajectory(traj: Trajectory, path: Path | str, constraint: VelocityConstraint,
                    wind_ned_mps=(0.0, 0.0, 0.0), title: str = "",
                    guard: VelocityConstraint | None = None) -> Path:  # fmt: skip
    """Draw ``traj`` planned against ``constraint`` into ``path`` (:func:`trajectory_figure`)."""
    import matplotlib.pyplot as plt

    path = Path(path)
    fig = trajectory_figure(traj, constraint, wind_ned_mps, title, guard)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=100)
    except OSError as exc:
        raise FlighttestError(f"cannot write plot {path}: {exc.strerror}") from None
    finally:
        plt.close(fig)
    return path


def trajectory_figure(traj: Trajectory, constraint: VelocityConstraint, wind_ned_mps=(0.0, 0.0, 0.0),
                      title: str = "", guard: VelocityConstraint | None = None):  # fmt: skip
    """The figure of ``traj`` planned against ``constraint``, the ``guard``'s region shaded (default:
    the constraint's own, for a plan that is not a vehicle's, e.g. Table II's). The caller closes it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from flighttest.model.chart import (
        GUARD_COLOUR,
        GUARD_SHADE,
        VD_COLOUR,
        W_COLOUR,
        fitted_range,
        mark_ends,
    )

    whose = "guard" if guard is not None else "the plan's"  # no vehicle (Table II): the plan's own region
    guard = guard or constraint
    t = traj.t_s
    fig, ax = plt.subplots(2, 3, figsize=(16, 9))

    _draw_path(fig, ax[0, 0], traj)

    a = ax[0, 1]
    h = -traj.column("d_m")
    a.plot(t, h, color="tab:blue", lw=1.5)
    mark_ends(a, t, h)
    a.set_ylim(*fitted_range(h, 0.0, min_span=1.0))
    a.set_xlabel("t, s")
    a.set_ylabel("height relative to the start, m")
    a.set_title("height")
    a.legend(loc="best", fontsize=8)

    a = ax[0, 2]
    speeds = {"v_N": traj.column("vn_mps"), "v_E": traj.column("ve_mps"), "v_D (descent rate)": traj.column("vd_mps")}
    colours = {"v_N": "tab:purple", "v_E": "tab:orange", "v_D (descent rate)": VD_COLOUR}
    for label, v in speeds.items():
        if label.startswith("v_D") or np.ptp(v) > 0 or v.any():  # a straight-down plan has no N and E to show
            a.plot(t, v, color=colours[label], label=label)
    norm = np.linalg.norm(np.stack(list(speeds.values())), axis=0)
    a.plot(t, norm, "k--", lw=1, label="|v|")
    a.set_ylim(*fitted_range(norm, *speeds.values(), 0.0, min_span=0.5))
    a.set_xlabel("t, s")
    a.set_ylabel("m/s (NED: v_D > 0 descending)")
    a.set_title("speeds")
    a.legend(loc="best", fontsize=8)

    a = ax[1, 0]
    angles = []
    for c in ("roll_deg", "pitch_deg", "yaw_deg"):
        if c in traj.df:
            # unwrapped: a yaw through ±180° is a turn, not a jump across the panel
            v = np.degrees(np.unwrap(np.radians(traj.column(c))))
            a.plot(t, v, label=c.replace("_deg", ""))
            angles.append(v)
    a.set_ylim(*fitted_range(*angles, min_span=10.0))
    a.set_xlabel("t, s")
    a.set_ylabel("deg (unwrapped)")
    a.set_title("attitude")
    a.legend(loc="best", fontsize=8)

    w, u = blade_series(traj, wind_ned_mps)
    g_bound = _bound(guard, u)
    region = f"{whose} region: forbidden"
    boundary = f"{whose} boundary: {_describe(guard)}"
    plan_line = None if _same(guard, constraint) else f"the plan's bound: {_describe(constraint)}"

    a = ax[1, 1]
    lo, hi = _region_limits(w, g_bound)
    a.fill_between(t, g_bound, hi + 1.0, **GUARD_SHADE, label=region)
    a.plot(t, g_bound, "-", color=GUARD_COLOUR, lw=1.5, label=boundary)
    if plan_line:
        a.plot(t, _bound(constraint, u), "--", color="tab:red", lw=1.2, label=plan_line)
    a.plot(t, w, color=W_COLOUR, lw=1.6, label="w: descent through the disk")
    a.set_ylim(lo, hi)
    a.set_xlabel("t, s")
    a.set_ylabel("w, m/s (down through the disk positive)")
    a.set_title("w against the guard region (its boundary at the plan's u)")

    a = ax[1, 2]
    u_hi = max(1.08 * float(np.nanmax(u)), MIN_U_SPAN_MPS)  # u ≥ 0: the view starts just left of 0
    u_lo = -0.03 * u_hi
    grid = np.linspace(0.0, u_hi, 200)
    lo, hi = _region_limits(w, _bound(guard, grid))
    a.fill_between(grid, _bound(guard, grid), hi + 1.0, **GUARD_SHADE, label=region)
    a.plot(grid, _bound(guard, grid), "-", color=GUARD_COLOUR, lw=1.5, label=boundary)
    if plan_line:
        a.plot(grid, _bound(constraint, grid), "--", color="tab:red", lw=1.2, label=plan_line)
    a.plot(u, w, color=W_COLOUR, lw=1.6, label="the plan")
    mark_ends(a, u, w)
    a.set_xlim(u_lo, u_hi)
    a.set_ylim(lo, hi)
    a.set_xlabel("u: in-plane air speed through the disk, m/s")
    a.set_ylabel("w, m/s (down through the disk positive)")
    a.set_title("blade-frame velocity space")
    # one legend for both w panels, under them: inside, it would cover the region it names
    handles, labels = a.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", bbox_to_anchor=(0.67, 0.0), ncol=3, fontsize=8.5, frameon=False)

    for a in ax.flat:
        a.grid(True, alpha=0.3)
    basis = traj.meta.get("plan_basis")
    what = {"mission": " as the mission flies it", "paper": ", the paper's problem"}.get(basis, "")
    case = traj.meta.get("table_case")
    of = f"the paper's Table II case {case}" if case else f"{traj.meta.get('vehicle', '?')}{what}"
    fig.suptitle(title or f"{traj.kind} plan for {of}: t_f = {traj.duration_s:.2f} s")
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    return fig
