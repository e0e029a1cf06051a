"""Inputs at the edges of their ranges (issue 23): one line, exit 2, nothing written — or, for a file a folder
walk meets with a name flighttest does not take, a note with the rest analysed.

Near-zero values that pass their ranges but make a plan last for ever (a vertical plan's acceleration fraction,
an autopilot limit in a profile, the probe's chirp rate); output paths of the wrong kind or length (the profile
``identify --write-profile`` writes, ``campaign -o``, ``fly --log-dir``); a log whose telemetry holds descent
speeds no vehicle flies (identify's grid of onsets was sized from them). Every case ran into a traceback, an
allocation of terabytes or exit 1 before.
"""

from __future__ import annotations

import io
import json
import os
import struct
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pymavlink.dialects.v20 import common as mavlink

from flighttest.analysis import identify
from flighttest.analysis.batch import find_logs
from flighttest.analysis.identify import identify_onset
from flighttest.analysis.loaders import load_log
from flighttest.cli import main
from flighttest.errors import FlighttestError
from flighttest.inputs import PATH_MAX_BYTES, check_output_folder
from flighttest.model.profiles import SHIPPED_DIR, load_profile, write_w_allow
from flighttest.model.trajectory import MAX_ROWS, sample_times
from flighttest.planner.probe import plan_probe
from flighttest.planner.vertical import plan_vertical
from synthetic import SyntheticFlight, write_tlog

ARDUCOPTER_TOML = (SHIPPED_DIR / "arducopter_sitl.toml").read_text(encoding="utf-8")
PROBE_ONSET_MPS = 0.7


def _tree(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.fixture
def cli(tmp_path, monkeypatch, capsys):
    """``run(*argv) -> (rc, stdout, stderr)`` in an empty working folder with an empty user profile folder."""
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setenv("FLIGHTTEST_VEHICLES", str(tmp_path / "vehicles"))
    monkeypatch.setenv("HOME", str(tmp_path))

    def run(*argv: str) -> tuple[int, str, str]:
        capsys.readouterr()
        rc = main(list(argv))
        out, err = capsys.readouterr()
        return rc, out, err

    run.root = tmp_path  # type: ignore[attr-defined]
    return run


def _refused(cli, argv: list[str], needle: str) -> None:
    """``argv`` with and without ``--json``: exit 2, one error line holding ``needle``, no traceback, nothing
    written anywhere under the test's folder."""
    for extra in ([], ["--json"]):
        before = _tree(cli.root)
        rc, out, err = cli(*argv, *extra)
        lines = err.strip().splitlines()
        assert rc == 2, (argv, rc, out, err[-2000:])
        assert len(lines) == 1 and lines[0].startswith("flighttest: error:") and needle in lines[0], err[-2000:]
        if extra:
            assert "error" in json.loads(out)
        else:
            assert out == ""
        assert _tree(cli.root) == before, sorted(_tree(cli.root) - before)


# -- plans from near-zero values ---------------------------------------------------------------------


@pytest.mark.parametrize("fraction", ["1e-300", "5e-324", "1e-6"])
def test_plan_vertical_with_a_near_zero_accel_fraction_is_one_line(cli, fraction):
    # 1e-300 divided by zero (the too-short bisection's peak rounded to 0); 1e-6 was refused only by the
    # trajectory's own check, after sampling twenty minutes of it
    _refused(cli, ["plan", "vertical", "--accel-fraction", fraction, "-o", "v"], "would take")


def _arducopter_with(tmp_path: Path, key: str, value: str) -> Path:
    lines = [f"{key} = {value}" if ln.split("=")[0].strip() == key else ln for ln in ARDUCOPTER_TOML.splitlines()]
    assert lines != ARDUCOPTER_TOML.splitlines()
    path = tmp_path / f"ap_{key}.toml"
    path.write_text("\n".join(lines).replace('name = "arducopter_sitl"', f'name = "ap_{key}"') + "\n")
    return path


@pytest.mark.parametrize(
    ("key", "value"),
    [
        ("descent_max_mps", "1e-9"),  # a cruise of 1 nm/s: a 2.18 TiB sample grid
        ("max_speed_mps", "1e-300"),
        ("accel_z_max_mps2", "1e-300"),
        ("jerk_z_max_mps3", "5e-324"),  # the S-curve's peak acceleration rounds to 0: a division by zero
    ],
)
def test_plan_vertical_for_a_profile_with_a_near_zero_limit_is_one_line(cli, tmp_path, key, value):
    profile = _arducopter_with(tmp_path, key, value)
    _refused(cli, ["plan", "vertical", "--vehicle", str(profile), "-o", "v"], "would take")


@pytest.mark.parametrize(
    ("t_f_s", "rate_hz"),
    [(1e9, 100.0), (600.5, 100.0), (600.0, 2000.0), (float("nan"), 100.0), (10.0, float("inf")), (-1.0, 100.0)],
)
def test_sample_times_refuses_before_allocating(t_f_s, rate_hz):
    with pytest.raises(FlighttestError, match="trajectory sampling"):
        sample_times(t_f_s, rate_hz)
    assert len(sample_times(600.0, 1000.0)) <= MAX_ROWS  # the largest a trajectory holds still samples


def test_a_vertical_plan_of_the_longest_duration_is_still_made():
    x500 = load_profile("x500")
    plan = plan_vertical(x500, 100.0, w_allow_mps=0.5, margin_mps=0.3, accel_fraction=0.5)  # 0.2 m/s: 500 s
    assert 400.0 < plan.t_f_s <= 600.0 and plan.d_m[-1] == 100.0
    with pytest.raises(FlighttestError, match="would take"):
        plan_vertical(x500, 120.0, w_allow_mps=0.5, margin_mps=0.3, accel_fraction=0.5)


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--omega0", "1e-300"], "omega0"),  # ω0·t_sat² overflowed (OverflowError)
        (["--omega0", "1e-160"], "omega0"),
        (["--omega0", "1e-4"], "omega0"),
        (["--ramp", "1e-300"], "ramp"),  # infinite accelerations: "non-finite value in column 'ad_mps2'"
        (["--duration", "1e-300"], "duration"),
    ],
)
def test_plan_probe_with_a_near_zero_rate_or_time_is_one_line(cli, argv, needle):
    _refused(cli, ["plan", "probe", *argv, "-o", "p"], needle)


def test_the_probe_chirp_keeps_its_plans():
    plan = plan_probe(omega0_rps2=2 * np.pi / 60.0**2 * 1.01, duration_s=60.0, ramp_s=3.0)  # one cycle just fits
    assert plan.cycles >= 1
    with pytest.raises(FlighttestError, match="omega0"):
        plan_probe(omega0_rps2=2 * np.pi / 60.0**2 * 0.99, duration_s=60.0)


# -- the profile identify writes ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def probe_tlog(tmp_path_factory) -> Path:
    """A probe of another program (no mission recorded) with a known onset."""
    flight = SyntheticFlight(duration_s=60.0, descents=[], probe=(10.0, 2.0, 0.01, 40.0), onset_mps=PROBE_ONSET_MPS)
    return write_tlog(flight, tmp_path_factory.mktemp("probe") / "probe.tlog", rate_hz=25.0)


@pytest.mark.parametrize("kind", ["folder", "user-folder-is-a-file"])
def test_identify_write_profile_onto_a_path_of_another_kind_is_one_line(cli, probe_tlog, kind):
    vehicles = cli.root / "vehicles"
    if kind == "folder":  # where x500.toml would go is a folder: IsADirectoryError from the write
        (vehicles / "x500.toml").mkdir(parents=True)
        needle = "is a folder"
    else:  # $FLIGHTTEST_VEHICLES names a file: FileExistsError from mkdir
        vehicles.write_text("not a folder\n")
        needle = "is a file"
    _refused(cli, ["identify", str(probe_tlog), "--vehicle", "x500", "--write-profile"], needle)
    rc, out, _ = cli("identify", str(probe_tlog), "--vehicle", "x500", "--json")  # without: the onset, no write
    assert rc == 0 and json.loads(out)["profile_written"] is None


def test_write_w_allow_never_stores_what_the_loader_refuses(tmp_path, monkeypatch):
    monkeypatch.setenv("FLIGHTTEST_VEHICLES", str(tmp_path / "vehicles"))
    x500 = load_profile("x500")
    with pytest.raises(FlighttestError, match="source is too long"):
        write_w_allow(x500, 0.8, "x" * 2001)
    (tmp_path / "dir.toml").mkdir()
    with pytest.raises(FlighttestError, match="is a folder"):
        write_w_allow(x500, 0.8, "measured", target=tmp_path / "dir.toml")
    assert not (tmp_path / "vehicles").exists()
    # a probe log deep in a long campaign folder: its path is shortened in the provenance, and the profile loads
    onset = identify.Onset(0.8, 0.05, 0.1, 0.01, 8.0, 2.0, 1.5, 100, 5.0, 0.01, 0.01, 0.01, ("p_radps",), None)
    long_log = tmp_path / "/".join(["d" * 200] * 15) / "probe"
    source = onset.provenance(long_log, "flighttest campaign")
    assert len(source) < 1000 and source.count("…") == 1
    written = write_w_allow(x500, 0.8, source)
    assert load_profile(str(written)).vrs.source == source


# -- output folders ------------------------------------------------------------------------------------


LONG_NAME = "c" * 300


@pytest.mark.parametrize(
    "argv",
    [
        # was "stopped by an unexpected error: OSError: [Errno 36] File name too long", exit 1
        ["campaign", "--sim", "--yes", "-o", LONG_NAME],
        ["campaign", "--sim", "--yes", "-o", f"runs/{LONG_NAME}/c"],
        ["fly", "vertical", "--connect", "udpout://127.0.0.1:9", "--vehicle", "x500", "--yes", "--log-dir", LONG_NAME],
    ],
)
def test_an_output_folder_name_too_long_for_the_file_system_is_one_line(cli, argv):
    _refused(cli, argv, "too long")


def test_an_output_folder_with_no_room_for_its_files_is_one_line(cli):
    deep = "/".join(["d" * 200] * ((PATH_MAX_BYTES - 50) // 201))  # within PATH_MAX, no room inside it
    assert PATH_MAX_BYTES - 200 < len(deep) <= PATH_MAX_BYTES
    _refused(cli, ["campaign", "--sim", "--yes", "-o", deep], "room for the files written inside")


def test_a_campaign_refused_for_its_folder_name_says_so_in_json(cli):
    rc, out, _ = cli("campaign", "--sim", "--yes", "-o", LONG_NAME, "--json")
    doc = json.loads(out)
    assert rc == 2 and doc["outcome"] == "refused" and set(doc) == {"error", "outcome", "out_dir"}


# -- a folder walk --------------------------------------------------------------------------------------


def test_analyse_dir_skips_a_file_with_a_newline_in_its_name_and_analyses_the_rest(cli, probe_tlog):
    logs = cli.root / "logs"
    (logs / "sub\nfolder").mkdir(parents=True)
    good = logs / "good.tlog"
    good.write_bytes(probe_tlog.read_bytes())
    (logs / "bad\nname.tlog").write_bytes(probe_tlog.read_bytes())
    (logs / "sub\nfolder" / "inner.tlog").write_bytes(probe_tlog.read_bytes())
    rc, out, err = cli("analyse", str(logs), "--json", "--jobs", "1")
    assert rc == 0, err
    assert [d["log"] for d in json.loads(out)] == [str(good)]
    notes = err.strip().splitlines()
    assert len(notes) == 2 and all(n.startswith("flighttest: note: skipped the ") for n in notes), err
    assert any(repr(str(logs / "bad\nname.tlog")) in n for n in notes)
    assert any(repr(str(logs / "sub\nfolder")) in n for n in notes)
    assert (logs / "flighttest-descents.parquet").is_file()
    found, skipped = find_logs(logs)
    assert found == [good] and len(skipped) == 2
    rc, _, err = cli("analyse", str(logs / "bad\nname.tlog"))  # named on the command line: refused, as before
    assert rc == 2 and "control character" in err


# -- telemetry beyond physics ---------------------------------------------------------------------------


def _with_descent_speed(src: Path, dst: Path, vd_mps: float, count: int) -> Path:
    """``src`` with ``count`` LOCAL_POSITION_NED messages in its second half re-packed (a valid CRC) with
    ``vz = vd_mps``: what a damaged record that still passes its checksum, or a resynchronised reader's
    garbage frame, hands the analysis."""
    data = src.read_bytes()
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    out, pos, done = bytearray(), 0, 0
    while pos + 16 <= len(data):
        magic = data[pos + 8]
        flen = 12 + data[pos + 9] + (13 if data[pos + 10] & 1 else 0) if magic == 0xFD else 8 + data[pos + 9]
        record = data[pos : pos + 8 + flen]
        msgid = struct.unpack_from("<I", record[15:18] + b"\0")[0]
        if msgid == mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED and pos > len(data) // 2 and done < count:
            m = mav.decode(bytearray(record[8:]))
            record = record[:8] + mav.local_position_ned_encode(m.time_boot_ms, m.x, m.y, m.z, m.vx, m.vy,
                                                                vd_mps).pack(mav)  # fmt: skip
            done += 1
        out += record
        pos += 8 + flen
    assert done == count
    dst.write_bytes(bytes(out))
    return dst


@pytest.mark.parametrize("vd_mps", [1e30, 1e6, float("inf")])
def test_identify_leaves_out_descent_speeds_no_vehicle_flies(cli, probe_tlog, tmp_path, vd_mps):
    # 1e30: "ValueError: Maximum allowed size exceeded" (the onset grid ran to 1e30 m/s); 1e6: 4 TiB
    log = _with_descent_speed(probe_tlog, tmp_path / "damaged.tlog", vd_mps, 30)
    rc, out, err = cli("identify", str(log), "--vehicle", "x500", "--json")
    assert rc == 0, err
    assert json.loads(out)["w_onset_mps"] == pytest.approx(PROBE_ONSET_MPS, abs=0.05)  # the good samples kept


def test_identify_refuses_a_fit_larger_than_it_handles(probe_tlog, monkeypatch):
    monkeypatch.setattr(identify, "MAX_FIT_CELLS", 10_000)
    with pytest.raises(FlighttestError, match="more than identify fits") as err:
        identify_onset(load_log(probe_tlog), load_profile("x500"), identify.IdentifyConfig(n_boot=3))
    assert "\n" not in str(err.value)


def test_an_ordinary_deep_output_folder_is_still_taken(tmp_path):
    deep = tmp_path.joinpath(*(["d" * 200] * 10))
    assert check_output_folder(deep, "-o") == deep


# -- found by the fuzz lane (tests/test_fuzz_lane.py) ----------------------------------------------------


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["campaign", "--connect", "", "-o", "camp"], "--connect"),  # was a ValueError: "either a link or the fake"
        (["campaign", "--sim", "-o", "camp", "--sim-param", "COM_RC_OVERRIDE=" + "9" * 400], "--sim-param"),  # float()
    ],
)
def test_campaign_options_found_by_the_fuzz_lane_are_one_line(cli, argv, needle):
    _refused(cli, argv, needle)


@pytest.fixture
def latin1_logs(cli, probe_tlog) -> Path:
    """A folder holding a probe log whose name is not UTF-8 (byte 0xff: Latin-1 'ÿ' from an old card)."""
    logs = cli.root / "logs"
    logs.mkdir()
    (logs / os.fsdecode(b"probe-\xff.tlog")).write_bytes(probe_tlog.read_bytes())
    return logs


def test_a_log_whose_name_is_not_utf8_is_analysed_reported_and_identified(cli, latin1_logs):
    log = latin1_logs / os.fsdecode(b"probe-\xff.tlog")
    # each was "analysis failed (UnicodeEncodeError ...", "writing the report failed (TypeError ..." or a traceback
    rc, out, err = cli("analyse", str(latin1_logs), "--json", "--jobs", "1")
    assert rc == 0 and json.loads(out)[0]["descents"], err
    table = pd.read_parquet(latin1_logs / "flighttest-descents.parquet")
    assert set(table["log"]) == {str(latin1_logs) + "/probe-\\xff.tlog"}  # the bytes shown, the text UTF-8
    rc, _, err = cli("report", str(log), "-o", str(cli.root / "report"), "--vehicle", "x500")
    assert rc == 0 and "\\xff" in (cli.root / "report" / "report.md").read_text(encoding="utf-8"), err
    rc, out, err = cli("identify", str(log), "--vehicle", "x500", "--write-profile", "--json")
    assert rc == 0, err
    stored = load_profile(json.loads(out)["profile_written"])
    assert "probe-\\xff.tlog" in stored.vrs.source


def test_a_strict_stdout_prints_a_name_that_is_not_utf8(latin1_logs, monkeypatch, tmp_path):
    # stdout is strict under a UTF-8 locale such as en_US.UTF-8: printing the name was a UnicodeEncodeError
    raw = io.BytesIO()
    monkeypatch.setattr(sys, "stdout", io.TextIOWrapper(raw, encoding="utf-8", errors="strict", write_through=True))
    monkeypatch.setattr(sys, "stderr", io.TextIOWrapper(io.BytesIO(), encoding="utf-8", errors="backslashreplace"))
    assert main(["analyse", str(latin1_logs), "--jobs", "1", "--parquet", str(tmp_path / "t.parquet")]) == 0
    assert b"-\xff.tlog" in raw.getvalue()  # the name's own bytes, as ls shows them (rich may wrap the path)
