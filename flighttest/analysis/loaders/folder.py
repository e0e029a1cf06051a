"""flighttest's own log folders (docs/CONTRACTS.md "Flight log folders") → :class:`FlightLog`.

The vehicle state comes from ``flight.tlog`` (see :mod:`.tlog`); ``setpoints.csv`` and ``guard.csv``
are put on the state clock through their ``unix_s`` column (the tlog's wall clock), and
``meta.json``, ``events.jsonl``, ``summary.json`` and the flown ``trajectory.json`` are kept as the
log's metadata (mission, vehicle, trajectory kind). A folder still being written, or one whose
process was killed, loads with what is there: unreadable side files become notes.

Height sources and the attitude source are the tlog's. Parameters, the first that has any:
``params.json`` (``{"params": {name: value}, ...}``, the snapshot read at preflight), the
``"params"`` of ``preflight.json`` (the few the preflight checks read), the tlog's ``PARAM_VALUE``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from flighttest.analysis.loaders.tlog import load_tlog
from flighttest.analysis.schema import FlightLog
from flighttest.errors import FlighttestError

TLOG_NAME = "flight.tlog"


def is_log_folder(path: Path) -> bool:
    return path.is_dir() and ((path / TLOG_NAME).is_file() or (path / "meta.json").is_file())


def _json(path: Path, notes: list[str]) -> dict:
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        notes.append(f"{path.name} unreadable ({exc})")
        return {}
    return data if isinstance(data, dict) else {}


def _csv(path: Path, notes: list[str], unix0: float, start_unix: float | None) -> pd.DataFrame | None:
    if not path.is_file():
        return None
    try:
        df = pd.read_csv(path)
    except (OSError, ValueError) as exc:
        notes.append(f"{path.name} unreadable ({exc})")
        return None
    if df.empty:
        return None
    if "unix_s" in df and np.isfinite(unix0) and df["unix_s"].notna().any():
        df["t_s"] = df["unix_s"] - unix0
    elif "t_s" in df and start_unix is not None and np.isfinite(unix0):
        df["t_s"] = df["t_s"] + (start_unix - unix0)
    else:
        notes.append(f"{path.name}: no common clock with the tlog; its times are relative to mission start")
    return df


def _params(path: Path, log: FlightLog, notes: list[str]) -> tuple[dict[str, float], str | None]:
    for name in ("params.json", "preflight.json"):
        raw = _json(path / name, notes).get("params")
        if isinstance(raw, dict):
            params = {
                str(k): float(v) for k, v in raw.items() if isinstance(v, int | float) and not isinstance(v, bool)
            }
            if params:
                return dict(sorted(params.items())), name
    return log.params, log.params_source


def load_folder(path: Path) -> FlightLog:
    notes: list[str] = []
    tlog = path / TLOG_NAME
    if not tlog.is_file():
        raise FlighttestError(f"{path}: flight log folder has no {TLOG_NAME}")
    log = load_tlog(tlog)
    meta = _json(path / "meta.json", notes)
    summary = _json(path / "summary.json", notes)
    traj = _json(path / "trajectory.json", notes)
    if summary:
        meta["summary"] = summary
    if traj:
        meta["trajectory_meta"] = traj
    unix0 = float(log.state["unix_s"].iloc[0])
    start = meta.get("start_unix_s", meta.get("start_unix"))
    start = float(start) if isinstance(start, int | float) else None
    setpoints = _csv(path / "setpoints.csv", notes, unix0, start)
    guard = _csv(path / "guard.csv", notes, unix0, start)
    params, params_source = _params(path, log, notes)
    events: list[dict] = []
    ev_path = path / "events.jsonl"
    if ev_path.is_file():
        for line in ev_path.read_text(encoding="utf-8", errors="replace").splitlines():
            try:
                ev = json.loads(line)
            except ValueError:
                continue  # the last line of a killed process may be cut
            if isinstance(ev, dict):
                if isinstance(ev.get("unix_s"), int | float):
                    ev["t_s"] = ev["unix_s"] - unix0
                events.append(ev)
    return FlightLog(
        path=path,
        source="flighttest-folder",
        state=log.state,
        setpoints=setpoints,
        guard=guard,
        events=events,
        meta=meta,
        missing=log.missing,
        notes=log.notes + notes,
        heights=log.heights,
        attitude_source=log.attitude_source,
        params=params,
        params_source=params_source,
    )
