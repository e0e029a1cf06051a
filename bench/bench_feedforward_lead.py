"""The feed-forward lead against what it costs in margin: one row per flighttest helix folder.

    python bench/bench_feedforward_lead.py LOG_ROOT_OR_FOLDER ...

For each helix folder (flown with ``fly helix --config`` copies of ``missions/helix_descent.toml`` that set
``[flight] feedforward_lead_s``): the lead flown (its ``feedforward`` event), the outcome, the time hover to
hover, the plan's least margin to the guard's bound (the preflight's), the guard's least margin over the
descent's stream, the margin the flight used (their difference: what the build-up narrows the next one by,
``flighttest.analysis.margin_evidence``), and the tilt's lag: how late the attitude's lean, ``g · tan(tilt)``
along it, followed the horizontal acceleration sent (``setpoints.csv``), the delay that fits them best in RMS.
Pure analysis of the folders; the flights are flown on PX4 SITL or ArduCopter SITL (bench/RESULTS.md, "The
feed-forward lead, swept on both SITLs").
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from flighttest.analysis.margin_evidence import flight_evidence  # noqa: E402
from flighttest.model.aero import G_MPS2  # noqa: E402
from flighttest.model.frames import quat_to_rotmat  # noqa: E402

STEP_S = 0.01
LAGS_S = np.arange(0.0, 0.61, STEP_S)


def events_of(folder: Path) -> list[dict]:
    out = []
    for line in (folder / "events.jsonl").read_text().splitlines():
        try:
            out.append(json.loads(line))
        except ValueError:
            continue
    return out


def tilt_acceleration_ne(q_wxyz: np.ndarray) -> np.ndarray:
    """The horizontal acceleration the lean makes while the thrust carries the weight: −g · z_ne / z_d of the
    body's z axis in NED."""
    z_ned = quat_to_rotmat(q_wxyz)[:, :, 2]
    return -G_MPS2 * z_ned[:, :2] / z_ned[:, 2:3]


def tilt_lag_s(folder: Path, t0_s: float, t1_s: float) -> float:
    """The delay of the attitude's lean behind the acceleration sent over ``[t0_s, t1_s]`` (flighttest's clock)."""
    sp = pd.read_csv(folder / "setpoints.csv")
    g = pd.read_csv(folder / "guard.csv").dropna(subset=["qw"])
    grid = np.arange(t0_s, t1_s, STEP_S)
    sent = np.stack([np.interp(grid, sp["t_s"], sp[c]) for c in ("an_mps2", "ae_mps2")], axis=1)
    tilt = tilt_acceleration_ne(g[["qw", "qx", "qy", "qz"]].to_numpy())
    rms = [math.sqrt(float(np.mean(np.sum((np.stack([np.interp(grid + lag, g["t_s"], tilt[:, i]) for i in (0, 1)],
                                                     axis=1) - sent) ** 2, axis=1)))) for lag in LAGS_S]  # fmt: skip
    return float(LAGS_S[int(np.argmin(rms))])


def row(folder: Path) -> dict:
    ev = events_of(folder)
    lead = next((e.get("lead_s") for e in ev if e.get("event") == "feedforward"), None)
    t0 = next((e["t_s"] for e in ev if e.get("event") == "stream_start"), None)
    t1 = next((e["t_s"] for e in ev if e.get("event") == "stream_end"), None)
    e = flight_evidence(folder)
    used = (None if e.min_margin_mps is None or e.plan_min_margin_mps is None
            else e.plan_min_margin_mps - e.min_margin_mps)  # fmt: skip
    return {"folder": folder.name, "lead_s": lead, "outcome": e.outcome, "hover_to_hover_s": e.hover_to_hover_s,
            "plan_least_mps": e.plan_min_margin_mps, "guard_least_mps": e.min_margin_mps, "used_mps": used,
            "tilt_lag_s": tilt_lag_s(folder, t0, t1) if t0 is not None and t1 is not None else None}  # fmt: skip


def main(argv: list[str]) -> None:
    found = (p.parent for a in argv for p in Path(a).rglob("events.jsonl"))
    folders = sorted({f for f in found if f.name.endswith("-helix")})
    rows = [row(f) for f in folders]
    rows.sort(key=lambda r: (r["lead_s"] is None, r["lead_s"] or 0.0))
    print(f"{'lead s':>7} {'outcome':>10} {'h2h s':>7} {'plan least':>10} {'guard least':>11} {'used':>6} "
          f"{'tilt lag s':>10}  folder")
    fmt = lambda v, f: "–".rjust(int(f.split(".")[0])) if v is None else format(v, f)  # noqa: E731
    for r in rows:
        print(f"{fmt(r['lead_s'], '7.2f')} {r['outcome'] or '–':>10} {fmt(r['hover_to_hover_s'], '7.2f')} "
              f"{fmt(r['plan_least_mps'], '10.3f')} {fmt(r['guard_least_mps'], '11.3f')} {fmt(r['used_mps'], '6.3f')} "
              f"{fmt(r['tilt_lag_s'], '10.2f')}  {r['folder']}")  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:] or ["logs"])
