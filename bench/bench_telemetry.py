"""Benchmark the telemetry a real link delivers and the flying process's own worst pause (issue 11).

    python bench/bench_telemetry.py [PX4_SIH_DIR] [--seconds 40] [--fake-flights] [--skip-pauses] [--json]

**1. Inter-arrival times on real PX4** (``PX4_SIH_DIR``, default ``../shared/px4_sih``: the six
reference flights of flighttest against PX4 SITL with SIH). A ``.tlog`` record's timestamp is when
flighttest's ``.tlog`` recorder thread received the message (``flighttest/flying/tlog_recorder.py``), in the flying
process. Per stream — position-velocity (``LOCAL_POSITION_NED``, what MAVSDK's
``position_velocity_ned`` is made of; ``ODOMETRY``), attitude (``ATTITUDE_QUATERNION``), and "state
(any)", the two merged, which is what the guard's staleness judges — and per flight phase (from the
``phase`` events of ``events.jsonl``; after an ``abort`` event the time is "ladder" until the ladder's
Land, which counts as "land"), the gaps' p50 / p99 / p99.9 / max. Beside them the same for the
position-velocity samples as flighttest's event loop handled them (``guard.csv``, one row per
sample, stamped on the loop), and how much later the loop handled each than the recorder received it.
Then every flight's telemetry is replayed through the guard's stale rule, the old one (3 periods,
60 ms) and the current one (``flighttest.flying.guard``: phase-aware), in virtual time at the mission's
ticker period: how many times each would have aborted. (A gap counts in the phase in which the
link went quiet.)

**2. The flying process's own worst pause** (each mode in a fresh subprocess, ``--seconds`` of
flying): the runner's objects as ``flighttest fly helix`` builds them (the helix plan, the
profile, the mission config, MAVSDK, CasADi and the planner imported; the ``MissionRunner`` with its
guard, ``FlightLogWriter`` and ``SetpointStreamer``; the real ``VehicleLink`` subscription code fed by a
thread that hands MAVSDK's own telemetry objects to the loop at 50 Hz per stream as MAVSDK's
callbacks do; the ``.tlog`` recorder thread receiving the reference flights' message mix over UDP;
a parameter snapshot of 1 000 parameters as at preflight), flying the phases of a mission: takeoff
(telemetry only), climb, settle, the helix stream, settle, land. Measured: every interval between
the streamer's setpoints (its 50 Hz deadline-paced ticker) and of a 50 Hz probe ticker, each
garbage collection (``gc.callbacks``: generation, duration), and the time of each flight-log
write on the loop. Modes: ``gc`` — the collector as CPython runs it; ``mitigated`` — the
runner's ``flighttest.flying.pauses.FlightCollector`` (freeze, no automatic runs, collections at the
settles' safe points); and ``gc+full`` / ``mitigated+full``: the same with one full collection
forced mid-stream, the pause CPython's own full collection costs whenever it comes. Then each
flight-log write alone, 3 000 times, against the same formatting into memory (no I/O) as a control.

**3. With ``--fake-flights``**: two real ``flighttest fly vertical --height 5`` flights against the
fake (real MAVSDK, real UDP), every collection recorded through ``gc.callbacks`` by a wrapper, the
runner's mitigation switched off in the first ("gc") and as shipped in the second ("mitigated"):
setpoint intervals in the offboard phases, position-velocity gaps on the loop by phase (``guard.csv``),
collections while flying, and the runner's own ``gc`` / ``stale_rule`` events.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import json
import math
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flighttest.analysis.loaders.mavlink_frames import decode, read_frames  # noqa: E402

DEFAULT_REF = ROOT.parent / "shared" / "px4_sih"
STREAMS = ("LOCAL_POSITION_NED", "ODOMETRY", "ATTITUDE_QUATERNION")
STATE = "state (any)"
LOOP = "posvel on the loop"
PHASE_LABEL = {"arm": "takeoff", "takeoff": "takeoff", "climb": "climb", "settle": "hover",
               "stream": "stream", "land": "land", "hold": "hold"}  # fmt: skip
PHASE_ORDER = ("takeoff", "climb", "hover", "stream", "ladder", "land", "ground", "all")
OLD_STALE_S = 0.060  # the rule the reference flights flew with: 3 periods at 50 Hz
TICK_S = 0.02  # the stale ticker's period (the telemetry period)


# -- 1. the reference flights ----------------------------------------------------------------------------


def arrivals(tlog: Path, sysid: int = 1) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """Receive times (UNIX s) of each state stream from the vehicle, and of both merged; and the
    longest step of PX4's own send stamps (``time_boot_ms``) per stream, ms."""
    frames = read_frames(tlog)
    out, sent = {}, {}
    for name in STREAMS:
        d = decode(frames, name, sysid=sysid)
        out[name] = np.sort(d.recv_us / 1e6) if d is not None else np.array([])
        if d is not None:
            stamp_ms = d.fields["time_usec"] / 1000.0 if name == "ODOMETRY" else d.fields["time_boot_ms"]
            sent[name] = float(np.diff(np.sort(stamp_ms.astype(float))).max())
    out[STATE] = np.sort(np.concatenate([out["LOCAL_POSITION_NED"], out["ATTITUDE_QUATERNION"]]))
    return out, sent


def phase_spans(events: list[dict]) -> list[tuple[float, str]]:
    """(UNIX start, label) of each span of the flight, in order."""
    spans: list[tuple[float, str]] = []
    in_ladder = False
    for e in events:
        if e["event"] == "abort" and not in_ladder:
            in_ladder = True
            spans.append((e["unix_s"], "ladder"))
        elif e["event"] == "ladder" and e.get("rung") == "LAND":
            spans.append((e["unix_s"], "land"))
        elif e["event"] == "ladder" and e.get("rung") == "DONE":
            spans.append((e["unix_s"], "ground"))
        elif e["event"] == "phase" and not in_ladder:
            spans.append((e["unix_s"], PHASE_LABEL.get(e["phase"], "ground")))
    return spans


def phase_at(spans: list[tuple[float, str]], t: np.ndarray) -> np.ndarray:
    starts = np.array([s for s, _ in spans])
    labels = np.array(["ground"] + [lab for _, lab in spans])
    return labels[np.searchsorted(starts, t, side="right")]


def loop_times(folder: Path, events: list[dict]) -> tuple[np.ndarray, pd.DataFrame]:
    """UNIX times at which the loop handled each position-velocity sample (``guard.csv``)."""
    g = pd.read_csv(folder / "guard.csv")
    g = g[(g["verdict"] != "stale") & g["vn_mps"].notna()]
    unix0 = float(np.median([e["unix_s"] - e["t_s"] for e in events]))
    return unix0 + g["t_s"].to_numpy(float), g


def loop_delay_ms(folder: Path, g: pd.DataFrame, t_loop: np.ndarray) -> np.ndarray:
    """Loop handling time − recorder receive time of the same LOCAL_POSITION_NED (matched on velocity)."""
    frames = read_frames(folder / "flight.tlog")
    d = decode(frames, "LOCAL_POSITION_NED", sysid=1)
    if d is None:
        return np.array([])

    def key(a, b, c):
        return [f"{float(f'{x:.6g}'):.4f}|{float(f'{y:.6g}'):.4f}|{float(f'{z:.6g}'):.4f}" for x, y, z in zip(a, b, c)]

    rec = pd.DataFrame({"k": key(d.fields["vx"], d.fields["vy"], d.fields["vz"]), "t_rec": d.recv_us / 1e6})
    rec = rec.drop_duplicates("k", keep=False)
    mine = pd.DataFrame({"k": key(g["vn_mps"], g["ve_mps"], g["vd_mps"]), "t_loop": t_loop})
    m = mine.merge(rec, on="k")
    return ((m["t_loop"] - m["t_rec"]) * 1000.0).to_numpy()


def stats_ms(gaps_ms: np.ndarray) -> dict[str, float]:
    if len(gaps_ms) == 0:
        return {"n": 0, "p50": math.nan, "p99": math.nan, "p99.9": math.nan, "max": math.nan}
    p = np.percentile(gaps_ms, [50, 99, 99.9])
    return {"n": len(gaps_ms), "p50": float(p[0]), "p99": float(p[1]), "p99.9": float(p[2]),
            "max": float(gaps_ms.max())}  # fmt: skip


def replay_stale(t_state: np.ndarray, t_posvel: np.ndarray, spans, rule: str) -> list[tuple[float, str, str]]:
    """Replay sample arrivals through the stale rule in virtual time, a tick every ``TICK_S``: the
    aborts it would have ordered, (UNIX time, phase label, reason). ``rule`` "old": 60 ms in every
    phase the guard was armed in (arm … settle after the stream); "new": ``flighttest.flying.guard``'s."""
    from flighttest.flying import guard as gd
    from flighttest.model.profiles import load_profile

    region = load_profile("x500").guard_region()
    if rule == "old":
        limits = gd.GuardLimits(region=region, telemetry_period_s=TICK_S, stale_periods=3.0)
    else:
        limits = gd.GuardLimits(region=region, telemetry_period_s=TICK_S)
    raw_phase = {"takeoff": "takeoff", "climb": "climb", "hover": "settle", "stream": "stream", "land": "land",
                 "hold": "hold", "ladder": "", "ground": ""}  # fmt: skip
    guard = gd.Guard(limits)
    events = sorted([(t, 0) for t in t_state] + [(t, 1) for t in t_posvel])
    ticks = np.arange(events[0][0], events[-1][0], TICK_S)
    labels = phase_at(spans, ticks)
    out, i, in_gap = [], 0, False
    for now, label in zip(ticks, labels):
        while i < len(events) and events[i][0] <= now:
            t, kind = events[i]
            if kind == 1:
                guard.last_velocity_t = t
            guard.note_state_sample(t)
            i += 1
        phase = raw_phase.get(label, "")
        if not phase or phase == "ground":
            continue  # not flying, or the ladder in charge: the guard does not act on staleness
        guard.armed = phase != "land"  # the runner's setting: landing is PX4's
        if rule == "old":
            d = guard.on_tick(now) if phase != "land" else None
        else:
            d = guard.on_tick(now, phase)
        if d is None:
            in_gap = False
        elif d.aborts and not in_gap:
            in_gap = True
            out.append((float(now), label, d.reason))
    return out


def reference(ref: Path) -> dict:
    folders = sorted(p for p in ref.iterdir() if (p / "flight.tlog").is_file())
    if not folders:
        raise SystemExit(f"no flight folders with a flight.tlog in {ref}")
    pooled: dict[tuple[str, str], list[np.ndarray]] = {}
    per_flight, delays, replays, worst = {}, [], {}, []
    for f in folders:
        events = [json.loads(line) for line in (f / "events.jsonl").read_text().splitlines() if line.strip()]
        spans = phase_spans(events)
        arr, sent = arrivals(f / "flight.tlog")
        t_loop, g = loop_times(f, events)
        arr[LOOP] = np.sort(t_loop)
        row = {}
        for stream, t in arr.items():
            gaps = np.diff(t) * 1000.0
            labels = phase_at(spans, t[:-1])  # the phase in which the link went quiet
            for label in set(labels):
                pooled.setdefault((stream, label), []).append(gaps[labels == label])
            pooled.setdefault((stream, "all"), []).append(gaps)
            row[stream] = {"max_ms": float(gaps.max()), "over_60_ms": int((gaps > 60).sum()),
                           "over_100_ms": int((gaps > 100).sum()), "over_250_ms": int((gaps > 250).sum())}  # fmt: skip
            if stream == STATE:
                for k in np.argsort(gaps)[-3:][::-1]:
                    worst.append((f.name, float(gaps[k]), str(labels[k]), float(t[k] - events[0]["unix_s"]
                                                                                + events[0]["t_s"])))  # fmt: skip
        row["sent_step_max_ms"] = sent
        per_flight[f.name] = row
        dl = loop_delay_ms(f, g, t_loop)
        delays.append(dl)
        per_flight[f.name]["loop_delay_ms"] = stats_ms(dl)
        replays[f.name] = {rule: replay_stale(arr[STATE], arr["LOCAL_POSITION_NED"], spans, rule)
                           for rule in ("old", "new")}  # fmt: skip
    table = {}
    for (stream, label), parts in pooled.items():
        table.setdefault(stream, {})[label] = stats_ms(np.concatenate(parts))
    return {"flights": [f.name for f in folders], "table": table, "per_flight": per_flight,
            "loop_delay_ms": stats_ms(np.concatenate(delays)), "replays": replays,
            "worst_state_gaps": sorted(worst, key=lambda w: -w[1])[:8]}  # fmt: skip


def print_reference(r: dict) -> None:
    print(f"\n## PX4 SITL (SIH) telemetry inter-arrival, {len(r['flights'])} reference flights (ms)\n")
    print("| stream | phase | gaps | p50 | p99 | p99.9 | max |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for stream in (*STREAMS, STATE, LOOP):
        for label in PHASE_ORDER:
            s = r["table"].get(stream, {}).get(label)
            if s is None or s["n"] == 0:
                continue
            name = f"**{label}**" if label == "all" else label
            print(f"| {stream} | {name} | {s['n']} | {s['p50']:.1f} | {s['p99']:.1f} | {s['p99.9']:.1f} | "
                  f"{s['max']:.1f} |")  # fmt: skip
    print("\nPer flight, max gap ms (gaps > 60 / > 100 / > 250 ms):\n")
    print("| flight | " + " | ".join((*STREAMS, STATE, LOOP)) + " | loop − recorder p50 / p99 / max |")
    print("|---|" + "---:|" * (len(STREAMS) + 3))
    for name, row in r["per_flight"].items():
        cells = [f"{row[s]['max_ms']:.1f} ({row[s]['over_60_ms']}/{row[s]['over_100_ms']}/{row[s]['over_250_ms']})"
                 for s in (*STREAMS, STATE, LOOP)]  # fmt: skip
        dl = row["loop_delay_ms"]
        print(f"| {name} | " + " | ".join(cells) + f" | {dl['p50']:.1f} / {dl['p99']:.1f} / {dl['max']:.1f} |")
    print("\nPX4's own send stamps (time_boot_ms; ODOMETRY time_usec), longest step per flight, ms: "
          + "; ".join(f"{n} " + "/".join(f"{v:.0f}" for v in row["sent_step_max_ms"].values())
                      for n, row in r["per_flight"].items()) + f" ({' / '.join(STREAMS)})")  # fmt: skip
    print("\nLongest state (any) gaps: " + "; ".join(f"{n} {g:.0f} ms ({lab}, t={t:.1f} s)"
                                                     for n, g, lab, t in r["worst_state_gaps"]))  # fmt: skip
    print("\nStale rule replayed (virtual time, 20 ms ticks): aborts it would have ordered\n")
    print("| flight | old: 60 ms everywhere | new: flighttest.flying.guard |")
    print("|---|---|---|")
    for name, rep in r["replays"].items():
        old = "; ".join(f"{lab} {why}" for _, lab, why in rep["old"]) or "none"
        new = "; ".join(f"{lab} {why}" for _, lab, why in rep["new"]) or "none"
        print(f"| {name} | {len(rep['old'])}: {old} | {len(rep['new'])}: {new} |")


# -- 2. the process's own pauses ---------------------------------------------------------------------------


def _mavlink_mix() -> list[bytes]:
    """One second of the reference flights' message mix from the vehicle (about 260 messages)."""
    from pymavlink.dialects.v20 import common as m

    mav = m.MAVLink(None, srcSystem=1, srcComponent=1)
    one = {
        "attitude": lambda: mav.attitude_encode(0, 0, 0, 0, 0, 0, 0),
        "aq": lambda: mav.attitude_quaternion_encode(0, 1, 0, 0, 0, 0, 0, 0),
        "gpi": lambda: mav.global_position_int_encode(0, 0, 0, 0, 0, 0, 0, 0, 0),
        "imu": lambda: mav.highres_imu_encode(0, *([0.0] * 13), 0),
        "lpn": lambda: mav.local_position_ned_encode(0, 0, 0, 0, 0, 0, 0),
        "odo": lambda: mav.odometry_encode(0, 1, 2, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0, 0, 0, 0, [0] * 21, [0] * 21),
        "vfr": lambda: mav.vfr_hud_encode(0, 0, 0, 0, 0, 0),
        "hb": lambda: mav.heartbeat_encode(2, 12, 0, 0, 0),
    }
    per_s = {"attitude": 100, "aq": 50, "gpi": 50, "imu": 50, "lpn": 50, "odo": 30, "vfr": 10, "hb": 1}
    frames = {k: f().pack(mav) for k, f in one.items()}
    seq = []
    for k, n in per_s.items():
        seq += [(i / n, frames[k]) for i in range(n)]
    return [b for _, b in sorted(seq, key=lambda x: x[0])]


class _FakeTelemetry:
    """What ``VehicleLink._start_subscriptions`` uses of MAVSDK's TelemetryAsync: rate setters and
    async generators fed as MAVSDK feeds them (a C thread → ``loop.call_soon_threadsafe``)."""

    STREAMS = ("position_velocity_ned", "attitude_quaternion", "imu", "wind", "flight_mode", "armed",
               "landed_state", "in_air", "battery", "health", "health_all_ok")  # fmt: skip

    def __init__(self) -> None:
        self.queues: dict[str, asyncio.Queue] = {}
        self.loop: asyncio.AbstractEventLoop | None = None
        for name in ("position_velocity_ned", "attitude_quaternion", "imu", "battery", "landed_state"):
            setattr(self, f"set_rate_{name}", self._setter(name))
        for name in self.STREAMS:
            setattr(self, f"subscribe_{name}", self._subscriber(name))

    @staticmethod
    def _setter(name: str):
        async def set_rate(hz: float) -> None:
            return None

        set_rate.__name__ = f"set_rate_{name}"
        return set_rate

    def _subscriber(self, name: str):
        async def gen():
            self.loop = asyncio.get_running_loop()
            q = self.queues.setdefault(name, asyncio.Queue())
            while True:
                yield await q.get()

        gen.__name__ = f"subscribe_{name}"
        return gen

    def destroy(self) -> None:
        pass

    def push(self, name: str, item) -> None:  # from the emitter thread, as MAVSDK's callback does
        q = self.queues.get(name)
        if q is not None and self.loop is not None:
            self.loop.call_soon_threadsafe(q.put_nowait, item)


class _FakeSystem:
    async def is_connected_state(self):
        yield True
        await asyncio.Event().wait()


class _FakeOffboard:
    """MAVSDK's synchronous offboard plugin: builds the C structs, sends nothing."""

    def set_position_velocity_acceleration_ned(self, p, v, a) -> None:
        p.to_c_struct(), v.to_c_struct(), a.to_c_struct()

    def set_velocity_ned(self, v) -> None:
        v.to_c_struct()


def _emitter(tel: _FakeTelemetry, state: dict, stop: threading.Event, udp_port: int | None) -> None:
    """50 Hz position-velocity, attitude and IMU as MAVSDK's objects, plus the .tlog datagrams."""
    from mavsdk.plugins import telemetry as t

    mix = _mavlink_mix()
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    period, k, j = 0.02, 0, 0
    t0 = time.perf_counter()
    while not stop.is_set():
        z = -state["alt_m"]
        pv = t.PositionVelocityNed(t.PositionNed(0.0, 0.0, z), t.VelocityNed(0.0, 0.0, state["vd_mps"]))
        tel.push("position_velocity_ned", pv)
        tel.push("attitude_quaternion", t.Quaternion(1.0, 0.0, 0.0, 0.0, k))
        tel.push("imu", t.Imu(t.AccelerationFrd(0.0, 0.0, -9.81), t.AngularVelocityFrd(0.0, 0.0, 0.0),
                              t.MagneticFieldFrd(0.2, 0.0, 0.4), 20.0, k))  # fmt: skip
        if udp_port is not None:
            for _ in range(len(mix) // 50):
                sock.sendto(mix[j % len(mix)], ("127.0.0.1", udp_port))
                j += 1
        k += 1
        delay = t0 + k * period - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    sock.close()


def _timed(obj, name: str, sink: list[float]) -> None:
    fn = getattr(obj, name)

    def wrapper(*a, **kw):
        t0 = time.perf_counter()
        try:
            return fn(*a, **kw)
        finally:
            sink.append(time.perf_counter() - t0)

    setattr(obj, name, wrapper)


async def _fly_phases(traj_path: Path, seconds: float, mode: str, tmp: Path) -> dict:
    # the modules `flighttest fly helix` has loaded by the time it flies
    import casadi  # noqa: F401
    import mavsdk.asyncio  # noqa: F401

    import flighttest.planner.helix  # noqa: F401
    from flighttest.analysis.params import snapshot
    from flighttest.cli import build_parser
    from flighttest.cli.fly import build_request
    from flighttest.flying.link import VehicleLink
    from flighttest.flying.log_writer import FlightLogWriter
    from flighttest.flying.pauses import FlightCollector
    from flighttest.flying.runner import MissionRunner
    from flighttest.flying.streamer import Setpoint, SetpointStreamer
    from flighttest.flying.tlog_recorder import TlogRecorder

    args = build_parser().parse_args(["fly", str(traj_path), "--connect", "udpout://127.0.0.1:14580", "--vehicle",
                                      "x500", "--yes", "--log-dir", str(tmp / "logs")])  # fmt: skip
    req = build_request(args)
    runner = MissionRunner(req)
    runner.log = log = FlightLogWriter(tmp / "logs", "bench")
    params = {f"PARAM_{i:04d}": float(i) for i in range(1000)}
    recorder = TlogRecorder(tmp / "bench.tlog").start()
    link = VehicleLink("udpout://127.0.0.1:14580", telemetry_hz=50.0)
    tel = _FakeTelemetry()
    link.telemetry, link.system = tel, _FakeSystem()
    runner.link = link
    await link._start_subscriptions()
    streamer = SetpointStreamer(_FakeOffboard(), log, 50.0, here=lambda: (0.0, 0.0, -link.state.alt_m))
    runner.streamer = streamer
    link.on_posvel.append(runner.watch.on_posvel)
    link.on_attitude.append(runner.guard.note_state_sample)
    link.on_imu.append(runner.watch.on_imu)
    writes: dict[str, list[float]] = {k: [] for k in ("guard", "setpoint", "event", "flush_if_due")}
    for name, sink in writes.items():
        _timed(log, name, sink)
    vstate = {"alt_m": 0.0, "vd_mps": 0.0}
    stop = threading.Event()
    emitter = threading.Thread(target=_emitter, args=(tel, vstate, stop, recorder.port), daemon=True)
    emitter.start()
    ticker_task = asyncio.create_task(runner.watch.stale_ticker())
    loop = asyncio.get_running_loop()
    probe_iv: list[tuple[float, float]] = []

    async def probe() -> None:
        last = loop.time()
        while True:
            await asyncio.sleep(0.02)
            now = loop.time()
            probe_iv.append((now, now - last))
            last = now

    probe_task = asyncio.create_task(probe())
    mitigate = mode.startswith("mitigated")
    force_full = mode.endswith("+full")
    full_ms = math.nan
    gcx = FlightCollector(enabled=mitigate)
    with gcx:  # the runner opens it once connected, before the preflight
        await asyncio.sleep(1.0)  # the preflight's second of telemetry …
        snapshot(params, {}, "PX4", time.time(), None)  # … and its parameter snapshot
        gcx.hold_off()  # before arming
        t_fly = loop.time()
        streamer.intervals_s.clear()
        runner.guard.armed = True
        # takeoff: PX4 flies, flighttest only listens
        runner.set_phase("takeoff")
        for _ in range(int(0.15 * seconds / 0.05)):
            vstate["alt_m"] = min(vstate["alt_m"] + 0.05, 2.0)
            await asyncio.sleep(0.05)
        runner.set_phase("climb")
        hold = Setpoint(0.0, 0.0, -5.0)
        await streamer.stream(lambda k: hold, "climb", max_ticks=int(0.15 * seconds * 50))
        vstate["alt_m"] = 5.0
        runner.set_phase("settle")
        gcx.safe_point()  # the runner's _settle
        await streamer.stream(lambda k: hold, "settle", max_ticks=int(0.1 * seconds * 50))
        runner.set_phase("stream")
        # the helix, again and again for a share of the flight like a probe's sweep
        t_end = time.perf_counter() + 0.4 * seconds
        n = 0
        while time.perf_counter() < t_end:
            if force_full and n == 1:
                t0 = time.perf_counter()
                gc.collect()
                full_ms = (time.perf_counter() - t0) * 1000.0
            await streamer.fly_trajectory(runner.traj, (0.0, 0.0, -5.0), lambda: time.perf_counter() > t_end)
            n += 1
        runner.set_phase("settle")
        gcx.safe_point()
        await streamer.stream(lambda k: hold, "settle", max_ticks=int(0.1 * seconds * 50))
        runner.set_phase("land")
        runner.guard.armed = False
        for _ in range(int(0.1 * seconds / 0.05)):
            vstate["alt_m"] = max(vstate["alt_m"] - 0.05, 0.0)
            await asyncio.sleep(0.05)
        pending_before_exit = gc.get_count()
        fly_s = loop.time() - t_fly
    restored = {"enabled": gc.isenabled(), "threshold": gc.get_threshold(), "frozen": gc.get_freeze_count()}
    stop.set()
    emitter.join(2.0)
    for task in (ticker_task, probe_task):
        task.cancel()
    await asyncio.gather(ticker_task, probe_task, return_exceptions=True)
    await link.close()
    recorder.stop()
    log.close()
    garbage = gc.collect()
    st = np.asarray(streamer.intervals_s) * 1000.0
    pr = np.asarray([iv for t, iv in probe_iv if t > t_fly + 0.02]) * 1000.0
    return {
        "mode": mode, "fly_s": fly_s, "tracked_objects": len(gc.get_objects()),
        "setpoint_interval_ms": {"p50": float(np.percentile(st, 50)), "p99": float(np.percentile(st, 99)),
                                 "p99.9": float(np.percentile(st, 99.9)), "max": float(st.max()), "n": len(st)},
        "probe_interval_ms": {"p50": float(np.percentile(pr, 50)), "p99": float(np.percentile(pr, 99)),
                              "p99.9": float(np.percentile(pr, 99.9)), "max": float(pr.max()), "n": len(pr)},
        "gc": gcx.stats.to_dict(), "forced_full_ms": full_ms,
        "writes_us": {k: {"n": len(v), "p50": float(np.percentile(v, 50) * 1e6) if v else math.nan,
                          "p99": float(np.percentile(v, 99) * 1e6) if v else math.nan,
                          "max": float(max(v) * 1e6) if v else math.nan} for k, v in writes.items()},
        "garbage_after": garbage, "pending_before_exit": list(pending_before_exit), "restored": restored,
        "tlog_messages": recorder.messages, "setpoints_sent": streamer.sent,
        "stale_decisions": int((pd.read_csv(log.dir / "guard.csv")["verdict"] == "stale").sum()),
    }  # fmt: skip


def child(args: argparse.Namespace) -> None:
    with tempfile.TemporaryDirectory(prefix="bench-telemetry-") as tmp:
        res = asyncio.run(_fly_phases(Path(args.traj), args.seconds, args.mode, Path(tmp)))
    print(json.dumps(res))


def pauses(seconds: float, modes: list[str]) -> list[dict]:
    from flighttest.flying.mission_scripts import load_mission_module
    from flighttest.flying.missions_config import load_mission_config
    from flighttest.model.profiles import load_profile

    out = []
    with tempfile.TemporaryDirectory(prefix="bench-telemetry-plan-") as tmp:
        mod = load_mission_module("helix")
        profile = load_profile("x500")
        t0 = time.perf_counter()
        traj = mod.plan(profile, load_mission_config(mod.CONFIG))
        plan_s = time.perf_counter() - t0
        traj.save(Path(tmp) / "helix")
        print(f"(helix planned in {plan_s:.1f} s: {traj.duration_s:.2f} s long)", file=sys.stderr)
        for mode in modes:
            p = subprocess.run([sys.executable, __file__, "--child", "--mode", mode, "--traj",
                                str(Path(tmp) / "helix.csv"), "--seconds", str(seconds)],
                               capture_output=True, text=True, cwd=ROOT)  # fmt: skip
            if p.returncode != 0:
                raise SystemExit(f"child {mode} failed:\n{p.stderr}")
            out.append(json.loads(p.stdout.strip().splitlines()[-1]))
            print(f"({mode} done)", file=sys.stderr)
    return out


def print_pauses(rows: list[dict]) -> None:
    print(f"\n## The flying process's own pauses ({rows[0]['fly_s']:.0f} s of flying per mode)\n")
    print(
        "| mode | setpoint interval p50 / p99 / p99.9 / **max** ms | probe ticker max ms | "
        "collections gen0/1/2 | longest gen0 / gen1 / gen2 ms | forced full collection ms | "
        "tracked objects | stale decisions |"
    )
    print("|---|---|---:|---|---|---:|---:|---:|")
    for r in rows:
        s, p, g = r["setpoint_interval_ms"], r["probe_interval_ms"], r["gc"]
        c, m = g["collections"], g["max_ms"]
        print(f"| {r['mode']} | {s['p50']:.1f} / {s['p99']:.1f} / {s['p99.9']:.1f} / **{s['max']:.1f}** | "
              f"{p['max']:.1f} | {c['gen0']}/{c['gen1']}/{c['gen2']} | {m['gen0']:.2f} / {m['gen1']:.2f} / "
              f"{m['gen2']:.2f} | {r['forced_full_ms']:.1f} | {r['tracked_objects']} | "
              f"{r['stale_decisions']} |")  # fmt: skip
    print("\nFlight-log writes on the loop (µs, p50 / p99 / max):\n")
    for r in rows:
        w = r["writes_us"]
        print(f"- {r['mode']}: " + "; ".join(f"{k} {v['p50']:.0f} / {v['p99']:.0f} / {v['max']:.0f} (n={v['n']})"
                                              for k, v in w.items()))  # fmt: skip
    for r in rows:
        if r["mode"].startswith("mitigated"):
            g = r["gc"]
            print(f"\n{r['mode']}: entry collection {g['entry_ms']:.1f} ms, {g['frozen']} objects frozen, "
                  f"{g['safe_points']} safe points; objects pending at the end {r['pending_before_exit']}, "
                  f"{r['garbage_after']} unreachable collected after the flight; collector after exit: "
                  f"{r['restored']}")  # fmt: skip


def log_writes(n: int = 3000) -> dict:
    """The flight log's writes alone (no threads, no loop): are they slow, or is the machine? Each
    ``FlightLogWriter`` write ``n`` times, and the same CSV formatting into memory as a control (no I/O)."""
    import csv
    import io

    from flighttest.flying.guard import Decision, GuardSample
    from flighttest.flying.log_writer import FlightLogWriter, csv_number

    def run(fn) -> dict[str, float]:
        ts = []
        for _ in range(n):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        us = np.asarray(ts) * 1e6
        p = np.percentile(us, [50, 99, 99.9])
        return {"p50": float(p[0]), "p99": float(p[1]), "p99.9": float(p[2]), "max": float(us.max())}

    out = {}
    with tempfile.TemporaryDirectory(prefix="bench-telemetry-log-") as tmp:
        log = FlightLogWriter(tmp, "bench")
        s = GuardSample(1.0, 0.1, 0.2, 0.3, 1.0, 0.0, 0.0, 0.0, 5.0)
        dec = Decision(1.0, "ok", "none", "", 0.1, 0.2, 0.3, 0.4, s)
        out["guard row"] = run(lambda: log.guard(dec))
        out["setpoint row"] = run(lambda: log.setpoint(time.monotonic(), "stream", *([0.1] * 10)))
        out["event (flushes every file)"] = run(lambda: log.event(time.monotonic(), "phase", phase="stream"))
        out["flush_if_due"] = run(log.flush_if_due)
        log.close()
    buf = io.StringIO()
    w = csv.writer(buf)
    row = [1.0, 2.0, "ok", 0.1, 0.2, 0.3, 0.4, "none", "", *([0.1] * 11)]

    def fmt_only() -> None:
        w.writerow([csv_number(float(x)) if isinstance(x, float | int) else x for x in row])
        if buf.tell() > 1_000_000:
            buf.seek(0)
            buf.truncate()

    out["control: a guard row formatted into memory"] = run(fmt_only)
    return out


def print_log_writes(r: dict) -> None:
    print("\n## Flight-log writes alone (µs; 3000 each)\n")
    print("| write | p50 | p99 | p99.9 | max |")
    print("|---|---:|---:|---:|---:|")
    for k, v in r.items():
        print(f"| {k} | {v['p50']:.0f} | {v['p99']:.0f} | {v['p99.9']:.0f} | {v['max']:.0f} |")


_WRAPPER = """
import gc, json, sys, time, atexit
rec, t0 = [], [0.0]
def cb(phase, info):
    if phase == "start":
        t0[0] = time.perf_counter()
    else:
        rec.append((time.time(), info["generation"], (time.perf_counter() - t0[0]) * 1000.0))
gc.callbacks.append(cb)
mode, out, argv = sys.argv[1], sys.argv[2], sys.argv[3:]
if mode == "gc":  # the collector as CPython runs it: the runner's FlightCollector changes nothing
    import flighttest.flying.pauses as p
    init = p.FlightCollector.__init__
    p.FlightCollector.__init__ = lambda self, enabled=True, young_limit=p.YOUNG_LIMIT: init(self, False, young_limit)
atexit.register(lambda: json.dump(rec, open(out, "w")))
from flighttest.cli import main
sys.exit(main(argv))
"""
OFFBOARD = ("climb", "settle", "stream")


def fake_flights(modes: list[str], mission: str = "vertical") -> list[dict]:
    """Real ``flighttest fly`` flights against the fake (real MAVSDK, real UDP), every collection
    recorded (``gc.callbacks`` in a wrapper), with the runner's mitigation off ("gc") and on."""
    from sitl_fakes.launcher import FakeVehicle

    out = []
    with tempfile.TemporaryDirectory(prefix="bench-telemetry-fly-") as tmp:
        for mode in modes:
            rec_path = Path(tmp) / f"gc-{mode}.json"
            with FakeVehicle("x500", param={"MPC_Z_VEL_MAX_DN": 3.0}) as fake:
                argv = ["fly", mission, "--connect", fake.url, "--vehicle", "x500", "--height", "5", "--yes",
                        "--json", "--log-dir", str(Path(tmp) / mode)]  # fmt: skip
                p = subprocess.run([sys.executable, "-c", _WRAPPER, mode, str(rec_path), *argv], cwd=ROOT,
                                   capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=300)  # fmt: skip
            summary = json.loads(p.stdout)
            log = Path(summary["log_dir"])
            meta = json.loads((log / "meta.json").read_text())
            unix0 = meta["start_unix_s"]
            events = [json.loads(x) for x in (log / "events.jsonl").read_text().splitlines() if x.strip()]
            phases = [(e["t_s"], e["phase"]) for e in events if e["event"] == "phase"]
            starts = np.array([t for t, _ in phases])
            names = np.array(["init"] + [ph for _, ph in phases])

            def phase_of(t, starts=starts, names=names):
                return names[np.searchsorted(starts, t, side="right")]

            sp = pd.read_csv(log / "setpoints.csv")
            iv, ph = np.diff(sp["t_s"].to_numpy()) * 1000.0, sp["phase"].to_numpy()[1:]
            same = sp["phase"].to_numpy()[1:] == sp["phase"].to_numpy()[:-1]
            off = same & np.isin(ph, OFFBOARD)
            g = pd.read_csv(log / "guard.csv")
            g = g[g["verdict"] != "stale"]
            gt = g["t_s"].to_numpy()
            ggap = np.diff(gt) * 1000.0
            gph = phase_of(gt[1:])
            rec = json.loads(rec_path.read_text()) if rec_path.is_file() else []
            coll = [(t - unix0, gen, ms) for t, gen, ms in rec if t - unix0 >= 0]
            flying = [(t, gen, ms, str(phase_of(t))) for t, gen, ms in coll
                      if phase_of(t) not in ("init", "connect", "preflight")]  # fmt: skip
            gc_events = [e for e in events if e["event"] == "gc"]
            out.append({
                "mode": mode, "outcome": summary["outcome"], "reason": summary.get("abort_reason"),
                "setpoint_interval_offboard_ms": stats_ms(iv[off]),
                "posvel_gap_by_phase_ms": {str(k): stats_ms(ggap[gph == k]) for k in sorted(set(gph))},
                "collections_in_flight": {f"gen{k}": sum(1 for c in flying if c[1] == k) for k in (0, 1, 2)},
                "longest_in_flight": max(flying, key=lambda c: c[2], default=None),
                "longest_before_arming": max(((t, gen, ms) for t, gen, ms in coll if phase_of(t) in
                                              ("connect", "preflight")), key=lambda c: c[2], default=None),
                "gc_events": gc_events, "telemetry_gaps": [e for e in events if e["event"] == "telemetry_gaps"],
                "stale_rule": next((e for e in events if e["event"] == "stale_rule"), None),
            })  # fmt: skip
            print(f"(fake flight {mode} done: {summary['outcome']})", file=sys.stderr)
    return out


def print_fake_flights(rows: list[dict]) -> None:
    print(
        "\n## Real flights on the fake (`flighttest fly vertical --height 5`), collector as CPython runs it vs the "
        "runner's mitigation\n"
    )
    print(
        "| mode | outcome | setpoint interval in offboard p50 / p99 / max ms | posvel gap on the loop, max ms by "
        "phase | collections while flying gen0/1/2 | longest collection while flying | longest before arming |"
    )
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        s = r["setpoint_interval_offboard_ms"]
        gaps = ", ".join(f"{k} {v['max']:.0f}" for k, v in r["posvel_gap_by_phase_ms"].items() if v["n"])
        c = r["collections_in_flight"]
        lf, lb = r["longest_in_flight"], r["longest_before_arming"]
        lf_s = f"gen{lf[1]} {lf[2]:.1f} ms ({lf[3]})" if lf else "none"
        lb_s = f"gen{lb[1]} {lb[2]:.1f} ms" if lb else "none"
        print(
            f"| {r['mode']} | {r['outcome']} | {s['p50']:.1f} / {s['p99']:.1f} / {s['max']:.1f} | {gaps} | "
            f"{c['gen0']}/{c['gen1']}/{c['gen2']} | {lf_s} | {lb_s} |"
        )
    for r in rows:
        if r["gc_events"]:
            print(
                f"\n{r['mode']} gc events: "
                + "; ".join(
                    json.dumps({k: v for k, v in e.items() if k not in ("unix_s", "event")}) for e in r["gc_events"]
                )
            )
        if r["stale_rule"]:
            rule = {k: v for k, v in r["stale_rule"].items() if k not in ("unix_s", "event")}
            print(f"{r['mode']} stale rule: {json.dumps(rule)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("ref", nargs="?", type=Path, default=DEFAULT_REF, help="the px4_sih reference folder")
    ap.add_argument("--seconds", type=float, default=40.0, help="flying time per pause-measurement mode")
    ap.add_argument("--modes", default="gc,mitigated,gc+full,mitigated+full")
    ap.add_argument("--skip-pauses", action="store_true")
    ap.add_argument("--skip-reference", action="store_true")
    ap.add_argument("--fake-flights", action="store_true", help="also fly the fake twice (collector on / mitigated)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--mode", help=argparse.SUPPRESS)
    ap.add_argument("--traj", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args)
        return
    out = {"load_average": os.getloadavg()}
    if not args.skip_reference:
        out["reference"] = reference(args.ref)
    if not args.skip_pauses:
        out["pauses"] = pauses(args.seconds, args.modes.split(","))
    if not args.skip_pauses:
        out["log_writes"] = log_writes()
    if args.fake_flights:
        out["fake_flights"] = fake_flights(["gc", "mitigated"])
    out["load_average_after"] = os.getloadavg()
    if args.json:
        print(json.dumps(out, default=str, indent=1))
        return
    print(f"load average before: {', '.join(f'{x:.2f}' for x in out['load_average'])}")
    if "reference" in out:
        print_reference(out["reference"])
    if "pauses" in out:
        print_pauses(out["pauses"])
    if "log_writes" in out:
        print_log_writes(out["log_writes"])
    if "fake_flights" in out:
        print_fake_flights(out["fake_flights"])
    print(f"\nload average after: {', '.join(f'{x:.2f}' for x in out['load_average_after'])}")


if __name__ == "__main__":
    main()
