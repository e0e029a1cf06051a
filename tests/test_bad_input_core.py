"""Bad input never reaches a vehicle, a profile or a traceback (issue 12): the input layer.

A table-driven corpus of hand-written bad inputs run through ``flighttest.cli.main`` in-process:
every one must exit with code 2, print exactly one ``flighttest: error:`` line on stderr, no
traceback, nothing on stdout (with ``--json``: JSON with an ``error``), and write nothing. Then the
loaders one by one (profiles, mission configs, trajectories, campaign records, the preflight's
trajectory checks), and property tests with hypothesis over random profiles and trajectories.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flighttest import inputs as ip
from flighttest.campaign.state import CampaignState
from flighttest.cli import main
from flighttest.errors import FlighttestError
from flighttest.flying import preflight as pf
from flighttest.flying.missions_config import load_mission_config, mission_config_from_dict
from flighttest.model.profiles import SHIPPED_DIR, load_profile, profile_from_dict
from flighttest.model.trajectory import FORMAT, MAX_ROWS, Trajectory
from flighttest.planner.export import vertical_trajectory
from flighttest.planner.vertical import plan_vertical
from flighttest.tomlfile import read_toml

X500_TOML = (SHIPPED_DIR / "x500.toml").read_text(encoding="utf-8")
VERTICAL_TOML = (Path(__file__).parents[1] / "missions" / "vertical_descent.toml").read_text(encoding="utf-8")
X500 = load_profile("x500")
FLY = ["fly", "vertical", "--connect", "udpout://127.0.0.1:9", "--yes"]
LONG = "n" * 300


def _x500_with(**fields: str) -> str:
    """The x500 profile with top-level fields replaced (values as TOML text)."""
    lines = X500_TOML.splitlines()
    for key, value in fields.items():
        lines = [f"{key} = {value}" if ln.split("=")[0].strip() == key else ln for ln in lines]
        if not any(ln.split("=")[0].strip() == key for ln in lines):
            lines.insert(1, f"{key} = {value}")
    return "\n".join(lines) + "\n"


def _vertical_with(section: str, line: str) -> str:
    return VERTICAL_TOML.replace(f"[{section}]\n", f"[{section}]\n{line}\n", 1)


# -- the corpus folder: damaged files of every kind --------------------------------------------------

BAD_TOML_BYTES = {
    "binary": bytes(range(256)) * 4,
    "utf16": X500_TOML.encode("utf-16"),
    "utf16le": X500_TOML.encode("utf-16-le"),
    "latin1": X500_TOML.replace("PX4 SITL", "PX4 SITL café").encode("latin-1"),
    "deep": ("a = " + "[" * 5000 + "]" * 5000 + "\n").encode(),
    "deeptable": ("a = " + "{b = " * 3000 + "1" + "}" * 3000 + "\n").encode(),
    "bigint": ("mass_kg = 1" + "0" * 5000 + "\n").encode(),
    "huge": ("# " + "x" * 1_100_000 + "\n").encode(),
    "empty": b"",
    "density": _x500_with(air_density_kgpm3="1e300").encode(),
    "vh": _x500_with(mass_kg="500.0", n_rotors="3", rotor_diameter_m="0.01", max_thrust_per_rotor_n="5000.0").encode(),
    "twr": _x500_with(max_thrust_per_rotor_n="5000.0").encode(),
    "mass_str": _x500_with(mass_kg='"2.0"').encode(),
    "mass_nan": _x500_with(mass_kg="nan").encode(),
    "mass_huge": _x500_with(mass_kg="1e308").encode(),
    "rotors_bool": _x500_with(n_rotors="true").encode(),
    "rotors_many": _x500_with(n_rotors="1000000").encode(),
    "name_slash": _x500_with(name='"../evil"').encode(),
    "name_ctrl": _x500_with(name='"x\\u0007"').encode(),
    "speed_huge": _x500_with(max_speed_mps="1e308").encode(),
    "vrs_list": (X500_TOML.split("\n[drag]")[0] + "\nvrs = [1, 2]\n").encode(),
    "wallow_huge": (X500_TOML + "w_allow_mps = 1e308\n").encode(),
}

BAD_CONFIG_BYTES = {
    "cfg_binary": bytes(range(256)) * 4,
    "cfg_utf16": VERTICAL_TOML.encode("utf-16"),
    "cfg_latin1": VERTICAL_TOML.replace("baseline", "baseline café").encode("latin-1"),
    "cfg_deep": ("mission = " + "[" * 5000 + "]" * 5000 + "\n").encode(),
    "cfg_plan_string": VERTICAL_TOML.replace("descent_m = 3.0", "descent_m = '3.0'").encode(),
    "cfg_plan_unknown": _vertical_with("plan", "descent = 3.0").encode(),
    "cfg_plan_list": VERTICAL_TOML.replace("descent_m = 3.0", "descent_m = [3.0]").encode(),
    "cfg_plan_huge": VERTICAL_TOML.replace("descent_m = 3.0", "descent_m = 1e9").encode(),
    "cfg_plan_bool": VERTICAL_TOML.replace("accel_fraction = 0.15", "accel_fraction = true").encode(),
    "cfg_height": VERTICAL_TOML.replace("start_height_m = 5.0", "start_height_m = 1e308").encode(),
    "cfg_geofence": VERTICAL_TOML.replace("geofence_radius_m = 10.0", "geofence_radius_m = inf").encode(),
    "cfg_debounce": VERTICAL_TOML.replace("debounce_samples = 3", "debounce_samples = 1000000000").encode(),
    "cfg_stale": VERTICAL_TOML.replace("stale_after_s = 0.25", "stale_periods = 1e300").encode(),
    "cfg_mission": VERTICAL_TOML.replace('mission = "vertical"', 'mission = ["vertical"]').encode(),
    "cfg_table": b'mission = "vertical"\nflight = 5\n',
}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("corpus")
    for name, data in {**BAD_TOML_BYTES, **BAD_CONFIG_BYTES}.items():
        (d / f"{name}.toml").write_bytes(data)
    os.mkfifo(d / "fifo.toml")
    os.mkfifo(d / "fifo.csv")
    (d / "dir.toml").mkdir()
    (d / "adir").mkdir()
    (d / "folder.csv").mkdir()
    (d / "afile").write_text("a file, not a folder\n")
    good = pd.DataFrame({"vn": [0.0, 1.0], "ve": [0.0, 0.0], "vd": [1.0, -0.5], "qw": [1.0, 1.0], "qx": [0.0, 0.0],
                         "qy": [0.0, 0.0], "qz": [0.0, 0.0]})  # fmt: skip
    good.to_csv(d / "states.csv", index=False)
    good.assign(vn=[1e308, 1e308], ve=[1e308, 1e308], vd=[1e308, 1e308]).to_csv(d / "fast.csv", index=False)
    good.assign(qw=[1e308, 1.0]).to_csv(d / "bigquat.csv", index=False)
    (d / "binary.csv").write_bytes(bytes(range(256)) * 8)
    (d / "utf16.csv").write_bytes((d / "states.csv").read_text().encode("utf-16"))
    _write_trajectory_corpus(d)
    return d


def _good_vertical() -> Trajectory:
    return vertical_trajectory(plan_vertical(X500, 3.0, accel_fraction=0.5), "x500", X500.mass_kg)


def _hover(t_f: float, rate_hz: float = 10.0) -> Trajectory:
    t = np.arange(0.0, t_f + 1e-9, 1.0 / rate_hz)
    z = np.zeros_like(t)
    cols = {c: z for c in ("n_m", "e_m", "d_m", "vn_mps", "ve_mps", "vd_mps", "an_mps2", "ae_mps2", "ad_mps2",
                           "yaw_deg")}  # fmt: skip
    meta = {"format": FORMAT, "kind": "vertical", "vehicle": "x500", "problem": {}, "status": "closed_form",
            "t_f_s": float(t[-1])}  # fmt: skip
    return Trajectory(df=pd.DataFrame({"t_s": t, **cols}), meta=meta)


def _step3m(tr: Trajectory) -> Trajectory:
    """A 3 m position step in 10 ms with zero velocity, the rest untouched (issue 12)."""
    df = tr.df.copy()
    i = len(df) // 2
    df.loc[i:, "d_m"] = df.loc[i:, "d_m"] + 3.0
    return Trajectory(df=df, meta=dict(tr.meta))


def _edited(tr: Trajectory, **changes) -> Trajectory:
    df = tr.df.copy()
    meta = dict(tr.meta)
    for key, value in changes.items():
        if key.startswith("meta_"):
            meta[key.removeprefix("meta_")] = value
        else:
            col, row = key.rsplit("__", 1)
            df.loc[int(row), col] = value
    return Trajectory(df=df, meta=meta)


def _drifting() -> Trajectory:
    """Each step 15 mm off (under the per-step tolerance), 1.5 m after 100 steps."""
    tr = _hover(10.0)
    tr.df["n_m"] = 0.015 * np.arange(len(tr.df))
    return tr


def _consistent_fast(speed_mps: float) -> Trajectory:
    tr = _hover(2.0)
    tr.df["ve_mps"] = speed_mps
    tr.df["e_m"] = speed_mps * tr.df["t_s"]
    return tr


BAD_TRAJECTORIES = {
    "step3m": lambda: _step3m(_good_vertical()),
    "step3m_hover": lambda: _step3m(_hover(2.0, rate_hz=100.0)),
    "vel_jump": lambda: _edited(_good_vertical(), vd_mps__40=3.0),
    "t_huge": lambda: _edited(_good_vertical(), t_s__100=1e308),
    "t_last_huge": lambda: _edited(_hover(2.0), t_s__20=1e308),
    "long": lambda: _hover(601.0, rate_hz=1.0),
    "deep_d": lambda: _consistent_descent(200.0),
    "fast": lambda: _consistent_fast(150.0),
    "accel_huge": lambda: _edited(_hover(2.0), ad_mps2__5=1e6),
    "drift": _drifting,
    "tf_string": lambda: _edited(_good_vertical(), meta_t_f_s="3.5"),
    "tf_wrong": lambda: _edited(_good_vertical(), meta_t_f_s=1e308),
    "problem_list": lambda: _edited(_good_vertical(), meta_problem=[1, 2]),
    "vehicle_number": lambda: _edited(_good_vertical(), meta_vehicle=5),
    "yaw_huge": lambda: _edited(_good_vertical(), yaw_deg__3=1e300),
}


def _consistent_descent(depth_m: float) -> Trajectory:
    tr = _hover(depth_m, rate_hz=1.0)
    tr.df["vd_mps"] = 1.0
    tr.df["d_m"] = tr.df["t_s"]
    return tr


def _write_trajectory_corpus(d: Path) -> None:
    for name, make in BAD_TRAJECTORIES.items():
        make().save(d / f"traj_{name}")
    good = _good_vertical()
    good.save(d / "traj_good")
    for name, data in (("bin", bytes(range(256)) * 8), ("utf16", (d / "traj_good.csv").read_text().encode("utf-16"))):
        (d / f"traj_csv{name}.csv").write_bytes(data)
        (d / f"traj_csv{name}.json").write_bytes((d / "traj_good.json").read_bytes())
        (d / f"traj_meta{name}.csv").write_bytes((d / "traj_good.csv").read_bytes())
        (d / f"traj_meta{name}.json").write_bytes(data)
    (d / "traj_metadeep.csv").write_bytes((d / "traj_good.csv").read_bytes())
    (d / "traj_metadeep.json").write_text('{"a": ' + "[" * 100_000 + "]" * 100_000 + "}")
    (d / "traj_metalist.csv").write_bytes((d / "traj_good.csv").read_bytes())
    (d / "traj_metalist.json").write_text("[1, 2, 3]")
    (d / "traj_nojson.csv").write_bytes((d / "traj_good.csv").read_bytes())
    text = (d / "traj_good.csv").read_text().splitlines()
    (d / "traj_bool.csv").write_text("\n".join([text[0]] + [",".join(["true"] * len(text[0].split(",")))] * 3) + "\n")
    (d / "traj_bool.json").write_bytes((d / "traj_good.json").read_bytes())


# -- running the command line -------------------------------------------------------------------------


def _tree(*roots: Path) -> set[str]:
    out = set()
    for r in roots:
        for dirpath, dirnames, filenames in os.walk(r):
            out.update(os.path.join(dirpath, n) for n in dirnames + filenames)
    return out


@pytest.fixture
def cli(tmp_path, monkeypatch, corpus, capsys):
    """``run(argv) -> (rc, stdout, stderr)`` in a clean working folder with no user profiles."""
    work = tmp_path / "work"
    work.mkdir()
    (tmp_path / "vehicles").mkdir()
    monkeypatch.chdir(work)
    monkeypatch.setenv("FLIGHTTEST_VEHICLES", str(tmp_path / "vehicles"))
    monkeypatch.setenv("HOME", str(tmp_path))

    def run(argv: list[str]) -> tuple[int, str, str]:
        capsys.readouterr()
        rc = main([a.replace("{d}", str(corpus)) for a in argv])
        out, err = capsys.readouterr()
        return rc, out, err

    run.work = work  # type: ignore[attr-defined]
    return run


def _assert_refused(cli, corpus, argv: list[str], needle: str | None = None) -> str:
    before = _tree(cli.work, corpus)
    rc, out, err = cli(argv)
    as_json = "--json" in argv
    assert rc == 2, (argv, rc, out, err)
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("flighttest: error:"), err
    if needle:
        assert needle in lines[0], lines[0]
    if as_json:
        assert "error" in json.loads(out), out
    else:
        assert out == "", out
    assert _tree(cli.work, corpus) == before, "a refused command wrote something"
    return lines[0]


CLI_CASES = [
    # plan: every number has a physical range, checked before anything is computed
    (["plan", "vertical", "--height", "1e9"], "--height"),
    (["plan", "vertical", "--height", "1e5"], "≤ 120 m"),
    (["plan", "vertical", "--height", "0"], "--height"),
    (["plan", "vertical", "--height", "-5"], "--height"),
    (["plan", "vertical", "--height", "nan"], "finite"),
    (["plan", "vertical", "--height", "inf"], "finite"),
    (["plan", "vertical", "--height", "abc"], "--height"),
    (["plan", "vertical", "--height", "1e308", "--json"], "--height"),
    (["plan", "vertical", "--height", ""], "--height"),
    (["plan", "vertical", "--w-allow", "0"], "--w-allow"),
    (["plan", "vertical", "--w-allow", "1e308"], "--w-allow"),
    (["plan", "vertical", "--margin", "-1"], "--margin"),
    (["plan", "vertical", "--margin", "-1e-1"], "--margin"),
    (["plan", "vertical", "--accel-fraction", "2"], "--accel-fraction"),
    (["plan", "vertical", "--accel-fraction", "0"], "--accel-fraction"),
    (["plan", "probe", "--speed-step", "1e-300"], "--speed-step"),
    (["plan", "probe", "--speed-step", "0"], "--speed-step"),
    (["plan", "probe", "--duration", "1e9"], "--duration"),
    (["plan", "probe", "--omega0", "1e308"], "--omega0"),
    (["plan", "probe", "--amplitude", "1e9"], "--amplitude"),
    (["plan", "probe", "--ramp", "-1"], "--ramp"),
    (["plan", "probe", "--max-descent-speed", "1e308"], "--max-descent-speed"),
    (["plan", "probe", "--start-alt", "1e308"], "--start-alt"),
    (["plan", "probe", "--floor", "-1"], "--floor"),
    (["plan", "probe", "--amplitude", "9", "--start-alt", "10", "--floor", "2"], "altitude floor"),
    (["plan", "probe", "--json", "--duration", "-1e-1"], "--duration"),
    (["plan", "helix", "--height", "1e9"], "--height"),
    (["plan", "helix", "--radius", "0"], "--radius"),
    (["plan", "helix", "--radius", "1e308"], "--radius"),
    (["plan", "helix", "--paper", "--tilt-max", "90"], "--tilt-max"),
    (["plan", "helix", "--paper", "--rate-max", "1e308"], "--rate-max"),
    (["plan", "helix", "--paper", "--thrust-fraction", "1.5"], "--thrust-fraction"),
    (["plan", "helix", "--paper", "--wind", "1e308", "0", "0"], "--wind"),
    (["plan", "helix", "--paper", "--end", "1e308", "0"], "--end"),
    (["plan", "helix", "--paper", "--end", "5", "0"], "radius"),
    # the paper's bounds do not apply to the helix `fly helix` flies: its [plan] sets them
    (["plan", "helix", "--end", "1", "0"], "only with --paper"),
    (["plan", "helix", "--json", "--tilt-max", "30", "--margin", "0.2"], "--tilt-max, --margin: only with --paper"),
    (["plan", "helix", "--intervals", "5"], "--intervals"),
    (["plan", "helix", "--intervals", "1000000"], "--intervals"),
    (["plan", "helix", "--intervals", "2.5"], "--intervals"),
    (["plan", "planar", "--height", "1e9"], "--height"),
    (["plan", "planar", "--phi-bound", "1e308"], "--phi-bound"),
    (["plan", "planar", "--phi-bound", "abc"], "--phi-bound"),
    (["plan", "planar", "--f-min", "5", "--f-max", "1"], "--f-min"),
    (["plan", "planar", "--v-bound", "0"], "--v-bound"),
    (["plan", "planar", "--omega-max", "inf"], "--omega-max"),
    (["plan", "planar", "--case", "9"], "--case"),
    (["plan", "planar", "--wind", "nan", "0"], "--wind"),
    (["plan", "verticle"], "invalid choice"),
    (["plan", "vertical", "--bogus"], "unrecognized"),
    (["plan", "vertical", "--json", "--bogus"], "unrecognized"),
    # plan: outputs checked before the plan is computed
    (["plan", "vertical", "-o", ""], "empty"),
    (["plan", "vertical", "-o", "", "--json"], "empty"),
    (["plan", "vertical", "-o", "{d}/afile/x"], "afile"),
    (["plan", "vertical", "-o", "{d}/adir/"], "folder"),
    (["plan", "vertical", "-o", "{d}/folder"], "is a folder"),
    (["plan", "vertical", "-o", LONG], "too long"),
    (["plan", "vertical", "-o", "x\nname"], "control character"),
    (["plan", "vertical", "--plot", "chart.jpg"], ".png"),
    (["plan", "vertical", "--plot", ""], "empty"),
    (["plan", "vertical", "--plot", "{d}/afile/p.png"], "afile"),
    (["plan", "probe", "--plot", "{d}/adir"], "--plot"),
    # region check: bounded speeds, finite math, files and outputs
    (["region", "check", "--vehicle", "x500", "--v-ned", "1e308", "1e308", "1e308", "--quat", "1", "0", "0", "0"],
     "--v-ned"),
    (["region", "check", "--vehicle", "x500", "--v-ned", "1e308", "1e308", "1e308", "--quat", "1", "0", "0", "0",
      "--json"], "--v-ned"),
    (["region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "1", "--quat", "1e308", "0", "0", "0"], "--quat"),
    (["region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "1", "--quat", "1", "0", "0", "0", "--wind-ned",
      "inf", "0", "0"], "--wind-ned"),
    (["region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "1", "--quat", "1", "0", "0", "0", "--w-allow",
      "-1"], "--w-allow"),
    (["region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "1", "--quat", "1", "0", "0", "0", "--w-allow",
      "1e308"], "--w-allow"),
    (["region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "1", "--quat", "1", "0", "0", "0", "--margin",
      "1e308"], "--margin"),
    (["region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "--quat", "1", "0", "0", "0"], "--v-ned"),
    (["region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "1", "--quat", "0", "0", "0", "0"], "unit"),
    (["region", "check", "--vehicle", "x500", "--csv", ""], "empty"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/missing.csv"], "not found"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/adir"], "folder"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/fifo.csv"], "regular file"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/fast.csv"], "vn"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/fast.csv", "--json"], "vn"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/bigquat.csv"], "qw"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/binary.csv"], "binary.csv"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/utf16.csv"], "utf16.csv"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/states.csv", "-o", ""], "empty"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/states.csv", "-o", "{d}/afile/x.csv"], "afile"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/states.csv", "-o", "{d}/adir"], "folder"),
    (["region", "check", "--vehicle", "x500", "--csv", "{d}/states.csv", "-o", LONG], "too long"),
    (["region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "1", "--quat", "1", "0", "0", "0", "-o", "x.csv"],
     "--csv"),
    # region chart: the output path before drawing
    (["region", "chart", "--vehicle", "x500", "-o", ""], "empty"),
    (["region", "chart", "--vehicle", "x500", "-o", "chart.jpg"], ".png"),
    (["region", "chart", "--vehicle", "x500", "-o", "chart"], ".png"),
    (["region", "chart", "--vehicle", "x500", "-o", "{d}/adir"], "-o"),
    (["region", "chart", "--vehicle", "x500", "-o", "{d}/adir.png/"], "folder"),
    (["region", "chart", "--vehicle", "x500", "-o", "{d}/afile/c.png"], "afile"),
    (["region", "chart", "--vehicle", "x500", "-o", LONG + ".png"], "too long"),
    (["region", "chart", "--vehicle", "x500", "-o", "/proc/version/c.png"], "-o"),
    # sim: the fake's numbers and its truth log, before it binds a port
    (["sim", "--physics-hz", "1e308"], "--physics-hz"),
    (["sim", "--telemetry-hz", "0"], "--telemetry-hz"),
    (["sim", "--gust-mps", "1e308"], "--gust-mps"),
    (["sim", "--gust-tau-s", "0"], "--gust-tau-s"),
    (["sim", "--truth-drag", "1e308,0"], "--truth-drag"),
    (["sim", "--truth-drag", "1,2,3"], "--truth-drag"),
    (["sim", "--truth-onset", "1e308"], "--truth-onset"),
    (["sim", "--seed", "-1"], "--seed"),
    (["sim", "--wind-ned", "1e308", "0", "0"], "--wind-ned"),
    (["sim", "--truth-log", "{d}/afile/t.csv"], "afile"),
    (["sim", "--truth-log", "{d}/adir"], "folder"),
    # fly: numbers and files read before anything connects
    ([*FLY, "--vehicle", "x500", "--height", "1e308"], "--height"),
    ([*FLY, "--vehicle", "x500", "--height", "1e308", "--json"], "--height"),
    (["fly", "{d}/traj_step3m.csv", "--connect", "udpout://127.0.0.1:9", "--vehicle", "x500", "--yes"],
     "not physically consistent"),
    (["fly", "{d}/traj_t_huge.csv", "--connect", "udpout://127.0.0.1:9", "--vehicle", "x500", "--yes"], "t_s"),
    (["fly", "{d}/traj_step3m_hover", "--connect", "udpout://127.0.0.1:9", "--vehicle", "x500", "--yes", "--json"],
     "consistent"),
    # the campaign record
    (["campaign", "--sim", "-o", "{d}/adir/../afile"], "afile"),
]


@pytest.mark.parametrize(("argv", "needle"), CLI_CASES, ids=[" ".join(c[0])[:60] for c in CLI_CASES])
def test_bad_command_lines_are_one_error_line(cli, corpus, argv, needle):
    _assert_refused(cli, corpus, argv, needle)


PROFILE_COMMANDS = {
    "vehicle show": ["vehicle", "show", "{p}"],
    "vehicle show --json": ["vehicle", "show", "{p}", "--json"],
    "region chart": ["region", "chart", "--vehicle", "{p}", "-o", "c.png"],
    "region check": ["region", "check", "--vehicle", "{p}", "--v-ned", "0", "0", "1", "--quat", "1", "0", "0", "0"],
    "plan vertical": ["plan", "vertical", "--vehicle", "{p}", "-o", "v"],
    "plan probe --json": ["plan", "probe", "--vehicle", "{p}", "-o", "p", "--json"],
    "plan helix": ["plan", "helix", "--vehicle", "{p}", "-o", "h"],
    "plan planar": ["plan", "planar", "--vehicle", "{p}", "-o", "pl"],
    "sim": ["sim", "--vehicle", "{p}", "--port", "0", "--duration-s", "0.1"],
    "fly": [*FLY, "--vehicle", "{p}"],
    "campaign": ["campaign", "--sim", "-o", "camp", "--vehicle", "{p}"],
}
EVERY_COMMAND_KINDS = ("binary", "utf16", "latin1", "deep", "fifo", "density")


@pytest.mark.parametrize("kind", EVERY_COMMAND_KINDS)
@pytest.mark.parametrize("command", sorted(PROFILE_COMMANDS))
def test_a_damaged_profile_is_refused_by_every_command(cli, corpus, command, kind):
    argv = [a.replace("{p}", f"{{d}}/{kind}.toml") for a in PROFILE_COMMANDS[command]]
    line = _assert_refused(cli, corpus, argv)
    assert f"{kind}.toml" in line


@pytest.mark.parametrize(
    ("kind", "needle"),
    [("binary", "binary file"), ("utf16", "UTF-16"), ("utf16le", "NUL bytes"), ("latin1", "not UTF-8"),
     ("deep", "nested too deeply"), ("deeptable", "nested too deeply"), ("bigint", "malformed TOML"),
     ("huge", "too large"), ("empty", "'name' is missing"), ("fifo", "regular file"), ("dir", "folder"),
     ("density", "air_density_kgpm3"), ("vh", "v_h"), ("twr", "thrust/weight"), ("mass_str", "mass_kg"),
     ("mass_nan", "mass_kg"), ("mass_huge", "mass_kg"), ("rotors_bool", "n_rotors"), ("rotors_many", "n_rotors"),
     ("name_slash", "'name'"), ("name_ctrl", "'name'"), ("speed_huge", "max_speed_mps"), ("vrs_list", "'vrs'"),
     ("wallow_huge", "w_allow_mps")],
)
def test_every_kind_of_damaged_profile_is_one_line_naming_it(cli, corpus, kind, needle):
    line = _assert_refused(cli, corpus, ["vehicle", "show", f"{{d}}/{kind}.toml"], needle)
    assert f"{kind}.toml" in line


@pytest.mark.parametrize(
    ("kind", "needle"),
    [("cfg_binary", "binary"), ("cfg_utf16", "UTF-16"), ("cfg_latin1", "not UTF-8"), ("cfg_deep", "nested"),
     ("cfg_plan_string", "'descent_m' must be a finite number"), ("cfg_plan_unknown", "unknown key 'descent'"),
     ("cfg_plan_list", "'descent_m'"), ("cfg_plan_huge", "'descent_m'"), ("cfg_plan_bool", "'accel_fraction'"),
     ("cfg_height", "'start_height_m'"), ("cfg_geofence", "'geofence_radius_m'"),
     ("cfg_debounce", "'debounce_samples'"), ("cfg_stale", "'stale_periods'"), ("cfg_mission", "'mission'"),
     ("cfg_table", "[flight] must be a table"), ("fifo", "regular file"), ("dir", "folder")],
)
def test_a_damaged_mission_config_is_refused_before_connecting(cli, corpus, kind, needle):
    line = _assert_refused(cli, corpus, [*FLY, "--vehicle", "x500", "--config", f"{{d}}/{kind}.toml"], needle)
    assert f"{kind}.toml" in line
    with pytest.raises(FlighttestError, match=r"^[^\n]*$"):
        load_mission_config(corpus / f"{kind}.toml")


def test_negative_numbers_in_scientific_notation_are_numbers(cli):
    rc, out, err = cli(["region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "-1e-1", "--quat", "1", "0", "0",
                        "0", "--json"])  # fmt: skip
    assert rc == 0, err
    res = json.loads(out)
    assert res["w_mps"] == pytest.approx(-0.1) and res["verdict"] == "allowed"
    rc, out, err = cli(["region", "check", "--vehicle", "x500", "--v-ned", "-1E+0", "-.5", "-2.", "--quat", "1", "-0",
                        "0", "-0e0", "--wind-ned", "-1e-3", "0", "0", "--json"])  # fmt: skip
    assert rc == 0, err
    assert json.loads(out)["w_mps"] == pytest.approx(-2.0)


def test_huge_speeds_are_never_allowed(cli, corpus):
    # 100 m/s on every axis is the bound: still a number, and forbidden (through the disk at 100 m/s)
    rc, out, err = cli(["region", "check", "--vehicle", "x500", "--v-ned", "100", "100", "100", "--quat", "1", "0", "0",
                        "0", "--json"])  # fmt: skip
    assert rc == 0 and json.loads(out)["verdict"] == "forbidden"


def test_good_outputs_still_work_and_create_missing_folders(cli):
    rc, out, err = cli(["region", "chart", "--vehicle", "x500", "-o", "new/sub/chart.svg"])
    assert rc == 0, err
    assert (cli.work / "new/sub/chart.svg").read_bytes().lstrip().startswith(b"<?xml")
    assert [p.name for p in (cli.work / "new/sub").iterdir()] == ["chart.svg"]  # no temporary left
    rc, out, err = cli(["plan", "vertical", "--height", "120", "-o", "deep/v120", "--json"])
    assert rc == 0, err
    assert json.loads(out)["t_f_s"] < 600
    assert Trajectory.load(cli.work / "deep/v120", X500).duration_s < 600


def test_vehicle_list_skips_a_damaged_profile_with_one_warning(cli, corpus, tmp_path):
    users = tmp_path / "vehicles"
    for kind in ("binary", "utf16", "deep"):
        (users / f"{kind}.toml").write_bytes(BAD_TOML_BYTES[kind])
    os.mkfifo(users / "fifo.toml")
    (users / "mine.toml").write_text(X500_TOML.replace('name = "x500"', 'name = "mine"'))
    rc, out, err = cli(["vehicle", "list", "--json"])
    assert rc == 0
    names = {p["name"] for p in json.loads(out)}
    assert {"mambo", "tunnel_rig", "x500", "mine"} <= names
    lines = err.strip().splitlines()
    assert len(lines) == 4 and all(ln.startswith("flighttest: warning: skipped") for ln in lines)
    assert all(any(f"{k}.toml" in ln for ln in lines) for k in ("binary", "utf16", "deep", "fifo"))
    rc, out, err = cli(["vehicle", "list"])
    assert rc == 0 and "mine" in out and "Traceback" not in err
    # by name, the damaged one is refused (exit 2), the others load
    _assert_refused(cli, corpus, ["vehicle", "show", "utf16"], "UTF-16")
    assert cli(["vehicle", "show", "mine", "--json"])[0] == 0


# -- loaders one by one --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "needle"),
    [("step3m", "not physically consistent"), ("step3m_hover", "position changes by 3"),
     ("vel_jump", "velocity"), ("t_huge", "t_s = 1e+308"), ("t_last_huge", "t_s = 1e+308"),
     ("long", "at most 600 s"), ("deep_d", "d_m"), ("fast", "ve_mps"), ("accel_huge", "ad_mps2"),
     ("drift", "drifted"), ("tf_string", "t_f_s"), ("tf_wrong", "t_f_s"), ("problem_list", "'problem'"),
     ("vehicle_number", "'vehicle'"), ("yaw_huge", "yaw_deg"), ("csvbin", "malformed"), ("csvutf16", "traj_csvutf16"),
     ("metabin", "binary"), ("metautf16", "UTF-16"), ("metadeep", "nested"), ("metalist", "JSON object"),
     ("nojson", "not found"), ("bool", "non-numeric")],
)
def test_trajectory_files_that_are_not_physical_are_refused_at_load(corpus, name, needle):
    with pytest.raises(FlighttestError) as exc:
        Trajectory.load(corpus / f"traj_{name}.csv")
    msg = str(exc.value)
    assert needle in msg and "\n" not in msg, msg


def test_trajectory_load_refuses_special_files_and_empty_paths(corpus, tmp_path):
    os.mkfifo(tmp_path / "f.csv")
    (tmp_path / "f.json").write_bytes((corpus / "traj_good.json").read_bytes())
    for path, needle in ((tmp_path / "f.csv", "regular file"), ("", "empty"), (corpus / "adir", "not found")):
        with pytest.raises(FlighttestError, match=needle):
            Trajectory.load(path)


def test_too_many_rows_are_refused_without_reading_them_all(tmp_path):
    n = MAX_ROWS + 5
    t = np.arange(n) * 1e-4  # 60 s
    header = "t_s,n_m,e_m,d_m,vn_mps,ve_mps,vd_mps,an_mps2,ae_mps2,ad_mps2,yaw_deg\n"
    body = "\n".join(f"{x:.4f},0,0,0,0,0,0,0,0,0,0" for x in t)
    (tmp_path / "big.csv").write_text(header + body + "\n")
    (tmp_path / "big.json").write_text(json.dumps({"format": FORMAT, "kind": "vertical", "vehicle": "x500",
                                                   "problem": {}, "status": "x", "t_f_s": float(t[-1])}))  # fmt: skip
    with pytest.raises(FlighttestError, match="rows"):
        Trajectory.load(tmp_path / "big.csv")


def test_limits_with_a_profile_are_still_checked(corpus):
    fast = _consistent_fast(20.0)  # consistent, within the absolute bounds, too fast for an x500
    fast.validate()
    with pytest.raises(FlighttestError, match="speed 20"):
        fast.validate(X500)
    hard = _hover(0.1, rate_hz=100.0)
    hard.df["thrust_n"] = 15.0
    hard.df["ad_mps2"] = -30.0  # a climb the rotors cannot give, whatever the thrust column says
    hard.df["vd_mps"] = -30.0 * hard.df["t_s"]
    hard.df["d_m"] = -15.0 * hard.df["t_s"] ** 2
    with pytest.raises(FlighttestError, match="required thrust"):
        hard.validate(X500)
    Trajectory.load(corpus / "traj_good.csv", X500)


def test_planner_outputs_pass_the_consistency_checks():
    for h in (0.1, 1.0, 5.0, 30.0, 120.0):
        tr = vertical_trajectory(plan_vertical(X500, h), "x500", X500.mass_kg)
        tr.validate(X500)
        tr.resample(50.0).validate(X500)


@pytest.mark.parametrize("rate_hz", [1.0, 5.0, 20.0, 50.0, 200.0])
def test_the_preflight_recheck_accepts_resampled_plans_and_still_catches_a_step(rate_hz, tmp_path):
    region = X500.guard_region()
    flown = _good_vertical().resample(rate_hz)  # what the mission streams: [flight] rate_hz is 1-200
    assert pf.trajectory_stats(flown, region, 3.0).problem == ""
    flown.save(tmp_path / "flown")  # a flight log's copy loads again
    Trajectory.load(tmp_path / "flown", X500)
    if rate_hz >= 20:
        stepped = _step3m(_good_vertical()).resample(rate_hz)
        assert "consistent" in pf.trajectory_stats(stepped, region, 3.0).problem


def test_preflight_refuses_what_the_loader_would():
    region = X500.guard_region()
    good = pf.trajectory_stats(_good_vertical(), region, 3.0)
    by = {c.name: c for c in pf.trajectory_checks(good, X500, 5.0, 1.0, 10.0)}
    assert all(c.status != pf.FAIL for c in by.values())
    for start in (1e308, math.inf, math.nan, 121.0, -1.0):
        by = {c.name: c for c in pf.trajectory_checks(good, X500, start, 1.0, 10.0)}
        assert by["height"].status == pf.FAIL, start
    by = {c.name: c for c in pf.trajectory_checks(good, X500, 5.0, math.nan, 10.0)}
    assert by["height"].status == pf.FAIL
    by = {c.name: c for c in pf.trajectory_checks(good, X500, 5.0, 1.0, math.inf)}
    assert by["horizontal room"].status == pf.FAIL
    broken = pf.trajectory_stats(_step3m(_good_vertical()), region, 3.0)  # built in memory: never loaded
    by = {c.name: c for c in pf.trajectory_checks(broken, X500, 10.0, 1.0, 10.0)}
    assert by["trajectory limits"].status == pf.FAIL and "consistent" in by["trajectory limits"].value
    climb = _hover(10.0)
    climb.df["vd_mps"], climb.df["d_m"] = -1.0, -climb.df["t_s"]
    by = {c.name: c for c in pf.trajectory_checks(pf.trajectory_stats(climb, region, 3.0), X500, 115.0, 1.0, 10.0)}
    assert by["height"].status == pf.FAIL and "highest 125.00 m" in by["height"].value


def test_config_overrides_from_the_command_line_are_ranged():
    cfg = mission_config_from_dict({"mission": "vertical"})
    for bad in ({"start_height_m": 1e308}, {"min_alt_m": -1.0}, {"geofence_radius_m": math.inf},
                {"start_height_m": "5"}):  # fmt: skip
        with pytest.raises(FlighttestError, match="options"):
            cfg.with_flight(**bad)
    assert cfg.with_flight(start_height_m=120).flight.start_height_m == 120.0


def test_plan_tables_are_typed_per_mission():
    ok = mission_config_from_dict({"mission": "helix", "plan": {"trajectory": "my_helix", "n_intervals": 40}})
    assert ok.plan == {"trajectory": "my_helix", "n_intervals": 40}
    for mission, plan, needle in (
        ("vertical", {"descent_m": "3"}, "'descent_m' must be a finite number"),
        ("vertical", {"trajectory": "x"}, "unknown key 'trajectory' for mission 'vertical'"),
        ("helix", {"n_intervals": 60.0}, "'n_intervals' must be an integer"),
        ("helix", {"trajectory": 5}, "'trajectory' must be a string"),
        ("helix", {"thrust_min_fraction": 0.8, "thrust_max_fraction": 0.5}, "thrust_min_fraction"),
        ("probe", {"omega0_rps2": 1e308}, "'omega0_rps2'"),
        ("file", {"descent_m": 3.0}, "unknown key"),
    ):
        with pytest.raises(FlighttestError, match=needle):
            mission_config_from_dict({"mission": mission, "plan": plan}, "m.toml")


CAMPAIGN_RECORDS = {
    "list": [1, 2],
    "string": "campaign",
    "number": 5,
    "null": None,
    "no_format": {"vehicle": "x500"},
    "steps_list": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0, "steps": []},
    "created_str": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": "1.0", "steps": {}},
    "vehicle_num": {"format": "flighttest-campaign/1", "vehicle": 5, "created_unix_s": 1.0, "steps": {}},
    "step_str": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0,
                 "steps": {"probe": "done"}},
    "status_bad": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0,
                   "steps": {"probe": {"status": "finished"}}},
    "unknown_step": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0,
                     "steps": {"lunch": {}}},
    "elapsed_str": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0,
                    "steps": {"probe": {"status": "done", "elapsed_s": "12"}}},
    "outputs_list": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0,
                     "steps": {"probe": {"status": "done", "outputs": []}}},
    "path_number": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0,
                    "steps": {"probe": {"status": "done", "outputs": {"log_dir": 5}}}},
    "time_string": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0,
                    "steps": {"vertical": {"status": "done", "outputs": {"descent_time_s": "8.3"}}}},
    "files_str": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0,
                  "steps": {"report": {"status": "done", "outputs": {"files": "a.png"}}}},
    "error_num": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0,
                  "steps": {"probe": {"status": "failed", "error": 3}}},
    "extra_key": {"format": "flighttest-campaign/1", "vehicle": "x500", "created_unix_s": 1.0,
                  "steps": {"probe": {"status": "done", "colour": "red"}}},
}  # fmt: skip


@pytest.mark.parametrize("kind", [*CAMPAIGN_RECORDS, "deep", "binary", "utf16", "dir", "fifo", "broken"])
def test_a_campaign_record_of_another_shape_is_one_error_line(tmp_path, kind):
    root = tmp_path / "camp"
    root.mkdir()
    rec = root / "campaign.json"
    if kind in CAMPAIGN_RECORDS:
        rec.write_text(json.dumps(CAMPAIGN_RECORDS[kind]))
    elif kind == "deep":
        rec.write_text("[" * 100_000 + "]" * 100_000)
    elif kind == "binary":
        rec.write_bytes(bytes(range(256)))
    elif kind == "utf16":
        rec.write_bytes(json.dumps({"format": "flighttest-campaign/1"}).encode("utf-16"))
    elif kind == "dir":
        rec.mkdir()
    elif kind == "fifo":
        os.mkfifo(rec)
    else:
        rec.write_text('{"format": ')
    with pytest.raises(FlighttestError) as exc:
        CampaignState.open(root, "x500")
    msg = str(exc.value)
    assert "campaign.json" in msg and "\n" not in msg


@pytest.mark.parametrize("kind", ["list", "steps_list", "time_string"])
def test_the_campaign_command_refuses_a_damaged_record(cli, tmp_path, kind):
    root = tmp_path / "camp"
    root.mkdir()
    (root / "campaign.json").write_text(json.dumps(CAMPAIGN_RECORDS[kind]))
    rc, out, err = cli(["campaign", "--sim", "-o", str(root), "--json"])
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "campaign.json" in err
    assert "error" in json.loads(out)
    assert sorted(p.name for p in root.iterdir()) == ["campaign.json"]


def test_a_good_campaign_record_still_round_trips(tmp_path):
    state = CampaignState.open(tmp_path / "c", "x500")
    state.begin("probe")
    state.finish("probe", "done", {"log_dir": str(tmp_path / "c" / "flights" / "f"), "outcome": "probe_stopped",
                                   "abort_reason": None, "descent_time_s": None, "guard_aborts": 0})  # fmt: skip
    again = CampaignState.open(tmp_path / "c", "x500")
    assert again.steps["probe"].outputs["log_dir"] == "flights/f" and again.done("probe")


# -- the input layer itself ------------------------------------------------------------------------------


def test_read_toml_words_every_encoding_problem(corpus, tmp_path):
    for kind, needle in (("binary", "binary"), ("utf16", "UTF-16"), ("latin1", "byte 0xe9"), ("deep", "nested")):
        with pytest.raises(FlighttestError, match=needle):
            read_toml(corpus / f"{kind}.toml", "vehicle profile")
    bom = tmp_path / "bom.toml"
    bom.write_bytes(b"\xef\xbb\xbf" + X500_TOML.encode())
    assert read_toml(bom, "vehicle profile")["name"] == "x500"  # Windows editors write a BOM: fine


def test_ranges_as_argparse_types_and_validators():
    assert ip.HEIGHT_M("5") == 5.0 and ip.HEIGHT_M(" 120 ") == 120.0
    with pytest.raises(Exception, match=r"≥ 0\.1 and ≤ 120 m"):
        ip.HEIGHT_M("1e9")
    assert ip.INTERVALS("60") == 60
    with pytest.raises(FlighttestError, match="--x must be a finite number"):
        ip.HEIGHT_M.check(math.nan, "--x")
    for bad in (True, "5", None, [5], math.inf):
        assert not ip.HEIGHT_M.ok(bad)
    assert ip.SYSID.check(255, "--sysid") == 255 and not ip.SYSID.ok(256) and not ip.SYSID.ok(1.0)


def test_atomic_write_leaves_nothing_behind_on_failure(tmp_path):
    target = tmp_path / "a" / "b" / "out.csv"
    with pytest.raises(RuntimeError), ip.atomic_write(target) as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []
    with ip.atomic_write(target) as tmp:
        tmp.write_text("whole")
    assert target.read_text() == "whole" and [p.name for p in target.parent.iterdir()] == ["out.csv"]


def test_output_path_checks(tmp_path):
    (tmp_path / "f").write_text("x")
    (tmp_path / "d").mkdir()
    ok = ip.check_output_path(tmp_path / "new" / "x.png", "out", ip.IMAGE_SUFFIXES)
    assert ok.name == "x.png" and not (tmp_path / "new").exists()  # nothing created by the check
    for path, needle in (("", "empty"), (tmp_path / "d", "folder"), (f"{tmp_path}/f/x.png", "file"),
                         (tmp_path / "x.PNG", None), (tmp_path / "x.gif", ".png"), (tmp_path / ("y" * 256), "long"),
                         ("a\x00b.png", "control"), (f"{tmp_path}/d/", "folder")):  # fmt: skip
        if needle is None:
            ip.check_output_path(path, "out", ip.IMAGE_SUFFIXES)
            continue
        with pytest.raises(FlighttestError, match=needle):
            ip.check_output_path(path, "out", ip.IMAGE_SUFFIXES if str(path).endswith(("png", "gif")) else None)


# -- property tests ----------------------------------------------------------------------------------------

_X500_DICT = read_toml(SHIPPED_DIR / "x500.toml", "vehicle profile")
_NUMERIC_FIELDS = ["mass_kg", "n_rotors", "rotor_diameter_m", "arm_length_m", "max_thrust_per_rotor_n",
                   "max_tilt_deg", "air_density_kgpm3", "min_thrust_per_rotor_n", "max_speed_mps", "max_climb_mps",
                   "yaw_moment_per_thrust_m"]  # fmt: skip
_ANY_VALUE = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=1e-6, max_value=1e6),
    st.integers(min_value=-(10**20), max_value=10**20),
    st.booleans(),
    st.text(max_size=5),
    st.lists(st.floats(), max_size=4),
    st.none(),
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.dictionaries(st.sampled_from([*_NUMERIC_FIELDS, "inertia_kgm2", "max_rate_dps", "name"]), _ANY_VALUE,
                       max_size=4),
       st.dictionaries(st.sampled_from(["cone_deg", "w_allow_mps", "margin_mps", "onera_k", "eps_vrs", "eps_tws"]),
                       _ANY_VALUE, max_size=3))  # fmt: skip
def test_random_profiles_load_with_finite_figures_or_are_refused(top, vrs):
    data = {**_X500_DICT, **{k: v for k, v in top.items() if v is not None}}
    data["vrs"] = {**_X500_DICT["vrs"], **{k: v for k, v in vrs.items() if v is not None}}
    try:
        prof = profile_from_dict(data, "random.toml")
    except FlighttestError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("random.toml")
        return
    json.dumps(prof.summary(), allow_nan=False)
    for value in (prof.v_h_mps, prof.w_allow_mps, prof.w_allow_mps / prof.v_h_mps, prof.thrust_to_weight):
        assert math.isfinite(value) and value > 0
    assert math.isfinite(prof.max_accel_up_mps2) and prof.max_accel_down_mps2 > 0
    prof.guard_region().check(0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0)


@st.composite
def _piecewise_constant_accel(draw):
    """A trajectory integrated exactly from piecewise-constant accelerations, sampled at the switches."""
    n_seg = draw(st.integers(1, 5))
    rate = draw(st.sampled_from([10.0, 50.0, 100.0]))
    t_all, p_all, v_all, a_all = [np.zeros(1)], [np.zeros((1, 3))], [np.zeros((1, 3))], []
    t0, p0, v0 = 0.0, np.zeros(3), np.zeros(3)
    for _ in range(n_seg):
        dur = draw(st.floats(0.05, 3.0))
        a = np.array([draw(st.floats(-1.0, 1.0)) for _ in range(3)])
        grid = np.arange(1.0 / rate, dur, 1.0 / rate)
        tau = np.append(grid[grid < dur - 1e-3], dur)  # no two samples closer than 1 ms
        p = p0 + v0 * tau[:, None] + 0.5 * a * tau[:, None] ** 2
        v = v0 + a * tau[:, None]
        t_all.append(t0 + tau)
        p_all.append(p)
        v_all.append(v)
        a_all.append(np.repeat(a[None, :], len(tau), axis=0))
        t0, p0, v0 = t0 + dur, p[-1], v[-1]
    t = np.concatenate(t_all)
    p, v = np.concatenate(p_all), np.concatenate(v_all)
    acc = np.concatenate([a_all[0][:1], *a_all])  # the sample at a switch carries the new segment's value
    names = ("n_m", "e_m", "d_m"), ("vn_mps", "ve_mps", "vd_mps"), ("an_mps2", "ae_mps2", "ad_mps2")
    cols = {"t_s": t}
    for block, arr in zip(names, (p, v, acc)):
        cols.update({c: arr[:, k] for k, c in enumerate(block)})
    cols["yaw_deg"] = np.zeros_like(t)
    meta = {"format": FORMAT, "kind": "vertical", "vehicle": "x", "problem": {}, "status": "x", "t_f_s": float(t[-1])}
    return Trajectory(df=pd.DataFrame(cols), meta=meta)


@settings(max_examples=60, deadline=None)
@given(_piecewise_constant_accel(), st.integers(0, 10**6), st.sampled_from(["n_m", "d_m", "vn_mps", "vd_mps"]),
       st.floats(-1e6, 1e6))  # fmt: skip
def test_consistent_trajectories_load_and_perturbed_ones_are_caught(tr, row_seed, col, delta):
    tr.validate()  # exact kinematics: always accepted
    i = 1 + row_seed % (len(tr.df) - 1)
    bad = Trajectory(df=tr.df.copy(), meta=dict(tr.meta))
    bad.df.loc[i, col] += delta
    big = abs(delta) > (0.5 if col.endswith("_m") else 1.0)
    try:
        bad.validate()
    except FlighttestError as exc:
        assert "\n" not in str(exc)
        return
    assert not big, f"a jump of {delta:g} in {col} at row {i} was accepted"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(2, 30).flatmap(lambda n: st.lists(
    st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-5, 5)), min_size=11, max_size=11),
    min_size=n, max_size=n)))  # fmt: skip
def test_random_tables_are_accepted_or_refused_in_one_line(rows):
    df = pd.DataFrame(rows, columns=["t_s", "n_m", "e_m", "d_m", "vn_mps", "ve_mps", "vd_mps", "an_mps2", "ae_mps2",
                                     "ad_mps2", "yaw_deg"])  # fmt: skip
    meta = {"format": FORMAT, "kind": "probe", "vehicle": "x", "problem": {}, "status": "x", "t_f_s": 0.0}
    with np.errstate(over="raise", invalid="raise"):  # no arithmetic on unchecked values: nothing overflows
        try:
            Trajectory(df=df, meta=meta).validate(X500)
        except FlighttestError as exc:
            assert "\n" not in str(exc)


_CONFIG_KEYS = {
    "flight": ["start_height_m", "min_alt_m", "geofence_radius_m", "settle_s", "rate_hz", "land"],
    "guard": ["horizon_s", "debounce_samples", "stale_periods", "max_descent_mps", "observe_region"],
    "abort": ["recovery_s", "recover_max_s", "hold_dwell_s"],
    "plan": ["descent_m", "accel_fraction", "extra_margin_mps", "radius_m", "trajectory"],
}


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(["vertical", "probe", "helix", "file"]),
       st.lists(st.tuples(st.sampled_from(sorted(_CONFIG_KEYS)), st.integers(0, 5), _ANY_VALUE),
                max_size=5))  # fmt: skip
def test_random_configs_load_typed_and_ranged_or_are_refused(mission, entries):
    data: dict = {"mission": mission}
    for section, k, value in entries:
        keys = _CONFIG_KEYS[section]
        data.setdefault(section, {})[keys[k % len(keys)]] = value
    try:
        cfg = mission_config_from_dict(data, "random.toml")
    except FlighttestError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("random.toml")
        return
    for section in ("flight", "guard", "abort"):
        for key, value in cfg.to_dict()[section].items():
            assert value is None or isinstance(value, bool) or math.isfinite(value), (section, key)
    assert 0 < cfg.flight.start_height_m <= ip.MAX_HEIGHT_M and cfg.flight.min_alt_m < cfg.flight.start_height_m
    for value in cfg.plan.values():
        assert isinstance(value, str) or (not isinstance(value, bool) and math.isfinite(value))


@settings(max_examples=200, deadline=None)
@given(st.one_of(st.text(max_size=12), st.floats().map(repr), st.integers().map(str)),
       st.sampled_from([ip.HEIGHT_M, ip.VELOCITY_MPS, ip.SPEED_STEP_MPS, ip.INTERVALS, ip.FRACTION]))  # fmt: skip
def test_random_command_line_numbers_are_in_range_or_refused(word, rng):
    import argparse

    try:
        value = rng(word)
    except argparse.ArgumentTypeError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("must be")
        return
    assert rng.ok(value) and math.isfinite(value)
