"""Many flights at once: walk a folder, analyse every log on every core, keep a Parquet history.

``find_logs(root)`` returns flighttest log folders (a folder counts once, its ``flight.tlog`` is
not listed again) and loose ``.tlog``/``.bin``/``.ulg`` files. ``analyse_many`` runs the pipeline
in a process pool (``os.cpu_count()`` workers); a log that fails gives one error line, not a
stopped campaign. ``write_parquet`` stores the per-descent table (one row per descent, the
``log`` column says which file) for pandas or DuckDB.
"""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd

from flighttest.analysis.loaders import LOG_SUFFIXES
from flighttest.analysis.loaders.folder import is_log_folder
from flighttest.analysis.segment import SegmentConfig
from flighttest.errors import FlighttestError

PARQUET_NAME = "flighttest-descents.parquet"


def find_logs(root: Path) -> list[Path]:
    found: list[Path] = []
    for dirpath, dirnames, filenames in os.walk(root):
        d = Path(dirpath)
        if is_log_folder(d):
            found.append(d)
            dirnames.clear()
            continue
        dirnames.sort()
        found += [d / f for f in sorted(filenames) if Path(f).suffix.lower() in LOG_SUFFIXES]
    return found


def _one(args: tuple[str, str | None, SegmentConfig | None]) -> tuple[str, dict | None, str | None]:
    path, vehicle, seg = args
    from flighttest.analysis.pipeline import analyse_path

    try:
        a = analyse_path(path, vehicle, seg)
    except FlighttestError as exc:
        return path, None, str(exc)
    except Exception as exc:  # a worker must never take the campaign down
        return path, None, f"{path}: analysis failed ({type(exc).__name__}: {exc})"
    return path, {"summary": a.summary(), "descents": a.descents, "events": a.log.events, "meta": a.log.meta}, None


def analyse_many(
    paths: list[Path], vehicle: str | None, seg: SegmentConfig | None = None, workers: int | None = None
) -> list[tuple[str, dict | None, str | None]]:
    """(path, {"summary", "descents", "events", "meta"} or None, error or None) per log, in input order."""
    jobs = [(str(p), vehicle, seg) for p in paths]
    workers = max(1, min(workers or os.cpu_count() or 1, len(jobs)))
    if workers == 1:
        return [_one(j) for j in jobs]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(_one, jobs))


def write_parquet(tables: list[pd.DataFrame], out: Path) -> Path:
    frames = [t for t in tables if len(t)]
    df = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=["log", "descent"])
    for col in df.columns:
        if df[col].dtype == object:
            df[col] = df[col].astype("string")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        df.to_parquet(out, index=False)
    except OSError as exc:
        raise FlighttestError(f"{out}: cannot write Parquet ({exc.strerror})") from None
    return out
