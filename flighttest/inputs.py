"""The one input layer: every number, file and output path a command takes is checked here, once.

- :class:`Range` is a physical range with a unit. The same object is an argparse ``type=`` (its
  error becomes ``argument --height: must be ...``) and the validator of TOML fields
  (``Range.check(value, name)`` raises one :class:`FlighttestError` line naming the input).
- :func:`check_input_file` / :func:`read_text_file`: an input is a readable regular file (never a
  FIFO or a device, which would hang the reader), of bounded size, and text files are UTF-8 (a
  UTF-16, Latin-1 or binary file is one line saying so, not a ``UnicodeDecodeError``).
- :func:`check_output_path` runs before any work starts: the path is not empty, not a folder, not
  under a file, its name fits the file system, and it has the extension the writer needs. Missing
  folders are created only when the file is written (:func:`atomic_write`), so a refused or failed
  command leaves nothing behind; the file appears whole or not at all.
- :class:`ArgumentParser`: argparse with one-line errors (raised as :class:`UsageError`, which the
  CLI prints as ``flighttest: error: ...`` with exit code 2) and negative numbers in scientific
  notation (``--v-ned 0 0 -1e-1``) taken as numbers, not options.

Physical bounds (why these numbers):

- heights ≤ 120 m: the ceiling of small unmanned aircraft in the EU open category and the US
  (400 ft); a descent test never needs more, and an unbounded height makes the planners allocate
  without end (``plan vertical --height 1e9``).
- speeds ≤ 100 m/s per axis (no multicopter flies faster), winds ≤ 30 m/s for flying (a gale),
  accelerations ≤ 100 m/s² (10 g).
- durations ≤ 600 s: a trajectory or a probe sweep longer than ten minutes outlasts the battery.
- horizontal distances ≤ 1000 m: a flight test stays within sight.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import stat
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from flighttest.errors import FlighttestError

MAX_HEIGHT_M = 120.0
MAX_HORIZONTAL_M = 1000.0
MAX_SPEED_MPS = 100.0
MAX_WIND_MPS = 30.0
MAX_ACCEL_MPS2 = 100.0
MAX_DURATION_S = 600.0
MAX_TOML_BYTES = 1_000_000  # a profile or mission config is a few kB
MAX_JSON_BYTES = 16_000_000  # sidecars and campaign records
MAX_CSV_BYTES = 256_000_000  # 600 s of a trajectory at 1 kHz is ~120 MB
NAME_MAX_BYTES = 255  # one path component on Linux, macOS and Windows file systems
PATH_MAX_BYTES = 4095
# an output folder leaves this much of PATH_MAX_BYTES to what is written inside it (the campaign's deepest,
# flights/<time>-<mission>/ and a temporary file's name, is under 100 bytes)
OUTPUT_FOLDER_ROOM_BYTES = 200


class UsageError(FlighttestError):
    """A command line argparse refused (bad option, bad number): exit code 2 like any bad input."""


# -- numbers ----------------------------------------------------------------------------------------


def _fmt(x: float) -> str:
    return f"{x:g}"


def shown(value: Any, limit: int = 60) -> str:
    """``repr`` of a bad value for an error line, cut short: a line must stay one line and short."""
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """``: did you mean 'x500'?`` for a name close to a known one (case aside), else ``""``."""
    import difflib

    known = list(known)
    by_lower = {k.lower(): k for k in known}
    close = by_lower.get(name.lower()) or next(iter(difflib.get_close_matches(name, known, n=1, cutoff=0.6)), None)
    return f": did you mean {close!r}?" if close else ""


@dataclass(frozen=True)
class Range:
    """A finite number in ``[lo, hi]`` (``lo_open``/``hi_open`` exclude an end; ``None``: unbounded
    on that side). ``integer`` asks for a whole number. Callable as an argparse ``type``."""

    lo: float | None = None
    hi: float | None = None
    unit: str = ""
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False

    def bounds(self) -> str:
        """The range in words: ``> 0 and ≤ 120 m``, ``≥ 1 and ≤ 100``, or ``finite``."""
        unit = self.unit if self.unit.startswith("°") else f" {self.unit}" if self.unit else ""
        parts = []
        if self.lo is not None:
            parts.append(f"{'>' if self.lo_open else '≥'} {_fmt(self.lo)}")
        if self.hi is not None:
            parts.append(f"{'<' if self.hi_open else '≤'} {_fmt(self.hi)}")
        return " and ".join(parts) + unit if parts else "finite"

    def describe(self) -> str:
        """What a value must be: ``a number > 0 and ≤ 120 m``, ``a whole number ≥ 10 and ≤ 1000``."""
        if self.integer:
            return "a whole number" + ("" if self.lo is None and self.hi is None else f" {self.bounds()}")
        return "a finite number" if self.lo is None and self.hi is None else f"a number {self.bounds()}"

    def ok(self, value: Any) -> bool:
        if isinstance(value, bool) or not isinstance(value, int | float):
            return False
        if self.integer and not isinstance(value, int):
            return False
        if isinstance(value, float) and not math.isfinite(value):
            return False
        v = float(value) if not isinstance(value, int) else value
        if self.lo is not None and (v <= self.lo if self.lo_open else v < self.lo):
            return False
        return not (self.hi is not None and (v >= self.hi if self.hi_open else v > self.hi))

    def _need(self, value: Any) -> str:
        if isinstance(value, float) and not math.isfinite(value) and not self.integer:
            bounds = self.bounds()
            return "a finite number" + ("" if bounds == "finite" else f", {bounds}")
        return self.describe()

    def check(self, value: Any, name: str) -> Any:
        """``value`` as float (int when ``integer``) or one FlighttestError line naming ``name``."""
        if not self.ok(value):
            raise FlighttestError(f"{name} must be {self._need(value)} (got {shown(value)})")
        return int(value) if self.integer else float(value)

    def __call__(self, text: str) -> Any:
        """argparse ``type``: parse a command-line word, refuse it with the range in the message."""
        word = text.strip()
        try:
            value: Any = int(word, 10) if self.integer else float(word)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {self.describe()} (got {shown(text)})") from None
        if not self.ok(value):
            raise argparse.ArgumentTypeError(f"must be {self._need(value)} (got {shown(text)})")
        return value


FINITE = Range()
HEIGHT_M = Range(0.1, MAX_HEIGHT_M, "m")  # a descent or a probe amplitude
START_HEIGHT_M = Range(0.0, MAX_HEIGHT_M, "m", lo_open=True)  # above home
ALTITUDE_FLOOR_M = Range(0.0, MAX_HEIGHT_M, "m")
DISTANCE_M = Range(0.0, MAX_HORIZONTAL_M, "m", lo_open=True)  # radii, bounds, geofences
POSITION_M = Range(-MAX_HORIZONTAL_M, MAX_HORIZONTAL_M, "m")  # a point relative to the start
SPEED_MPS = Range(0.0, MAX_SPEED_MPS, "m/s", lo_open=True)
VELOCITY_MPS = Range(-MAX_SPEED_MPS, MAX_SPEED_MPS, "m/s")  # one NED component
WIND_MPS = Range(-MAX_WIND_MPS, MAX_WIND_MPS, "m/s")  # one NED component, for flying
MARGIN_MPS = Range(0.0, 5.0, "m/s")
W_ALLOW_MPS = Range(0.0, 20.0, "m/s")  # a straight-down rate tolerated: region check allows 0 (the cone)
W_ALLOW_POSITIVE_MPS = Range(0.01, 20.0, "m/s")  # a boundary the vehicle can descend along (onsets: ~0.5-2 m/s)
ACCEL_MPS2 = Range(-MAX_ACCEL_MPS2, MAX_ACCEL_MPS2, "m/s²")
FRACTION = Range(0.0, 1.0, lo_open=True)
QUAT_COMPONENT = Range(-100.0, 100.0)  # finite math; the unit norm is checked after, with its own message
TILT_DEG = Range(0.0, 90.0, "°", lo_open=True, hi_open=True)
ROLL_BOUND_DEG = Range(0.0, 180.0, "°", lo_open=True)
BODY_RATE_DPS = Range(0.0, 3600.0, "°/s", lo_open=True)
BODY_RATE_RPS = Range(0.0, 63.0, "rad/s", lo_open=True)  # 3600 °/s
DURATION_S = Range(0.0, MAX_DURATION_S, "s", lo_open=True)
CHIRP_RATE_RPS2 = Range(0.0, 10.0, "rad/s²", lo_open=True)
SPEED_STEP_MPS = Range(0.01, 10.0, "m/s")  # the probe's speed grid: ≤ 10 000 rows at 100 m/s
INTERVALS = Range(10, 500, integer=True)  # mesh intervals of the minimum-time solvers
SYSID = Range(1, 255, integer=True)


# -- argparse ---------------------------------------------------------------------------------------

# argparse's own pattern ('^-\d+$|^-\d*\.\d+$') misses '-1e-1', '-1.', '-inf': those would be taken
# for options and the command would fail with "expected 3 arguments". No option of ours looks like
# a number, so every number-looking word is a value (non-finite ones are then refused by Range).
_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.IGNORECASE)


class ArgumentParser(argparse.ArgumentParser):
    """argparse with one-line errors (:class:`UsageError`) and negative numbers in any notation.

    Sub-parsers made with ``add_subparsers().add_parser`` are of this class too (argparse uses the
    parent's class), so setting it on the root parser covers every command.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        # argparse has no public hook for this; the attribute is how it recognises negative numbers
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str):  # type: ignore[override]
        """Raise instead of printing usage and exiting: the CLI prints one line (and JSON with
        ``--json``), so a mistyped option looks like every other bad input."""
        where = self.prog.removeprefix("flighttest").strip()
        first = " ".join(message.split())
        raise UsageError(f"{where + ': ' if where else ''}{first} (see '{self.prog} --help')")


# -- files to read -----------------------------------------------------------------------------------

_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


class InputFileError(FlighttestError):
    """A file that cannot be read as asked: ``path`` and ``reason`` kept for callers that word it."""

    def __init__(self, path: Path | str, what: str, reason: str, message: str | None = None) -> None:
        super().__init__(message or f"{what} {path}: {reason}")
        self.path = str(path)
        self.reason = reason


def _path_text(path: Path | str, what: str) -> str:
    text = os.fspath(path)
    if not text.strip():
        raise InputFileError(text, what, "the path is empty", f"{what}: the path is empty")
    if _CONTROL.search(text):
        raise InputFileError(repr(text), what, "the path contains a control character (a stray newline?)")
    try:
        size = len(os.fsencode(text))
    except UnicodeError:
        raise InputFileError(repr(text), what, "the path cannot be encoded for this file system") from None
    if size > PATH_MAX_BYTES:
        raise InputFileError(text[:60] + "…", what, f"the path is too long ({size} bytes; at most {PATH_MAX_BYTES})")
    for part in Path(text).parts:
        n = len(os.fsencode(part))
        if n > NAME_MAX_BYTES:
            raise InputFileError(text[:60] + "…", what, f"a name in the path is too long ({n} bytes; at most "
                                 f"{NAME_MAX_BYTES})")  # fmt: skip
    return text


def _stat_error(exc: OSError, what: str, path: str) -> FlighttestError:
    if isinstance(exc, FileNotFoundError):
        return InputFileError(path, what, "not found", f"{what} not found: {path}")
    if isinstance(exc, NotADirectoryError):
        return InputFileError(path, what, "a folder in the path is a file")
    if isinstance(exc, PermissionError):
        return InputFileError(path, what, "permission denied")
    return InputFileError(path, what, str(exc.strerror or exc))


def check_input_file(path: Path | str, what: str, max_bytes: int) -> Path:
    """``path`` if it is a readable regular file of at most ``max_bytes``; else one error line."""
    text = _path_text(path, what)
    try:
        st = os.stat(text)
    except OSError as exc:
        raise _stat_error(exc, what, text) from None
    if stat.S_ISDIR(st.st_mode):
        raise InputFileError(text, what, "is a folder, not a file")
    if not stat.S_ISREG(st.st_mode):
        raise InputFileError(text, what, "is not a regular file (a FIFO, socket or device)")
    if st.st_size > max_bytes:
        raise InputFileError(text, what, f"too large ({st.st_size:,} bytes; at most {max_bytes:,})")
    if not os.access(text, os.R_OK):
        raise InputFileError(text, what, "permission denied")
    return Path(text)


def read_bytes_file(path: Path | str, what: str, max_bytes: int) -> bytes:
    p = check_input_file(path, what, max_bytes)
    try:
        with open(p, "rb") as f:
            data = f.read(max_bytes + 1)  # a file growing under us is still bounded
    except OSError as exc:
        raise _stat_error(exc, what, str(p)) from None
    if len(data) > max_bytes:
        raise InputFileError(p, what, f"too large (more than {max_bytes:,} bytes)")
    return data


def decode_text(data: bytes, path: Path | str, what: str) -> str:
    """UTF-8 text of a file (a UTF-8 byte-order mark is dropped); anything else is one line."""
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise InputFileError(path, what, "UTF-16 text; save it as UTF-8")
    if b"\x00" in data:
        raise InputFileError(path, what, "a binary file (NUL bytes), not UTF-8 text")
    try:
        return data.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as exc:
        bad = data[exc.start]
        raise InputFileError(
            path,
            what,
            f"not UTF-8 text (byte 0x{bad:02x} at offset {exc.start}; Latin-1 or another encoding? save it as UTF-8)",
        ) from None


def read_text_file(path: Path | str, what: str, max_bytes: int) -> str:
    """The UTF-8 text of a readable regular file of bounded size, or one FlighttestError line."""
    return decode_text(read_bytes_file(path, what, max_bytes), path, what)


# -- files to write -----------------------------------------------------------------------------------

IMAGE_SUFFIXES = (".png", ".pdf", ".svg")  # what the figures' matplotlib backend (Agg) writes


def check_output_path(path: Path | str, what: str, suffixes: Sequence[str] | None = None) -> Path:
    """``path`` if a file can be written there; checked before work starts, so nothing is computed
    (or flown) for an output that cannot be written.

    Refused: an empty path, a control character, a path ending in a separator or naming an existing
    folder, a FIFO or device, a name too long for the file system, a missing or unknown extension
    (``suffixes``, lower case), a folder in the path that is a file, an unwritable folder. Missing
    folders are fine: :func:`atomic_write` creates them when it writes.
    """
    text = _path_text(path, what)
    if text.endswith(("/", os.sep)) or Path(text).name in ("", ".", ".."):
        raise FlighttestError(f"{what} {text!r}: names a folder, not a file")
    p = Path(text)
    if suffixes is not None and p.suffix.lower() not in suffixes:
        got = f"'{p.suffix}'" if p.suffix else "none"
        raise FlighttestError(f"{what} {text}: the file name needs the extension {' or '.join(suffixes)} (got {got})")
    try:
        st = os.stat(p)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise _stat_error(exc, what, text) from None
    if st is not None:
        if stat.S_ISDIR(st.st_mode):
            raise FlighttestError(f"{what} {text}: is a folder, not a file")
        if not stat.S_ISREG(st.st_mode):
            raise FlighttestError(f"{what} {text}: is not a regular file (a FIFO, socket or device)")
    parent = p.parent
    while True:  # the nearest existing folder: a file there means the path cannot be made
        try:
            pst = os.stat(parent)
        except FileNotFoundError:
            if parent == parent.parent:
                break
            parent = parent.parent
            continue
        except OSError as exc:
            raise _stat_error(exc, what, text) from None
        if not stat.S_ISDIR(pst.st_mode):
            raise FlighttestError(f"{what} {text}: {parent} is a file, not a folder")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise FlighttestError(f"{what} {text}: the folder {parent} is not writable")
        break
    return p


@contextlib.contextmanager
def atomic_write(path: Path | str) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path``, on any error it is
    removed, with the folders this call created. A reader never sees half a file."""
    target = Path(path)
    created: list[Path] = []
    folder = target.parent
    while not folder.exists() and folder != folder.parent:
        created.append(folder)
        folder = folder.parent
    tmp = target.with_name(f".{target.name[:200]}.{os.getpid()}.tmp")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        for d in created:  # innermost first
            with contextlib.suppress(OSError):
                d.rmdir()
        raise


def check_text(value: Any, name: str, max_chars: int = 1000, single_line: bool = False) -> str:
    """A string field of a file: a string, bounded, without control characters (newlines allowed
    unless ``single_line``)."""
    if not isinstance(value, str):
        raise FlighttestError(f"{name} must be a string (got {shown(value)})")
    if len(value) > max_chars:
        raise FlighttestError(f"{name} is too long ({len(value)} characters; at most {max_chars})")
    bad = _CONTROL.search(value) if single_line else re.search(r"[\x00-\x08\x0b-\x1f\x7f]", value)
    if bad:
        raise FlighttestError(f"{name} contains a control character ({bad.group()!r})")
    if _SURROGATE.search(value):  # a file name's undecodable bytes: no UTF-8 file can hold them
        raise FlighttestError(f"{name} is not UTF-8 text (holds {_SURROGATE.search(value).group()!r})")
    return value


_SURROGATE = re.compile("[\ud800-\udfff]")


def check_path_text(path: Path | str, what: str) -> str:
    """The checks every path gets before the file system is asked about it: not empty (``Path('')``
    is the current folder), no control character, within the file system's length limits (a stat
    of a longer path raises ``ENAMETOOLONG``). For inputs that may be a file or a folder (log
    folders); :func:`check_input_file` and :func:`check_output_path` run the same checks."""
    return _path_text(path, what)


def display_path(path: Path | str) -> str:
    """A path as UTF-8 text, for tables, Parquet and messages: a name in another encoding (Latin-1 from an
    old card; Python keeps its bytes as surrogates, which UTF-8 text cannot hold) shows its bytes as ``\\xNN``."""
    return os.fsencode(os.fspath(path)).decode("utf-8", "backslashreplace")


def check_output_folder(text: str | os.PathLike, name: str) -> Path:
    """An output *folder* (``-o DIR``, ``--log-dir``) checked before anything is written or connects: a
    name (an empty one would be the current folder), no control character, and a folder there must be
    possible: the nearest existing ancestor is a writable folder, not a file. Nothing is created here."""
    text = os.fspath(text)
    if not text.strip() or any(not c.isprintable() for c in text):
        raise FlighttestError(f"{name} {text!r}: not a folder name (empty, or a control character)")
    _path_text(text, name)  # each name and the whole within the file system's limits
    size = len(os.fsencode(text))
    if size > PATH_MAX_BYTES - OUTPUT_FOLDER_ROOM_BYTES:
        most = PATH_MAX_BYTES - OUTPUT_FOLDER_ROOM_BYTES
        raise FlighttestError(f"{name} {text[:60]}…: the path is too long ({size} bytes; an output folder at most "
                              f"{most}, room for the files written inside)")  # fmt: skip
    root = Path(text)
    probe = root
    while True:  # the nearest folder that exists
        try:
            st = os.stat(probe)
            break
        except (FileNotFoundError, NotADirectoryError):
            if probe == probe.parent:
                return root
            probe = probe.parent
        except OSError as exc:
            raise FlighttestError(f"{name} {text}: {probe}: {exc.strerror or exc}") from None
    if not stat.S_ISDIR(st.st_mode):
        raise FlighttestError(f"{name} {text}: {probe} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise FlighttestError(f"{name} {text}: the folder {probe} is not writable")
    return root
