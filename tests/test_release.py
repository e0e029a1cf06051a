"""A release flies: the wheel holds the missions and profiles, and an installed wheel finds them.

The wheel is built without build isolation (offline; the test extra brings setuptools >= 77) from a
copy of the sources, so the build leaves nothing in the checkout. `.ci/run` goes further: it builds
with isolation, installs the wheel with its dependencies in a fresh venv and flies the campaign.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from flighttest.errors import FlighttestError
from flighttest.flying import mission_scripts
from flighttest.flying.mission_scripts import MISSIONS

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("pyproject.toml", "README.md", "flighttest", "missions", "sitl_fakes")
JUNK = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")


def _run(*cmd, **kw) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, **kw)
    assert proc.returncode == 0, f"{' '.join(map(str, cmd))}\n{proc.stdout}\n{proc.stderr}"
    return proc


def _source_files(folder: str, pattern: str) -> set[str]:
    return {p.relative_to(ROOT).as_posix() for p in (ROOT / folder).rglob(pattern) if "__pycache__" not in p.parts}


# What the installed wheel sees: run with the wheel's files first on sys.path, from an empty folder
# and with an empty home, so neither the checkout nor ~/.config can answer.
LOOKUP = """
import json
from flighttest.flying import mission_scripts as ms
from flighttest.flying.missions_config import load_mission_config
out = {}
for name in ms.MISSIONS:
    module = ms.load_mission_module(name)
    cfg = load_mission_config(ms.mission_config_path(name))
    out[name] = {"dir": str(ms.mission_dir(name)), "script": module.__file__, "config": str(module.CONFIG),
                 "has_plan": callable(module.plan), "mission": cfg.mission}
out["checkout"] = str(ms.CHECKOUT_DIR)
print(json.dumps(out))
"""


def test_wheel_ships_missions_and_profiles_and_finds_them_installed(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name, ignore=JUNK)
        else:
            shutil.copy2(ROOT / name, src / name)
    dist = tmp_path / "dist"
    _run(sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
         "-w", str(dist), str(src))  # fmt: skip
    (wheel,) = dist.glob("flighttest-*.whl")

    names = set(zipfile.ZipFile(wheel).namelist())
    missions = {f"flighttest/missions/{stem}.{ext}" for stem in MISSIONS.values() for ext in ("py", "toml")}
    assert missions <= names, sorted(missions - names)
    assert {f"flighttest/missions/{p.name}" for p in (ROOT / "missions").iterdir() if p.is_file()} <= names
    profiles = _source_files("flighttest/model/profiles", "*.toml")
    assert profiles and profiles <= names, sorted(profiles - names)
    # every module of the source tree, so a package folder missing from pyproject's list fails here
    modules = _source_files("flighttest", "*.py") | _source_files("sitl_fakes", "*.py")
    assert modules <= names, f"not in the wheel (add the package to pyproject.toml): {sorted(modules - names)}"
    assert not any(n.startswith("missions/") for n in names), "missions/ must ship inside flighttest/"
    # the tests' helpers (tests/synthetic.py's log writers) are not something a user runs
    assert not any(n.startswith("tests/") or n.endswith("/synthetic.py") for n in names), sorted(names)
    meta = zipfile.ZipFile(wheel).read("flighttest-0.1.0.dist-info/METADATA").decode()
    assert "License-Expression: MIT" in meta

    site = tmp_path / "site"
    _run(sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "-q", "--target", str(site), str(wheel))
    empty, home = tmp_path / "empty", tmp_path / "home"
    empty.mkdir()
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("FLIGHTTEST_MISSIONS", "PYTHONPATH")}
    env |= {"PYTHONPATH": str(site), "HOME": str(home)}
    out = json.loads(_run(sys.executable, "-P", "-c", LOOKUP, cwd=empty, env=env).stdout)
    packaged = site / "flighttest" / "missions"
    assert out["checkout"] == "None"
    for name, stem in MISSIONS.items():
        assert Path(out[name]["dir"]) == packaged
        assert Path(out[name]["script"]) == packaged / f"{stem}.py"
        assert Path(out[name]["config"]) == packaged / f"{stem}.toml"
        assert out[name]["has_plan"] and out[name]["mission"] == name

    # a user folder shadows the packaged copy, mission by mission
    user = tmp_path / "my missions"
    user.mkdir()
    for ext in ("py", "toml"):
        shutil.copy2(packaged / f"vertical_descent.{ext}", user)
    env["FLIGHTTEST_MISSIONS"] = str(user)
    out = json.loads(_run(sys.executable, "-P", "-c", LOOKUP, cwd=empty, env=env).stdout)
    assert Path(out["vertical"]["script"]) == user / "vertical_descent.py"
    assert Path(out["helix"]["dir"]) == packaged


# -- the lookup order, in process ----------------------------------------------------------------


@pytest.fixture
def dirs(tmp_path, monkeypatch):
    """A fake shipped folder with all missions, an empty home, and no $FLIGHTTEST_MISSIONS."""
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    for stem in MISSIONS.values():
        for ext in ("py", "toml"):
            shutil.copy2(mission_scripts.MISSIONS_DIR / f"{stem}.{ext}", shipped)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("FLIGHTTEST_MISSIONS", raising=False)
    monkeypatch.setattr(mission_scripts, "CHECKOUT_DIR", shipped)
    return tmp_path, shipped


def _copy(src: Path, dst: Path, stem: str, exts=("py", "toml")) -> None:
    dst.mkdir(parents=True, exist_ok=True)
    for ext in exts:
        shutil.copy2(src / f"{stem}.{ext}", dst)


def test_checkout_missions_when_no_user_copies(dirs):
    _, shipped = dirs
    assert mission_scripts.mission_config_path("helix") == shipped / "helix_descent.toml"
    assert mission_scripts.search_dirs()[-1] == shipped


def test_user_folders_first_in_order(dirs, monkeypatch):
    tmp, shipped = dirs
    a, b, home = tmp / "a", tmp / "b", tmp / "home" / ".config" / "flighttest" / "missions"
    _copy(shipped, b, "vrs_probe")
    _copy(shipped, b, "helix_descent")
    _copy(shipped, a, "helix_descent")
    _copy(shipped, home, "vertical_descent")
    monkeypatch.setenv("FLIGHTTEST_MISSIONS", os.pathsep.join([str(a), str(b)]))
    assert mission_scripts.search_dirs() == [a, b, home, shipped]
    assert mission_scripts.mission_dir("helix") == a
    assert mission_scripts.mission_dir("probe") == b
    assert mission_scripts.mission_dir("vertical") == home
    module = mission_scripts.load_mission_module("vertical")
    assert Path(module.__file__) == home / "vertical_descent.py"
    assert Path(module.CONFIG) == home / "vertical_descent.toml"


def test_half_a_mission_in_a_user_folder_is_an_error(dirs, monkeypatch):
    tmp, shipped = dirs
    _copy(shipped, tmp / "mine", "helix_descent", exts=("toml",))
    monkeypatch.setenv("FLIGHTTEST_MISSIONS", str(tmp / "mine"))
    with pytest.raises(FlighttestError, match=r"helix_descent\.toml: mission 'helix' needs helix_descent\.py"):
        mission_scripts.mission_dir("helix")


def test_packaged_copy_when_checkout_absent(dirs, monkeypatch):
    tmp, shipped = dirs
    monkeypatch.setattr(mission_scripts, "CHECKOUT_DIR", tmp / "no-checkout")
    monkeypatch.setattr(mission_scripts, "packaged_dir", lambda: shipped)
    assert mission_scripts.mission_dir("probe") == shipped
    monkeypatch.setattr(mission_scripts, "packaged_dir", lambda: None)
    with pytest.raises(FlighttestError, match="no shipped missions"):
        mission_scripts.mission_dir("probe")
    with pytest.raises(FlighttestError, match="unknown mission"):
        mission_scripts.mission_dir("loop")


def test_zipped_packaged_copy_is_extracted_beside_each_other(tmp_path, monkeypatch):
    zpath = tmp_path / "flighttest.zip"
    with zipfile.ZipFile(zpath, "w") as z:
        for stem in MISSIONS.values():
            for ext in ("py", "toml"):
                z.write(mission_scripts.MISSIONS_DIR / f"{stem}.{ext}", f"flighttest/missions/{stem}.{ext}")
    monkeypatch.setattr(mission_scripts, "_packaged_resource", lambda: zipfile.Path(zpath, "flighttest/missions/"))
    mission_scripts.packaged_dir.cache_clear()
    try:
        folder = mission_scripts.packaged_dir()
        assert isinstance(folder, Path) and folder.is_dir()
        assert sorted(p.name for p in folder.iterdir()) == sorted(
            f"{stem}.{ext}" for stem in MISSIONS.values() for ext in ("py", "toml")
        )
    finally:
        mission_scripts.packaged_dir.cache_clear()
