"""Campaign wall time against the fake: where the field day's minutes go, step by step and phase by phase.

    python bench/bench_campaign.py [--vehicle x500] [--runs 1] [--keep DIR] [--json]

Each run is one real ``flighttest campaign --sim --yes --json -o DIR`` subprocess (as an operator
would rehearse it): probe, identify, plan, vertical, helix, report. Flights happen in real time,
so one run takes 2-3 minutes. Measured:

- **total**: wall time around the subprocess (Python start to exit, fake stopped);
- **per step**: ``elapsed_s`` from ``DIR/campaign.json`` and its share of the total; what is left
  (total − sum of steps) is the overhead outside the steps: interpreter start and imports before
  the first step, bookkeeping between steps, stopping the fake and exiting after the last;
- **per flight step**: the flight's phases from ``outputs.log_dir/events.jsonl`` (each ``phase``
  event runs until the next one; the abort ladder's rungs count as phases of their own), plus the
  step's own setup before the flight's first event (for the probe: starting the fake) and
  teardown after its ``end`` event; the descent is the ``stream`` phase (the trajectory or the
  probe's sweep), shown against the step time: how much of a flight is the descent itself;
- **CPU**: user + system seconds of the campaign process and the fake it started (``os.wait4``:
  the fake is its waited-for child, so it is included), over the wall time.

The machine (CPU count, Python, load average before and after) is printed because other work on
the machine shows in the wall times. With ``--runs N`` > 1 the tables give mean and min / max.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from flighttest.campaign.state import FLIGHT_STEPS, STEPS  # noqa: E402

SETUP = "(step setup before connect)"
TEARDOWN = "(step teardown after flight end)"
GROUPS = ("ground (setup, connect, preflight, arm)", "up (takeoff, climb, settle)", "stream (descent or sweep)",
          "down (hover, land or abort ladder, teardown)")  # fmt: skip


def _group(phase: str) -> str:
    """Which part of a flight a phase belongs to: what is descent, what is getting there and back."""
    if phase in (SETUP, "connect", "preflight", "arm"):
        return GROUPS[0]
    if phase in ("takeoff", "climb", "settle"):
        return GROUPS[1]
    return GROUPS[2] if phase == "stream" else GROUPS[3]


def _load() -> str:
    return "load average " + " / ".join(f"{v:.2f}" for v in os.getloadavg()) + " (1/5/15 min)"


def machine() -> str:
    return (f"machine: {os.cpu_count()} CPUs ({platform.machine()}), Python {platform.python_version()}, "
            f"{platform.system()} {platform.release()}")  # fmt: skip


def run_campaign(out_dir: Path, vehicle: str | None) -> dict[str, Any]:
    """One campaign subprocess → wall/CPU seconds, launch and exit unix times, return code, its JSON summary."""
    cmd = [sys.executable, "-m", "flighttest", "campaign", "--sim", "--yes", "--json", "-o", str(out_dir)]
    if vehicle:
        cmd += ["--vehicle", vehicle]
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    stderr_path = out_dir.parent / f"{out_dir.name}.stderr.log"  # progress, kept for a failed run
    with open(stderr_path, "wb") as err:
        launch_unix_s, t0 = time.time(), time.monotonic()
        p = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=err, stdin=subprocess.DEVNULL)
        stdout = p.stdout.read()
        _, status, ru = os.wait4(p.pid, 0)
        wall_s, exit_unix_s = time.monotonic() - t0, time.time()
    p.stdout.close()
    try:
        summary = json.loads(stdout)
    except ValueError:
        summary = {}
    return {"wall_s": wall_s, "cpu_s": ru.ru_utime + ru.ru_stime, "launch_unix_s": launch_unix_s,
            "exit_unix_s": exit_unix_s, "returncode": os.waitstatus_to_exitcode(status), "summary": summary,
            "stderr_log": str(stderr_path)}  # fmt: skip


def flight_phases(log_dir: Path, step_start_unix_s: float, step_end_unix_s: float) -> dict[str, float]:
    """Seconds per phase of one flight step, from its ``events.jsonl``, summed over repeats of a phase
    name except that a phase seen again after the descent (the hover before landing) is its own row."""
    events = [json.loads(line) for line in (log_dir / "events.jsonl").read_text().splitlines() if line.strip()]
    marks: list[tuple[str, float]] = []  # (phase label, unix start)
    seen: set[str] = set()
    end_unix_s: float | None = None
    for e in events:
        kind, t = e.get("event"), e.get("unix_s")
        if t is None:
            continue
        if kind == "phase":
            name = str(e["phase"])
            if name in seen and "stream" in seen:
                name = f"{name} (after descent)"
            seen.add(str(e["phase"]))
            marks.append((name, float(t)))
        elif kind == "ladder_start":
            marks.append((f"abort: {str(e.get('rung', '')).lower()}", float(t)))
        elif kind == "ladder" and e.get("rung"):
            marks.append((f"abort: {str(e['rung']).lower()}", float(t)))
        elif kind == "end":
            end_unix_s = float(t)
    if not marks:
        return {SETUP: step_end_unix_s - step_start_unix_s}
    end_unix_s = end_unix_s if end_unix_s is not None else max(t for _, t in marks)
    out: dict[str, float] = {SETUP: marks[0][1] - step_start_unix_s}
    for (name, t), (_, t_next) in zip(marks, [*marks[1:], ("end", end_unix_s)], strict=True):
        out[name] = out.get(name, 0.0) + (t_next - t)
    out[TEARDOWN] = step_end_unix_s - end_unix_s
    return out


def analyse_run(run: dict[str, Any], out_dir: Path) -> dict[str, Any]:
    """Per step wall time, overhead outside the steps, flight phases and descent share of one run."""
    state = json.loads((out_dir / "campaign.json").read_text())
    steps: dict[str, dict[str, Any]] = {}
    for name in STEPS:
        rec = state["steps"].get(name, {})
        if rec.get("started_unix_s") is None or rec.get("elapsed_s") is None:
            steps[name] = {"status": rec.get("status", "missing")}
            continue
        start, elapsed = float(rec["started_unix_s"]), float(rec["elapsed_s"])
        s: dict[str, Any] = {"status": rec["status"], "elapsed_s": elapsed, "start_unix_s": start,
                             "outcome": rec.get("outputs", {}).get("outcome")}  # fmt: skip
        log_dir = rec.get("outputs", {}).get("log_dir")
        log_dir = out_dir / log_dir if log_dir else None  # stored relative to the campaign folder
        if name in FLIGHT_STEPS and log_dir and (log_dir / "events.jsonl").is_file():
            phases = flight_phases(log_dir, start, start + elapsed)
            s["phases_s"] = phases
            # the descent: stream start → target height reached; the probe has none (its sweep is stopped
            # by the detector), so there it is the stream phase, the sweep
            s["descent_time_s"] = rec["outputs"].get("descent_time_s")
            s["descent_s"] = s["descent_time_s"] if s["descent_time_s"] is not None else phases.get("stream", 0.0)
            s["groups_s"] = {g: sum(v for k, v in phases.items() if _group(k) == g) for g in GROUPS}
        steps[name] = s
    timed = [s for s in steps.values() if "elapsed_s" in s]
    sum_steps = sum(s["elapsed_s"] for s in timed)
    overhead: dict[str, float] = {}
    if timed:
        first = min(s["start_unix_s"] for s in timed)
        last_end = max(s["start_unix_s"] + s["elapsed_s"] for s in timed)
        overhead = {
            "before the first step (interpreter, imports, checks)": first - run["launch_unix_s"],
            "between steps (bookkeeping)": (last_end - first) - sum_steps,
            "after the last step (summary, fake stop, exit)": run["exit_unix_s"] - last_end,
        }
    return {"total_s": run["wall_s"], "cpu_s": run["cpu_s"], "returncode": run["returncode"],
            "sum_steps_s": sum_steps, "outside_steps_s": run["wall_s"] - sum_steps,
            "overhead_s": overhead, "steps": steps}  # fmt: skip


# --- printing ---------------------------------------------------------------------------------------------------


def _stats(values: list[float]) -> tuple[float, float, float]:
    return statistics.fmean(values), min(values), max(values)


def _fmt(values: list[float], many: bool) -> list[str]:
    mean, lo, hi = _stats(values)
    return [f"{mean:.2f}"] + ([f"{lo:.2f} / {hi:.2f}"] if many else [])


def _table(header: list[str], rows: list[list[str]], indent: str = "") -> None:
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    line = [h.ljust(w) if i == 0 else h.rjust(w) for i, (h, w) in enumerate(zip(header, widths, strict=True))]
    print(indent + "  ".join(line))
    print(indent + "  ".join("-" * w for w in widths))
    for r in rows:
        cells = [c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths, strict=True))]
        print(indent + "  ".join(cells))


def report(results: list[dict[str, Any]]) -> None:
    many = len(results) > 1
    mm = ["min / max"] if many else []
    totals = [r["total_s"] for r in results]
    print(f"\nwhole campaign: {_fmt(totals, many)[0]} s wall"
          + (f" (min / max {_fmt(totals, True)[1]})" if many else "")
          + f", CPU (campaign + fake) {100 * sum(r['cpu_s'] for r in results) / sum(totals):.1f} % of one core"
          + f", {len(results)} run(s), exit codes {sorted({r['returncode'] for r in results})}")  # fmt: skip

    rows = []
    for name in STEPS:
        done = [r["steps"][name] for r in results if "elapsed_s" in r["steps"][name]]
        if not done:
            rows.append([name, "—", *(["—"] if many else []), "—", results[0]["steps"][name]["status"], "", ""])
            continue
        el = [s["elapsed_s"] for s in done]
        share = [100 * s["elapsed_s"] / r["total_s"] for s, r in zip(done, results, strict=False)]
        status = ", ".join(sorted({s["status"] + (f" ({s['outcome']})" if s.get("outcome") else "") for s in done}))
        desc = [s["descent_s"] for s in done if "descent_s" in s]
        rows.append([name, *_fmt(el, many), f"{statistics.fmean(share):.1f}", status,
                     f"{statistics.fmean(desc):.2f}" if desc else "",
                     f"{100 * statistics.fmean(desc) / statistics.fmean(el):.0f}" if desc else ""])  # fmt: skip
    outside = [r["outside_steps_s"] for r in results]
    share = [100 * o / t for o, t in zip(outside, totals, strict=True)]
    rows.append(["outside the steps", *_fmt(outside, many), f"{statistics.fmean(share):.1f}", "", "", ""])
    rows.append(["total", *_fmt(totals, many), "100.0", "", "", ""])
    print()
    _table(["step", "wall s", *mm, "share %", "status", "descent s", "descent % of step"], rows)

    print("\noverhead outside the steps:")
    keys = list(results[0]["overhead_s"])
    _table(["", "s", *mm], [[k, *_fmt([r["overhead_s"].get(k, 0.0) for r in results], many)] for k in keys], "  ")

    for name in sorted(FLIGHT_STEPS, key=STEPS.index):
        flights = [r["steps"][name] for r in results if "phases_s" in r["steps"][name]]
        if not flights:
            continue
        labels: list[str] = []
        for f in flights:
            labels += [k for k in f["phases_s"] if k not in labels]
        labels.sort(key=lambda k: (k == TEARDOWN, k != SETUP))  # setup first, teardown last, flight order between
        step_s = statistics.fmean(f["elapsed_s"] for f in flights)
        rows = [[k, *_fmt([f["phases_s"].get(k, 0.0) for f in flights], many),
                 f"{100 * statistics.fmean(f['phases_s'].get(k, 0.0) for f in flights) / step_s:.1f}"]
                for k in labels]  # fmt: skip
        desc = statistics.fmean(f["descent_s"] for f in flights)
        what = "descent (stream start → target height)" if flights[0].get("descent_time_s") else "sweep (stream)"
        print(f"\n{name}: step {step_s:.2f} s, {what} {desc:.2f} s = {100 * desc / step_s:.0f} % of it, "
              f"everything else {step_s - desc:.2f} s")  # fmt: skip
        _table(["phase", "s", *mm, "% of step"], rows, "  ")
        groups = [
            [g, *_fmt([f["groups_s"][g] for f in flights], many),
             f"{100 * statistics.fmean(f['groups_s'][g] for f in flights) / step_s:.1f}"]
            for g in GROUPS
        ]  # fmt: skip
        print()
        _table(["part of the flight", "s", *mm, "% of step"], groups, "  ")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--vehicle", help="vehicle profile (campaign default: x500)")
    ap.add_argument("--runs", type=int, default=1, help="campaigns to run one after the other (default 1)")
    ap.add_argument("--keep", type=Path, metavar="DIR", help="keep the campaign folders in DIR/run-K")
    ap.add_argument("--json", action="store_true", help="print the measurements as JSON")
    args = ap.parse_args()
    if args.runs < 1:
        ap.error("--runs must be ≥ 1")
    if args.keep and args.keep.exists() and any(args.keep.iterdir()):
        ap.error(f"--keep {args.keep}: not empty (a campaign folder that exists would be resumed, not re-run)")
    print(machine(), flush=True)
    print(f"before: {_load()}", flush=True)
    results = []
    with tempfile.TemporaryDirectory(prefix="bench_campaign_") as tmp:
        base = args.keep or Path(tmp)
        for k in range(args.runs):
            out_dir = base / f"run-{k + 1}"
            run = run_campaign(out_dir, args.vehicle)
            if not (out_dir / "campaign.json").is_file():
                print(f"run {k + 1}: no campaign.json (exit {run['returncode']}); stderr:", file=sys.stderr)
                print(Path(run["stderr_log"]).read_text()[-3000:], file=sys.stderr)
                return 1
            res = analyse_run(run, out_dir)
            results.append(res)
            print(f"run {k + 1}/{args.runs}: {res['total_s']:.1f} s, exit {res['returncode']}"
                  + (f", folder {out_dir}" if args.keep else ""), flush=True)  # fmt: skip
    print(f"after: {_load()}")
    if args.json:
        print(json.dumps(results, indent=2))
    else:
        report(results)
    return 0 if all(r["returncode"] == 0 for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
