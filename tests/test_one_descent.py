"""One flight, one main descent (issue 25): ``flighttest fly --json``, ``analyse --json``, ``compare --json``
and ``report`` give the same main descent and times for each mission flown on the fake over real UDP
MAVLink, the plan timed by the same rule beside it, rates from one height (mean ≤ max), and every
flight judged with the profile it flew with. Each mission is flown once for the whole module.

What is checked is the agreement, whatever the flight's outcome: a flight that aborted has its main
descent cut at the abort, not reached, in every command alike. A descent not reached is flown once
more; the vertical must reach its end height (the reached path is checked on it at least).
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from sitl_fakes.launcher import FakeVehicle
from test_fly_missions import FLY_TIMEOUT_S, ci_config, fly_cmd

pytestmark = pytest.mark.flight

MISSIONS = ("vertical", "helix", "probe")
# what these flights check is the analysis, not the stale-telemetry rule: 0.8 s at 50 Hz, so a machine loaded
# by other flights does not end them early (test_fly_missions tests the rule)
STALE_PERIODS = 40.0
ATTEMPTS = 2  # a flight a loaded machine still aborted is flown once more
TIME_TOL_S = 0.05  # the bar: every command's times for one descent within this
HEIGHT_TOL_M = 0.05
RATE_TOL_MPS = 0.05


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flighttest", *args], capture_output=True, text=True,
                          timeout=300, stdin=subprocess.DEVNULL)  # fmt: skip


@pytest.fixture(scope="module")
def flown(tmp_path_factory) -> dict[str, dict]:
    """Each mission flown once on one fake: {mission: {"fly": fly --json, "folder": Path}}."""
    tmp = tmp_path_factory.mktemp("one_descent")
    out: dict[str, dict] = {}
    with FakeVehicle("x500", truth_log=tmp / "truth.csv") as fake:
        for mission in MISSIONS:
            config = ci_config(tmp, mission, stale_periods=STALE_PERIODS)
            for attempt in range(ATTEMPTS):
                cmd = fly_cmd(mission, fake.url, tmp / "logs" / f"{mission}-{attempt}", "--config", str(config))
                p = subprocess.run(cmd, capture_output=True, text=True, timeout=FLY_TIMEOUT_S,
                                   stdin=subprocess.DEVNULL)  # fmt: skip
                summary = json.loads(p.stdout)
                if summary["outcome"] == "probe_stopped" or summary["main_descent"]["reached"]:
                    break
            assert summary["log_dir"] and summary["phase_at_end"] not in ("connect", "preflight"), p.stderr[-2000:]
            out[mission] = {"fly": summary, "folder": Path(summary["log_dir"])}
    return out


@pytest.fixture(scope="module")
def analysed(flown) -> dict[str, dict]:
    p = _cli("analyse", *(str(flown[m]["folder"]) for m in MISSIONS), "--json", "--jobs", "1")
    assert p.returncode == 0, p.stderr
    return dict(zip(MISSIONS, json.loads(p.stdout)))


@pytest.fixture(scope="module")
def compared(flown) -> dict[str, dict]:
    p = _cli("compare", *(str(flown[m]["folder"]) for m in MISSIONS), "--json", "--allow-unequal")
    assert p.returncode == 0, p.stderr
    return dict(zip(MISSIONS, json.loads(p.stdout)))


@pytest.fixture(scope="module")
def reported(flown, tmp_path_factory) -> dict[str, list[str]]:
    """The report's overview row of each flight: [#, outcome, descent s, planned s, start m, height m, inside s]."""
    out = tmp_path_factory.mktemp("report")
    p = _cli("report", *(str(flown[m]["folder"]) for m in MISSIONS), "-o", str(out))
    assert p.returncode == 0, p.stderr
    md = (out / "report.md").read_text()
    rows = [line for line in md.splitlines() if re.match(r"\| [123] \| ", line)][:3]
    cells = [[c.strip() for c in row.strip("|").split("|")] for row in rows]
    return {"md": md, **{m: c for m, c in zip(MISSIONS, cells)}}


def _close(a, b, tol) -> bool:
    return a is not None and b is not None and abs(a - b) <= tol


def test_fly_analyse_compare_and_report_give_each_flight_one_descent(flown, analysed, compared, reported):
    """One test item, so one worker flies the three flights: as five items xdist spread them over both
    workers, and each flew them (131 s apiece, CI of ef96539; xdist's loadgroup does not group under pytest 9)."""
    for mission in ("vertical", "helix"):
        check_one_descent(flown, analysed, compared, reported, mission)
    check_the_vertical_reached_its_end(flown)
    check_the_probe_has_no_descent_time_anywhere(flown, analysed, compared, reported)
    check_compare_says_the_vertical_and_the_helix_differ(flown)


def check_one_descent(flown, analysed, compared, reported, mission) -> None:
    fly = flown[mission]["fly"]
    live, post = fly["main_descent"], analysed[mission]["main_descent"]
    reached = live["reached"]
    # fly: the live timer's main descent, the plan timed by the same rule beside it
    want = fly["descent_time_s"]
    assert live["descent_time_s"] is None if want is None else live["descent_time_s"] == pytest.approx(want, abs=1e-3)
    assert fly["planned_descent_s"] == live["planned_descent_s"] > 0
    # analyse: the same descent, from the same samples of the log (the tlog's clock is the wall clock)
    assert post["basis"] == live["basis"] == "planned descent" and post["reached"] == reached
    for key, tol in (("descent_time_s", TIME_TOL_S), ("planned_descent_s", TIME_TOL_S), ("start_unix_s", TIME_TOL_S),
                     ("duration_s", TIME_TOL_S), ("height_m", HEIGHT_TOL_M), ("start_height_m", HEIGHT_TOL_M),
                     ("mean_rate_mps", RATE_TOL_MPS)):  # fmt: skip
        assert _close(post[key], live[key], tol) or post[key] is live[key] is None, (key, post[key], live[key])
    # the max rate only after the flight, on the vehicle's clock (fly times samples as they arrive)
    assert live["max_rate_mps"] is None
    d = analysed[mission]["descents"]
    assert all(x["mean_rate_mps"] <= x["max_rate_mps"] for x in d)
    # compare: the same figures
    row = compared[mission]
    assert row["main_basis"] == "planned descent"
    same = _close(row["descent_time_s"], post["descent_time_s"], TIME_TOL_S)
    assert same or row["descent_time_s"] is post["descent_time_s"] is None
    assert _close(row["planned_descent_s"], post["planned_descent_s"], TIME_TOL_S)
    # the report: the same times in its overview, and what the flight was judged with
    cells = reported[mission]
    assert float(cells[3]) == pytest.approx(post["planned_descent_s"], abs=0.006)
    assert analysed[mission]["judged_with"]["basis"] == "as flown"
    if not reached:  # cut by the abort, or not settled before the landing: no descent time anywhere
        assert cells[2] == "–" and row["speedup_vs_first"] is None
        assert f"- descent time: not reached ({post['planned_descent_s']:.2f} s planned)" in reported["md"]
        return
    # one descent across the stream and the settle after it, not pieces; the landing is a descent of its own
    (main,) = [x for x in d if x["main"]]
    assert main["phase"] == "stream" and main["settled"]
    assert main["duration_s"] == pytest.approx(post["descent_time_s"], abs=1e-3)
    assert not [x for x in d if not x["main"] and x["start_s"] < main["end_s"] and x["end_s"] > main["start_s"]]
    assert _close(row["duration_s"], post["descent_time_s"], TIME_TOL_S)
    assert _close(row["height_m"], post["height_m"], HEIGHT_TOL_M) and row["main_descent_note"] is None
    assert float(cells[2]) == pytest.approx(post["descent_time_s"], abs=0.006)
    assert f"descent time: {post['descent_time_s']:.2f} s against {post['planned_descent_s']:.2f} s planned" in (
        reported["md"]
    )
    assert analysed[mission]["tracking_error"]["max_m"] < 2.0


def check_the_vertical_reached_its_end(flown) -> None:
    """The checks above saw a descent reached at least once (the vertical baseline's)."""
    assert flown["vertical"]["fly"]["outcome"] == "completed" and flown["vertical"]["fly"]["main_descent"]["reached"]


def check_the_probe_has_no_descent_time_anywhere(flown, analysed, compared, reported) -> None:
    fly = flown["probe"]["fly"]
    assert fly["descent_time_s"] is None and fly["main_descent"]["descent_time_s"] is None
    assert "returns to its start" in fly["main_descent"]["note"]
    post = analysed["probe"]["main_descent"]
    assert post["descent_time_s"] is None and post["basis"] == "log segment"
    row = compared["probe"]
    assert row["descent_time_s"] is None and row["speedup_vs_first"] is None
    # its main descent (the sweep's largest) is the same one in analyse and compare
    assert row["start_s"] == pytest.approx(post["start_s"], abs=1e-3)
    assert row["duration_s"] == pytest.approx(post["duration_s"], abs=1e-3)
    assert reported["probe"][2] == "–"
    assert all(x["mean_rate_mps"] <= x["max_rate_mps"] for x in analysed["probe"]["descents"])


def check_compare_says_the_vertical_and_the_helix_differ(flown) -> None:
    """The vertical 5 → 2 m and the helix 7 → 2 m: compare says so, and gives no speed-up unless asked
    (refused with exit code 2 where both have a descent time to divide)."""
    v, h = (str(flown[m]["folder"]) for m in ("vertical", "helix"))
    both = all(flown[m]["fly"]["main_descent"]["reached"] for m in ("vertical", "helix"))
    p = _cli("compare", v, h, "--json")
    rows = json.loads(p.stdout)
    assert rows[1]["speedup_vs_first"] is None
    assert "plans to descend 5.00 m against 3.00 m" in rows[1]["descent_differs"]
    assert "starts at" in rows[1]["descent_differs"]
    if both:
        assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1 and "--allow-unequal" in p.stderr
        p = _cli("compare", v, h, "--json", "--allow-unequal")
        assert p.returncode == 0 and json.loads(p.stdout)[1]["speedup_vs_first"] > 0
    else:
        assert p.returncode == 0, p.stderr
