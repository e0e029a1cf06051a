"""Helix (and vertical) planned vs flown: on real autopilots from their log folders, on the fake in fast time.

    python bench/bench_helix_flown.py [LOG_FOLDER ...] [--fake-seeds N] [--vehicle sih_quadx]

For each flighttest log folder given (flown against PX4 SITL, a real vehicle or the fake): mission,
outcome, planned duration ``t_f_s`` (trajectory.json), the flown descent time (summary.json, the
vertical-axis rule), their ratio, the horizontal error when the end height was reached, and the
guard's smallest measured and predicted margins while streaming. Then, with ``--fake-seeds N``, the
same for the helix ``flighttest fly helix`` plans for ``--vehicle``, flown through the fake's PX4
cascade in fast time (``sitl_fakes.replay``) with N seeds of PX4-like estimate error and the
mission's guard — no link, no clock, so the figures are the plan's and the autopilot model's alone.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flighttest.analysis.descent_time import DescentTimer  # noqa: E402
from flighttest.flying import guard as gd  # noqa: E402
from flighttest.flying.feedforward import CatchUpLimit, Feedforward, for_autopilot  # noqa: E402
from flighttest.flying.mission_scripts import MISSIONS_DIR  # noqa: E402
from flighttest.flying.missions_config import FlightConfig, load_mission_config  # noqa: E402
from flighttest.model.profiles import load_profile  # noqa: E402
from flighttest.planner.export import helix_trajectory  # noqa: E402
from flighttest.planner.helix import solve_helix  # noqa: E402
from flighttest.planner.tracking import TrackingMargin, helix_problem_for_flight  # noqa: E402
from sitl_fakes.estimator import EstimateError  # noqa: E402
from sitl_fakes.physics import RigidBodyState  # noqa: E402
from sitl_fakes.replay import SetpointStream, px4_params, replay  # noqa: E402


def folder_row(folder: Path) -> dict:
    summary = json.loads((folder / "summary.json").read_text())
    traj = json.loads((folder / "trajectory.json").read_text())
    events = [json.loads(line) for line in (folder / "events.jsonl").read_text().splitlines() if line.strip()]
    start = next((e["t_s"] for e in events if e["event"] == "stream_start"), None)
    g = pd.read_csv(folder / "guard.csv")
    end = next((e["t_s"] for e in events if e["event"] in ("abort", "descent_reached")), math.inf)
    during = g[(g.t_s >= (start or math.inf)) & (g.t_s <= end)]
    t_f = float(traj.get("t_f_s", math.nan))
    flown = summary.get("descent_time_s")
    return {
        "folder": folder.name,
        "mission": summary.get("mission"),
        "outcome": summary.get("outcome"),
        "t_f_s": round(t_f, 2),
        "descent_time_s": None if flown is None else round(flown, 2),
        "flown_over_planned": None if flown is None else round(flown / t_f, 2),
        "horizontal_error_m": None if summary.get("horizontal_error_m") is None
        else round(summary["horizontal_error_m"], 2),
        "min_margin_mps": round(float(during.margin_mps.min()), 3) if len(during) else None,
        "min_predicted_margin_mps": round(float(during.predicted_margin_mps.min()), 3) if len(during) else None,
        "abort_reason": summary.get("abort_reason"),
    }


def fake_rows(vehicle: str, seeds: int) -> list[dict]:
    prof = load_profile(vehicle)
    cfg = load_mission_config(MISSIONS_DIR / "helix_descent.toml")
    t0 = time.perf_counter()
    plan = helix_trajectory(
        solve_helix(helix_problem_for_flight(prof, 5.0, 3.0, TrackingMargin.from_plan(cfg.plan))),
        prof.name, prof.mass_kg,
    )  # fmt: skip
    plan_s = time.perf_counter() - t0
    ff = Feedforward(FlightConfig().feedforward_lead_s, prof.drag_n_per_mps / prof.mass_kg)
    # as the mission streams it (flighttest.flying.streamer): down setpoints within the catch-up limit
    fl = cfg.flight
    catch_up = CatchUpLimit(fl.catch_up_excess_mps, fl.catch_up_floor_mps, px4_params()["MPC_Z_P"])
    sent = for_autopilot(plan, ff).resample(50.0).df
    vd_plan = np.concatenate([[0.0], sent.vd_mps.to_numpy()])
    t = np.concatenate([[0.0], sent.t_s.to_numpy() + 1.0])
    off = np.array([0.0, 0.0, -7.0])
    stream = SetpointStream(
        t,
        np.vstack([off, sent[["n_m", "e_m", "d_m"]].to_numpy() + off]),
        np.vstack([[0.0, 0.0, 0.0], sent[["vn_mps", "ve_mps", "vd_mps"]].to_numpy()]),
        np.vstack([[0.0, 0.0, 0.0], sent[["an_mps2", "ae_mps2", "ad_mps2"]].to_numpy()]),
        np.radians(np.concatenate([[0.0], sent.yaw_deg.to_numpy()])),
    )
    end_ned = np.array([sent.n_m.iloc[-1], sent.e_m.iloc[-1], sent.d_m.iloc[-1]]) + off
    rows = []
    for seed in range(seeds):
        r = replay(prof, stream, RigidBodyState(d_m=-7.0, on_ground=False), t[-1] + 3.0,
                   estimate_error=EstimateError(), seed=seed,
                   catch_up_down=lambda k, d, d_est: catch_up.limit(d, d_est, vd_plan[k]))  # fmt: skip
        guard = gd.Guard(gd.GuardLimits(region=prof.guard_region(), horizon_s=cfg.guard.horizon_s,
                                        debounce_samples=cfg.guard.debounce_samples,
                                        clear_violation_mps=cfg.guard.clear_violation_mps))  # fmt: skip
        guard.armed = True
        margins, pmargins, abort = [], [], None
        for ts in np.arange(1.0, t[-1], 0.02):
            i = r.at(ts)
            d = guard.on_sample(gd.GuardSample(ts, *r.est_vel_ned[i], *r.quat[i], -r.pos_ned[i, 2]))
            margins.append(d.margin_mps)
            pmargins.append(d.predicted_margin_mps)
            if d.aborts and abort is None:
                abort = round(ts - 1.0, 2)
        # timed as flighttest times it (analysis.descent_time), on the estimate (what PX4 reports)
        timer = DescentTimer(1.0, tuple(end_ned))
        got = None
        for k in range(0, r.t_s.size, 5):  # 50 Hz, as telemetry arrives
            got = timer.update(r.t_s[k], *r.est_pos_ned[k], r.est_vel_ned[k, 2]) or got
        rows.append({
            "seed": seed, "t_f_s": round(plan.meta["t_f_s"], 2), "plan_s": round(plan_s, 1),
            "descent_time_s": None if got is None else round(got.descent_time_s, 2),
            "horizontal_error_m": None if got is None else round(got.horizontal_error_m, 2),
            "min_margin_mps": round(min(margins), 3), "min_predicted_margin_mps": round(min(pmargins), 3),
            "abort_s": abort,
        })  # fmt: skip
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="*", type=Path)
    ap.add_argument("--fake-seeds", type=int, default=0)
    ap.add_argument("--vehicle", default="sih_quadx")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    flown = [folder_row(f) for f in args.folders]
    fake = fake_rows(args.vehicle, args.fake_seeds) if args.fake_seeds else []
    if args.json:
        print(json.dumps({"flown": flown, "fake": fake}, indent=2))
        return 0
    for row in flown:
        print(" ".join(f"{k}={v}" for k, v in row.items()))
    by_mission: dict[str, list[float]] = {}
    for row in flown:
        if row["descent_time_s"] is not None:
            by_mission.setdefault(row["mission"], []).append(row["descent_time_s"])
    for mission, times in by_mission.items():
        print(f"{mission}: {len(times)} completed, descent time median {statistics.median(times):.2f} s")
    for row in fake:
        print("fake " + " ".join(f"{k}={v}" for k, v in row.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
