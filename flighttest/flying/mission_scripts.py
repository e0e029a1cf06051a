"""The mission scripts users run and edit: ``<script>.py`` with its TOML config beside it.

A script defines ``CONFIG`` (its TOML, beside it) and ``plan(profile, cfg) -> Trajectory``. A mission's
two files come from the first of these folders that holds either of them:

1. the user folders: each folder of ``$FLIGHTTEST_MISSIONS`` (``os.pathsep``-separated), then
   ``~/.config/flighttest/missions``. Copies people edit shadow the shipped ones, as vehicle profiles
   do, and they survive upgrades: an installed release's own files are not for editing.
2. the checkout's ``missions/``, when flighttest runs from a source tree (the README's editable
   install): the files the README points at, so an edited script is what flies.
3. the copy packaged in the wheel (``flighttest/missions``, mapped from ``missions/`` in
   ``pyproject.toml`` and read through :mod:`importlib.resources`), so an installed release flies
   without a checkout. A source tree has no packaged copy and an installed release no checkout, so
   2 and 3 are the same files seen from the two kinds of install.

Both files come from one folder, because a script reads ``CONFIG`` beside itself; a user folder with
only one of the two is an error naming it, never passed over in silence. Scripts are executed from
their file paths, so a packaged copy that is not on the file system (a zipped install) is extracted
once per process.
"""

from __future__ import annotations

import atexit
import functools
import importlib.util
import os
import shutil
import tempfile
from importlib import resources
from pathlib import Path
from types import ModuleType

from flighttest.errors import FlighttestError

MISSIONS = {"probe": "vrs_probe", "helix": "helix_descent", "vertical": "vertical_descent", "drag": "drag_calibration"}

_SOURCE_ROOT = Path(__file__).resolve().parents[2]
# the checkout's missions/: only when this flighttest is a source tree (site-packages has no pyproject.toml)
CHECKOUT_DIR: Path | None = _SOURCE_ROOT / "missions" if (_SOURCE_ROOT / "pyproject.toml").is_file() else None


def user_dirs() -> list[Path]:
    env = os.environ.get("FLIGHTTEST_MISSIONS", "")
    dirs = [Path(p).expanduser() for p in env.split(os.pathsep) if p]
    dirs.append(Path("~/.config/flighttest/missions").expanduser())
    return dirs


def _packaged_resource() -> resources.abc.Traversable:
    return resources.files("flighttest") / "missions"


@functools.cache
def packaged_dir() -> Path | None:
    """The wheel's ``flighttest/missions`` as a folder on disk, or None (a source tree has none)."""
    res = _packaged_resource()
    if not res.is_dir():
        return None
    if isinstance(res, Path):
        return res
    # not on the file system (a zipped install): as_file() takes single files only before Python
    # 3.12, and a script needs its TOML beside it, so the folder is copied out once
    tmp = Path(tempfile.mkdtemp(prefix="flighttest-missions-"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    for item in res.iterdir():
        if item.is_file():
            with resources.as_file(item) as path:
                shutil.copyfile(path, tmp / item.name)
    return tmp


def shipped_dir() -> Path | None:
    """The missions that come with flighttest: the checkout's in a source tree, else the packaged copy."""
    if CHECKOUT_DIR is not None and CHECKOUT_DIR.is_dir():
        return CHECKOUT_DIR
    return packaged_dir()


def search_dirs() -> list[Path]:
    """Where missions are looked for, first match wins (see the module docstring for why)."""
    shipped = shipped_dir()
    return user_dirs() + ([shipped] if shipped is not None else [])


def mission_dir(name: str) -> Path:
    """The folder the mission's script and TOML are taken from."""
    if name not in MISSIONS:
        raise FlighttestError(f"unknown mission {name!r} (known: {', '.join(MISSIONS)})")
    stem = MISSIONS[name]
    dirs = search_dirs()
    for d in dirs:
        script, config = d / f"{stem}.py", d / f"{stem}.toml"
        if script.is_file() and config.is_file():
            return d
        if script.is_file() or config.is_file():
            have, missing = (script, config.name) if script.is_file() else (config, script.name)
            raise FlighttestError(f"{have}: mission {name!r} needs {missing} beside it (copy both files)")
    raise FlighttestError(
        f"mission {name!r} not found: no {stem}.py in {', '.join(str(d) for d in dirs)}"
        + ("" if shipped_dir() else " (and this flighttest has no shipped missions: a broken install?)")
    )


def mission_script_path(name: str) -> Path:
    return mission_dir(name) / f"{MISSIONS[name]}.py"


def mission_config_path(name: str) -> Path:
    return mission_dir(name) / f"{MISSIONS[name]}.toml"


def load_mission_module(name: str) -> ModuleType:
    path = mission_script_path(name)
    spec = importlib.util.spec_from_file_location(f"flighttest_mission_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# The shipped missions' folder (tests read the shipped TOMLs from it); lookups go through mission_dir().
MISSIONS_DIR: Path = shipped_dir() or Path(__file__).resolve().parents[1] / "missions"
