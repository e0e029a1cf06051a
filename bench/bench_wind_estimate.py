"""flighttest's wind estimate against the simulators' truth on ../shared/wind_sitl (real PX4 SITL and
ArduCopter SITL, 3 m/s of steady wind blowing east), from our folders and from the autopilots' own logs.

    python bench/bench_wind_estimate.py [--json]

Per flight and log: the estimate's error against the truth's wind over the airborne samples (median, p95,
max), its stated 1 σ (median) and the share of samples within 2.45 σ (the guard's coverage). The truth is
tests/test_wind_sitl.py's (SIH_WIND_N/E; ArduCopter's SIM_WIND_* with its sqrt(alt / SIM_WIND_T_ALT) profile).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from flighttest.analysis import wind as wind_mod
from flighttest.flying.wind import WIND_COVERAGE_SIGMAS
from test_wind_sitl import FLIGHTS, WIND_DIR, _Flights


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if not (WIND_DIR / "px4-helix-wind3e").is_dir():
        print(f"needs {WIND_DIR}", file=sys.stderr)
        return 2
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        flights = _Flights(Path(tmp))
        for name in FLIGHTS:
            truth, analyses = flights(name)
            for kind, a in analyses.items():
                s = a.log.state
                air = wind_mod.airborne_mask(s)
                boot = s["boot_s"].to_numpy(float)[air]
                tb = truth["boot_s"].to_numpy(float)
                true = np.column_stack([np.interp(boot, tb, truth[c].to_numpy(float)) for c in ("wn", "we")])
                err = np.hypot(*(a.log.wind.ned_mps[air, :2] - true).T)
                sd = a.log.wind.sd_mps[air]
                rows.append({"flight": name, "log": kind, "samples": int(air.sum()),
                             "err_median_mps": round(float(np.median(err)), 3),
                             "err_p95_mps": round(float(np.percentile(err, 95)), 3),
                             "err_max_mps": round(float(err.max()), 3),
                             "sd_median_mps": round(float(np.median(sd)), 3),
                             "within_2_45_sd": round(float(np.mean(err <= WIND_COVERAGE_SIGMAS * sd)), 3)})  # fmt: skip
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print("| flight | log | error median / p95 / max m/s | 1 σ median m/s | within 2.45 σ |")
    print("|---|---|---|---:|---:|")
    for r in rows:
        print(f"| {r['flight']} | {r['log']} | {r['err_median_mps']:.3f} / {r['err_p95_mps']:.3f} / "
              f"{r['err_max_mps']:.3f} | {r['sd_median_mps']:.3f} | {r['within_2_45_sd']:.0%} |")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
