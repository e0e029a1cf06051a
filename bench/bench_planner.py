"""Planner benchmark: the six Table II cases and a 5 m helix; optimal times vs the paper, solve wall time.

    python bench/bench_planner.py [--omega-sweep] [--helix-vehicle x500] [--helix-radius 2]

Targets: each planar case ≤ 1 s, the helix ≤ 15 s (2-core machine). Solve times include building
the NLP (the first planar case pays for the compiled NLPs that the later cases re-use).
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from flighttest.planner.cases import TABLE_II, detected_classes
from flighttest.planner.helix import problem_for_vehicle, solve_helix
from flighttest.planner.planar import PlanarProblem, solve_planar
from flighttest.planner.vertical import plan_vertical
from flighttest.profiles import load_profile


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--omega-sweep", action="store_true", help="min time of the flip cases vs the ω bound")
    ap.add_argument("--helix-vehicle", default="x500")
    ap.add_argument("--helix-radius", type=float, default=2.0)
    ap.add_argument("--helix-intervals", type=int, default=60)
    args = ap.parse_args()

    print(
        "| case | paper t_f (s) | our t_f (s) | solve (s) | class (detected) | paper class | max abs Y (m) "
        "| max abs phi (deg) | min f_coll (m/s2) | worst margin 1 kHz (m/s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n, case in TABLE_II.items():
        sol = solve_planar(case.problem)
        x = sol.result.x
        ok = "ok" if detected_classes(sol.manoeuvre()) == case.paper_class else "MISMATCH"
        print(f"| {n} | {case.paper_t_f_s:.2f} | {sol.t_f_s:.3f} | {sol.solve_s:.2f} | {sol.manoeuvre()['label']} "
              f"({ok}) | {'+'.join(sorted(case.paper_class))} | {np.abs(x[:, 0]).max():.2f} | "
              f"{math.degrees(np.abs(x[:, 4]).max()):.1f} | {sol.result.u[:, 0].min():.2f} | "
              f"{sol.check['worst_margin_mps']:+.4f} |")  # fmt: skip

    prof = load_profile(args.helix_vehicle)
    p = problem_for_vehicle(prof, height_m=5.0, radius_m=args.helix_radius, n_intervals=args.helix_intervals,
                            n_coarse=args.helix_intervals // 2)  # fmt: skip
    t0 = time.perf_counter()
    sol = solve_helix(p)
    wall = time.perf_counter() - t0
    vert = plan_vertical(prof, 5.0)
    c = sol.check
    print()
    print(f"helix {prof.name} 5 m, radius {args.helix_radius:g} m, N={args.helix_intervals}: status {sol.status}, "
          f"t_f {sol.t_f_s:.3f} s, solve {wall:.2f} s, turns {c['turns']:.2f}, max radius {c['max_radius_m']:.3f} m, "
          f"max tilt {c['max_tilt_deg']:.1f} deg, worst margin {c['worst_margin_mps']:+.4f} m/s; "
          f"vertical baseline {vert.t_f_s:.2f} s (cruise {vert.cruise_mps:.3f} m/s)")  # fmt: skip

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
