"""The foundation commands through a real subprocess, as scripts call them."""

import json
import math
import subprocess
import sys

import pandas as pd
import pytest


def run(*args, check=True):
    proc = subprocess.run(
        [sys.executable, "-m", "flighttest", *args], capture_output=True, text=True, timeout=120
    )
    if check and proc.returncode != 0:
        raise AssertionError(f"exit {proc.returncode}: {proc.stderr}")
    return proc


def test_help_explains_itself():
    out = run("--help").stdout
    for word in ("vehicle", "region", "demo", "--json"):
        assert word in out


def test_vehicle_list_and_show_json():
    rows = json.loads(run("vehicle", "list", "--json").stdout)
    names = {r["name"] for r in rows}
    assert {"mambo", "tunnel_rig", "x500"} <= names
    show = json.loads(run("vehicle", "show", "mambo", "--json").stdout)
    for key in ("v_h_mps", "w_allow_mps", "w_allow_n", "cone_deg"):
        assert isinstance(show[key], float)
    assert show["w_allow_mps"] == pytest.approx(show["w_allow_n"] * show["v_h_mps"], rel=1e-3)


def test_region_check_single_state_json():
    s = 5.0
    a = math.radians(30)
    out = json.loads(
        run("region", "check", "--vehicle", "x500", "--v-ned", str(s * math.cos(a)), "0", str(s * math.sin(a)),
            "--quat", "1", "0", "0", "0", "--json").stdout
    )
    assert out["verdict"] == "forbidden"
    assert out["w_mps"] == pytest.approx(2.5) and out["margin_mps"] < 0
    out = json.loads(run("region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "-1", "--quat", "1", "0", "0",
                         "0", "--json").stdout)
    assert out["verdict"] == "allowed"


def test_region_check_csv(tmp_path):
    src = tmp_path / "states.csv"
    pd.DataFrame(
        {"vn": [0, 5, 0], "ve": [0, 0, 0], "vd": [3, 1, -2], "qw": [1, 1, 1], "qx": [0, 0, 0], "qy": [0, 0, 0],
         "qz": [0, 0, 0], "wn": [0, 0, 0], "we": [0, 0, 0], "wd": [0, 0, 0]}
    ).to_csv(src, index=False)
    dst = tmp_path / "out.csv"
    run("region", "check", "--vehicle", "x500", "--csv", str(src), "-o", str(dst))
    out = pd.read_csv(dst)
    assert out["verdict"].tolist() == ["forbidden", "allowed", "allowed"]
    assert out["w"].tolist() == pytest.approx([3, 1, -2])
    assert {"u", "margin"} <= set(out.columns)
    # stdout form
    text = run("region", "check", "--vehicle", "x500", "--csv", str(src)).stdout
    assert text.splitlines()[0].endswith("verdict,w,u,margin")


def test_region_chart_png(tmp_path):
    out = tmp_path / "chart.png"
    run("region", "chart", "--vehicle", "mambo", "-o", str(out))
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("vehicle", "show", "nope"), "unknown vehicle"),
        (("region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "1", "--quat", "2", "0", "0", "0"), "unit"),
        (("region", "check", "--vehicle", "x500", "--v-ned", "0", "0", "nan", "--quat", "1", "0", "0", "0"), "finite"),
        (("region", "check", "--vehicle", "x500"), "--v-ned"),
    ],
)
def test_bad_input_one_line_exit_2(args, needle):
    proc = run(*args, check=False)
    assert proc.returncode == 2
    assert needle in proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_bad_csv_and_bad_toml(tmp_path):
    src = tmp_path / "s.csv"
    src.write_text("vn,ve,vd,qw\n0,0,1,1\n")
    proc = run("region", "check", "--vehicle", "x500", "--csv", str(src), check=False)
    assert proc.returncode == 2 and "missing column(s) qx, qy, qz" in proc.stderr
    src.write_text("vn,ve,vd,qw,qx,qy,qz\n0,0,1,0.5,0,0,0\n")
    proc = run("region", "check", "--vehicle", "x500", "--csv", str(src), check=False)
    assert proc.returncode == 2 and "row 2" in proc.stderr and "Traceback" not in proc.stderr
    toml = tmp_path / "v.toml"
    toml.write_text("name = 'x'\nmass_kg = \n")
    proc = run("vehicle", "show", str(toml), check=False)
    assert proc.returncode == 2 and "malformed TOML" in proc.stderr and "Traceback" not in proc.stderr
