"""One rule for a flight's descent (issue 25), without flying: flighttest log folders around synthetic
tlogs of known motion, analysed, compared and reported through the CLI.

- a descent that slows down mid-way (the stream, then the settle after it) is ONE main descent, from
  the first setpoint until at the end height and settled, and the landing after it another;
- rates come from the height the descent was timed on: mean ≤ max in every row;
- ``compare`` says when main descents start or descend differently and refuses their speed-up
  (one line, exit code 2) unless ``--allow-unequal``;
- a flight is judged with the ``w_allow`` in its ``meta.json``, today's profile only with ``--profile-now``;
- the report: outcome, abort reason, descent and planned time per flight, a legend for every column,
  the parameters once, every table within 80 columns.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from flighttest.analysis import descent_time as dt
from flighttest.analysis.loaders import load_log
from flighttest.analysis.pipeline import analyse
from flighttest.analysis.segment import find_descents
from flighttest.cli import main
from flighttest.model.profiles import load_profile, write_w_allow
from synthetic import UNIX0, SyntheticFlight, write_tlog

START_M, DESCENT_M = 10.0, 3.0
T_STREAM = 10.0
PIECE_S = 3.6  # each half of the descent: 1.5 m at up to π·1.5/(2·3.6) = 0.65 m/s
PAUSE_S = 1.5  # between the halves: longer than the segmentation's merge gap (1 s)
T_LAND = 24.0
FLOWN_W_ALLOW = 0.8475  # what the flights flew with (meta.json): 0.65 m/s is outside its region
TODAY_W_ALLOW = 0.6  # a profile rewritten since (identify --write-profile): 0.65 m/s is inside its region


def _flight(start_m: float = START_M, descent_m: float = DESCENT_M) -> SyntheticFlight:
    half = descent_m / 2
    t2 = T_STREAM + PIECE_S + PAUSE_S
    return SyntheticFlight(duration_s=34.0, start_alt_m=start_m,
                           descents=[(T_STREAM, half, PIECE_S), (t2, half, PIECE_S), (T_LAND, 2.0, 3.0)])  # fmt: skip


def _plan(descent_m: float = DESCENT_M, t_f: float = 8.0) -> pd.DataFrame:
    """A minimum-jerk plan of ``descent_m`` in ``t_f`` (trajectory.csv's columns, relative to the start)."""
    t = np.arange(0.0, t_f + 1e-9, 0.02)
    s = t / t_f
    d = descent_m * (10 * s**3 - 15 * s**4 + 6 * s**5)
    vd = descent_m / t_f * (30 * s**2 - 60 * s**3 + 30 * s**4)
    zero = np.zeros_like(t)
    return pd.DataFrame({"t_s": t, "n_m": zero, "e_m": zero, "d_m": d, "vn_mps": zero, "ve_mps": zero, "vd_mps": vd,
                         "an_mps2": zero, "ae_mps2": zero, "ad_mps2": zero, "yaw_deg": zero})  # fmt: skip


def _folder(root: Path, name: str, start_m: float = START_M, descent_m: float = DESCENT_M,
            outcome: str = "completed", reason: str | None = None) -> Path:  # fmt: skip
    """A flighttest log folder of the synthetic flight: its events say where the planned descent began
    (the stream at T_STREAM, the settle when the plan ended, the landing at T_LAND)."""
    folder = root / name
    folder.mkdir(parents=True)
    flight = _flight(start_m, descent_m)
    write_tlog(flight, folder / "flight.tlog")
    summary = load_profile("x500").summary() | {"w_allow_mps": FLOWN_W_ALLOW, "w_allow_source": "as flown in the test"}
    meta = {"start_unix_s": UNIX0, "mission": "vertical", "vehicle": summary, "trajectory_meta": {"kind": "vertical"}}
    (folder / "meta.json").write_text(json.dumps(meta))
    plan = _plan(descent_m)
    plan.to_csv(folder / "trajectory.csv", index=False)
    origin = [0.0, 0.0, -start_m]
    t_settle = T_STREAM + float(plan["t_s"].iloc[-1])
    events = [{"t_s": T_STREAM, "event": "phase", "phase": "stream"},
              {"t_s": T_STREAM, "event": "stream_start", "origin_ned": origin, "rows": len(plan),
               "end_ned": [0.0, 0.0, -start_m + descent_m]},
              {"t_s": t_settle, "event": "phase", "phase": "settle"},
              {"t_s": T_LAND, "event": "phase", "phase": "land"}]  # fmt: skip
    text = "".join(json.dumps({**e, "unix_s": UNIX0 + e["t_s"]}) + "\n" for e in events)
    (folder / "events.jsonl").write_text(text)
    (folder / "summary.json").write_text(json.dumps({"outcome": outcome, "abort_reason": reason}))
    return folder


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("main-descent")
    return {
        "vertical": _folder(root, "20260101-000000-vertical"),
        "higher": _folder(root, "20260101-001000-vertical", start_m=12.0, descent_m=5.0),
        "aborted": _folder(root, "20260101-002000-vertical", outcome="aborted", reason="in guard region"),
    }


def _cli(capsys, *args: str) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def test_a_descent_that_pauses_is_one_main_descent_and_the_landing_another(logs):
    a = analyse(load_log(logs["vertical"]))
    # the segmentation alone cuts it in two at the pause (and would call the landing a third)
    alone, _ = find_descents(a.log.state.copy())
    assert len(alone) == 3
    d = a.descents
    assert list(d["main"]) == [True, False] and list(d["phase"]) == ["stream", "land"]
    main_row, land = d.iloc[0], d.iloc[1]
    timed = dt.from_log(a.log)
    assert main_row["start_s"] == pytest.approx(T_STREAM, abs=0.01)
    assert main_row["end_s"] == pytest.approx(timed.reached.t_s) and main_row["settled"]
    assert main_row["duration_s"] == pytest.approx(timed.reached.descent_time_s)
    # reached once the second half is within 0.2 m and slow: before it ends, after it began
    t_second = T_STREAM + PIECE_S + PAUSE_S
    assert t_second < main_row["end_s"] < t_second + PIECE_S
    assert DESCENT_M - 0.2 <= main_row["height_m"] <= DESCENT_M
    assert land["start_s"] > main_row["end_s"] and land["height_m"] == pytest.approx(2.0, abs=0.1)
    # mean and max from the one height: the fastest fall of either half, π·1.5/(2·3.6)
    assert (d["mean_rate_mps"] <= d["max_rate_mps"]).all()
    assert main_row["max_rate_mps"] == pytest.approx(math.pi * 1.5 / (2 * PIECE_S), abs=0.03)
    # the record analyse --json, compare and the report give: the same descent, and the plan timed alike
    m = a.main
    assert m["basis"] == "planned descent" and m["descent_time_s"] == pytest.approx(main_row["duration_s"], abs=1e-3)
    plan = _plan()
    want = dt.planned_descent(plan["t_s"], plan["n_m"], plan["e_m"], plan["d_m"], plan["vd_mps"]).descent_time_s
    assert m["planned_descent_s"] == pytest.approx(want, abs=1e-3) and 6.0 < want < 8.0  # t_f 8 s: the same band
    assert m["start_height_m"] == pytest.approx(START_M, abs=0.05) and m["planned_height_m"] == DESCENT_M
    # flown against planned: the vehicle paused where the plan did not
    assert a.summary()["tracking_error"]["max_vertical_m"] > 0.3


def test_the_plan_flown_exactly_takes_the_planned_time():
    plan = _plan()
    t, n, e, d, vd = (plan[c].to_numpy() for c in ("t_s", "n_m", "e_m", "d_m", "vd_mps"))
    planned = dt.planned_descent(t, n, e, d, vd)
    hover = np.arange(t[-1] + 0.02, t[-1] + 3.0, 0.02)
    still = 0 * hover
    flown = dt.descent_reached(np.r_[t, hover], np.r_[n, still], np.r_[e, still], np.r_[d, d[-1] + still],
                               np.r_[vd, still], 0.0, (0.0, 0.0, DESCENT_M))  # fmt: skip
    assert flown.descent_time_s == pytest.approx(planned.descent_time_s, abs=1e-9)
    assert planned.descent_time_s < planned.t_f_s and planned.height_m == DESCENT_M
    # a plan that comes back to its start (the probe) has no descent time
    back = dt.planned_descent(t, n, e, np.r_[d[: len(d) // 2], d[len(d) // 2 :: -1]][: len(t)], vd)
    assert back.descent_time_s is None


def test_compare_refuses_a_speedup_across_unequal_descents(logs, capsys):
    v, h = str(logs["vertical"]), str(logs["higher"])
    code, out, err = _cli(capsys, "compare", v, h, "--json")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--allow-unequal" in err
    rows = json.loads(out)
    assert rows[0]["descent_differs"] is None and rows[0]["speedup_vs_first"] == 1.0
    assert rows[1]["speedup_vs_first"] is None
    assert rows[1]["descent_differs"].startswith("starts at 12.0")
    assert rows[1]["descent_differs"].endswith("against 10.00 m and plans to descend 5.00 m against 3.00 m")
    code, out, err = _cli(capsys, "compare", v, h, "--json", "--allow-unequal")
    assert code == 0 and json.loads(out)[1]["speedup_vs_first"] > 0 and not err
    code, out, err = _cli(capsys, "compare", v, str(logs["aborted"]), "--json")
    assert code == 0 and json.loads(out)[1]["speedup_vs_first"] == pytest.approx(1.0)  # alike: no refusal
    code, out, err = _cli(capsys, "compare", v, h)  # the table still prints, the refusal is one line
    assert code == 2 and "speed-up ×" in out and err.count("\n") == 1 and err.startswith("flighttest: error: ")


@pytest.fixture
def rewritten(tmp_path, monkeypatch):
    """Today's x500 says w_allow TODAY_W_ALLOW (the flights flew with FLOWN_W_ALLOW)."""
    vehicles = tmp_path / "vehicles"
    monkeypatch.setenv("FLIGHTTEST_VEHICLES", str(vehicles))
    write_w_allow(load_profile("x500"), TODAY_W_ALLOW, "a later identify", target=vehicles / "x500.toml")
    assert load_profile("x500").w_allow_mps == TODAY_W_ALLOW


def test_a_flight_is_judged_with_what_it_flew_with(logs, capsys, rewritten, tmp_path):
    code, out, _ = _cli(capsys, "analyse", str(logs["vertical"]), "--json", "--jobs", "1")
    (flown,) = json.loads(out)
    assert code == 0 and flown["judged_with"]["basis"] == "as flown"
    assert flown["judged_with"]["w_allow_mps"] == FLOWN_W_ALLOW == flown["judged_with"]["flown_w_allow_mps"]
    code, out, _ = _cli(capsys, "analyse", str(logs["vertical"]), "--json", "--jobs", "1", "--profile-now")
    (now,) = json.loads(out)
    assert now["judged_with"]["basis"] == "today's profile" and now["judged_with"]["w_allow_mps"] == TODAY_W_ALLOW
    inside = [next(x["time_inside_s"] for x in r["descents"] if x["main"]) for r in (flown, now)]
    assert inside[0] == 0.0 < inside[1]
    # the terminal and the report say which
    code, out, _ = _cli(capsys, "analyse", str(logs["vertical"]), "--jobs", "1")
    assert f"judged with: x500 as it flew (w_allow {FLOWN_W_ALLOW:.3f} m/s" in " ".join(out.split())
    code, out, _ = _cli(capsys, "analyse", str(logs["vertical"]), "--jobs", "1", "--profile-now")
    assert f"it flew with {FLOWN_W_ALLOW:.3f} m/s" in " ".join(out.split())
    code, _, err = _cli(capsys, "report", str(logs["vertical"]), "--profile-now", "-o", str(tmp_path / "rep"))
    md = (tmp_path / "rep" / "report.md").read_text()
    assert code == 0 and f"- judged with: x500 (today's profile: w_allow {TODAY_W_ALLOW:.3f} m/s); it flew with" in md


def test_the_report_per_flight_legend_parameters_once_80_columns(logs, tmp_path, capsys):
    out = tmp_path / "rep"
    code, _, err = _cli(capsys, "report", str(logs["vertical"]), str(logs["aborted"]), "-o", str(out))
    assert code == 0, err
    md = (out / "report.md").read_text()
    tables = [line for line in md.splitlines() if line.startswith("|")]
    assert tables and max(len(line) for line in tables) <= 80
    a = analyse(load_log(logs["vertical"]))
    m = a.main
    assert f"| 1 | completed | {m['descent_time_s']:.2f} | {m['planned_descent_s']:.2f} |" in md
    assert f"- descent time: {m['descent_time_s']:.2f} s against {m['planned_descent_s']:.2f} s planned" in md
    assert "- outcome: aborted: in guard region" in md and "judged with: x500 as it flew" in md
    # a legend for every column of every table (the parameter tables' columns are flight numbers)
    legend = md.split("## What the columns mean")[1].split("\n## ")[0]
    lines = md.splitlines()
    header_rows = [lines[k - 1] for k, line in enumerate(lines) if line.startswith("|-")]
    headers = {h.strip() for row in header_rows for h in row.strip("|").split("|")} - {"parameter", "value"}
    assert {"inside s", "fluct. max", "descent s", "planned s"} <= headers
    for h in headers:
        assert h.isdigit() or f"**{h}**" in legend, h
    # the parameters once, for every flight
    assert md.count("## Parameters") == 1 and "### Parameters (" not in md
    assert (out / "20260101-000000-vertical_tracking.png").stat().st_size > 10_000
    shutil.rmtree(out)
