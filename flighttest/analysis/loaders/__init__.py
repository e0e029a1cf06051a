"""Load any supported log into a :class:`~flighttest.analysis.schema.FlightLog`.

``load_log(path)`` checks the path first (not empty, not too long, a folder or a regular file: a
FIFO or a device would block the reader for ever) and then tells the format from the **content**,
whatever the file is called: a PX4 ULog starts with ``ULog``, an ArduPilot DataFlash log with
``A3 95``, a MAVLink ``.tlog`` is a chain of records ``[8-byte big-endian UNIX µs][0xFD|0xFE frame]``
(several in a row are checked, so stray bytes do not pass for one). The name decides only when the
content says nothing: a ``.tlog`` whose first records are damaged still goes to the tlog reader,
which resynchronises; a ``.ulg`` or ``.bin`` without its magic is refused as such. Anything else
is refused with one line.

Damaged content never escapes as another exception: every reader's own failure on a file becomes
one :class:`FlighttestError` line naming the file, and numpy's warnings about the NaN and
infinities a damaged file holds are silenced here, at the reader, not for the caller's code.
"""

from __future__ import annotations

import os
import stat
import struct
import warnings
from pathlib import Path

import numpy as np

from flighttest.analysis.loaders.folder import is_log_folder, load_folder
from flighttest.analysis.schema import FlightLog
from flighttest.errors import FlighttestError
from flighttest.inputs import check_path_text

LOG_SUFFIXES = {".tlog", ".bin", ".ulg"}
# a log is read whole (the tlog reader holds it in memory, DataFlash maps it): an hour of PX4 ULog at
# its default rates is ~0.5 GB, so this is room to spare, and a bound on what a mistaken path costs
MAX_LOG_BYTES = 4_000_000_000
SNIFF_BYTES = 64 * 1024
ULOG_MAGIC = b"ULog"
DF_MAGIC = b"\xa3\x95"
_TLOG_RECORDS = 3  # consecutive records that make a tlog (random bytes chain 3 with odds ~1e-20)
_TLOG_SCAN = 4096  # offsets tried for the first record (a damaged first record is skipped)
_TLOG_GAP_US = 3 * 24 * 3600 * 1_000_000  # the tlog reader's resync window (mavlink_frames)
FORMAT_NAMES = {
    "tlog": "MAVLink tlog",
    "dataflash": "ArduPilot DataFlash log",
    "ulog": "PX4 ULog",
    "folder": "flighttest log folder",
}
_SUFFIX_FORMAT = {".tlog": "tlog", ".mavlink": "tlog", ".bin": "dataflash", ".ulg": "ulog"}


def check_log_path(path: Path | str) -> Path:
    """``path`` if it can be a log: a folder, or a readable, non-empty regular file of bounded size.

    One :class:`FlighttestError` line otherwise; never blocks (a FIFO is refused, not opened)."""
    text = check_path_text(path, "log")
    try:
        st = os.stat(text)
    except FileNotFoundError:
        raise FlighttestError(f"{text}: no such file or folder") from None
    except NotADirectoryError:
        raise FlighttestError(f"{text}: a folder in the path is a file") from None
    except OSError as exc:
        raise FlighttestError(f"{text}: cannot read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        return Path(text)
    if not stat.S_ISREG(st.st_mode):
        raise FlighttestError(f"{text}: not a regular file (a FIFO, socket or device); a log is a file or a folder")
    if st.st_size == 0:
        raise FlighttestError(f"{text}: empty file")
    if st.st_size > MAX_LOG_BYTES:
        raise FlighttestError(f"{text}: too large for a flight log ({st.st_size:,} bytes; at most {MAX_LOG_BYTES:,})")
    if not os.access(text, os.R_OK):
        raise FlighttestError(f"{text}: permission denied")
    return Path(text)


def _chains_tlog_records(head: bytes, start: int) -> bool:
    """Whether ``_TLOG_RECORDS`` tlog records follow each other from ``start`` (or, in a short file,
    at least two up to its exact end), their timestamps within the reader's resync window."""
    n, pos, count, last = len(head), start, 0, None
    while count < _TLOG_RECORDS:
        if pos == n and count >= 2:
            return True
        if pos + 8 + 8 > n:
            return False
        magic = head[pos + 8]
        if magic == 0xFD:
            flen = 12 + head[pos + 9] + (13 if head[pos + 10] & 1 else 0)
        elif magic == 0xFE:
            flen = 8 + head[pos + 9]
        else:
            return False
        ts = struct.unpack_from(">Q", head, pos)[0]
        if last is not None and abs(ts - last) >= _TLOG_GAP_US:
            return False
        if pos + 8 + flen > n:
            return False
        last, pos, count = ts, pos + 8 + flen, count + 1
    return True


def sniff(head: bytes) -> str | None:
    """'ulog', 'dataflash' or 'tlog' from the first bytes of a file; None when they are none of these."""
    if head.startswith(ULOG_MAGIC):
        return "ulog"
    if head.startswith(DF_MAGIC):
        return "dataflash"
    for start in range(min(_TLOG_SCAN, len(head))):
        if head[start + 8 : start + 9] in (b"\xfd", b"\xfe") and _chains_tlog_records(head, start):
            return "tlog"
    return None


def _head(path: Path, size: int = SNIFF_BYTES) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(size)
    except OSError as exc:
        raise FlighttestError(f"{path}: cannot read ({exc.strerror or exc})") from None


def log_format(path: Path) -> str:
    """'folder', 'tlog', 'dataflash' or 'ulog'; raises FlighttestError for anything else."""
    path = check_log_path(path)
    if path.is_dir():
        if is_log_folder(path):
            return "folder"
        raise FlighttestError(f"{path}: not a flighttest log folder (no flight.tlog or meta.json)")
    kind = sniff(_head(path))
    if kind is not None:
        return kind
    suffix = path.suffix.lower()
    if _SUFFIX_FORMAT.get(suffix) == "tlog":
        return "tlog"  # damaged from the start: the tlog reader resynchronises on later records
    if suffix == ".ulg":
        raise FlighttestError(f"{path}: not a PX4 ULog file (bad header)")
    if suffix == ".bin":
        raise FlighttestError(f"{path}: not an ArduPilot DataFlash log (bad header)")
    raise FlighttestError(
        f"{path}: unknown log format: the content is not a MAVLink .tlog, an ArduPilot DataFlash .bin or a PX4 "
        "ULog .ulg (nor is it a flighttest log folder)"
    )


def looks_like_log(path: Path) -> bool:
    """For walking folders: a regular file named like a log, or whose first bytes are one's."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return False  # a FIFO named x.tlog would block the reader
    except OSError:
        return False
    if path.suffix.lower() in LOG_SUFFIXES:
        return True
    try:
        with open(path, "rb") as fh:
            return sniff(fh.read(_TLOG_SCAN + 1024)) is not None
    except OSError:
        return False


def _read(path: Path, kind: str) -> FlightLog:
    if kind == "folder":
        return load_folder(path)
    if kind == "tlog":
        from flighttest.analysis.loaders.tlog import load_tlog

        return load_tlog(path)
    if kind == "dataflash":
        from flighttest.analysis.loaders.dataflash import load_dataflash

        return load_dataflash(path)
    from flighttest.analysis.loaders.ulog import load_ulog

    return load_ulog(path)


def load_log(path: Path | str) -> FlightLog:
    path = check_log_path(path)  # before Path(): Path("") would be the current folder
    kind = log_format(path)
    # a damaged log holds NaN, infinities and repeated times: numpy's warnings about them say nothing
    # the loaders do not handle (non-finite samples are dropped, missing streams noted)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        try:
            log = _read(path, kind)
        except FlighttestError:
            raise
        except Exception as exc:  # a reader tripping over damaged content: the file's problem, in one line
            detail = " ".join(f"{type(exc).__name__}: {exc}".split())[:200]
            what = FORMAT_NAMES[kind]
            raise FlighttestError(f"{path}: cannot read this {what}: its content is damaged ({detail})") from None
    expected = _SUFFIX_FORMAT.get(path.suffix.lower())
    if kind != "folder" and expected is not None and expected != kind:
        log.notes.append(f"the content is a {FORMAT_NAMES[kind]} although the name ends in {path.suffix}")
    return log
