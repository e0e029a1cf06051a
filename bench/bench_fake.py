"""Benchmark the fake vehicle: real-time factor, CPU, setpoint → truth-log latency.

    python bench/bench_fake.py [--seconds 20] [--physics-hz 250] [--telemetry-hz 50] [--json]

Starts ``python -m sitl_fakes`` (truth log at every physics step), connects a pymavlink ground
station (so every telemetry stream is really packed and sent), arms it in Offboard and streams
position setpoints at 20 Hz with a unique north value each, while it hovers. Then reports:
- real-time factor: simulated seconds (state rows / physics rate) per wall-clock second;
- CPU of the fake process (user + system, /proc) as % of one core;
- setpoint latency: send time → arrival row in the truth log (``unix_s``), and send time → first
  state row whose controller target carries that setpoint (the physics acting on it).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

import pandas as pd
from pymavlink import mavutil

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from sitl_fakes.launcher import FakeVehicle

POSITION_YAW_MASK = 0b100111111000


def cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--physics-hz", type=float, default=250.0)
    ap.add_argument("--telemetry-hz", type=float, default=50.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="bench_fake_"))
    fake = FakeVehicle(
        truth_log=tmp / "truth.csv", physics_hz=args.physics_hz, telemetry_hz=args.telemetry_hz
    ).start()
    sends: dict[float, float] = {}
    try:
        conn = mavutil.mavlink_connection(fake.url.replace("udpout://", "udpout:"), source_system=200)
        conn.mav.heartbeat_send(6, 8, 0, 0, 0)
        conn.wait_heartbeat(timeout=5)
        for _ in range(5):
            conn.mav.set_position_target_local_ned_send(0, 1, 1, 1, POSITION_YAW_MASK, 0, 0, -2, 0, 0, 0, 0, 0, 0, 0, 0)
            time.sleep(0.05)
        conn.mav.command_long_send(1, 1, 176, 0, 1, 6, 0, 0, 0, 0, 0)
        conn.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        time.sleep(0.5)
        cpu0, wall0 = cpu_seconds(fake.proc.pid), time.monotonic()
        received = 0
        i = 0
        while time.monotonic() - wall0 < args.seconds:
            north = round(0.001 * (i % 1000), 3)  # unique per send within a 50 s window, tiny moves
            sends[north] = time.time()
            conn.mav.set_position_target_local_ned_send(
                0, 1, 1, 1, POSITION_YAW_MASK, north, 0, -2, 0, 0, 0, 0, 0, 0, 0, 0
            )
            i += 1
            end = time.monotonic() + 0.05
            while time.monotonic() < end:  # drain telemetry like a ground station does
                if conn.recv_match(blocking=True, timeout=0.01) is not None:
                    received += 1
        cpu1, wall1 = cpu_seconds(fake.proc.pid), time.monotonic()
        conn.close()
    finally:
        fake.stop()

    df = pd.read_csv(fake.truth_log, low_memory=False)
    st = df[df.kind == "state"]
    t = st.t_s.astype(float)
    window = st[(t >= t.iloc[0] + 0.6) & (t <= t.iloc[0] + 0.6 + (wall1 - wall0))]
    rtf = len(window) / args.physics_hz / (wall1 - wall0)
    sp = df[df.kind == "setpoint"]
    arrival_ms = [
        1e3 * (float(u) - sends[round(float(n), 3)])
        for n, u in zip(sp.sp_n_m, sp.unix_s)
        if round(float(n), 3) in sends
    ]
    # first state row whose active target is each setpoint
    effect_ms = []
    firsts = st.dropna(subset=["sp_n_m"]).groupby(st.sp_n_m.round(3)).unix_s.min()
    for n, u in firsts.items():
        if n in sends:
            effect_ms.append(1e3 * (float(u) - sends[n]))
    # the first send of a value can be shadowed by a later resend of it: keep positive figures
    effect_ms = [x for x in effect_ms if x >= 0]
    result = {
        "physics_hz": args.physics_hz,
        "telemetry_hz": args.telemetry_hz,
        "seconds": round(wall1 - wall0, 2),
        "real_time_factor": round(rtf, 4),
        "cpu_percent_of_one_core": round(100 * (cpu1 - cpu0) / (wall1 - wall0), 1),
        "telemetry_msgs_per_s": round(received / (wall1 - wall0), 1),
        "setpoints_sent": len(sends),
        "setpoint_arrival_ms_median": round(statistics.median(arrival_ms), 3),
        "setpoint_arrival_ms_p99": round(sorted(arrival_ms)[int(0.99 * (len(arrival_ms) - 1))], 3),
        "setpoint_effect_ms_median": round(statistics.median(effect_ms), 3),
        "setpoint_effect_ms_p99": round(sorted(effect_ms)[int(0.99 * (len(effect_ms) - 1))], 3),
        "truth_rows_per_s": round(len(df) / (float(df.t_s.iloc[-1]) - float(df.t_s.iloc[0])), 1),
        "overruns": int(df.detail.astype(str).str.startswith("overrun").sum()),
    }
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for k, v in result.items():
            print(f"{k:32s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
