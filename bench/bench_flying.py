"""Benchmark flying: guard reaction latency, setpoint jitter, CPU of the flying process.

    python bench/bench_flying.py [--violations 6] [--telemetry-hz 50] [--json]

Each deliberate violation is one real flight of ``flighttest fly`` (a subprocess, as in the field)
against a fresh fake: take off, climb, settle, then a vertical descent planned at 2·w_allow, which
the guard must abort. It is flown twice per repetition: with the guard's prediction off
(``horizon_s = 0``: the guard can only react to a measured sample, which is what the latency
target is about) and as configured (``horizon_s = 0.2``: it usually acts *before* the vehicle is
inside, so the "latency" comes out negative). Plus one nominal vertical mission for jitter and CPU.

- **latency**: from the first telemetry sample inside the guard region — the first
  LOCAL_POSITION_NED + ATTITUDE_QUATERNION pair in the flight's ``.tlog`` whose blade-frame (w, u)
  is inside ``profile.guard_region()``, stamped with the fake's clock (``time_boot_ms``) — to the
  arrival at the vehicle (the fake's truth log, same clock) of the first setpoint that arrests the
  sink (v_D ≤ 0: the hold the stopped stream leaves, then the recovery setpoint); a flight whose
  vehicle was never inside before that arrival counts as "acted before entry" (no latency);
- **setpoint jitter**: ``|interval − 1/rate|`` between consecutive sends of one phase, from every
  flight's ``setpoints.csv`` (sender side), p50 / p99 / max;
- **CPU**: user + system seconds of the ``flighttest fly`` process (``os.wait4``) over its wall time.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

import numpy as np
import pandas as pd
import tomli_w
from pymavlink import mavutil

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from flighttest.model.profiles import load_profile
from flighttest.planner.export import vertical_trajectory
from flighttest.planner.vertical import plan_vertical
from sitl_fakes.launcher import FakeVehicle

ROOT = Path(__file__).resolve().parents[1]


def fly(args: list[str]) -> tuple[dict, float, float]:
    """Run ``flighttest fly`` → (summary, cpu seconds, wall seconds)."""
    t0 = time.monotonic()
    p = subprocess.Popen([sys.executable, "-m", "flighttest", "fly", *args, "--json", "--yes"], cwd=ROOT,
                         stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)  # fmt: skip
    out = p.stdout.read()
    _, _, ru = os.wait4(p.pid, 0)
    wall = time.monotonic() - t0
    p.stdout.close()
    return json.loads(out), ru.ru_utime + ru.ru_stime, wall


def first_inside_sample_s(tlog: Path, region, after_boot_s: float, before_boot_s: float) -> float | None:
    """Fake-clock time of the first state sample in the tlog inside the guard region, in a window."""
    m = mavutil.mavlink_connection(str(tlog))
    att: dict[int, tuple] = {}
    pos: list[tuple[int, float, float, float]] = []
    while (msg := m.recv_match(type=["LOCAL_POSITION_NED", "ATTITUDE_QUATERNION"])) is not None:
        if msg.get_type() == "ATTITUDE_QUATERNION":
            att[msg.time_boot_ms] = (msg.q1, msg.q2, msg.q3, msg.q4)
        else:
            pos.append((msg.time_boot_ms, msg.vx, msg.vy, msg.vz))
    for t_ms, vn, ve, vd in sorted(pos):
        if not after_boot_s <= t_ms / 1000.0 <= before_boot_s or t_ms not in att:
            continue
        allowed, *_ = region.check(vn, ve, vd, *att[t_ms])
        if not allowed:
            return t_ms / 1000.0
    return None


def sink_arrested_rx_s(truth: pd.DataFrame) -> tuple[float | None, float | None]:
    """(fake-clock time the descent was first commanded, first arrival of a setpoint with v_D ≤ 0 after it)."""
    sp = truth[truth["kind"] == "setpoint"]
    vd = pd.to_numeric(sp["sp_vd_mps"], errors="coerce")
    down = sp[vd > 0.1]
    if down.empty:
        return None, None
    t_down = float(down["t_s"].iloc[0])
    later = sp[(sp["t_s"] > t_down) & (vd <= 0.0)]
    return t_down, (float(later["t_s"].iloc[0]) if not later.empty else None)


def jitter_ms(setpoints_csv: Path, period_s: float) -> np.ndarray:
    df = pd.read_csv(setpoints_csv)
    out = []
    for _, g in df.groupby((df["phase"] != df["phase"].shift()).cumsum()):
        if len(g) > 2:
            out.append(np.abs(np.diff(g["t_s"].to_numpy()) - period_s) * 1000.0)
    return np.concatenate(out) if out else np.array([])


def violation(tmp: Path, k: int, horizon_s: float, telemetry_hz: float, bad: Path) -> dict:
    cfg = tmp / f"cfg-{k}-{horizon_s:g}.toml"
    cfg.write_text(tomli_w.dumps({"mission": "file", "flight": {"telemetry_hz": telemetry_hz},
                                  "guard": {"horizon_s": horizon_s}}))  # fmt: skip
    truth_log = tmp / f"truth-{k}-{horizon_s:g}.csv"
    with FakeVehicle("x500", truth_log=truth_log, param={"MPC_Z_VEL_MAX_DN": 3.0}, seed=k) as fake:
        s, cpu, wall = fly([str(bad), "--connect", fake.url, "--vehicle", "x500", "--height", "5",
                            "--config", str(cfg), "--log-dir", str(tmp / "logs")])  # fmt: skip
    truth = pd.read_csv(truth_log, low_memory=False)
    t_down, t_rx = sink_arrested_rx_s(truth)
    region = load_profile("x500").guard_region()
    # inside before the sink was arrested (what the guard had to catch); None: it acted before entry
    t_in = first_inside_sample_s(Path(s["log_dir"]) / "flight.tlog", region, t_down or 0.0, t_rx or 1e9)
    lat = (t_rx - t_in) * 1000.0 if (t_in is not None and t_rx is not None) else None
    st = truth[truth["kind"] == "state"]
    return {"outcome": s["outcome"], "verdict": s.get("abort_verdict"), "latency_ms": lat,
            "first_inside_s": t_in, "arrest_rx_s": t_rx, "cpu_s": cpu, "wall_s": wall,
            "max_depth_n": float(st["depth_n"].max()), "log_dir": s["log_dir"],
            "jitter_ms": jitter_ms(Path(s["log_dir"]) / "setpoints.csv", 1.0 / 50.0)}  # fmt: skip


def pct(a, q):
    a = np.asarray([x for x in a if x is not None], float)
    return float(np.percentile(a, q)) if a.size else float("nan")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--violations", type=int, default=6, help="deliberate violations per guard setting")
    ap.add_argument("--telemetry-hz", type=float, default=50.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    prof = load_profile("x500")
    with tempfile.TemporaryDirectory(prefix="bench_flying_") as d:
        tmp = Path(d)
        plan = plan_vertical(prof, height_m=2.5, w_allow_mps=2 * prof.w_allow_mps, margin_mps=0.0, accel_fraction=0.5)
        bad = tmp / "bad_vertical"
        vertical_trajectory(plan, "x500", prof.mass_kg).save(bad)
        bad = bad.with_suffix(".csv")
        runs: dict[str, list[dict]] = {"reaction (horizon 0)": [], "as flown (horizon 0.2 s)": []}
        for k in range(args.violations):
            for name, h in (("reaction (horizon 0)", 0.0), ("as flown (horizon 0.2 s)", 0.2)):
                r = violation(tmp, k, h, args.telemetry_hz, bad)
                runs[name].append(r)
                if not args.json:
                    print(f"{name:26s} #{k}: {r['outcome']} ({r['verdict']}), latency "
                          f"{r['latency_ms'] if r['latency_ms'] is None else round(r['latency_ms'], 1)} ms, "
                          f"depth_n max {r['max_depth_n']:.3f}", flush=True)  # fmt: skip
        # one nominal mission: jitter and CPU over a whole flight
        cfg = tomllib.loads((ROOT / "missions" / "vertical_descent.toml").read_text())
        cfg["flight"]["telemetry_hz"] = args.telemetry_hz
        (tmp / "vertical.toml").write_text(tomli_w.dumps(cfg))
        with FakeVehicle("x500", truth_log=tmp / "truth-nominal.csv") as fake:
            s, cpu, wall = fly(["vertical", "--connect", fake.url, "--vehicle", "x500", "--height", "5",
                                "--config", str(tmp / "vertical.toml"), "--log-dir", str(tmp / "logs")])  # fmt: skip
        nominal_jitter = jitter_ms(Path(s["log_dir"]) / "setpoints.csv", 0.02)
    all_jitter = np.concatenate([nominal_jitter] + [r["jitter_ms"] for rs in runs.values() for r in rs])
    result: dict = {"telemetry_hz": args.telemetry_hz, "violations_per_setting": args.violations}
    for name, rs in runs.items():
        lat = [r["latency_ms"] for r in rs]
        result[name] = {
            "aborted": sum(r["outcome"] == "aborted" for r in rs), "n": len(rs),
            "acted_before_entry": sum(r["latency_ms"] is None for r in rs),
            "verdicts": sorted({str(r["verdict"]) for r in rs}),
            "latency_p50_ms": pct(lat, 50), "latency_p99_ms": pct(lat, 99), "latency_max_ms": pct(lat, 100),
            "latency_min_ms": pct(lat, 0), "max_depth_n": max(r["max_depth_n"] for r in rs),
            "cpu_pct_of_core": 100.0 * sum(r["cpu_s"] for r in rs) / sum(r["wall_s"] for r in rs),
        }  # fmt: skip
    result["nominal_vertical"] = {"outcome": s["outcome"], "descent_time_s": s["descent_time_s"],
                                  "cpu_s": cpu, "wall_s": wall, "cpu_pct_of_core": 100.0 * cpu / wall,
                                  "jitter_p50_ms": pct(nominal_jitter, 50), "jitter_p99_ms": pct(nominal_jitter, 99),
                                  "jitter_max_ms": pct(nominal_jitter, 100)}  # fmt: skip
    result["setpoint_jitter_all_flights"] = {"n": int(all_jitter.size), "p50_ms": pct(all_jitter, 50),
                                             "p99_ms": pct(all_jitter, 99), "max_ms": pct(all_jitter, 100)}  # fmt: skip
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for k, v in result.items():
            print(f"{k}: {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
