"""Many flights at once: walk a folder, analyse every log on every core, keep a Parquet history.

``find_logs(root)`` returns flighttest log folders (a folder counts once, its ``flight.tlog`` is
not listed again) and loose log files: named ``.tlog``/``.bin``/``.ulg``, or of any name when
their first bytes are a log's (:func:`flighttest.analysis.loaders.looks_like_log`); FIFOs and
devices are never listed (reading one would block), and a name with a control character is skipped
with a note (the other logs are analysed). ``analyse_many`` runs the pipeline in a process
pool (``os.cpu_count()`` workers); a log that fails gives one error line, not a stopped campaign.
``write_parquet`` stores the per-descent table (one row per descent, the ``log`` column says which
file) for pandas or DuckDB, written whole or not at all.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

from flighttest.analysis.loaders import looks_like_log
from flighttest.analysis.loaders.folder import is_log_folder
from flighttest.analysis.segment import SegmentConfig
from flighttest.errors import FlighttestError
from flighttest.inputs import InputFileError, atomic_write, check_path_text

PARQUET_NAME = "flighttest-descents.parquet"
MAX_JOBS = 256  # worker processes: beyond any machine's cores, and each holds a log in memory


@contextlib.contextmanager
def quiet_numerics() -> Iterator[None]:
    """Around the analysis of one log: numpy's RuntimeWarnings (all-NaN windows of streams a log
    lacks, divisions by a zero spread) and matplotlib's layout warnings about empty axes say nothing
    the analysis does not handle, and on stderr they were up to 35 lines per log. Only inside this
    block: a caller's own code keeps its warnings."""
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        warnings.filterwarnings("ignore", category=UserWarning, module=r"matplotlib\..*")
        yield


def find_logs(root: Path) -> tuple[list[Path], list[str]]:
    """(logs, skipped): the logs under ``root`` in sorted order, and one line per file or folder left out
    because its path is not one flighttest takes (a control character such as a newline in the name, a
    path beyond the file system's length): named and skipped, so the rest of the folder is analysed."""
    found: list[Path] = []
    skipped: list[str] = []

    def takes(path: Path, kind: str) -> bool:
        try:
            check_path_text(path, kind)
        except InputFileError as exc:
            skipped.append(f"skipped the {kind} {exc.path}: {exc.reason}; rename it to analyse it")
            return False
        return True

    for dirpath, dirnames, filenames in os.walk(root):
        d = Path(dirpath)
        if is_log_folder(d):
            found.append(d)
            dirnames.clear()
            continue
        dirnames[:] = sorted(n for n in dirnames if takes(d / n, "folder"))
        found += [d / f for f in sorted(filenames)
                  if f != PARQUET_NAME and takes(d / f, "file") and looks_like_log(d / f)]  # fmt: skip
    return found, skipped


def _one(args: tuple[str, str | None, SegmentConfig | None, bool]) -> tuple[str, dict | None, str | None]:
    path, vehicle, seg, profile_now = args
    from flighttest.analysis.pipeline import analyse_path

    try:
        with quiet_numerics():
            a = analyse_path(path, vehicle, seg, profile_now)
            result = {"summary": a.summary(), "descents": a.descents, "events": a.log.events, "meta": a.log.meta}
    except FlighttestError as exc:
        return path, None, str(exc)
    except Exception as exc:  # a worker must never take the campaign down
        detail = " ".join(f"{type(exc).__name__}: {exc}".split())[:200]
        return path, None, f"{path}: analysis failed ({detail})"
    return path, result, None


def analyse_many(
    paths: list[Path], vehicle: str | None, seg: SegmentConfig | None = None, workers: int | None = None,
    profile_now: bool = False,
) -> list[tuple[str, dict | None, str | None]]:
    """(path, {"summary", "descents", "events", "meta"} or None, error or None) per log, in input order;
    ``profile_now``: judge each flight with its vehicle's profile as it is today, not as it flew."""
    jobs = [(str(p), vehicle, seg, profile_now) for p in paths]
    workers = max(1, min(workers or os.cpu_count() or 1, len(jobs), MAX_JOBS))
    if workers == 1:
        return [_one(j) for j in jobs]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(_one, jobs))


def descent_table(tables: list[pd.DataFrame]) -> pd.DataFrame:
    """The per-descent tables of many logs as one (an empty table with the key columns when none)."""
    frames = [t for t in tables if len(t)]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=["log", "descent"])


def write_parquet(tables: list[pd.DataFrame], out: Path) -> Path:
    df = descent_table(tables)
    for col in df.columns:
        if df[col].dtype == object:
            df[col] = df[col].astype("string")
    try:
        with atomic_write(out) as tmp:
            df.to_parquet(tmp, index=False)
    except OSError as exc:
        raise FlighttestError(f"{out}: cannot write Parquet ({exc.strerror or exc})") from None
    return out
