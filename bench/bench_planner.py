"""Planner benchmark: the six Table II cases and helices; optimal times vs the paper, solve wall time.

    python bench/bench_planner.py [--repeats 3] [--omega-sweep] [--helix-vehicle x500] [--helix-radius 2]
                                  [--helix-height 5 20] [--helix-only] [--helix-sweep]

Targets: each planar case ≤ 1 s, the helix ≤ 15 s (2-core machine), also for long descents
(issue 11: 20 m at radius 2 m within 5 % of an independent solver's 9.99 s). ``--helix-height``
lists the descents of the helix lines (5 and 20 m by default); ``--helix-sweep`` solves 2, 5, 10,
20 and 30 m at radius 1, 2 and 3 m for the helix vehicle, each in a fresh process (cold: it builds
its own NLPs, as ``flighttest plan helix`` does). ``--helix-only`` skips the planar cases. Planar solve times are given
two ways, each as min / median over ``--repeats`` runs: "cold" solves every case in a fresh Python
process (it builds its own NLPs: the honest cold start), "in sequence" solves the six cases one
after the other in one process (the first pays for the compiled NLPs, later ones re-use them).
The load average is printed because other work on the machine shows in the wall times.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import time

import numpy as np

from flighttest.model.profiles import load_profile
from flighttest.planner.cases import TABLE_II, detected_classes
from flighttest.planner.helix import problem_for_vehicle, solve_helix
from flighttest.planner.planar import PlanarProblem, clear_ocp_cache, solve_planar
from flighttest.planner.vertical import plan_vertical


def _one_case(n: int) -> None:
    sol = solve_planar(TABLE_II[n].problem)
    print(json.dumps({"t_f_s": sol.t_f_s, "solve_s": sol.solve_s}))


def _cold(n: int) -> dict:
    out = subprocess.run([sys.executable, __file__, "--one-case", str(n)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.splitlines()[-1])


def _load() -> str:
    return "load average " + " / ".join(f"{v:.2f}" for v in os.getloadavg()) + " (1/5/15 min)"


def _min_med(values: list[float]) -> str:
    return f"{min(values):.2f} / {statistics.median(values):.2f}"


def _helix(vehicle: str, height: float, radius: float, intervals: int):
    prof = load_profile(vehicle)
    p = problem_for_vehicle(prof, height_m=height, radius_m=radius, n_intervals=intervals,
                            n_coarse=intervals // 2)  # fmt: skip
    t0 = time.perf_counter()
    sol = solve_helix(p)
    return prof, p, sol, time.perf_counter() - t0


def _one_helix(vehicle: str, height: float, radius: float, intervals: int) -> None:
    _, _, sol, wall = _helix(vehicle, height, radius, intervals)
    c = sol.check
    print(json.dumps({"status": sol.status, "t_f_s": sol.t_f_s, "solve_s": wall, "n_intervals": c["n_intervals"],
                      "limits_ok": c["limits_ok"], "turns": c["turns"], "max_radius_m": c["max_radius_m"],
                      "solves": len(sol.attempts)}))  # fmt: skip


def helix_sweep(vehicle: str, intervals: int) -> None:
    """2–30 m at radius 1, 2, 3 m, each solve in a fresh process (what ``flighttest plan helix`` pays)."""
    print(f"| {vehicle} | radius 1 m | radius 2 m | radius 3 m |")
    print("|---|---|---|---|")
    for height in (2.0, 5.0, 10.0, 20.0, 30.0):
        cells = []
        for radius in (1.0, 2.0, 3.0):
            out = subprocess.run([sys.executable, __file__, "--one-helix", vehicle, str(height), str(radius),
                                  str(intervals)], capture_output=True, text=True, check=True)  # fmt: skip
            r = json.loads(out.stdout.splitlines()[-1])
            bad = r["status"] != "optimal" or not r["limits_ok"]
            ok = f" **{r['status']}, limits_ok {r['limits_ok']}**" if bad else ""
            cells.append(f"{r['t_f_s']:.2f} s in {r['solve_s']:.1f} s "
                         f"(N={r['n_intervals']}, {r['turns']:.1f} turns){ok}")  # fmt: skip
        print(f"| {height:g} m | " + " | ".join(cells) + " |")


def helix_line(vehicle: str, radius: float, intervals: int, height: float = 5.0) -> None:
    prof, p, sol, wall = _helix(vehicle, height, radius, intervals)
    vert = plan_vertical(prof, height)
    c = sol.check
    print(f"helix {prof.name} {height:g} m, radius {radius:g} m, N={c['n_intervals']}: status {sol.status}, "
          f"t_f {sol.t_f_s:.3f} s, "
          f"solve {wall:.2f} s, turns {c['turns']:.2f}, max radius {c['max_radius_m']:.4f} m, "
          f"max tilt {c['max_tilt_deg']:.2f} deg (limit {math.degrees(p.tilt_max_rad):g}), "
          f"max rate {c['max_rate_dps']:.1f} dps (limit {math.degrees(max(p.rate_max_rps)):g}), "
          f"thrust {c['min_thrust_mps2']:.2f}..{c['max_thrust_mps2']:.2f} m/s2 "
          f"(limits {p.f_min_mps2:.2f}..{p.f_max_mps2:.2f}), worst cone margin {c['worst_margin_mps']:+.4f} m/s, "
          f"limits_ok {c['limits_ok']}, node gap {c['node_gap_m'] * 1000:.2f} mm, solves {len(sol.attempts)}; "
          f"vertical baseline {vert.t_f_s:.2f} s (cruise {vert.cruise_mps:.3f} m/s, "
          f"accel {vert.a_down_mps2:.2f}/{vert.a_up_mps2:.2f} m/s2)")  # fmt: skip


def _helices(args: argparse.Namespace) -> None:
    print()
    for height in args.helix_height:
        helix_line(args.helix_vehicle, args.helix_radius, args.helix_intervals, height)
        print(_load())
    if args.helix_vehicle != "mambo":
        helix_line("mambo", args.helix_radius, args.helix_intervals)
    print(_load())
    if args.helix_sweep:
        print()
        helix_sweep(args.helix_vehicle, args.helix_intervals)
        print(_load())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--omega-sweep", action="store_true", help="min time of the flip cases vs the ω bound")
    ap.add_argument("--repeats", type=int, default=3, help="runs per case for min/median solve times (3)")
    ap.add_argument("--helix-vehicle", default="x500")
    ap.add_argument("--helix-radius", type=float, default=2.0)
    ap.add_argument("--helix-intervals", type=int, default=60)
    ap.add_argument("--helix-height", type=float, nargs="+", default=[5.0, 20.0], metavar="M",
                    help="descents of the helix lines, m (5 20)")  # fmt: skip
    ap.add_argument("--helix-only", action="store_true", help="skip the planar cases")
    ap.add_argument("--helix-sweep", action="store_true", help="2-30 m x radius 1-3 m, each in a fresh process")
    ap.add_argument("--one-case", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--one-helix", nargs=4, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one_case:
        _one_case(args.one_case)
        return
    if args.one_helix:
        v, h, r, n = args.one_helix
        _one_helix(v, float(h), float(r), int(n))
        return

    print(_load())
    if args.helix_only:
        _helices(args)
        return
    cold = {n: [_cold(n)["solve_s"] for _ in range(args.repeats)] for n in TABLE_II}
    seq: dict[int, list[float]] = {n: [] for n in TABLE_II}
    sols = {}
    for _ in range(args.repeats):
        clear_ocp_cache()
        for n, case in TABLE_II.items():
            sols[n] = solve_planar(case.problem)
            seq[n].append(sols[n].solve_s)
    print(
        "| case | paper t_f (s) | our t_f (s) | solve cold, min / median (s) | solve in sequence, min / median (s) "
        "| class (detected) | paper class | max abs Y (m) | max abs phi (deg) | min f_coll (m/s2) "
        "| worst margin 1 kHz (m/s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for n, case in TABLE_II.items():
        sol = sols[n]
        x = sol.result.x
        ok = "ok" if detected_classes(sol.manoeuvre()) == case.paper_class else "MISMATCH"
        print(f"| {n} | {case.paper_t_f_s:.2f} | {sol.t_f_s:.3f} | {_min_med(cold[n])} | {_min_med(seq[n])} | "
              f"{sol.manoeuvre()['label']} ({ok}) | {'+'.join(sorted(case.paper_class))} | "
              f"{np.abs(x[:, 0]).max():.2f} | "
              f"{math.degrees(np.abs(x[:, 4]).max()):.1f} | {sol.result.u[:, 0].min():.2f} | "
              f"{sol.check['worst_margin_mps']:+.4f} |")  # fmt: skip
    print(_load())

    _helices(args)

    if args.omega_sweep:
        print()
        print("| omega_max (rad/s) | case 5 t_f (s) [paper 2.27] | case 6 t_f (s) [paper 2.08] |")
        print("|---|---|---|")
        for om in (3.0, 4.0, 4.5, 5.0, 6.0):
            ts = []
            for y_final in ("fixed", "free"):
                pp = PlanarProblem(y_bound_m=15, y_final=y_final, phi_bound_rad=None, omega_max_rps=om,
                                   n_intervals=160)  # fmt: skip
                ts.append(solve_planar(pp).t_f_s)
            print(f"| {om:g} | {ts[0]:.3f} | {ts[1]:.3f} |")


if __name__ == "__main__":
    main()
