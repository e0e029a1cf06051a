"""Load any supported log into a :class:`~flighttest.analysis.schema.FlightLog`.

``load_log(path)`` sniffs the content (not only the suffix): a flighttest log folder, a MAVLink
``.tlog``, an ArduPilot DataFlash ``.bin`` (magic ``A3 95``) or a PX4 ``.ulg`` (magic ``ULog``).
Anything else is refused with one line.
"""

from __future__ import annotations

from pathlib import Path

from flighttest.analysis.loaders.folder import is_log_folder, load_folder
from flighttest.analysis.schema import FlightLog
from flighttest.errors import FlighttestError

LOG_SUFFIXES = {".tlog", ".bin", ".ulg"}


def log_format(path: Path) -> str:
    """'folder', 'tlog', 'dataflash' or 'ulog'; raises FlighttestError for anything else."""
    if path.is_dir():
        if is_log_folder(path):
            return "folder"
        raise FlighttestError(f"{path}: not a flighttest log folder (no flight.tlog or meta.json)")
    if not path.exists():
        raise FlighttestError(f"{path}: no such file or folder")
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise FlighttestError(f"{path}: cannot read ({exc.strerror})") from None
    if not head:
        raise FlighttestError(f"{path}: empty file")
    if head.startswith(b"ULog"):
        return "ulog"
    if head.startswith(b"\xa3\x95"):
        return "dataflash"
    suffix = path.suffix.lower()
    if suffix in {".tlog", ".mavlink"}:
        return "tlog"
    if suffix == ".ulg":
        raise FlighttestError(f"{path}: not a PX4 ULog file (bad header)")
    if suffix == ".bin":
        raise FlighttestError(f"{path}: not an ArduPilot DataFlash log (bad header)")
    raise FlighttestError(
        f"{path}: unknown log format '{suffix or path.name}' (expected .tlog, .bin, .ulg or a flighttest log folder)"
    )


def load_log(path: Path | str) -> FlightLog:
    path = Path(path)
    kind = log_format(path)
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
