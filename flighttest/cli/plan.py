"""``flighttest plan planar|helix|vertical|probe``: plan a descent and write a trajectory file.

Every command writes ``PATH.csv`` + ``PATH.json`` (``flighttest.model.trajectory``), prints a rich
summary (or ``--json``), and can draw a PNG (``--plot``). A solve that does not converge is
reported with its status and best point, writes nothing, and exits with code 1.

``helix``, ``vertical`` and ``probe`` plan by default what ``flighttest fly`` flies: their defaults are the
mission's ``[plan]`` (and ``[flight]``) as ``fly`` finds its TOML (``mission_scripts.mission_config_path``),
and the sidecar says so (``plan_basis`` "mission", ``mission_config``). ``plan helix --paper`` plans the
paper's problem instead (the pure cone at the vehicle's full tilt and body rates: ``plan_basis`` "paper").

This module only parses options and reports: each command hands typed values to the planner's
builder of its kind (``flighttest.planner.problems``), solves, and passes the trajectory and what to
say about it to the one tail that validates, writes, plots and prints (``_write_and_report``).
"""

from __future__ import annotations

import argparse
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rich.table import Table
from rich.text import Text

from flighttest import inputs as ip
from flighttest.console import console, err_console, print_json
from flighttest.errors import FlighttestError
from flighttest.flying.mission_scripts import mission_config_path
from flighttest.flying.missions_config import load_mission_config
from flighttest.flying.plan_config import HelixPlanConfig, ProbePlanConfig, VerticalPlanConfig
from flighttest.model.profiles import VehicleProfile, load_profile

SOLVER_FAILED = 1
PAPER_THRUST_FRACTION = 0.9  # `plan helix --paper`: share of the rotors' maximum thrust (the mission's: [plan])
# the shipped missions' [plan] (flighttest.flying.plan_config), named in --help as "as shipped"; the
# commands read the mission's TOML as `flighttest fly` finds it, a user's edited copy included
PROBE, VERTICAL, HELIX = ProbePlanConfig(), VerticalPlanConfig(), HelixPlanConfig()
# `plan helix` options that shape the paper's problem only: the mission's come from its [plan]
PAPER_ONLY = {"end": "--end", "tilt_max": "--tilt-max", "rate_max": "--rate-max",
              "thrust_fraction": "--thrust-fraction", "wind": "--wind", "constraint": "--constraint",
              "margin": "--margin"}  # fmt: skip


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plan", help="minimum-time descents (planar, 3D helix), vertical baseline, probe")
    psub = p.add_subparsers(dest="plan_command", metavar="KIND", required=True)

    pp = psub.add_parser(
        "planar",
        help="planar minimum-time descent (paper Table II cases or your bounds)",
        description="Paper's planar model (Y, V_Y, Z, V_Z, φ; f_coll, ω). --case N reproduces Table II with "
        "its bounds (thrust may go negative there; the flips, cases 5-6, at 5 rad/s, not Table I's 1: "
        "docs/PAPER.md); otherwise bounds come from --vehicle (thrust ≥ 0) and the options below.",
    )
    pp.add_argument("--case", type=int, choices=range(1, 7), metavar="N", help="Table II case 1-6")
    pp.add_argument("--height", type=ip.HEIGHT_M, default=5.0, metavar="M", help="descent height (default 5)")
    pp.add_argument("--y-bound", type=ip.DISTANCE_M, metavar="M", help="|Y| bound, m (default 15 or the case's)")
    pp.add_argument("--y-final", choices=("fixed", "free"), help="final Y fixed at 0 or free within the bound")
    pp.add_argument("--phi-bound", type=_phi_bound, metavar="DEG", help="roll bound in degrees, or 'free' (flips)")
    pp.add_argument("--omega-max", type=ip.BODY_RATE_RPS, metavar="RPS", help="roll-rate bound, rad/s")
    pp.add_argument("--f-min", type=ip.ACCEL_MPS2, metavar="MPS2", help="min collective thrust per mass, m/s²")
    pp.add_argument("--f-max", type=ip.ACCEL_MPS2, metavar="MPS2", help="max collective thrust per mass, m/s²")
    pp.add_argument("--v-bound", type=ip.SPEED_MPS, metavar="MPS", help="speed bound per axis, m/s")
    pp.add_argument("--wind", nargs=2, type=ip.WIND_MPS, metavar=("WE", "WD"), help="wind east/down, m/s")
    pp.add_argument("--intervals", type=ip.INTERVALS, default=80, metavar="N", help="mesh intervals (default 80)")
    _common(pp, kind="planar", constraint=True)
    pp.set_defaults(func=cmd_planar)

    ph = psub.add_parser(
        "helix",
        help="3D minimum-time descent: by default the helix `fly helix` flies; --paper: the paper's problem",
        description="Rigid body with quaternions; inputs collective thrust and body rates; thrust ≥ 0. By "
        "default the plan `flighttest fly helix` flies in still air (in wind it also plans for winds and "
        "chooses in the start hover): the helix mission's [plan] (its TOML as `fly` finds "
        "it: the end of `flighttest fly --help`), inside the guard's region by its tracking margin, at a "
        "fraction of the vehicle's tilt, body rates and thrust. --paper plans the paper's problem instead: "
        "the pure 20° cone at the vehicle's full tilt and body rates and 0.9 of its thrust (faster, and too "
        "close to every limit to fly).",
    )
    ph.add_argument("--paper", action="store_true",
                    help="the paper's problem (pure cone, full tilt and body rates), not what `fly helix` flies")
    ph.add_argument("--height", type=ip.HEIGHT_M, metavar="M",
                    help=f"descent height (default: the mission's descent_m, {HELIX.descent_m:g} as shipped)")
    ph.add_argument("--radius", type=ip.DISTANCE_M, metavar="M",
                    help=f"horizontal radius bound (default: the mission's radius_m, {HELIX.radius_m:g} as shipped)")
    ph.add_argument("--intervals", type=ip.INTERVALS, metavar="N",
                    help=f"mesh intervals, at least (default: the mission's n_intervals, {HELIX.n_intervals} as "
                         "shipped; a long descent gets more)")  # fmt: skip
    paper = ph.add_argument_group("the paper's problem (--paper only)")
    paper.add_argument("--end", nargs=2, type=ip.POSITION_M, metavar=("N", "E"),
                       help="end point (m), default the start XY")
    paper.add_argument("--tilt-max", type=ip.TILT_DEG, metavar="DEG", help="tilt bound (default the profile's)")
    paper.add_argument("--rate-max", type=ip.BODY_RATE_DPS, metavar="DPS",
                       help="body-rate bound (default the profile's)")
    paper.add_argument("--thrust-fraction", type=ip.FRACTION, metavar="F",
                       help=f"share of max thrust to plan with (default {PAPER_THRUST_FRACTION:g})")
    paper.add_argument("--wind", nargs=3, type=ip.WIND_MPS, metavar=("WN", "WE", "WD"), help="wind NED, m/s")
    _common(ph, kind="helix", constraint=True, group=paper)
    ph.set_defaults(func=cmd_helix)

    pv = psub.add_parser("vertical", help="fastest straight-down descent keeping w ≤ w_allow (closed form)",
                         description="The vertical baseline `flighttest fly vertical` flies: defaults from the "
                         "vertical mission's [plan], its TOML as `fly` finds it.")  # fmt: skip
    pv.add_argument("--height", type=ip.HEIGHT_M, metavar="M",
                    help=f"descent height (default: the mission's descent_m, {VERTICAL.descent_m:g} as shipped)")
    pv.add_argument("--w-allow", type=ip.W_ALLOW_POSITIVE_MPS, metavar="MPS", help="override the profile's w_allow")
    pv.add_argument("--margin", type=ip.MARGIN_MPS, metavar="MPS", help="override the profile's guard margin")
    pv.add_argument("--extra-margin", type=ip.MARGIN_MPS, metavar="MPS",
                    help="cruise this far inside the guard's bound on top of its margin, room for the autopilot "
                         f"(default: the mission's extra_margin_mps, {VERTICAL.extra_margin_mps:g} as shipped; "
                         "0: the bound)")  # fmt: skip
    pv.add_argument("--accel-fraction", type=ip.FRACTION, metavar="F",
                    help="share of the accel limits (default: the mission's accel_fraction, "
                         f"{VERTICAL.accel_fraction:g} as shipped)")  # fmt: skip
    _common(pv, kind="vertical", constraint=False)
    pv.set_defaults(func=cmd_vertical)

    pr = psub.add_parser(
        "probe",
        help="VRS-onset probe: one-sided chirp d = A/2·(1 − cos(ω0 t²)) with ramp-in",
        description="The sweep `flighttest fly probe` flies: defaults from the probe mission's [plan] and "
        "[flight], its TOML as `fly` finds it. Descent speed grows slowly; ends at the last whole cycle under "
        "the speed cap and duration; the amplitude must fit above the altitude floor. Output lists when each "
        "descent speed is first reached.",
    )
    def shipped(key: str, value) -> str:
        return f"(default: the mission's {key}, {value:g} as shipped)"

    pr.add_argument("--amplitude", type=ip.HEIGHT_M, metavar="M",
                    help=f"max depth below start {shipped('amplitude_m', PROBE.amplitude_m)}")
    pr.add_argument("--omega0", type=ip.CHIRP_RATE_RPS2, metavar="RPS2",
                    help=f"chirp rate ω0, rad/s² {shipped('omega0_rps2', PROBE.omega0_rps2)}")
    pr.add_argument("--ramp", type=ip.DURATION_S, metavar="S", help=f"ramp-in time {shipped('ramp_s', PROBE.ramp_s)}")
    pr.add_argument("--max-descent-speed", type=ip.SPEED_MPS, metavar="MPS",
                    help="speed cap (default: the mission's max_descent_mps, else max_descent_ratio × the "
                         f"profile's w_allow: {PROBE.max_descent_ratio:g} × as shipped)")  # fmt: skip
    pr.add_argument("--duration", type=ip.DURATION_S, metavar="S",
                    help=f"longest duration {shipped('duration_s', PROBE.duration_s)}")
    pr.add_argument("--start-alt", type=ip.START_HEIGHT_M, metavar="M",
                    help="start altitude AGL (default the probe mission's start height)")
    pr.add_argument("--floor", type=ip.ALTITUDE_FLOOR_M, metavar="M",
                    help="altitude floor AGL (default the probe mission's floor)")
    pr.add_argument("--speed-step", type=ip.SPEED_STEP_MPS, default=0.1, metavar="MPS",
                    help="speed grid step of the table printed (0.1)")
    _common(pr, kind="probe", constraint=False)
    pr.set_defaults(func=cmd_probe)


def _common(p: argparse.ArgumentParser, kind: str, constraint: bool, group=None) -> None:
    """Options every plan takes; ``constraint`` adds --constraint and --margin (into ``group`` if given),
    and the solved plans (planar, helix) take --verbose."""
    p.add_argument("--vehicle", default="x500", help="vehicle profile name or .toml path (default x500)")
    if constraint:
        g = group or p
        g.add_argument("--constraint", choices=("cone", "guard"),
                       help="pure cone (w_allow = 0, the paper's) or the guard region (profile's w_allow); "
                            "default cone")  # fmt: skip
        g.add_argument("--margin", type=ip.MARGIN_MPS, metavar="MPS",
                       help="margin kept from the boundary (default: the profile's guard margin for vehicle "
                            "plans, 0 for Table II cases)")  # fmt: skip
    p.add_argument("-o", "--output", metavar="PATH",
                   help=f"output stem: writes PATH.csv and PATH.json (default trajectories/{kind}-...)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--plot", metavar="PNG",
                   help="write a figure of the path, height, speeds, attitude and w against the guard region "
                        "(.png, .pdf or .svg)")  # fmt: skip
    if kind in ("planar", "helix"):
        p.add_argument("--verbose", action="store_true", help="show IPOPT's output")


# -- helpers -----------------------------------------------------------------------------------------


def _phi_bound(text: str) -> float | str:
    """``--phi-bound``: degrees in (0, 180], or ``free`` (no roll bound: flips allowed)."""
    return "free" if text.strip().lower() == "free" else ip.ROLL_BOUND_DEG(text)


def _out_path(args: argparse.Namespace, default: str) -> Path:
    """The output stem, its two files and the plot checked before anything is solved: a plan that
    cannot be written is not computed (``-o ''`` or a path under a file is one line, not a traceback)."""
    from flighttest.model.trajectory import file_paths

    stem = args.output if args.output is not None else str(Path("trajectories") / default)
    if not str(stem).strip():
        raise FlighttestError("-o/--output: the path is empty")
    if str(stem).endswith(("/", os.sep)):
        raise FlighttestError(f"-o/--output {stem!r}: names a folder; give a file stem such as DIR/descent")
    for f in file_paths(stem):
        ip.check_output_path(f, "-o/--output")
    if args.plot is not None:
        ip.check_output_path(args.plot, "--plot", ip.IMAGE_SUFFIXES)
    return Path(stem)


def _save(traj, out: Path) -> Path:
    try:
        csv_path, _ = traj.save(out)
    except OSError as exc:
        raise FlighttestError(f"cannot write trajectory {out}: {exc.strerror or exc}") from None
    return csv_path


def _plot(args, traj, constraint, wind=(0.0, 0.0, 0.0), guard=None) -> str | None:
    if args.plot is None:
        return None
    from flighttest.planner.plot import plot_trajectory

    try:
        return str(plot_trajectory(traj, args.plot, constraint, wind, guard=guard))
    except OSError as exc:
        raise FlighttestError(f"--plot {args.plot}: cannot write ({exc.strerror or exc})") from None


@dataclass
class _Summary:
    """What a command reports about its plan, besides the files it wrote (``_write_and_report``)."""

    title: str
    status: str
    t_f_s: float
    solve_s: float
    fields: dict[str, Any]  # JSON keys after status, t_f_s, solve_s, path and plot
    rows: list[tuple[str, str]]  # table rows before the trajectory and plot rows


def _autopilot_rows(profile: VehicleProfile) -> list[tuple[str, str]]:
    """The row naming the autopilot limits the plan keeps within (none for a profile without them)."""
    from flighttest.planner.autopilot_limits import AUTOPILOT_LIMIT_FRACTION, NO_LIMITS, plan_limits

    ap = profile.autopilot
    if ap is None:
        return []
    named = [(label, v, unit) for label, v, unit in (
        ("vertical accel", ap.accel_z_max_mps2, "m/s²"), ("horizontal accel", ap.accel_h_max_mps2, "m/s²"),
        ("descent", ap.descent_max_mps, "m/s"), ("climb", ap.climb_max_mps, "m/s")) if v is not None]  # fmt: skip
    limits = ", ".join(f"{label} {v:g} {unit}" for label, v, unit in named) or "none given"
    if plan_limits(profile) is NO_LIMITS:  # PX4's: it clips, the plan is not shaped (planner.autopilot_limits)
        return [("autopilot limits", f"{ap.name} clips at {limits}: the preflight checks the plan against them")]
    return [("autopilot limits", f"≤ {AUTOPILOT_LIMIT_FRACTION:.0%} of {ap.name}'s {limits}")]


def _mission(name: str):
    """The named mission's config as `flighttest fly` reads it (a user's copy first, else the shipped one)."""
    return load_mission_config(mission_config_path(name))


def _basis(traj, cfg) -> None:
    """Record in the sidecar that ``traj`` is what the mission of ``cfg`` flies."""
    traj.meta.update({"plan_basis": "mission", "mission_config": cfg.path})


def _write_and_report(args: argparse.Namespace, traj, out_stem: Path, summary: _Summary, constraint,
                      wind: tuple[float, float, float] = (0.0, 0.0, 0.0),
                      validate_for: VehicleProfile | None = None) -> None:  # fmt: skip
    """The tail every command shares: check the trajectory against the vehicle (``validate_for``),
    write it, draw it (``--plot``: the plan against its ``constraint`` in the ``wind``, the region of the
    vehicle's guard shaded — the constraint's own without a vehicle), report it."""
    from flighttest.planner.problems import vehicle_constraint

    guard = None
    if validate_for is not None:
        traj.validate(validate_for, where="planned trajectory")
        guard = vehicle_constraint(validate_for, "guard")
    out = _save(traj, out_stem)
    plot = _plot(args, traj, constraint, wind, guard)
    if args.json:  # JSON only: scripts parse stdout
        print_json({"status": summary.status, "t_f_s": summary.t_f_s, "solve_s": summary.solve_s, "path": str(out),
                    "plot": plot, **summary.fields})  # fmt: skip
        return
    table = Table(title=summary.title, show_header=False)
    table.add_column("", style="bold")
    table.add_column("")
    for k, v in [*summary.rows, ("trajectory", str(out)), *([("plot", plot)] if plot else [])]:
        table.add_row(k, Text(v))  # as written: "[plan]" and paths are not rich markup
    console.print(table)


def _failed(args: argparse.Namespace, kind: str, sol) -> int:
    r = sol.result
    data = {
        "status": r.status,
        "t_f_s": r.t_f_s,
        "solve_s": sol.solve_s,
        "path": None,
        "best_point": {"t_f_s": r.t_f_s, "max_defect": r.max_defect, "iterations": r.iterations, "guess": r.guess},
        "attempts": sol.attempts,
    }
    if args.json:
        print_json(data)
    else:
        err_console.print(
            f"[red]{kind}: the solver did not converge[/red] (status {r.status}); best point: t_f = {r.t_f_s:.3f} s, "
            f"max dynamics defect {r.max_defect:.2e}, after {r.iterations} iterations from guess '{r.guess}'. "
            "Nothing written."
        )
    return SOLVER_FAILED


# -- commands ----------------------------------------------------------------------------------------


def cmd_planar(args: argparse.Namespace) -> int:
    from flighttest.planner.cases import table_case
    from flighttest.planner.export import planar_trajectory
    from flighttest.planner.planar import solve_planar
    from flighttest.planner.problems import planar_problem

    profile = load_profile(args.vehicle)
    if args.f_min is not None and args.f_max is not None and args.f_min >= args.f_max:
        raise FlighttestError(f"--f-min ({args.f_min:g}) must be below --f-max ({args.f_max:g})")
    case = table_case(args.case) if args.case is not None else None
    out_stem = _out_path(args, f"planar-case{args.case}" if case else f"planar-{profile.name}-{args.height:g}m")
    wind_y, wind_z = args.wind if args.wind else (0.0, 0.0)
    free = args.phi_bound == "free"
    p = planar_problem(
        profile,
        args.case,
        constraint_kind=args.constraint or "cone",
        margin_mps=args.margin,
        height_m=args.height,
        y_bound_m=args.y_bound,
        y_final=args.y_final,
        phi_bound_deg=None if free else args.phi_bound,
        flips=free,
        omega_max_rps=args.omega_max,
        f_min_mps2=args.f_min,
        f_max_mps2=args.f_max,
        v_bound_mps=args.v_bound,
        wind_y_mps=wind_y,
        wind_z_mps=wind_z,
        n_intervals=args.intervals,
    )
    sol = solve_planar(p, verbose=args.verbose)
    if not sol.success:
        return _failed(args, "planar", sol)
    meta = {"table_case": case.number, "paper_t_f_s": case.paper_t_f_s} if case else {}
    traj = planar_trajectory(sol, profile.name, profile.mass_kg, meta)
    man = sol.manoeuvre()
    x = sol.result.x
    fields = {
        "case": args.case,
        "paper_t_f_s": case.paper_t_f_s if case else None,
        "manoeuvre": man["label"],
        "max_abs_y_m": float(abs(x[:, 0]).max()),
        "max_abs_phi_deg": float(math.degrees(abs(x[:, 4]).max())),
        "final_y_m": float(x[-1, 0]),
        "min_f_coll_mps2": float(sol.result.u[:, 0].min()),
        "worst_margin_mps": sol.check["worst_margin_mps"],
        "check": sol.check,
        "problem": p.summary(),
        "attempts": sol.attempts,
    }
    rows = [
        ("status", sol.status),
        ("optimal time", f"{sol.t_f_s:.3f} s" + (f"  (paper {case.paper_t_f_s:.2f} s)" if case else "")),
        ("solve time", f"{sol.solve_s:.2f} s ({len(sol.attempts)} solves)"),
        ("manoeuvre", man["label"]),
        ("max |Y| / final Y", f"{fields['max_abs_y_m']:.2f} m / {fields['final_y_m']:.2f} m"),
        ("max |φ|", f"{fields['max_abs_phi_deg']:.1f}°"),
        ("min f_coll", f"{fields['min_f_coll_mps2']:.2f} m/s²"),
        ("constraint", f"{p.constraint.name}, margin {p.constraint.margin_mps:g} m/s"),
        (
            "worst margin (1 kHz re-sim)",
            f"{sol.check['worst_margin_mps']:+.4f} m/s at t={sol.check['worst_margin_t_s']:.2f} s",
        ),
    ]
    title = f"planar descent (Table II case {args.case})" if case else f"planar descent ({profile.name})"
    summary = _Summary(title, sol.status, sol.t_f_s, sol.solve_s, fields, rows)
    # Table II's bounds are the paper's, not a vehicle's (its thrust goes negative): not checked against one
    _write_and_report(args, traj, out_stem, summary, p.constraint, (0.0, p.wind_y_mps, p.wind_z_mps),
                      validate_for=None if case else profile)  # fmt: skip
    return 0


def cmd_helix(args: argparse.Namespace) -> int:
    from flighttest.planner.export import helix_trajectory
    from flighttest.planner.helix import solve_helix
    from flighttest.planner.problems import default_coarse_intervals, helix_problem
    from flighttest.planner.tracking import TrackingMargin, helix_problem_for_flight

    profile = load_profile(args.vehicle)
    cfg = _mission("helix")
    hp = HelixPlanConfig.from_table(cfg.plan)
    if not args.paper:
        given = [flag for key, flag in PAPER_ONLY.items() if getattr(args, key) is not None]
        if given:
            raise FlighttestError(f"{', '.join(given)}: only with --paper (the helix `fly helix` flies takes its "
                                  f"bounds from [plan] in {cfg.path}: edit them there)")  # fmt: skip
        if hp.trajectory:
            raise FlighttestError(f"{cfg.path}: the helix mission flies the planned file {hp.trajectory!r}, so "
                                  "`fly helix` plans nothing (--paper plans the paper's problem)")  # fmt: skip
    height = args.height if args.height is not None else hp.descent_m
    radius = args.radius if args.radius is not None else hp.radius_m
    n = args.intervals if args.intervals is not None else hp.n_intervals
    n_coarse = hp.n_coarse if args.intervals is None else default_coarse_intervals(n)
    out_stem = _out_path(args, f"helix-{profile.name}-{height:g}m-r{radius:g}" + ("-paper" if args.paper else ""))
    wind = tuple(args.wind) if args.wind else (0.0, 0.0, 0.0)
    if args.paper:
        p = helix_problem(
            profile,
            height_m=height,
            radius_m=radius,
            constraint_kind=args.constraint or "cone",
            margin_mps=args.margin,
            thrust_fraction=args.thrust_fraction if args.thrust_fraction is not None else PAPER_THRUST_FRACTION,
            tilt_max_deg=args.tilt_max,
            rate_max_dps=args.rate_max,
            wind_ned_mps=wind,
            end_ne_m=tuple(args.end) if args.end else (0.0, 0.0),
            n_intervals=n,
            n_coarse=n_coarse,
        )
        basis = {"plan_basis": "paper", "mission_config": None}
        planned_as = "the paper's problem: pure cone, full tilt and body rates (not what `fly helix` flies)"
    else:
        plan = {**cfg.plan, "descent_m": height, "radius_m": radius, "n_intervals": n}  # as `fly --descent` does
        p = helix_problem_for_flight(profile, height_m=height, radius_m=radius, margin=TrackingMargin.from_plan(plan),
                                     n_intervals=n, n_coarse=n_coarse,
                                     wind_radius_mps=hp.calm_wind_radius_mps)  # fmt: skip
        basis = {"plan_basis": "mission", "mission_config": cfg.path, "tracking_margin": plan}
        planned_as = f"what `fly helix` flies ([plan] of {cfg.path})"
    sol = solve_helix(p, verbose=args.verbose)
    if not sol.success:
        return _failed(args, "helix", sol)
    traj = helix_trajectory(sol, profile.name, profile.mass_kg, extra=basis)
    c = sol.check
    fields = {
        "vehicle": profile.name,
        "plan_basis": basis["plan_basis"],
        "mission_config": basis["mission_config"],
        "turns": c["turns"],
        "max_radius_m": c["max_radius_m"],
        "max_tilt_deg": c["max_tilt_deg"],
        "worst_margin_mps": c["worst_margin_mps"],
        "check": c,
        "problem": p.summary(),
        "attempts": sol.attempts,
    }
    rates = p.summary()["rate_max_dps"]
    rows = [
        ("planned as", planned_as),
        ("status", sol.status),
        ("optimal time", f"{sol.t_f_s:.3f} s for {height:g} m"),
        ("solve time", f"{sol.solve_s:.2f} s"),
        ("turns", f"{c['turns']:.2f}"),
        ("max radius", f"{c['max_radius_m']:.2f} m (bound {radius:g})"),
        ("max tilt", f"{c['max_tilt_deg']:.1f}° (bound {p.summary()['tilt_max_deg']:.1f}°)"),
        ("body-rate bound", f"{rates[0]:.0f}°/s roll and pitch"),
        ("constraint", f"{p.constraint.name}, margin {p.constraint.margin_mps:g} m/s"),
        ("worst margin (1 kHz re-sim)", f"{c['worst_margin_mps']:+.4f} m/s"),
        *_autopilot_rows(profile),
    ]
    summary = _Summary(f"3D descent ({profile.name})", sol.status, sol.t_f_s, sol.solve_s, fields, rows)
    _write_and_report(args, traj, out_stem, summary, p.constraint, wind, validate_for=profile)
    return 0


def cmd_vertical(args: argparse.Namespace) -> int:
    from flighttest.planner.export import vertical_trajectory
    from flighttest.planner.problems import vertical_constraint, vertical_plan

    profile = load_profile(args.vehicle)
    cfg = _mission("vertical")
    vp = VerticalPlanConfig.from_table(cfg.plan)
    height = args.height if args.height is not None else vp.descent_m
    out_stem = _out_path(args, f"vertical-{profile.name}-{height:g}m")
    plan = vertical_plan(
        profile, height, w_allow_mps=args.w_allow, margin_mps=args.margin,
        extra_margin_mps=args.extra_margin if args.extra_margin is not None else vp.extra_margin_mps,
        accel_fraction=args.accel_fraction if args.accel_fraction is not None else vp.accel_fraction,
        jerk_mps3=vp.jerk_max_mps3,
    )  # fmt: skip
    traj = vertical_trajectory(plan, profile.name, profile.mass_kg)
    _basis(traj, cfg)
    w_allow = plan.problem["w_allow_mps"]
    fields = {
        "plan_basis": "mission",
        "mission_config": cfg.path,
        "cruise_mps": plan.cruise_mps,
        "w_allow_mps": w_allow,
        "a_down_mps2": plan.a_down_mps2,
        "a_up_mps2": plan.a_up_mps2,
        "problem": plan.problem,
    }
    rows = [
        ("planned as", f"what `fly vertical` flies ([plan] of {cfg.path})"),
        ("duration", f"{plan.t_f_s:.2f} s for {height:g} m"),
        ("cruise", f"{plan.cruise_mps:.3f} m/s (w_allow {w_allow:.3f} m/s)"),
        ("accel down / up", f"{plan.a_down_mps2:.2f} / {plan.a_up_mps2:.2f} m/s²"),
        *_autopilot_rows(profile),
    ]
    summary = _Summary(f"vertical baseline ({profile.name})", "closed_form", plan.t_f_s, 0.0, fields, rows)
    _write_and_report(args, traj, out_stem, summary, vertical_constraint(profile, plan), validate_for=profile)
    return 0


def cmd_probe(args: argparse.Namespace) -> int:
    from flighttest.planner.export import probe_trajectory
    from flighttest.planner.problems import probe_plan, vehicle_constraint

    profile = load_profile(args.vehicle)
    out_stem = _out_path(args, f"probe-{profile.name}")
    # what `flighttest fly probe` flies unless told otherwise: its mission's [plan], start height and floor
    cfg = _mission("probe")
    pp, fl = ProbePlanConfig.from_table(cfg.plan), cfg.flight

    def given(value, default):
        return value if value is not None else default

    plan = probe_plan(
        profile,
        amplitude_m=given(args.amplitude, pp.amplitude_m),
        omega0_rps2=given(args.omega0, pp.omega0_rps2),
        ramp_s=given(args.ramp, pp.ramp_s),
        max_descent_mps=given(args.max_descent_speed, pp.top_speed_mps(profile.w_allow_mps)),
        duration_s=given(args.duration, pp.duration_s),
        start_alt_m=given(args.start_alt, fl.start_height_m),
        floor_alt_m=given(args.floor, fl.min_alt_m),
        speed_step_mps=args.speed_step,
        accel_fraction=pp.accel_fraction,
    )
    traj = probe_trajectory(plan, profile.name, profile.mass_kg)
    _basis(traj, cfg)
    fields = {
        "plan_basis": "mission",
        "mission_config": cfg.path,
        "cycles": plan.cycles,
        "max_descent_mps": plan.max_descent_mps,
        "w_allow_mps": profile.w_allow_mps,
        "speed_first_reached": plan.speed_first_reached,
        "problem": plan.problem,
    }
    rows = [
        ("planned as", f"what `fly probe` flies ([plan] of {cfg.path})"),
        ("duration", f"{plan.t_f_s:.2f} s, {plan.cycles} cycles"),
        # the cap the plan was made with: the autopilot's descent limit may have lowered it
        ("max descent speed", f"{plan.max_descent_mps:.2f} m/s (cap {plan.problem['max_descent_mps']:g})"),
        ("profile w_allow", f"{profile.w_allow_mps:.3f} m/s"),
        *_autopilot_rows(profile),
    ]
    summary = _Summary(f"probe reference ({profile.name})", "closed_form", plan.t_f_s, 0.0, fields, rows)
    # the plot's region is the guard's as `fly probe` flies it (the profile's w_allow and margin)
    _write_and_report(args, traj, out_stem, summary, vehicle_constraint(profile, "guard"), validate_for=profile)
    if not args.json:
        t = Table(title="descent speed first reached")
        t.add_column("speed (m/s)", justify="right")
        t.add_column("t (s)", justify="right")
        for row in plan.speed_first_reached[:: max(1, len(plan.speed_first_reached) // 15)]:
            t.add_row(f"{row['speed_mps']:.2f}", f"{row['t_s']:.2f}")
        console.print(t)
    return 0
