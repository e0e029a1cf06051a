"""Bad input to the analysis commands — ``analyse``, ``compare``, ``report`` — and the log loaders (issue 12).

Every bad command line runs ``flighttest.cli.main`` in this process, in text and in ``--json``
mode: exit code 2, one ``flighttest: error:`` line on stderr (fd-level, so a reader's C code
printing would show), no traceback, stdout JSON with ``error`` under ``--json`` and empty without,
nothing written, within seconds. Then formats told by content whatever the name, damaged ULogs
whose reader prints, every damaged side file of a log folder (a note, never a crash), event
values taken only as finite numbers, the segmentation's physical ranges, and ``--json`` staying
one document when some logs fail. Random byte mutations are in ``tests/test_fuzz_logs.py``.
"""

from __future__ import annotations

import json
import os
import shutil
import struct
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from flighttest.analysis.batch import quiet_numerics
from flighttest.analysis.fluctuation import FLUCTUATION_RANGES, FluctuationConfig
from flighttest.analysis.loaders import load_log, sniff
from flighttest.analysis.pipeline import analyse
from flighttest.analysis.segment import SEGMENT_RANGES, SegmentConfig
from flighttest.cli import main
from flighttest.errors import FlighttestError
from synthetic import UNIX0, SyntheticFlight, write_dataflash, write_tlog, write_ulog

LONG_NAME = "n" * 300
LONG_PATH = "/".join(["d" * 200] * 25)  # 5 kB: longer than any file system's path limit
FLIGHT = SyntheticFlight(duration_s=8.0, descents=[(2.0, 2.0, 1.5)])  # 2 m in 1.5 s from t = 2 s


@dataclass
class _Idle(SyntheticFlight):
    """Never armed, every motor output zero (PWM 0): a log recorded on the bench."""

    def armed(self, t):
        return np.zeros_like(np.asarray(t, float))

    def states(self, t):
        out = super().states(t)
        out["motors"] = np.full_like(out["motors"], -1.0)  # the writers' 1000 + 1000·m µs = 0
        return out


def _write_folder(root: Path, tlog: Path) -> Path:
    """A flighttest log folder around a synthetic tlog: every side file present and well formed."""
    root.mkdir(parents=True)
    shutil.copy(tlog, root / "flight.tlog")
    meta = {"start_unix_s": UNIX0, "mission": "vertical", "vehicle": {"name": "x500"},
            "trajectory_meta": {"kind": "vertical"}, "trajectory": {"path": "v.csv", "kind": "vertical"}}  # fmt: skip
    (root / "meta.json").write_text(json.dumps(meta))
    t = np.arange(0.0, 6.0, 0.1)
    sp = pd.DataFrame({"t_s": t, "unix_s": UNIX0 + t, "n_m": 0.0, "e_m": 0.0, "d_m": -10.0, "vn_mps": 0.0,
                       "ve_mps": 0.0, "vd_mps": 0.0, "an_mps2": 0.0, "ae_mps2": 0.0, "ad_mps2": 0.0, "yaw_deg": 0.0,
                       "phase": np.where(t >= 2.0, "stream", "settle")})  # fmt: skip
    sp.to_csv(root / "setpoints.csv", index=False)
    gd = pd.DataFrame({"t_s": t, "unix_s": UNIX0 + t, "verdict": "ok", "w_mps": 0.1, "u_mps": 0.0, "margin_mps": 0.5,
                       "predicted_margin_mps": 0.5, "action": "none", "reason": "", "alt_m": 10.0})  # fmt: skip
    gd.to_csv(root / "guard.csv", index=False)
    events = [{"t_s": 0.0, "unix_s": UNIX0, "event": "phase", "phase": "settle"},
              {"t_s": 2.0, "unix_s": UNIX0 + 2.0, "event": "phase", "phase": "stream"},
              {"t_s": 2.0, "unix_s": UNIX0 + 2.0, "event": "stream_start", "rows": 10},
              {"t_s": 4.5, "unix_s": UNIX0 + 4.5, "event": "descent_reached", "descent_time_s": 2.5}]  # fmt: skip
    (root / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events))
    (root / "summary.json").write_text(json.dumps({"outcome": "completed", "descent_time_s": 2.5}))
    (root / "trajectory.json").write_text(json.dumps({"format": "flighttest-trajectory/1", "kind": "vertical"}))
    (root / "params.json").write_text(json.dumps({"format": "flighttest-params/1", "params": {"MPC_XY_P": 0.95}}))
    (root / "preflight.json").write_text(json.dumps({"ok": True, "params": {"COM_OF_LOSS_T": 1.0}}))
    return root


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("analysis-corpus")
    write_tlog(FLIGHT, d / "s.tlog")
    write_ulog(FLIGHT, d / "s.ulg")
    write_dataflash(FLIGHT, d / "s.bin")
    _write_folder(d / "folder", d / "s.tlog")
    idle = _Idle(duration_s=6.0, descents=[(2.0, 2.0, 1.5)])
    for writer, name in ((write_tlog, "idle.tlog"), (write_ulog, "idle.ulg"), (write_dataflash, "idle.bin")):
        writer(idle, d / name)
    os.mkfifo(d / "fifo.tlog")
    os.mkfifo(d / "fifo")
    (d / "adir").mkdir()
    (d / "folder.csv").mkdir()
    (d / "folder.parquet").mkdir()
    (d / "afile").write_text("a file, not a folder\n")
    (d / "noise.dat").write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8)))
    return d


def _tree(*roots: Path) -> set[str]:
    out = set()
    for r in roots:
        for dirpath, dirnames, filenames in os.walk(r):
            out.update(os.path.join(dirpath, n) for n in dirnames + filenames)
    return out


@pytest.fixture
def cli(tmp_path, monkeypatch, corpus, capfd):
    """``run(argv) -> (rc, stdout, stderr, seconds)`` in a clean working folder (fd-level capture)."""
    work = tmp_path / "work"
    work.mkdir()
    (tmp_path / "vehicles").mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setenv("FLIGHTTEST_VEHICLES", str(tmp_path / "vehicles"))
    monkeypatch.setenv("HOME", str(tmp_path))

    def run(argv: list[str]) -> tuple[int, str, str, float]:
        capfd.readouterr()
        t0 = time.monotonic()
        rc = main([a.replace("{d}", str(corpus)) for a in argv])
        took = time.monotonic() - t0
        out, err = capfd.readouterr()
        return rc, out, err, took

    run.work = work  # type: ignore[attr-defined]
    return run


def _assert_refused(cli, corpus, argv: list[str], needle: str) -> str:
    before = _tree(cli.work, corpus)
    rc, out, err, took = cli(argv)
    assert rc == 2, (argv, rc, out, err)
    assert "Traceback" not in err + out
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("flighttest: error:"), err
    assert needle.lower() in lines[0].lower(), lines[0]
    if "--json" in argv:
        doc = json.loads(out)
        assert isinstance(doc, dict) and doc.get("error"), out
    else:
        assert out == "", out
    assert _tree(cli.work, corpus) == before, "a refused command wrote something"
    assert took < 5.0, f"took {took:.1f} s"
    return lines[0]


T = "{d}/s.tlog"
CASES = [
    # paths: checked before anything is read; never the current folder, never a blocking read
    ("analyse-empty", ["analyse", ""], "empty"),
    ("analyse-blank", ["analyse", "  "], "empty"),
    ("analyse-fifo", ["analyse", "{d}/fifo.tlog"], "regular file"),
    ("analyse-fifo-noext", ["analyse", "{d}/fifo"], "FIFO"),
    ("analyse-long-path", ["analyse", LONG_PATH], "too long"),
    ("analyse-long-name", ["analyse", f"{{d}}/{LONG_NAME}.tlog"], "too long"),
    ("analyse-newline", ["analyse", "{d}/s.tlog\n"], "control character"),
    ("analyse-missing", ["analyse", "{d}/missing.tlog"], "no such file"),
    ("analyse-under-file", ["analyse", "{d}/afile/x.tlog"], "is a file"),
    ("analyse-one-bad-of-two", ["analyse", T, "{d}/fifo.tlog"], "fifo.tlog"),
    ("analyse-not-a-log-folder", ["analyse", "{d}/adir"], "no flight logs found"),
    # numbers: each segmentation option has a physical range (named with the threshold it sets)
    ("settle-hold-huge", ["analyse", T, "--settle-hold", "1e308"], "--settle-hold (settle_hold_s)"),
    ("settle-hold-601", ["analyse", T, "--settle-hold", "601"], "≤ 600 s"),
    ("settle-hold-nan", ["analyse", T, "--settle-hold", "nan"], "--settle-hold"),
    ("settle-hold-inf", ["analyse", T, "--settle-hold", "inf"], "--settle-hold"),
    ("settle-hold-text", ["analyse", T, "--settle-hold", "long"], "--settle-hold"),
    ("settle-hold-negative", ["analyse", T, "--settle-hold", "-1e-1"], "--settle-hold"),
    ("rate-threshold-huge", ["analyse", T, "--rate-threshold", "1e9"], "rate_threshold_mps"),
    ("rate-threshold-zero", ["analyse", T, "--rate-threshold", "0"], "rate_threshold_mps"),
    ("min-height-huge", ["analyse", T, "--min-height", "1e5"], "min_height_m"),
    ("start-tol-negative", ["analyse", T, "--start-tol", "-1"], "start_tol_m"),
    ("end-tol-zero", ["analyse", T, "--end-tol", "0"], "end_tol_m"),
    ("jobs-zero", ["analyse", T, "--jobs", "0"], "--jobs"),
    ("jobs-huge", ["analyse", T, "--jobs", "100000"], "--jobs"),
    ("jobs-float", ["analyse", T, "--jobs", "1.5"], "--jobs"),
    ("vehicle-unknown", ["analyse", T, "--vehicle", "nope"], "nope"),
    # outputs: checked before any log is read
    ("csv-empty", ["analyse", T, "--csv", ""], "empty"),
    ("csv-folder", ["analyse", T, "--csv", "{d}/folder.csv"], "is a folder"),
    ("csv-folder-noext", ["analyse", T, "--csv", "{d}/adir"], ".csv"),
    ("csv-folder-slash", ["analyse", T, "--csv", "{d}/new/"], "folder"),
    ("csv-under-file", ["analyse", T, "--csv", "{d}/afile/t.csv"], "file"),
    ("csv-extension", ["analyse", T, "--csv", "table.txt"], ".csv"),
    ("csv-long", ["analyse", T, "--csv", LONG_NAME + ".csv"], "too long"),
    ("csv-fifo", ["analyse", T, "--csv", "{d}/fifo"], "--csv"),
    ("parquet-empty", ["analyse", T, "--parquet", ""], "empty"),
    ("parquet-folder", ["analyse", T, "--parquet", "{d}/folder.parquet"], "is a folder"),
    ("parquet-under-file", ["analyse", T, "--parquet", "{d}/afile/t.parquet"], "file"),
    ("parquet-extension", ["analyse", T, "--parquet", "t.csv"], ".parquet"),
    ("parquet-long", ["analyse", T, "--parquet", LONG_NAME + ".parquet"], "too long"),
    # compare: the same paths and numbers
    ("compare-empty", ["compare", T, ""], "empty"),
    ("compare-fifo", ["compare", T, "{d}/fifo.tlog"], "regular file"),
    ("compare-long", ["compare", T, LONG_PATH], "too long"),
    ("compare-settle-hold", ["compare", T, T, "--settle-hold", "1e308"], "--settle-hold"),
    ("compare-option", ["compare", T, "--bogus"], "unrecognized"),
    # report: its output folder, its logs, its numbers
    ("report-out-empty", ["report", T, "-o", ""], "empty"),
    ("report-out-file", ["report", T, "-o", "{d}/afile"], "is a file"),
    ("report-out-under-file", ["report", T, "-o", "{d}/afile/rep"], "is a file"),
    ("report-out-long", ["report", T, "-o", LONG_NAME], "too long"),
    ("report-out-md", ["report", T, "-o", "summary.md"], "folder"),
    ("report-out-newline", ["report", T, "-o", "rep\n"], "control character"),
    ("report-log-empty", ["report", "", "-o", "rep"], "empty"),
    ("report-log-fifo", ["report", "{d}/fifo.tlog", "-o", "rep"], "regular file"),
    ("report-log-long", ["report", LONG_PATH, "-o", "rep"], "too long"),
    ("report-settle-hold", ["report", T, "-o", "rep", "--settle-hold", "1e308"], "--settle-hold"),
    ("report-vehicle", ["report", T, "-o", "rep", "--vehicle", "nope"], "nope"),
    ("report-json", ["report", T, "-o", "rep", "--json"], "unrecognized"),
]


@pytest.mark.parametrize("as_json", [False, True], ids=["text", "json"])
@pytest.mark.parametrize(("case", "argv", "needle"), CASES, ids=[c[0] for c in CASES])
def test_bad_analysis_command_lines_are_one_error_line(cli, corpus, case, argv, needle, as_json):
    if as_json and case != "report-json":  # that row has its --json already
        argv = [*argv, "--json"]  # report has none: refused as an unknown option, still JSON
    _assert_refused(cli, corpus, argv, "unrecognized" if as_json and argv[0] == "report" else needle)


def test_good_outputs_are_written_whole_and_missing_folders_created(cli, corpus):
    outputs = ["--csv", "new/a/t.csv", "--parquet", "new/b/t.parquet"]
    rc, out, err, _ = cli(["analyse", T, "--jobs", "1", "--json", *outputs])
    assert rc == 0, err
    assert len(json.loads(out)) == 1
    assert len(pd.read_csv(cli.work / "new/a/t.csv")) == 1 and len(pd.read_parquet(cli.work / "new/b/t.parquet")) == 1
    assert sorted(p.name for p in (cli.work / "new").rglob("*")) == ["a", "b", "t.csv", "t.parquet"]  # no temporaries


def test_a_walked_folder_that_cannot_hold_the_parquet_table_is_still_analysed(cli, tmp_path, corpus):
    ro = tmp_path / "ro"
    ro.mkdir()
    shutil.copy(corpus / "s.tlog", ro / "s.tlog")
    ro.chmod(0o555)
    try:
        if os.access(ro, os.W_OK):
            pytest.skip("running as root: a read-only folder is writable")
        rc, out, err, _ = cli(["analyse", str(ro), "--jobs", "1", "--json"])
    finally:
        ro.chmod(0o755)
    assert rc == 0 and len(json.loads(out)) == 1
    assert err.startswith("flighttest: warning: not writing") and err.count("\n") == 1, err


# -- formats by content, whatever the name ------------------------------------------------------------


@pytest.mark.parametrize(
    ("source", "name", "kind"),
    [("s.bin", "flight.dat", "dataflash"), ("s.bin", "noext", "dataflash"), ("s.bin", "log:1.txt", "dataflash"),
     ("s.bin", "x.tlog", "dataflash"), ("s.ulg", "x.bin", "ulog"), ("s.ulg", "px4", "ulog"),
     ("s.tlog", "telemetry.log", "tlog"), ("s.tlog", "x.ulg", "tlog"), ("s.tlog", "LOG", "tlog")],
)  # fmt: skip
def test_the_format_comes_from_the_content(corpus, tmp_path, source, name, kind):
    p = tmp_path / name
    shutil.copy(corpus / source, p)
    t0 = time.monotonic()
    log = load_log(p)
    assert time.monotonic() - t0 < 5.0  # a DataFlash log not named .bin took 13-64 s
    assert log.source == kind and len(log.state) > 100
    named = {".tlog": "tlog", ".bin": "dataflash", ".ulg": "ulog"}.get(p.suffix)
    assert any("although the name" in n for n in log.notes) == (named is not None and named != kind)


def test_the_cli_reads_a_dataflash_log_of_any_name_and_walks_unnamed_logs(cli, corpus, tmp_path):
    walk = tmp_path / "walk"
    (walk / "sub").mkdir(parents=True)
    shutil.copy(corpus / "s.bin", walk / "sub" / "00000042")
    shutil.copy(corpus / "s.ulg", walk / "px4-log")
    shutil.copy(corpus / "s.tlog", walk / "a.tlog")
    (walk / "notes.txt").write_text("not a log\n")
    os.mkfifo(walk / "fifo.tlog")  # never opened: it would block the walk
    rc, out, err, took = cli(["analyse", str(walk), "--jobs", "1", "--json"])
    assert rc == 0, err
    assert sorted((Path(s["log"]).name, s["source"]) for s in json.loads(out)) == [
        ("00000042", "dataflash"), ("a.tlog", "tlog"), ("px4-log", "ulog")]  # fmt: skip
    assert took < 20


@pytest.mark.parametrize(
    ("head", "kind"),
    [(b"ULog\x01\x12\x35\x01", "ulog"), (b"\xa3\x95\x80", "dataflash"), (b"", None), (b"\x00" * 100, None),
     (b"hello, world\n" * 40, None), (bytes(range(256)) * 4, None)],
)  # fmt: skip
def test_sniff_recognises_magic_and_nothing_else(head, kind):
    assert sniff(head) == kind


def test_sniff_needs_several_chained_tlog_records(corpus):
    data = (corpus / "s.tlog").read_bytes()
    assert sniff(data[:4096]) == "tlog"
    assert sniff(data[5:4096]) == "tlog"  # a damaged first record: found at the next one
    rec = bytes(8) + b"\xfe\x09" + bytes(15)  # one plausible record, then noise
    assert sniff(rec + bytes(np.random.default_rng(1).integers(0, 256, 400, dtype=np.uint8))) is None


@pytest.mark.parametrize(
    ("name", "content", "needle"),
    [("noise.dat", None, "unknown log format"), ("x.ulg", b"not a ulog" * 20, "not a PX4 ULog"),
     ("x.bin", b"\x00\x01\x02" * 100, "not an ArduPilot DataFlash"), ("empty.tlog", b"", "empty file"),
     ("text.tlog", b"hello\n" * 100, "not a MAVLink")],
)  # fmt: skip
def test_content_that_is_no_log_is_one_line(corpus, tmp_path, name, content, needle):
    p = corpus / name if content is None else tmp_path / name
    if content is not None:
        p.write_bytes(content)
    with pytest.raises(FlighttestError, match=needle) as exc:
        load_log(p)
    assert "\n" not in str(exc.value)


# -- damaged ULogs: pyulog's own output never reaches stdout ---------------------------------------------


def _damaged_ulog(corpus: Path, tmp_path: Path) -> Path:
    """The synthetic ULog with garbage inside its definitions: pyulog prints its damage report."""
    data = (corpus / "s.ulg").read_bytes()
    p = tmp_path / "damaged.ulg"
    p.write_bytes(data[:400] + b"\x00\x00\x00" + bytes(range(200)) + data[400:])
    return p


def test_a_damaged_ulog_keeps_json_clean_and_says_so_in_one_note(cli, corpus, tmp_path):
    p = _damaged_ulog(corpus, tmp_path)
    rc, out, err, _ = cli(["analyse", str(p), "--json", "--jobs", "1"])
    doc = json.loads(out)  # nothing but JSON on stdout (pyulog's print() went there)
    assert "corrupt" not in err.lower() or err.startswith("flighttest: error:")
    if rc == 0:
        notes = doc[0]["notes"]
        assert sum("ULog reports corruption" in n for n in notes) == 1 and err == ""
    else:
        assert doc[0]["error"] and err.count("\n") == 1


def test_a_ulog_pyulog_would_resync_for_minutes_is_refused_in_seconds(tmp_path):
    # every offset of the definitions reads as a 64 kB message pyulog steps over one byte at a time
    p = tmp_path / "endless.ulg"
    p.write_bytes(b"ULog\x01\x12\x35\x01" + struct.pack("<Q", 0) + b"\xff" * 300_000)
    t0 = time.monotonic()
    with pytest.raises(FlighttestError, match="damaged beyond") as exc:
        load_log(p)
    assert time.monotonic() - t0 < 10.0 and "\n" not in str(exc.value)


def test_a_ulog_with_text_parameters_loads_the_numeric_ones(corpus, tmp_path):
    from synthetic import PX4_PARAMS

    log = load_log(corpus / "s.ulg")
    assert set(log.params) == set(PX4_PARAMS)


# -- logs that never armed, motors all zero -----------------------------------------------------------------


@pytest.mark.parametrize("name", ["idle.tlog", "idle.ulg", "idle.bin"])
def test_a_log_whose_motors_never_ran_is_analysed(corpus, name):
    log = load_log(corpus / name)
    assert not any(c.startswith("motor_") for c in log.state.columns) and "motors" in log.missing
    a = analyse(log, "x500")
    json.dumps(a.summary(), default=str)


def test_report_and_compare_of_never_armed_logs_and_a_probe_folder(cli, corpus, tmp_path):
    probe = _write_folder(tmp_path / "probe", corpus / "idle.tlog")
    meta = json.loads((probe / "meta.json").read_text())
    (probe / "meta.json").write_text(json.dumps({**meta, "mission": "probe", "trajectory_meta": {"kind": "probe"}}))
    # the probe folder takes report through identify too (the PNGs cost seconds a log: one log here)
    rc, out, err, _ = cli(["report", str(probe), "--vehicle", "x500", "-o", "rep"])
    assert rc == 0 and "Traceback" not in err, err
    assert (cli.work / "rep" / "report.md").is_file()
    args = ["{d}/idle.tlog", "{d}/idle.ulg", "{d}/idle.bin", str(probe), "--vehicle", "x500"]
    rc, out, err, _ = cli(["compare", *args, "--json", "--allow-unequal"])  # the idle logs' heights differ
    assert rc == 0 and len(json.loads(out)) == 4, err


# -- log folders: every damaged side file is a note, never a crash -------------------------------------------

_DEEP = "[" * 100_000 + "]" * 100_000
SIDE_FILES: dict[str, tuple[str, bytes | str | None, str]] = {
    # case: (file, content (None: a FIFO; "DIR": a folder), what the note says)
    "setpoints-unix-text": ("setpoints.csv", "t_s,unix_s,d_m,phase\n1.0,abc,-10,stream\n2.0,{u2},-10,stream\n"
                            "3.0,{u3},-9,stream\n", "row(s) without a usable time"),
    "setpoints-d-text": ("setpoints.csv", "t_s,unix_s,d_m,phase\n1.0,{u1},ten,stream\n2.0,{u2},-10,stream\n"
                         "3.0,{u3},-9,stream\n", "not numbers in d_m"),
    "setpoints-binary": ("setpoints.csv", bytes(range(256)) * 8, "binary"),
    "setpoints-utf16": ("setpoints.csv", "t_s,unix_s\n1,2\n".encode("utf-16"), "UTF-16"),
    "setpoints-no-time": ("setpoints.csv", "a,b\n1,2\n3,4\n", "no time column"),
    "setpoints-ragged": ("setpoints.csv", 't_s,unix_s\n1,2\n"3,4,5,6,7\n', "setpoints.csv"),
    "setpoints-fifo": ("setpoints.csv", None, "regular file"),
    "setpoints-dir": ("setpoints.csv", "DIR", "folder"),
    "guard-margin-text": ("guard.csv", "t_s,unix_s,verdict,margin_mps,action\n1,{u1},ok,wide,none\n"
                          "2,{u2},ok,0.5,none\n3,{u3},ok,0.5,none\n", "not numbers in margin_mps"),
    "guard-unix-text": ("guard.csv", "t_s,unix_s,verdict,margin_mps\n1,now,ok,0.5\n2,later,ok,0.5\n3,{u3},ok,1\n",
                        "row(s) without a usable time"),
    "guard-latin1": ("guard.csv", "t_s,unix_s,reason\n1,2,café\n".encode("latin-1"), "not UTF-8"),
    "meta-list": ("meta.json", "[1, 2]", "not a JSON object (a list)"),
    "meta-string": ("meta.json", '"vertical"', "not a JSON object"),
    "meta-null": ("meta.json", "null", "not a JSON object"),
    "meta-deep": ("meta.json", _DEEP, "nested too deeply"),
    "meta-broken": ("meta.json", '{"mission": ', "not valid JSON"),
    "meta-binary": ("meta.json", bytes(range(256)), "binary"),
    "meta-fifo": ("meta.json", None, "regular file"),
    "meta-start-text": ("meta.json", '{"start_unix_s": "soon", "mission": "vertical"}', "start_unix_s"),
    "meta-start-bool": ("meta.json", '{"start_unix_s": true}', "start_unix_s"),
    "meta-start-inf": ("meta.json", '{"start_unix_s": Infinity}', "start_unix_s"),
    "meta-kinds": ("meta.json", '{"mission": [1], "vehicle": {"name": 5}, "trajectory": {"kind": [1, 2], "path": 5},'
                   ' "trajectory_meta": "vertical"}', ""),
    "meta-vehicle-odd": ("meta.json", '{"vehicle": "../../../etc/passwd\\u0000"}', "vehicle"),
    "summary-list": ("summary.json", "[]", "summary.json skipped"),
    "summary-outcome": ("summary.json", '{"outcome": 5, "descent_time_s": "long"}', ""),
    "trajectory-list": ("trajectory.json", "[1]", "trajectory.json skipped"),
    "trajectory-kind": ("trajectory.json", '{"kind": {"a": 1}}', ""),
    "params-list": ("params.json", "[1]", "params.json skipped"),
    "params-values": ("params.json", '{"params": {"A": "x", "B": true, "C": Infinity, "D": [1]}}', ""),
    "params-not-dict": ("params.json", '{"params": [1, 2]}', ""),
    "preflight-deep": ("preflight.json", _DEEP, "nested too deeply"),
    "events-types": ("events.jsonl", '[1]\n2\n"x"\nnull\n{"event": "phase", "phase": "stream", "t_s": 2.0}\n',
                     "4 line(s) that are not JSON objects"),
    "events-broken": ("events.jsonl", '{"event": \n{"event": "phase"}\n', "not JSON"),
    "events-deep": ("events.jsonl", _DEEP + "\n{}\n", "not JSON"),
    "events-binary": ("events.jsonl", bytes(range(256)), "binary"),
    "events-times": ("events.jsonl", '{"event": "abort", "t_s": "soon", "unix_s": "x"}\n'
                     '{"event": "phase", "phase": "stream", "t_s": true}\n', "t_s"),
}  # fmt: skip


def _damage(folder: Path, file: str, content) -> None:
    p = folder / file
    p.unlink()
    if content is None:
        os.mkfifo(p)
    elif content == "DIR":
        p.mkdir()
    elif isinstance(content, bytes):
        p.write_bytes(content)
    else:
        for k in (1, 2, 3):
            content = content.replace(f"{{u{k}}}", repr(UNIX0 + k))
        p.write_text(content)
    if file == "preflight.json":
        (folder / "params.json").unlink()  # read only when params.json has no parameters


@pytest.mark.parametrize("case", sorted(SIDE_FILES))
def test_a_damaged_side_file_is_a_note_not_a_crash(corpus, tmp_path, case):
    file, content, needle = SIDE_FILES[case]
    folder = shutil.copytree(corpus / "folder", tmp_path / "f")
    _damage(folder, file, content)
    t0 = time.monotonic()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = load_log(folder)
    with quiet_numerics():  # as the commands run it
        a = analyse(log)  # the vehicle from meta.json, where it has one
    assert time.monotonic() - t0 < 10.0
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)]
    notes = log.notes + a.notes
    assert all("\n" not in n for n in notes)
    if needle:
        assert any(needle in n for n in notes), notes
    json.dumps(a.summary(), default=str)
    for table in (log.setpoints, log.guard):
        if table is not None:
            assert np.isfinite(table["t_s"].to_numpy(float)).all()
    for ev in log.events:
        assert "t_s" not in ev or (isinstance(ev["t_s"], float | int) and not isinstance(ev["t_s"], bool))


@pytest.mark.parametrize("case", ["setpoints-unix-text", "events-types", "meta-kinds", "guard-margin-text"])
def test_the_commands_take_a_folder_with_a_damaged_side_file(cli, corpus, tmp_path, case):
    file, content, _ = SIDE_FILES[case]
    folder = shutil.copytree(corpus / "folder", tmp_path / "f")
    _damage(folder, file, content)
    for argv in (["analyse", str(folder), "--json", "--jobs", "1"], ["compare", str(folder), str(folder), "--json"]):
        rc, out, err, _ = cli(argv)
        assert rc == 0 and err == "", err
        assert isinstance(json.loads(out), list)
    if case == "setpoints-unix-text":  # the issue's own case: text in unix_s crashed report
        rc, out, err, _ = cli(["report", str(folder), "-o", "rep"])
        assert rc == 0 and "Traceback" not in err and (cli.work / "rep" / "report.md").is_file(), err


def test_a_killed_process_s_cut_last_lines_are_no_note(corpus, tmp_path):
    folder = shutil.copytree(corpus / "folder", tmp_path / "f")
    for name in ("setpoints.csv", "guard.csv", "events.jsonl"):
        text = (folder / name).read_text()
        (folder / name).write_text(text + text.splitlines()[1][:5])  # the next row cut after 5 characters
    assert load_log(folder).notes == []


# -- events are taken as finite numbers, not as written ---------------------------------------------------


@pytest.mark.parametrize(
    ("value", "expected"),
    [("2.5", 2.5), ("true", None), ("false", None), ("-3.0", None), ('"2.5"', None), ("Infinity", None),
     ("NaN", None), ("1e400", None), ("null", None), ("[2.5]", None), ("0", 0.0)],
)  # fmt: skip
def test_compare_takes_descent_times_only_as_finite_non_negative_numbers(cli, corpus, tmp_path, value, expected):
    folder = shutil.copytree(corpus / "folder", tmp_path / "f")
    text = (folder / "events.jsonl").read_text().replace('"descent_time_s": 2.5', f'"descent_time_s": {value}')
    (folder / "events.jsonl").write_text(text)
    log = load_log(folder)
    reached = next(e for e in log.events if e["event"] == "descent_reached")
    if expected is None and value != "null":
        assert "descent_time_s" not in reached and any("descent_time_s" in n for n in log.notes)
    from flighttest.analysis.compare import flown_descent

    flown = flown_descent(log.events)
    if expected is None:
        assert flown is None or flown.get("timed_by") == "analysis"  # the analysis may time it again itself
    rc, out, err, _ = cli(["compare", str(folder), "--json"])
    assert rc == 0, err
    dt = json.loads(out)[0]["descent_time_s"]
    assert dt is None or (isinstance(dt, float) and dt >= 0), dt
    if expected is not None and dt is not None:
        assert dt == pytest.approx(expected) or dt >= 0
    rc, out, err, _ = cli(["compare", str(folder)])
    assert rc == 0 and "−" not in out.replace("–", "") and "-3.00" not in out


# -- --json is one document with one entry per log, whatever failed ------------------------------------------


def test_json_lists_every_log_with_an_error_entry_for_the_failed_ones(cli, corpus, tmp_path):
    bad = tmp_path / "bad.tlog"
    bad.write_bytes(b"hello\n" * 100)
    for command in ("analyse", "compare"):
        rc, out, err, _ = cli([command, T, str(bad), "{d}/s.ulg", "--json", "--vehicle", "x500"])
        assert rc == 2
        doc = json.loads(out)
        assert [Path(e["log"]).name for e in doc] == ["s.tlog", "bad.tlog", "s.ulg"]
        assert "error" not in doc[0] and "error" not in doc[2]
        assert set(doc[1]) == {"log", "error"} and "not a MAVLink" in doc[1]["error"]
        assert err.count("\n") == 1 and "bad.tlog" in err
    rc, out, err, _ = cli(["analyse", str(bad), "--json"])
    assert rc == 2 and [set(e) for e in json.loads(out)] == [{"log", "error"}]


def test_text_output_does_not_take_log_content_for_markup(cli, corpus, tmp_path):
    folder = shutil.copytree(corpus / "folder", tmp_path / "f")
    meta = {"mission": "[bold]x[/nope]", "start_unix_s": "[/]", "trajectory": {"kind": "[/x]"}}
    (folder / "meta.json").write_text(json.dumps(meta))
    (folder / "trajectory.json").unlink()  # its kind would name the trajectory instead
    rc, out, err, _ = cli(["analyse", str(folder), "--jobs", "1"])
    assert rc == 0 and "Traceback" not in err, err
    assert "[/]" in out
    for wide in ([], ["--wide"]):
        rc, out, err, _ = cli(["compare", str(folder), T, "--vehicle", "x500", *wide])
        assert rc == 0 and "Traceback" not in err, err
        assert "[/x]" in out


# -- numbers: every threshold has a physical range -------------------------------------------------------------


def test_every_segmentation_and_fluctuation_setting_is_ranged():
    assert set(SEGMENT_RANGES) == set(SegmentConfig.__dataclass_fields__)
    assert set(FLUCTUATION_RANGES) == set(FluctuationConfig.__dataclass_fields__)
    for cls, ranges in ((SegmentConfig, SEGMENT_RANGES), (FluctuationConfig, FLUCTUATION_RANGES)):
        cls()  # the defaults are within their ranges
        for name, rng in ranges.items():
            for bad in (0.0, -1.0, 1e308, float("nan"), float("inf"), True, "1"):
                with pytest.raises(FlighttestError, match=name):
                    cls(**{name: bad})
            cls(**{name: rng.hi})  # the bound itself is allowed and computes (no overflow)


def test_the_largest_allowed_thresholds_still_analyse(corpus):
    log = load_log(corpus / "s.tlog")
    cfg = SegmentConfig(**{k: r.hi for k, r in SEGMENT_RANGES.items()})
    a = analyse(log, None, cfg)
    assert a.descents.empty
