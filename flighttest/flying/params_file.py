"""Parameter files as QGroundControl writes and loads them, and what applying one would change.

QGroundControl's format (``ParameterManager::writeParametersToStream``): comment lines start with ``#``;
every other line is ``vehicle-id  component-id  NAME  value  MAV_PARAM_TYPE``, tab-separated. Mission
Planner's ``NAME,value`` lines (ArduPilot's ``.param`` files) load too. Values are compared as the vehicle
stores them (IEEE single precision: a file's 0.1 is the vehicle's 0.100000001).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from fnmatch import fnmatchcase
from pathlib import Path

import numpy as np

from flighttest.analysis.params import same_value
from flighttest.errors import FlighttestError
from flighttest.inputs import atomic_write, read_text_file, shown

MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9
INT_TYPES = frozenset(range(1, 9))  # UINT8 … INT64
MAX_FILE_BYTES = 4 * 1024 * 1024  # ArduCopter's full set is about 60 kB
MAX_NAME_CHARS = 16  # MAVLink's param_id
# values the autopilot keeps itself (statistics, the ground pressure of this boot, the mission's size, device
# ids, the flight time): a saved file's old values are left alone. ArduCopter SITL refused BARO1_GND_PRESS
# and MIS_TOTAL from a save of minutes before (bench/RESULTS.md, "Parameter files on real firmware").
AUTOPILOT_OWN = ("STAT_*", "BARO*_GND_PRESS", "MIS_TOTAL", "COMPASS_DEC", "FORMAT_VERSION", "SYSID_SW_*",
                 "*_DEVID*", "*_DEV_ID*", "LND_FLIGHT_T_*", "COM_FLIGHT_UUID")  # fmt: skip


@dataclass(frozen=True)
class ParamChange:
    name: str
    now: float | int
    new: float | int

    def record(self) -> dict:
        return {"name": self.name, "now": self.now, "new": self.new}


def file_text(v: float | int) -> str:
    """A value as the file holds it: the shortest text that reads back as the same single-precision value
    (1.2, not 1.20000005; 94502.83 whole, where a table's ``analysis.params.format_value`` rounds)."""
    return str(int(v)) if isinstance(v, int) else np.format_float_positional(np.float32(v), trim="-")


def write_params(path: Path | str, params: dict[str, float | int], sysid: int = 1, compid: int = 1,
                 autopilot: str | None = None) -> Path:  # fmt: skip
    """``params`` (name → value; an int is an integer parameter) as a QGroundControl parameter file."""
    path = Path(path)
    lines = [f"# Onboard parameters for Vehicle {sysid}", "#",
             f"# Stack: {autopilot or 'unknown'}", f"# Saved by flighttest on {time.strftime('%Y-%m-%d %H:%M:%S')}",
             "#", "# Vehicle-Id Component-Id Name Value Type"]  # fmt: skip
    for name in sorted(params):
        v = params[name]
        kind = MAV_PARAM_TYPE_INT32 if isinstance(v, int) else MAV_PARAM_TYPE_REAL32
        lines.append(f"{sysid}\t{compid}\t{name}\t{file_text(v)}\t{kind}")
    try:
        with atomic_write(path) as tmp:
            tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    except OSError as exc:
        raise FlighttestError(f"cannot write {path} ({exc.strerror or exc})") from None
    return path


def read_params(path: Path | str) -> dict[str, float | int]:
    """A QGroundControl (or Mission Planner) parameter file: name → value, an int where its type is an
    integer one. Any line that is not a parameter, a repeated name or a value that is not a finite number is
    refused, naming the line: nothing of a damaged file is applied."""
    path = Path(path)
    text = read_text_file(path, "parameter file", MAX_FILE_BYTES)
    out: dict[str, float | int] = {}
    for k, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        where = f"{path}:{k}"
        fields = line.split("\t") if "\t" in line else line.replace(",", " ").split()
        fields = [f.strip() for f in fields if f.strip()]
        if len(fields) == 5:
            _, _, name, value, kind = fields
            try:
                is_int = int(kind) in INT_TYPES
            except ValueError:
                raise FlighttestError(f"{where}: type {shown(kind)} is not a MAV_PARAM_TYPE number") from None
        elif len(fields) == 2:  # Mission Planner: NAME,value
            name, value = fields
            is_int = None
        else:
            raise FlighttestError(f"{where}: not a parameter line (QGroundControl's 'sysid compid NAME value "
                                  f"type', or 'NAME,value'): {shown(line, 60)}")  # fmt: skip
        if not (0 < len(name) <= MAX_NAME_CHARS and name.replace("_", "").isalnum() and name.isascii()):
            raise FlighttestError(f"{where}: {shown(name)} is not a parameter name")
        try:
            number = float(value)
        except ValueError:
            raise FlighttestError(f"{where}: {name} = {shown(value)} is not a number") from None
        if not math.isfinite(number):
            raise FlighttestError(f"{where}: {name} = {shown(value)} is not a finite number")
        if is_int or (is_int is None and number.is_integer() and "." not in value and "e" not in value.lower()):
            if not number.is_integer():
                raise FlighttestError(f"{where}: {name} is an integer parameter, not {shown(value)}")
            number = int(number)
        if name in out:
            raise FlighttestError(f"{where}: {name} appears twice")
        out[name] = number
    if not out:
        raise FlighttestError(f"{path}: no parameters in it")
    return out


def autopilot_own(name: str) -> bool:
    """A parameter the autopilot keeps itself (``AUTOPILOT_OWN``)."""
    return any(fnmatchcase(name, pattern) for pattern in AUTOPILOT_OWN)


def changes(now: dict[str, float | int], wanted: dict[str, float | int]) -> tuple[list[ParamChange], list[str]]:
    """What setting ``wanted`` on a vehicle holding ``now`` would change, in the file's order, and the names
    that differ but the autopilot keeps itself (left alone: ``AUTOPILOT_OWN``). Refuses (naming them) names the
    vehicle does not have and fractions for its integer parameters: nothing is half applied."""
    unknown = [n for n in wanted if n not in now]
    if unknown:
        more = f" and {len(unknown) - 8} more" if len(unknown) > 8 else ""
        raise FlighttestError(f"the vehicle has no parameter {', '.join(unknown[:8])}{more}: nothing applied")
    out, own = [], []
    for name, new in wanted.items():
        cur = now[name]
        if isinstance(cur, int) and not float(new).is_integer():
            raise FlighttestError(f"{name} is an integer parameter on the vehicle, not {new!r}: nothing applied")
        value: float | int = int(new) if isinstance(cur, int) else float(new)
        if not same_value(cur, value):
            (own.append(name) if autopilot_own(name) else out.append(ParamChange(name, cur, value)))
    return out, own
