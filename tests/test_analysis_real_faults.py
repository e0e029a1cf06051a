"""Issue 14's "Done when", end to end through ``flighttest analyse --json``, on logs with the faults of
the real logs it was written about, in each format (.bin, .tlog, .ulg):

- an estimator height that sits 4 m below home on the ground and 12 m by the end (the ArduCopter 4.5
  ``.BIN``): the descents come from the barometer, which agrees with the ground;
- an estimator excursion 7.5 m below the ground and back at the landing (the ArduCopter 3.4
  ``.tlog``): flagged as a glitch with its span and what each source said, not reported as a descent;
- a DataFlash log without ATT but with AHR2 and XKQ: blade-frame exposure all the same, the source named;
- issue 23, the ArduCopter 3.4 ``.tlog``'s hard landing as it really was: both position messages of its one
  estimator run on down to 7.8 m below home for half a minute after the touch-down, the vehicle armed on
  the ground, the GPS altitude sagging with them: the descent is the barometer's fall, the run-on a glitch
  (on the real log too, when ``FLIGHTTEST_AC34_TLOG`` names it).

The flight takes off from home, climbs 10 m and lands with a raised-cosine 10 m descent in 5 s
(15–20 s): its start and end follow in closed form from the segmentation's tolerances, and the same
flight logged without faults gives the exposure to expect.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest

from flighttest.analysis.loaders import load_log
from flighttest.analysis.segment import GLITCH_COLUMNS, SegmentConfig
from flighttest.cli import main
from synthetic import DF_RECORDS, SyntheticFlight, write_dataflash, write_tlog, write_ulog

MOVES = [(3.0, -10.0, 4.0), (15.0, 10.0, 5.0)]  # take off to 10 m, land 10 m in 5 s from 15 s
LAND_T0, LAND_H, LAND_D = MOVES[1]
EXCURSION = (19.0, 3.0, 7.5)  # the estimator dips 7.5 m below the ground from 19 s for 3 s
FLIGHTS = {
    "offset": SyntheticFlight(duration_s=30.0, start_alt_m=0.0, descents=MOVES, ekf_offset_m=(4.0, 12.0)),
    "excursion": SyntheticFlight(duration_s=30.0, start_alt_m=0.0, descents=MOVES, ekf_excursion=EXCURSION),
    "clean": SyntheticFlight(duration_s=30.0, start_alt_m=0.0, descents=MOVES),
}
NO_ATT = (*(r for r in DF_RECORDS if r != "ATT"), "AHR2", "XKQ")  # the issue's .BIN: AHR2 and XKQ, no ATT
# format: (writer, the flight's t = 0 on the log's boot clock, estimator, barometer, attitude sources)
FORMATS = {
    "bin": (lambda f, p: write_dataflash(f, p, records=NO_ATT), 20.0, "POS.RelHomeAlt", "BARO.Alt", {"AHR2", "XKQ"}),
    "tlog": (write_tlog, 5.0, "LOCAL_POSITION_NED.z", "ALTITUDE.altitude_monotonic", {"ATTITUDE_QUATERNION"}),
    "ulg": (write_ulog, 5.0, "vehicle_local_position.z", "vehicle_air_data.baro_alt_meter", {"vehicle_attitude"}),
}
EXPOSURE = ("time_inside_s", "time_near_s", "min_margin_mps")
TOL_S, TOL_M = 0.1, 0.1


def landing_window() -> tuple[float, float]:
    """Start and end of the landing under the segmentation's start/end tolerances (raised cosine)."""
    cfg = SegmentConfig()
    start = LAND_T0 + LAND_D / math.pi * math.acos(1 - 2 * cfg.start_tol_m / LAND_H)
    end = LAND_T0 + LAND_D / math.pi * math.acos(-1 + 2 * cfg.end_tol_m / LAND_H)
    return start, end


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    """``get(fault, fmt)`` → (the per-log JSON of ``flighttest analyse --json --vehicle x500``, the
    flight time of the state's t = 0); each log written and analysed once per module."""
    root = tmp_path_factory.mktemp("faults")
    cache: dict[tuple[str, str], tuple[dict, float]] = {}

    def get(fault: str, fmt: str, capsys) -> tuple[dict, float]:
        if (fault, fmt) not in cache:
            writer, boot0, *_ = FORMATS[fmt]
            path = writer(FLIGHTS[fault], root / f"{fault}.{fmt}")
            capsys.readouterr()
            assert main(["analyse", str(path), "--json", "--vehicle", "x500", "--jobs", "1"]) == 0
            out = capsys.readouterr().out
            data = json.loads(out)  # --json prints only JSON
            assert isinstance(data, list) and len(data) == 1
            origin = float(load_log(path).state["boot_s"].iloc[0]) - boot0
            cache[fault, fmt] = (data[0], origin)
        return cache[fault, fmt]

    return get


def _landing(d: dict, origin: float) -> dict:
    """The one descent, with its start on the flight's clock."""
    assert len(d["descents"]) == 1, [(x["start_s"], x["height_m"]) for x in d["descents"]]
    x = dict(d["descents"][0])
    x["flight_start_s"] = x["start_s"] + origin
    return x


def _assert_landing_is_the_truth(d: dict, origin: float) -> dict:
    x = _landing(d, origin)
    start, end = landing_window()
    assert x["flight_start_s"] == pytest.approx(start, abs=TOL_S)
    assert x["duration_s"] == pytest.approx(end - start, abs=TOL_S)
    assert x["height_m"] == pytest.approx(LAND_H, abs=TOL_M)
    assert x["start_alt_m"] == pytest.approx(LAND_H, abs=TOL_M)  # above home, not the estimator's datum
    return x


def _assert_exposure(d: dict, x: dict, clean: dict) -> None:
    """Blade-frame exposure computed (the attitude came from somewhere) and the clean flight's."""
    assert "attitude" not in d["missing"], d["missing"]
    ref = clean["descents"][0]
    for k in EXPOSURE:
        assert isinstance(x[k], float) and math.isfinite(x[k]), (k, x[k])
    assert x["time_inside_s"] == pytest.approx(ref["time_inside_s"], abs=TOL_S)
    assert x["min_margin_mps"] == pytest.approx(ref["min_margin_mps"], abs=0.1)


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_estimator_below_home_gives_way_to_the_barometer(analysed, capsys, fmt):
    _, _, estimator, baro, attitude = FORMATS[fmt]
    d, origin = analysed("offset", fmt, capsys)
    assert d["height_source"] == baro
    rows = {r["name"]: r for r in d["height_sources"]}
    assert set(rows[baro]) == {"name", "kind", "consistent", "ground_error_m", "below_ground_m",
                               "max_disagreement_m", "reason"}  # fmt: skip
    assert rows[baro]["kind"] == "baro" and rows[baro]["consistent"] and rows[baro]["ground_error_m"] < 0.1
    assert not rows[estimator]["consistent"] and "at home" in rows[estimator]["reason"]
    assert any(baro in n for n in d["notes"])
    x = _assert_landing_is_the_truth(d, origin)
    assert d["attitude_source"] in attitude
    _assert_exposure(d, x, analysed("clean", fmt, capsys)[0])
    assert d["params"] and d["params_source"]


@pytest.mark.parametrize("fmt", list(FORMATS))
def test_excursion_below_the_ground_is_a_glitch_not_a_descent(analysed, capsys, fmt):
    _, _, estimator, baro, attitude = FORMATS[fmt]
    d, origin = analysed("excursion", fmt, capsys)
    assert d["height_source"] == estimator  # consistent but for one span: still the one trusted
    assert all(r["consistent"] for r in d["height_sources"] if r["name"] in (estimator, baro))
    glitches = [g for g in d["glitches"] if g["kind"] == "disagreement"]
    assert len(glitches) == 1, d["glitches"]
    g = glitches[0]
    assert set(g) == set(GLITCH_COLUMNS)
    t0, dur, depth = EXCURSION
    assert g["start_s"] + origin == pytest.approx(t0, abs=0.3)
    assert g["end_s"] + origin == pytest.approx(t0 + dur, abs=0.3)
    assert g["duration_s"] == pytest.approx(g["end_s"] - g["start_s"])
    assert g["max_jump_m"] == pytest.approx(depth, abs=0.3)
    assert g["source"] == estimator
    assert g["sources"][estimator] == pytest.approx(-depth, abs=0.3)  # what each source said, referred to home
    assert g["sources"][baro] == pytest.approx(0.0, abs=0.3)
    # the landing is the truth's, and nothing starts inside the excursion
    x = _assert_landing_is_the_truth(d, origin)
    assert not (t0 - 0.5 < x["flight_start_s"] < t0 + dur + 0.5)
    assert d["attitude_source"] in attitude
    _assert_exposure(d, x, analysed("clean", fmt, capsys)[0])


def test_clean_flight_trusts_its_estimator_and_flags_nothing(analysed, capsys):
    for fmt, (_, _, estimator, *_rest) in FORMATS.items():
        d, origin = analysed("clean", fmt, capsys)
        assert d["height_source"] == estimator and d["glitches"] == []
        _assert_landing_is_the_truth(d, origin)


def test_dataflash_without_att_names_its_attitude(analysed, capsys):
    d, _ = analysed("offset", "bin", capsys)
    assert d["attitude_source"] == "AHR2"
    assert Path(d["log"]).suffix == ".bin" and d["source"] == "dataflash"


def test_report_names_the_sources_and_draws_both_heights(tmp_path, monkeypatch):
    """report.md says which height and attitude the numbers came from and lists the glitch with what
    each source said; the altitude plot draws the estimator's own height beside the trusted one and
    marks the glitch span with its kind."""
    from flighttest.analysis import report
    from flighttest.analysis.pipeline import analyse

    write, _, estimator, baro, _ = FORMATS["bin"]
    exc = analyse(load_log(write(FLIGHTS["excursion"], tmp_path / "exc.bin")), "x500")
    off = analyse(load_log(write(FLIGHTS["offset"], tmp_path / "off.bin")), "x500")
    lines = report.source_lines(off)
    assert f"`{baro}` (baro" in lines[0] and f"the estimator `{estimator}` is not consistent" in lines[0]
    assert lines[1] == "- attitude source: `AHR2`"
    md = "\n".join(report.heights_section(exc))
    assert "### Height sources" in md and "### Estimator glitches (1)" in md
    row = next(line for line in md.splitlines() if "| disagreement |" in line)
    assert row.startswith("| 1 |") and f"`{estimator}`" in row and len(row) <= 80  # the table fits 80 columns
    said = next(line for line in md.splitlines() if line.startswith("- glitch 1, what each source said"))
    assert f"`{estimator}` -7.50" in said and f"`{baro}` -0.0" in said

    figures = []
    monkeypatch.setattr(report.plt, "close", figures.append)
    assert report.plot_altitude(exc, tmp_path / "exc.png").is_file()
    monkeypatch.undo()
    (fig,) = figures
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert f"estimator {estimator} as logged" in legend and "glitch: height sources disagree" in legend
    assert any(f"{estimator} (estimator, trusted), glitches bridged" in t for t in legend)
    assert any(t.get_text().strip() == f"disagreement: {estimator}" for t in fig.axes[0].texts)
    report.plt.close(fig)


# -- issue 23: the ArduCopter 3.4 .tlog's hard landing ---------------------------------------------------

# A 9 m hover falls to the ground in 2 s at FALL_T0 (the barometer's fall, 7.1 m/s peak); the estimator's
# error then grows at 0.2 m/s to 7.8 m below home over 37 s and is gone within 10 s, the vehicle armed on
# the ground to the end; the GPS altitude sags with it (ArduCopter 3.4's EKF fuses GPS vertical velocity).
# The streams ArduCopter 3.4 sent at 10 Hz: no ALTITUDE, no EXTENDED_SYS_STATE, Euler ATTITUDE.
FALL_T0 = 240.0
AC34 = SyntheticFlight(
    duration_s=FALL_T0 + 60.0,
    start_alt_m=0.0,
    descents=[(5.0, -9.0, 6.0), (FALL_T0, 9.0, 2.0)],
    ekf_error_knots=((FALL_T0, 0.0), (FALL_T0 + 2, 0.4), (FALL_T0 + 39, 7.8), (FALL_T0 + 44, 0.3), (FALL_T0 + 49, 0.0)),
    gps_error_knots=((FALL_T0, 0.0), (FALL_T0 + 2, 0.4), (FALL_T0 + 39, 6.5), (FALL_T0 + 45, 0.5), (FALL_T0 + 55, 0.0)),
    disarm_s=math.inf,
    gps_noise_m=1.0,
    baro_noise_m=0.15,
)
AC34_STREAMS = ("pos", "global", "baro", "gps", "heartbeat", "att_euler", "servo", "params")
AC34_TLOG = os.environ.get("FLIGHTTEST_AC34_TLOG")


def _analyse_json(path: Path, capsys) -> dict:
    capsys.readouterr()
    assert main(["analyse", str(path), "--json", "--vehicle", "x500", "--jobs", "1"]) == 0
    (d,) = json.loads(capsys.readouterr().out)
    return d


def _assert_hard_landing(d: dict, fall_s: float, duration_s: tuple[float, float]) -> dict:
    """The landing is the barometer's 8–10 m fall, nothing is over 12 m, and the estimator's run-on
    below the ground is one listed glitch of LOCAL_POSITION_NED.z, with what every source said."""
    assert d["height_source"] == "LOCAL_POSITION_NED.z"
    assert max(x["height_m"] for x in d["descents"]) < 12.0, [(x["start_s"], x["height_m"]) for x in d["descents"]]
    (x,) = [x for x in d["descents"] if fall_s - 10.0 < x["start_s"] < fall_s + 10.0]
    assert 8.0 <= x["height_m"] <= 10.0 and duration_s[0] <= x["duration_s"] <= duration_s[1], x
    (g,) = [g for g in d["glitches"] if g["kind"] == "disagreement" and g["start_s"] > fall_s - 10.0]
    assert g["source"] == "LOCAL_POSITION_NED.z" and g["max_jump_m"] > 5.0
    said = g["sources"]
    assert said["LOCAL_POSITION_NED.z"] < -5.0 and said["GLOBAL_POSITION_INT.relative_alt"] < -5.0
    assert abs(said["SCALED_PRESSURE.press_abs"]) < 2.5
    assert any("the ground outranks" in n for n in d["notes"]) and not any("sided with it" in n for n in d["notes"])
    return x


def test_ardupilot_34_hard_landing_is_the_barometers_fall(tmp_path, capsys):
    path = write_tlog(AC34, tmp_path / "ac34.tlog", rate_hz=10.0, autopilot="ardupilot", streams=AC34_STREAMS)
    d = _analyse_json(path, capsys)
    origin = float(load_log(path).state["boot_s"].iloc[0]) - 5.0  # write_tlog's boot clock starts at 5 s
    x = _assert_hard_landing(d, FALL_T0 - origin, (1.5, 4.5))  # the 2 s fall less the segmentation's tolerances
    # the height's own fastest fall over 0.2 s: the fall's π·9/4 m/s, plus the estimator's error growing at
    # 0.2 m/s through it and the 10 Hz samples' noise over two intervals
    assert x["max_rate_mps"] == pytest.approx(math.pi * 9.0 / 4.0, abs=0.5)
    assert x["mean_rate_mps"] <= x["max_rate_mps"]
    (g,) = [g for g in d["glitches"] if g["kind"] == "disagreement"]
    assert g["start_s"] + origin == pytest.approx(FALL_T0 + 1.0, abs=1.5)  # the run-on, from the fall
    assert FALL_T0 + 43.0 < g["end_s"] + origin < FALL_T0 + 50.0  # ... to where the estimator is back
    assert g["max_jump_m"] == pytest.approx(7.8, abs=0.3)
    assert g["sources"]["GPS_RAW_INT.alt"] < -5.0  # the referee the ground overrules


@pytest.mark.skipif(not (AC34_TLOG and Path(AC34_TLOG).is_file()), reason="FLIGHTTEST_AC34_TLOG: the real log")
def test_the_real_ardupilot_34_tlog(capsys):
    """The issue's log itself (not in the repository): its hard landing about 1094 s in."""
    _assert_hard_landing(_analyse_json(Path(AC34_TLOG), capsys), 1094.0, (2.0, 4.5))
