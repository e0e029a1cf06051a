"""Does identify's stated uncertainty cover the truth? Its onset, its uncertainty and the terms of it for
probe log folders whose true onset is known (the fake's ``--truth-onset``, else Onera's for the vehicle).

Run: python bench/bench_identify_coverage.py TRUTH_MPS FOLDER... (e.g. the probe folders a flight lane left
under /tmp/pytest-of-$USER); prints one row per folder and the error in units of the stated uncertainty.
"""

from __future__ import annotations

import sys
from pathlib import Path

from flighttest.analysis.batch import quiet_numerics
from flighttest.analysis.identify import identify_onset
from flighttest.analysis.loaders import load_log
from flighttest.errors import FlighttestError
from flighttest.model.profiles import load_profile


def main(argv: list[str]) -> int:
    if len(argv) < 2:
        print(__doc__.strip().splitlines()[-2], file=sys.stderr)
        return 2
    truth = float(argv[0])
    print(f"{'folder':40s} {'read':>6s} {'±':>6s} {'boot':>6s} {'est':>6s} {'pass':>4s} {'err/±':>6s}")
    for folder in argv[1:]:
        log = load_log(Path(folder))
        name = log.vehicle_name or "x500"
        try:
            with quiet_numerics():
                o = identify_onset(log, load_profile(name))
        except FlighttestError as exc:
            print(f"{Path(folder).name[-40:]:40s} {str(exc)[-90:]}")
            continue
        err = abs(o.w_onset_mps - truth) / o.uncertainty_mps
        print(f"{Path(folder).name[-40:]:40s} {o.w_onset_mps:6.3f} {o.uncertainty_mps:6.3f} "
              f"{o.bootstrap_spread_mps:6.3f} {o.estimate_error_mps:6.3f} {o.onset_passes:4d} {err:6.2f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
