"""Analysis speed on a one-hour, 50 Hz .tlog against pymavlink's bare decode of the same file.

Writes (once, cached in the temp dir) a synthetic one-hour flight at 50 Hz (LOCAL_POSITION_NED,
ATTITUDE_QUATERNION, HIGHRES_IMU, SERVO_OUTPUT_RAW at 50 Hz; HEARTBEAT, WIND_COV at 1 Hz; a
5 m descent every minute), then times

1. pymavlink's bare decode: ``mavutil.mavlink_connection(path)`` and ``recv_msg()`` until the end
   (every message decoded once, nothing kept) — the fastest plain pymavlink loop;
2. our whole analysis: ``flighttest.analysis.pipeline.analyse_path`` (load, segment, exposure,
   fluctuation), each in a fresh child process so that peak memory (ru_maxrss) is its own.

Target: (2) ≤ 1.5 × (1). Run: ``python bench/bench_analysis.py`` (add ``--minutes N`` for a shorter file).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import resource
import sys
import tempfile
import time
from pathlib import Path


def bare_decode(path: str, q) -> None:
    from pymavlink import mavutil

    t0 = time.perf_counter()
    m = mavutil.mavlink_connection(path)
    n = 0
    while m.recv_msg() is not None:
        n += 1
    q.put((time.perf_counter() - t0, n, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024))


def our_analysis(path: str, q) -> None:
    from flighttest.analysis.pipeline import analyse_path

    t0 = time.perf_counter()
    a = analyse_path(path, "x500")
    q.put((time.perf_counter() - t0, len(a.descents), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024))


def baseline_rss(q) -> None:
    import flighttest.analysis.pipeline  # noqa: F401  (imports alone: numpy, pandas, pymavlink)

    q.put(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)


def in_child(fn, *args):
    q = mp.get_context("spawn").Queue()
    p = mp.get_context("spawn").Process(target=fn, args=(*args, q))
    p.start()
    out = q.get()
    p.join()
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=60.0)
    args = ap.parse_args()
    # the log writers are the tests' (tests/synthetic.py), not part of the installed package
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from synthetic import SyntheticFlight, write_tlog

    path = Path(tempfile.gettempdir()) / f"flighttest_bench_{args.minutes:g}min.tlog"
    if not path.exists():
        dur = args.minutes * 60
        descents = [(float(t0), 5.0, 2.5) for t0 in range(30, int(dur) - 30, 60)]
        # every descent goes 5 m further down, so start high enough for all of them
        flight = SyntheticFlight(duration_s=dur, start_alt_m=10.0 + 5.0 * len(descents), descents=descents)
        t0 = time.perf_counter()
        write_tlog(flight, path)
        print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t0:.1f} s")
    size_mb = path.stat().st_size / 1e6
    base_rss = in_child(baseline_rss)
    t_bare, n_msgs, rss_bare = in_child(bare_decode, str(path))
    t_ours, n_desc, rss_ours = in_child(our_analysis, str(path))
    print(f"file: {args.minutes:g} min at 50 Hz, {size_mb:.1f} MB, {n_msgs:,} messages")
    print(f"pymavlink bare decode (recv_msg loop): {t_bare:.2f} s, peak RSS {rss_bare:.0f} MB")
    print(
        f"flighttest analyse (load+segment+exposure+fluctuation): {t_ours:.2f} s, {n_desc} descents, "
        f"peak RSS {rss_ours:.0f} MB (imports alone {base_rss:.0f} MB)"
    )
    print(f"ratio ours / bare decode: {t_ours / t_bare:.3f} (target ≤ 0.2, issue 14)")


if __name__ == "__main__":
    main()
