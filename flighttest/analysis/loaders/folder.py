"""flighttest's own log folders (docs/CONTRACTS.md "Flight log folders") → :class:`FlightLog`.

The vehicle state comes from ``flight.tlog`` (see :mod:`.tlog`); ``setpoints.csv`` and ``guard.csv``
are put on the state clock through their ``unix_s`` column (the tlog's wall clock), and
``meta.json``, ``events.jsonl``, ``summary.json`` and the flown ``trajectory.json`` are kept as the
log's metadata (mission, vehicle, trajectory kind). A folder still being written, or one whose
process was killed, loads with what is there.

Side files are read as what they claim to be or not at all, each problem one note
(``FlightLog.notes``), never a crash and never a value taken as written: a JSON file that is not
UTF-8, not JSON, nested too deeply or not an object is skipped; CSV values that are not numbers are
read as missing (rows without a usable time dropped, so ``t_s`` is always a finite number); an
``events.jsonl`` line that is not a JSON object is skipped, and an event field with a unit
(``t_s``, ``descent_time_s``, ``horizontal_error_m``, ...) holding anything but a finite number —
``true``, a string, ``Infinity`` — or a negative duration or distance is dropped from its event.

Height sources, the attitude source and the autopilot's wind report are the tlog's; the wind flighttest
flew with is ``guard.csv``'s (``wn/we/wd_mps``, ``wind_sd_mps``, ``wind_source``:
:mod:`flighttest.analysis.wind` takes it). Parameters, the first that has any:
``params.json`` (``{"params": {name: value}, ...}``, the snapshot read at preflight), the
``"params"`` of ``preflight.json`` (the few the preflight checks read), the tlog's ``PARAM_VALUE``.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from flighttest.analysis.loaders.tlog import load_tlog
from flighttest.analysis.schema import FlightLog
from flighttest.errors import FlighttestError
from flighttest.inputs import MAX_CSV_BYTES, MAX_JSON_BYTES, read_text_file, shown

TLOG_NAME = "flight.tlog"
MAX_EVENTS_BYTES = 64_000_000  # an hour of events at a few per second is ~10 MB
TEXT_COLUMNS = {"setpoints.csv": {"phase"}, "guard.csv": {"verdict", "action", "reason", "wind_source"}}
# event fields with a unit are numbers; of those, these are spans that cannot be negative
_UNIT_FIELD = re.compile(r"_(s|ms|m|mps|mps2|hz|dps|deg|pct)$")
_NON_NEGATIVE_FIELD = re.compile(r"(^|_)(time|duration|elapsed|error|distance|jitter)(_[a-z0-9]+)*_(s|ms|m)$")
SIGNED_FIELDS = frozenset({"height_error_m"})  # descent_reached: d − d_end, > 0 below the end point


def is_log_folder(path: Path) -> bool:
    """A folder holding ``flight.tlog`` or ``meta.json`` (False, not an error, for a path the file
    system cannot even look at: too long, not a folder, not permitted)."""
    try:
        return path.is_dir() and ((path / TLOG_NAME).is_file() or (path / "meta.json").is_file())
    except OSError:
        return False


def _exists(path: Path) -> bool:
    try:
        return os.path.lexists(path)
    except (OSError, ValueError):
        return False


def _json(path: Path, notes: list[str]) -> dict:
    """The JSON object in ``path`` ({} when absent; {} and a note when it is anything else)."""
    if not _exists(path):
        return {}
    try:
        data = json.loads(read_text_file(path, path.name, MAX_JSON_BYTES))
    except FlighttestError as exc:
        notes.append(f"{path.name} skipped: {_reason(exc, path)}")
        return {}
    except RecursionError:
        notes.append(f"{path.name} skipped: nested too deeply")
        return {}
    except ValueError as exc:
        notes.append(f"{path.name} skipped: not valid JSON ({exc})")
        return {}
    if not isinstance(data, dict):
        notes.append(f"{path.name} skipped: not a JSON object (a {_json_type(data)})")
        return {}
    return data


def _reason(exc: FlighttestError, path: Path) -> str:
    """An input error's reason without the path it starts with (the note names the file already)."""
    text = str(getattr(exc, "reason", "") or exc)
    return text.removeprefix(f"{path.name} {path}: ").removeprefix(f"{path.name} ")


def _json_type(value: Any) -> str:
    return {list: "list", str: "string", bool: "boolean", int: "number", float: "number"}.get(type(value), "null")


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _csv(path: Path, notes: list[str], unix0: float, start_unix: float | None) -> pd.DataFrame | None:
    """A side table on the state clock: numeric columns as numbers (text in them read as missing),
    rows without a finite time dropped; None (with a note) when there is no usable time at all."""
    if not _exists(path):
        return None
    try:
        df = pd.read_csv(io.StringIO(read_text_file(path, path.name, MAX_CSV_BYTES)), low_memory=False)
    except FlighttestError as exc:
        notes.append(f"{path.name} skipped: {_reason(exc, path)}")
        return None
    except (ValueError, OverflowError, pd.errors.ParserError) as exc:  # EmptyDataError is a ValueError
        if "No columns to parse" not in str(exc):
            notes.append(f"{path.name} skipped: not a readable CSV table ({' '.join(str(exc).split())[:120]})")
        return None
    if df.empty:
        return None
    df.columns = [str(c) for c in df.columns]
    bad_cols = []
    # the last row of a killed process may be cut anywhere ("1.5e"): like a cut last line of
    # events.jsonl it is dropped or read as missing without a note
    body = np.arange(len(df)) < len(df) - 1
    for col in df.columns:
        if col in TEXT_COLUMNS.get(path.name, ()):
            continue
        if df[col].dtype.kind not in "biuf":
            num = pd.to_numeric(df[col], errors="coerce")
            if (num.isna() & df[col].notna() & body).any():
                bad_cols.append(col)
            df[col] = num
        df[col] = df[col].astype(float).where(np.isfinite(df[col].astype(float)))
    if bad_cols:
        notes.append(f"{path.name}: values that are not numbers in {', '.join(bad_cols[:5])} read as missing")
    if "unix_s" in df and np.isfinite(unix0) and df["unix_s"].notna().any():
        df["t_s"] = df["unix_s"] - unix0
    elif "t_s" in df and start_unix is not None and np.isfinite(unix0):
        df["t_s"] = df["t_s"] + (start_unix - unix0)
    elif "t_s" in df:
        notes.append(f"{path.name}: no common clock with the tlog; its times are relative to mission start")
    else:
        notes.append(f"{path.name} skipped: no time column (t_s or unix_s)")
        return None
    ok = np.isfinite(df["t_s"].to_numpy(float))
    if not ok.all():
        if (~ok & body).any():
            notes.append(f"{path.name}: {int((~ok & body).sum())} row(s) without a usable time dropped")
        df = df[ok].reset_index(drop=True)
    return df if len(df) else None


def _params(path: Path, log: FlightLog, notes: list[str]) -> tuple[dict[str, float], str | None]:
    for name in ("params.json", "preflight.json"):
        raw = _json(path / name, notes).get("params")
        if isinstance(raw, dict):
            params = {str(k): float(v) for k, v in raw.items() if _finite(v)}
            if params:
                return dict(sorted(params.items())), name
    return log.params, log.params_source


def _clean_event(ev: dict, dropped: dict[str, int]) -> dict:
    """The event without unit fields that are not finite numbers, or negative spans (counted in
    ``dropped`` by field name): ``"descent_time_s": true`` must not become a 1 s descent."""
    out = {}
    for key, value in ev.items():
        key = str(key)
        if isinstance(value, dict):  # a record of its own (the collector's per-generation max_ms)
            out[key] = value
            continue
        if isinstance(value, list) and "_ned_" in key and value and all(_finite(v) for v in value):
            out[key] = value  # a vector (wind_ned_mps), each component a number
            continue
        negative_span = _NON_NEGATIVE_FIELD.search(key) is not None and key not in SIGNED_FIELDS
        bad = not _finite(value) or (negative_span and value < 0)
        if _UNIT_FIELD.search(key) and value is not None and bad:
            dropped[key] = dropped.get(key, 0) + 1
            continue
        out[key] = value
    return out


def _events(path: Path, unix0: float, notes: list[str]) -> list[dict]:
    if not _exists(path):
        return []
    try:
        text = read_text_file(path, path.name, MAX_EVENTS_BYTES)
    except FlighttestError as exc:
        notes.append(f"{path.name} skipped: {_reason(exc, path)}")
        return []
    events: list[dict] = []
    lines = text.splitlines()
    damaged, not_object = 0, 0
    dropped: dict[str, int] = {}
    for k, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            ev = json.loads(line)
        except (ValueError, RecursionError):
            if k < len(lines) - 1:  # the last line of a killed process may be cut: not worth a note
                damaged += 1
            continue
        if not isinstance(ev, dict):
            not_object += 1
            continue
        ev = _clean_event(ev, dropped)
        if _finite(ev.get("unix_s")) and np.isfinite(unix0):
            ev["t_s"] = ev["unix_s"] - unix0
        events.append(ev)
    if damaged:
        notes.append(f"{path.name}: {damaged} line(s) that are not JSON skipped")
    if not_object:
        notes.append(f"{path.name}: {not_object} line(s) that are not JSON objects skipped")
    if dropped:
        fields = ", ".join(f"{k} ({n}×)" if n > 1 else k for k, n in list(dropped.items())[:5])
        notes.append(f"{path.name}: event fields that are not finite numbers (or negative spans) ignored: {fields}")
    return events


def _clean_meta(meta: dict, notes: list[str]) -> dict:
    """Fields the analysis reads from ``meta.json``/``trajectory.json`` of the type it needs, or gone."""
    for key in ("start_unix_s", "start_unix"):
        if key in meta and not _finite(meta[key]):
            notes.append(f"meta.json: {key} is not a finite number ({shown(meta[key], 30)}), ignored")
            del meta[key]
    traj = meta.get("trajectory")
    if isinstance(traj, dict):
        meta["trajectory"] = {k: v for k, v in traj.items() if k not in ("kind", "path") or isinstance(v, str)}
    elif traj is not None and not isinstance(traj, str):
        del meta["trajectory"]
    tm = meta.get("trajectory_meta")
    if isinstance(tm, dict) and "kind" in tm and not isinstance(tm["kind"], str):
        meta["trajectory_meta"] = {k: v for k, v in tm.items() if k != "kind"}
    elif tm is not None and not isinstance(tm, dict):
        del meta["trajectory_meta"]
    return meta


def load_folder(path: Path) -> FlightLog:
    notes: list[str] = []
    tlog = path / TLOG_NAME
    if not tlog.is_file():
        raise FlighttestError(f"{path}: flight log folder has no {TLOG_NAME}")
    from flighttest.analysis.loaders import check_log_path  # the package imports this module

    log = load_tlog(check_log_path(tlog))  # a regular file of bounded size, not empty
    meta = _json(path / "meta.json", notes)
    summary = _json(path / "summary.json", notes)
    traj = _json(path / "trajectory.json", notes)
    if summary:
        meta["summary"] = summary
    if traj:
        meta["trajectory_meta"] = traj
    meta = _clean_meta(meta, notes)
    unix0 = float(log.state["unix_s"].iloc[0])
    start = meta.get("start_unix_s", meta.get("start_unix"))
    start = float(start) if _finite(start) else None
    setpoints = _csv(path / "setpoints.csv", notes, unix0, start)
    guard = _csv(path / "guard.csv", notes, unix0, start)
    params, params_source = _params(path, log, notes)
    events = _events(path / "events.jsonl", unix0, notes)
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
        wind_reported=log.wind_reported,
        accel_source=log.accel_source,
    )
