"""What a campaign flown with ``--build-up N`` must show, judged from its files and the fake's truth."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from flighttest.campaign.steps import config_budget
from flighttest.flying.missions_config import load_mission_config

FLYING_MODES = ("OFFBOARD", "GUIDED")  # where flighttest flies the vehicle (PX4, ArduCopter)


def stream_window_unix(log_dir: Path) -> tuple[float, float]:
    events = [json.loads(line) for line in (log_dir / "events.jsonl").read_text().splitlines() if line.strip()]
    t0 = next(e["unix_s"] for e in events if e["event"] == "stream_start")
    t1 = next(e["unix_s"] for e in events if e["event"] == "stream_end")
    return t0, t1


def assert_build_up(out: Path, summary: dict, most: int) -> dict[str, list[dict]]:
    """Every descent's build-up: margins from evidence, never below the floor nor the evidence's sum, a reason
    to stop, the fastest clean flight kept, the report showing it,
    and the fake's true state never in its VRS region while flighttest flew. Returns the rows per descent."""
    rows = summary["build_up"]
    truth = pd.concat([pd.read_csv(p, low_memory=False) for p in sorted((out / "sim").glob("truth-*.csv"))])
    state = truth[truth["kind"] == "state"]
    for mission in ("vertical", "helix"):
        cfg = load_mission_config(out / "config" / f"{mission}_descent.toml")
        flown = rows[mission]
        assert 1 <= len(flown) <= most, flown
        assert summary["build_up_stop"][mission], summary["build_up_stop"]
        assert [r["flight"] for r in flown] == list(range(1, len(flown) + 1))
        # the first flight: the config's margin (its TOML's value or the default), a vehicle with no history
        assert flown[0]["margin_mps"] == pytest.approx(config_budget(mission, cfg).margin_mps)
        for r in flown[1:]:
            budget = json.loads((out / Path(r["plan"]).with_suffix(".json")).read_text())["margin_budget"]
            terms = {t["name"]: t["value_mps"] for t in budget["terms"]}
            assert set(terms) == {"tracking", "estimate", "reserve"}, budget
            # the estimate's error beyond what the guard's own margin covers (the profile's [vrs] margin_mps)
            estimate = next(t for t in budget["terms"] if t["name"] == "estimate")
            assert "less the guard's own margin" in estimate["source"], estimate
            assert budget["margin_mps"] == r["margin_mps"]
            # never optimistic: at least what the evidence measured and the floor
            assert r["margin_mps"] >= max(sum(terms.values()), cfg.build_up.floor_mps) - 1e-3, budget
            assert r["margin_mps"] >= 0.0 and terms["reserve"] == cfg.build_up.reserve_mps
        clean = [r for r in flown if r["outcome"] == "completed" and r["guard_silent"]]
        kept = next(f for f in summary["flights"] if f["step"] == mission)
        if clean:
            fastest = min(clean, key=lambda r: r["hover_to_hover_s"])
            assert Path(kept["log"]).name == Path(fastest["log_dir"]).name, (kept, fastest)
        assert not any(Path(r["log_dir"]).is_absolute() or Path(r["plan"]).is_absolute() for r in flown)
        for r in flown:
            t0, t1 = stream_window_unix(out / r["log_dir"])  # relative to the folder, as every path of it
            during = state[(state["unix_s"] >= t0) & (state["unix_s"] <= t1) & state["mode"].isin(FLYING_MODES)]
            assert len(during) > 100, r
            assert (during["depth_n"] <= 0).all(), (mission, r["flight"], during["depth_n"].max())
    if any(len(rows[m]) > 1 for m in rows):
        md = (out / "report" / "summary.md").read_text()
        assert "## Build-up" in md and "## Margins" in md and "Stopped: " in md
        assert (out / "report" / "build_up.png").stat().st_size > 10_000
    return rows
