"""The mission scripts users run and edit: ``missions/<script>.py`` with a TOML config beside each.

A script defines ``CONFIG`` (its TOML) and ``plan(profile, cfg) -> Trajectory``; they are found next to
the source tree (the README's editable install), so an edited script is what flies.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

from flighttest.errors import FlighttestError

MISSIONS = {"probe": "vrs_probe", "helix": "helix_descent", "vertical": "vertical_descent"}
MISSIONS_DIR = Path(__file__).resolve().parents[1] / "missions"


def mission_config_path(name: str) -> Path:
    return MISSIONS_DIR / f"{MISSIONS[name]}.toml"


def load_mission_module(name: str) -> ModuleType:
    path = MISSIONS_DIR / f"{MISSIONS[name]}.py"
    if not path.is_file():
        raise FlighttestError(f"mission script not found: {path}")
    spec = importlib.util.spec_from_file_location(f"flighttest_mission_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
