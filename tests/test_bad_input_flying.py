"""Bad input to the flying side — ``flighttest fly``, ``flighttest campaign``, the link — as a table.

Every row runs ``flighttest.cli.main`` in this process, in text and in ``--json`` mode, and must
give exit code 2, one stderr line ``flighttest: error: ...`` (fd-level: MAVSDK's C++ log would show
here too), no traceback, stdout JSON with ``error`` under ``--json``, no folder left under the log
roots (``--log-dir``, ``$FLIGHTTEST_LOG_DIR``, ``./logs``) and nothing of a campaign on disk —
within a couple of seconds, before anything connects (no vehicle runs here)."""

from __future__ import annotations

import json
import socket
import time
import tomllib
from pathlib import Path

import pandas as pd
import pytest
import tomli_w

from flighttest.cli import main
from flighttest.flying.mission_scripts import MISSIONS, MISSIONS_DIR

GOOD_URL = "udpout://127.0.0.1:9"  # valid, never reached: every row is refused before it connects

# (id, extra fly arguments, what the error line must name); the target is "vertical" unless given
FLY_CASES: list[tuple[str, list[str], str]] = [
    # URLs: refused by the text, or by what the machine can tell at once (no MAVSDK, no 15 s wait)
    ("url-newline", ["--connect", "udpin://0.0.0.0:14540\n"], "control character"),
    ("url-tab", ["--connect", "udpout://127.0.0.1:14580\t"], "whitespace"),
    ("url-space", ["--connect", " udpout://127.0.0.1:14580"], "whitespace"),
    ("url-nul", ["--connect", "udpout://127.0.0.1:145\x0080"], "control character"),
    ("url-empty", ["--connect", ""], "--connect"),
    ("url-scheme", ["--connect", "bogus://x"], "expected"),
    ("url-no-port", ["--connect", "udpout://127.0.0.1"], "port"),
    ("url-port-0", ["--connect", "udpout://127.0.0.1:0"], "out of range"),
    ("url-port-65536", ["--connect", "udpout://127.0.0.1:65536"], "out of range"),
    ("url-tcp-99999", ["--connect", "tcpout://host:99999"], "out of range"),
    ("url-port-sci", ["--connect", "udpout://127.0.0.1:1e3"], "not a number"),
    ("url-bad-ipv4", ["--connect", "udpout://999.1.1.1:14540"], "IPv4"),
    ("url-short-ipv4", ["--connect", "udpout://1.2.3:14540"], "IPv4"),
    ("url-bad-host", ["--connect", "udpout://a..b:14540"], "host name"),
    ("url-dash-host", ["--connect", "tcpout://-x-:5760"], "host name"),
    ("url-ipv6", ["--connect", "udpout://[::1]:14540"], "IPv6"),
    ("url-udpin-name", ["--connect", "udpin://localhost:14540"], "local IPv4"),
    ("url-udpin-foreign", ["--connect", "udpin://192.0.2.1:14540"], "not an address of this machine"),
    ("url-unresolvable", ["--connect", "tcpout://nonexistent.invalid:5760"], "resolve"),
    ("url-serial-missing", ["--connect", "serial:///dev/does-not-exist:57600"], "No such file"),
    ("url-serial-no-baud", ["--connect", "serial:///dev/ttyUSB0"], "baud"),
    ("url-serial-baud-0", ["--connect", "serial:///dev/null:0"], "baud rate 0"),
    ("url-serial-two-slashes", ["--connect", "serial://dev/ttyUSB0:57600"], "/dev/ttyUSB0"),
    ("url-serial-not-a-device", ["--connect", "serial:///etc/hostname:57600"], "not a serial device"),
    ("url-long", ["--connect", "udpout://" + "a" * 10_000 + ":1"], "characters"),
    # numbers: a physical range each, before any file is read
    ("height-huge", ["--height", "1e308"], "--height"),
    ("height-nan", ["--height", "nan"], "--height"),
    ("height-inf", ["--height", "inf"], "--height"),
    ("height-negative", ["--height", "-5"], "--height"),
    ("height-zero", ["--height", "0"], "--height"),
    ("height-121", ["--height", "121"], "--height"),
    ("height-text", ["--height", "abc"], "--height"),
    ("min-alt-huge", ["--min-alt", "1e9"], "--min-alt"),
    ("min-alt-negative", ["--min-alt", "-1"], "--min-alt"),
    ("min-alt-nan", ["--min-alt", "nan"], "--min-alt"),
    ("min-alt-above-height", ["--height", "3", "--min-alt", "3"], "altitude floor"),
    ("geofence-zero", ["--geofence-radius", "0"], "--geofence-radius"),
    ("geofence-huge", ["--geofence-radius", "1e308"], "--geofence-radius"),
    ("wind-nan", ["--wind-ned", "nan", "0", "0"], "--wind-ned"),
    ("wind-inf", ["--wind-ned", "0", "inf", "0"], "--wind-ned"),
    ("wind-huge", ["--wind-ned", "0", "0", "1e9"], "--wind-ned"),
    ("wind-sci-negative", ["--wind-ned", "0", "0", "-1e3"], "--wind-ned"),
    ("wind-two-numbers", ["--wind-ned", "1", "2"], "--wind-ned"),
    ("sysid-0", ["--sysid", "0"], "--sysid"),
    ("sysid-256", ["--sysid", "256"], "--sysid"),
    ("sysid-float", ["--sysid", "1.5"], "--sysid"),
    ("max-descent-not-probe", ["--max-descent-speed", "1"], "probe"),
    ("max-descent-zero", ["--max-descent-speed", "0"], "--max-descent-speed"),
    ("max-descent-nan", ["--max-descent-speed", "nan"], "--max-descent-speed"),
    ("max-descent-huge", ["--max-descent-speed", "1e308"], "--max-descent-speed"),
    ("unknown-option", ["--hieght", "5"], "unrecognized"),
    # files and folders
    ("vehicle-unknown", ["--vehicle", "nope"], "nope"),
    ("config-missing", ["--config", "{tmp}/missing.toml"], "missing.toml"),
    ("log-dir-empty", ["--log-dir", ""], "--log-dir"),
    ("log-dir-is-file", ["--log-dir", "{tmp}/a_file"], "is a file"),
    ("log-dir-under-file", ["--log-dir", "{tmp}/a_file/logs"], "is a file"),
    ("trajectory-missing", ["@{tmp}/missing.csv"], "not found"),
    ("trajectory-endless", ["@{tmp}/endless.csv"], "endless"),
]

# (id, campaign arguments) — every one refused before the fake starts or anything is written
CAMPAIGN_CASES: list[tuple[str, list[str], str]] = [
    ("no-terminal", ["--sim"], "--yes"),
    ("stale-0", ["--sim", "--yes", "--stale-periods", "0"], "--stale-periods"),
    ("stale-huge", ["--sim", "--yes", "--stale-periods", "1e9"], "--stale-periods"),
    ("stale-nan", ["--sim", "--yes", "--stale-periods", "nan"], "--stale-periods"),
    ("onset-zero", ["--sim", "--yes", "--truth-onset", "0"], "--truth-onset"),
    ("onset-huge", ["--sim", "--yes", "--truth-onset", "1e308"], "--truth-onset"),
    ("sim-wind-nan", ["--sim", "--yes", "--sim-wind", "0", "nan", "0"], "--sim-wind"),
    ("sim-wind-huge", ["--sim", "--yes", "--sim-wind", "0", "0", "-1e5"], "--sim-wind"),
    ("sim-seed-negative", ["--sim", "--yes", "--sim-seed", "-1"], "--sim-seed"),
    ("sim-param-unknown", ["--sim", "--yes", "--sim-param", "BOGUS=1"], "BOGUS"),
    ("sim-param-text", ["--sim", "--yes", "--sim-param", "MPC_LAND_SPEED=fast"], "MPC_LAND_SPEED"),
    ("sim-param-inf", ["--sim", "--yes", "--sim-param", "MPC_LAND_SPEED=inf"], "MPC_LAND_SPEED"),
    ("sim-param-int-float", ["--sim", "--yes", "--sim-param", "COM_OBL_RC_ACT=1.5"], "whole number"),
    ("sim-param-no-equals", ["--sim", "--yes", "--sim-param", "MPC_LAND_SPEED"], "NAME=NUMBER"),
    ("connect-newline", ["--connect", "udpin://0.0.0.0:14540\n", "--vehicle", "x500", "--yes"], "control"),
    ("connect-serial-missing", ["--connect", "serial:///dev/nope:57600", "--vehicle", "x500", "--yes"], "No such"),
    ("connect-port-range", ["--connect", "tcpout://host:99999", "--vehicle", "x500", "--yes"], "out of range"),
    ("connect-no-vehicle", ["--connect", GOOD_URL, "--yes"], "--vehicle"),
    ("connect-sim-option", ["--connect", GOOD_URL, "--vehicle", "x500", "--yes", "--truth-onset", "1"], "--sim"),
    ("vehicle-unknown", ["--sim", "--yes", "--vehicle", "nope"], "nope"),
    ("output-empty", ["--sim", "--yes", "-o", ""], "-o"),
    ("output-is-file", ["--sim", "--yes", "-o", "{tmp}/a_file"], "a_file"),
    ("output-under-file", ["--sim", "--yes", "-o", "{tmp}/a_file/c"], "is a file"),
]


@pytest.fixture(scope="module", autouse=True)
def _imported():
    """Import what the commands import once, outside the timed runs (the time limits are for the
    checks, not for loading the planners' libraries)."""
    from flighttest.cli import build_parser
    from flighttest.flying.mission_scripts import load_mission_module
    from flighttest.flying.runner import fly  # noqa: F401

    build_parser()
    load_mission_module("vertical")


@pytest.fixture
def sandbox(tmp_path, monkeypatch):
    """A tmp folder as the current folder and ``$FLIGHTTEST_LOG_DIR``; what it holds before the run."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("FLIGHTTEST_LOG_DIR", str(tmp_path / "envlogs"))
    (tmp_path / "a_file").write_text("not a folder\n")
    _endless_trajectory(tmp_path / "endless")
    return tmp_path


def _endless_trajectory(stem: Path) -> None:
    """A trajectory file whose second row is at t = 1e308 s: still, at the start point."""
    cols = ["t_s", "n_m", "e_m", "d_m", "vn_mps", "ve_mps", "vd_mps", "an_mps2", "ae_mps2", "ad_mps2", "yaw_deg"]
    rows = ["0," + ",".join(["0"] * 10), "1e308," + ",".join(["0"] * 10)]
    stem.with_suffix(".csv").write_text(",".join(cols) + "\n" + "\n".join(rows) + "\n")
    meta = {"format": "flighttest-trajectory/1", "kind": "vertical", "vehicle": "x500", "problem": {},
            "status": "closed_form", "t_f_s": 1e308}  # fmt: skip
    stem.with_suffix(".json").write_text(json.dumps(meta))


def _contents(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def _run(argv: list[str], capfd) -> tuple[int, str, str, float]:
    t0 = time.monotonic()
    rc = main(argv)
    took = time.monotonic() - t0
    out, err = capfd.readouterr()
    return rc, out, err, took


def _check(rc: int, out: str, err: str, took: float, as_json: bool, needle: str, limit_s: float = 2.5) -> None:
    assert rc == 2, (rc, out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("flighttest: error:"), err
    assert needle.lower() in lines[0].lower(), lines[0]
    assert "Traceback" not in err + out
    if as_json:
        doc = json.loads(out)  # stdout is one JSON document, nothing else
        assert isinstance(doc, dict) and doc.get("error"), out
    else:
        assert out.strip() == "", out
    assert took < limit_s, f"took {took:.1f} s"


def _fly_argv(extra: list[str], tmp: Path, as_json: bool) -> list[str]:
    extra = [a.replace("{tmp}", str(tmp)) for a in extra]
    target = "vertical"
    if extra and extra[0].startswith("@"):
        target, extra = extra[0][1:], extra[1:]
    base = {"--connect": GOOD_URL, "--vehicle": "x500", "--log-dir": str(tmp / "logs")}
    argv = ["fly", target]
    for key, value in base.items():
        if key not in extra:
            argv += [key, value]
    return argv + extra + ["--yes"] + (["--json"] if as_json else [])


@pytest.mark.parametrize("as_json", [False, True], ids=["text", "json"])
@pytest.mark.parametrize(("case", "extra", "needle"), FLY_CASES, ids=[c[0] for c in FLY_CASES])
def test_fly_refuses_bad_input_before_connecting(sandbox, capfd, case, extra, needle, as_json):
    before = _contents(sandbox)
    rc, out, err, took = _run(_fly_argv(extra, sandbox, as_json), capfd)
    # a host name that cannot resolve may take the resolver's time (bounded at 3 s) on a machine offline
    _check(rc, out, err, took, as_json, needle, limit_s=4.0 if case == "url-unresolvable" else 2.5)
    assert _contents(sandbox) == before, "a refused fly left something behind"


@pytest.mark.parametrize("as_json", [False, True], ids=["text", "json"])
@pytest.mark.parametrize(("case", "extra", "needle"), CAMPAIGN_CASES, ids=[c[0] for c in CAMPAIGN_CASES])
def test_campaign_refuses_bad_input_before_writing_anything(sandbox, capfd, case, extra, needle, as_json):
    extra = [a.replace("{tmp}", str(sandbox)) for a in extra]
    argv = ["campaign", *extra]
    if "-o" not in extra:
        argv += ["-o", str(sandbox / "campaign")]
    before = _contents(sandbox)
    rc, out, err, took = _run(argv + (["--json"] if as_json else []), capfd)
    _check(rc, out, err, took, as_json, needle)
    assert _contents(sandbox) == before, "a refused campaign wrote something (config/?)"


# -- refused after MAVSDK started: still one line and no folder --------------------------------------


def _quick_config(tmp: Path) -> Path:
    cfg = tomllib.loads((MISSIONS_DIR / f"{MISSIONS['vertical']}.toml").read_text())
    cfg["flight"]["connect_timeout_s"] = 1.0
    path = tmp / "quick.toml"
    path.write_text(tomli_w.dumps(cfg))
    return path


@pytest.mark.parametrize("as_json", [False, True], ids=["text", "json"])
def test_nobody_answering_is_one_line_and_leaves_no_log_folder(sandbox, capfd, as_json):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as silent:  # a port that hears and never answers
        silent.bind(("127.0.0.1", 0))
        url = f"udpout://127.0.0.1:{silent.getsockname()[1]}"
        cfg = _quick_config(sandbox)
        before = _contents(sandbox)
        argv = ["fly", "vertical", "--connect", url, "--vehicle", "x500", "--config", str(cfg), "--yes",
                "--log-dir", str(sandbox / "logs")] + (["--json"] if as_json else [])  # fmt: skip
        rc, out, err, took = _run(argv, capfd)
    assert rc == 2 and err.count("\n") == 1 and err.startswith("flighttest: error: no autopilot answered"), err
    assert "MAVSDK version" not in err and "[Info" not in err  # MAVSDK's own log stays off stderr
    if as_json:
        s = json.loads(out)
        assert s["outcome"] == "refused" and s["log_dir"] is None and "no autopilot" in s["error"]
    assert _contents(sandbox) == before  # no logs/ folder with an empty .tlog
    assert took < 6.0


def test_a_device_mavsdk_cannot_open_is_one_line_with_mavsdk_s_reason(sandbox, capfd):
    before = _contents(sandbox)
    argv = ["fly", "vertical", "--connect", "serial:///dev/null:57600", "--vehicle", "x500", "--yes",
            "--log-dir", str(sandbox / "logs")]  # fmt: skip
    rc, out, err, took = _run(argv, capfd)
    assert rc == 2 and err.count("\n") == 1, err
    assert err.startswith("flighttest: error: cannot open serial:///dev/null:57600") and "MAVSDK:" in err, err
    assert _contents(sandbox) == before
    assert took < 5.0


# -- a huge duration cannot crash fly() whatever the loader lets through ------------------------------


def test_the_mission_runner_refuses_an_endless_trajectory_before_resampling_it(tmp_path):
    from flighttest.flying.missions_config import MissionConfig
    from flighttest.flying.runner import FlyRequest, MissionRunner
    from flighttest.model.profiles import load_profile
    from flighttest.model.trajectory import REQUIRED_COLUMNS, Trajectory

    # built around the loader (which refuses it too): whatever reaches fly(), the runner must not crash
    df = pd.DataFrame({c: [0.0, 0.0] for c in REQUIRED_COLUMNS})
    df["t_s"] = [0.0, 1e308]
    traj = Trajectory(df, {"kind": "vertical"})
    req = FlyRequest(connect=GOOD_URL, profile=load_profile("x500"), config=MissionConfig("file"), trajectory=traj,
                     mission_name="endless", log_root=tmp_path / "logs")  # fmt: skip
    with pytest.raises(Exception) as info:
        MissionRunner(req)
    assert "trajectory lasts" in str(info.value) and "at most" in str(info.value)
    assert not (tmp_path / "logs").exists()


@pytest.mark.parametrize(("url", "use"), [("udp://:14540", "udpin://0.0.0.0:14540"),
                                          ("udp://0.0.0.0:14540", "udpin://0.0.0.0:14540"),
                                          ("tcp://127.0.0.1:5760", "tcpout://127.0.0.1:5760")])  # fmt: skip
def test_mavsdks_old_url_spellings_are_refused_at_once_with_the_one_to_use(url, use):
    from flighttest.flying.link import check_url

    with pytest.raises(Exception) as info:
        check_url(url)
    assert str(info.value).endswith(f"MAVSDK's old spelling: use {use}")


def test_check_url_keeps_every_documented_url():
    from flighttest.flying.link import check_url

    for url in ("udpin://0.0.0.0:14540", "udpin://127.0.0.1:14540", "udpout://127.0.0.1:14580",
                "udpout://localhost:14580", "tcpout://192.168.1.10:5760", "tcpin://0.0.0.0:5760",
                "serial:///dev/ttyAMA0:921600", "serial:///dev/ttyUSB0:57600",
                "serial_flowcontrol:///dev/ttyTHS1:921600", "udpout://my-laptop.local:14550"):  # fmt: skip
        assert check_url(url) == url

