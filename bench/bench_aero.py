"""Guard test throughput: 10⁶ states (v_ned, q, wind → verdict, margin) and one state at a time.

Run: python bench/bench_aero.py
Targets (issue 2): ≥ 5·10⁶ states/s vectorised on one core; ≤ 20 µs per single state through
GuardRegion.check, the same call the live guard makes per telemetry sample.
"""

from __future__ import annotations

import time

import numpy as np

from flighttest.model import aero
from flighttest.model.profiles import load_profile


def main() -> None:
    region = load_profile("x500").guard_region()
    rng = np.random.default_rng(0)
    n = 1_000_000
    v = rng.normal(0, 3, (3, n))
    q = rng.normal(0, 1, (4, n))
    q /= np.linalg.norm(q, axis=0)
    wind = rng.normal(0, 1, (3, n))
    cols = [np.ascontiguousarray(a) for a in (*v, *q, *wind)]

    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        allowed, _w, _u, margin = region.check(*cols)
        best = min(best, time.perf_counter() - t0)
    print(f"vectorised: {n:,} states in {best * 1e3:.1f} ms -> {n / best / 1e6:.1f} M states/s "
          f"({(~allowed).mean():.1%} forbidden)")

    state = [float(c[0]) for c in cols]
    reps = 200_000
    t0 = time.perf_counter()
    for _ in range(reps):
        region.check(*state)
    single = (time.perf_counter() - t0) / reps
    print(f"single state (floats, GuardRegion.check): {single * 1e6:.2f} µs")

    mu, eta = np.meshgrid(np.linspace(0, 3, 1000), np.linspace(-4, 1, 1000))
    t0 = time.perf_counter()
    aero.classify_n(mu, eta)
    print(f"Onera classification (Peters' v_i by bisection) of 10⁶ points: {time.perf_counter() - t0:.2f} s")


if __name__ == "__main__":
    main()
