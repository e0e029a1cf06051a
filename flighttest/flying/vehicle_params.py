"""A vehicle's parameters saved to a file, a flight-test file applied, the saved values restored.

The way QGroundControl loads parameter files (``flighttest.flying.params_file``), over the same MAVSDK link
the flights use: ``save`` reads every parameter; ``apply`` shows each change against what the vehicle holds,
asks first, saves what it is about to change to a backup file, sets each value and reads it back;
``restore`` is ``apply`` of a saved file. Parameters are never changed on an armed vehicle: a limit that
moves under a flying position controller is a step its setpoints did not plan for.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flighttest.analysis.params import format_value, same_value
from flighttest.errors import FlighttestError
from flighttest.flying.params_file import ParamChange, changes, read_params, write_params

# the full set on ArduCopter (about 1300 parameters) takes a few seconds over UDP, longer on a radio
READ_ALL_TIMEOUT_S = 60.0
SET_TIMEOUT_S = 5.0
# how long the armed state has to be reported before the vehicle counts as disarmed (heartbeats at 1 Hz)
ARMED_KNOWN_S = 2.5


@dataclass
class ParamsResult:
    """What a ``params`` command did, as ``--json`` prints it."""

    action: str
    file: str
    sysid: int | None = None
    autopilot: str | None = None
    count: int | None = None  # parameters saved or in the file
    changes: list[dict[str, Any]] = field(default_factory=list)
    applied: list[str] = field(default_factory=list)
    failed: list[dict[str, Any]] = field(default_factory=list)
    left_alone: list[str] = field(default_factory=list)  # differ, but the autopilot keeps them itself
    backup: str | None = None
    declined: bool = False

    def record(self) -> dict[str, Any]:
        return dict(self.__dict__)


async def _open(connect: str, sysid: int | None):
    from flighttest.flying.link import VehicleLink

    link = VehicleLink(connect, sysid=sysid, telemetry_hz=5.0)
    try:
        await link.open()
    except BaseException:
        await link.close()
        raise
    return link


async def _read_all(link) -> dict[str, float | int]:
    try:
        params = await link.get_all_params(READ_ALL_TIMEOUT_S)
    except Exception as exc:
        raise FlighttestError(f"cannot read the vehicle's parameters ({exc or type(exc).__name__})") from None
    if not params:
        raise FlighttestError("the vehicle reported no parameters")
    return params


async def save(connect: str, path: Path | str, sysid: int | None = None) -> ParamsResult:
    """Every parameter of the vehicle on ``connect`` into ``path`` (QGroundControl's format)."""
    link = await _open(connect, sysid)
    try:
        params = await _read_all(link)
        autopilot = await link.autopilot_name()
        write_params(path, params, sysid=link.target_sysid or 1, autopilot=autopilot)
        return ParamsResult("save", str(path), link.target_sysid, autopilot, len(params))
    finally:
        await link.close()


async def _refuse_if_armed(link) -> None:
    if not await link.wait_for(lambda s: s.t_armed is not None, ARMED_KNOWN_S):
        raise FlighttestError("the vehicle has not said whether it is armed: no parameter changed")
    if link.state.armed:
        raise FlighttestError("the vehicle is armed: parameters are changed on the ground, disarmed")


async def apply(connect: str, path: Path | str, *, action: str = "apply", backup: Path | str | None = None,
                confirm: Callable[[list[ParamChange]], bool] | None = None, sysid: int | None = None,
                show: Callable[[list[ParamChange], list[str]], None] = lambda *_: None) -> ParamsResult:  # fmt: skip
    """Set the parameters of the file ``path`` that differ on the vehicle (``action`` "apply" or "restore").
    ``show`` gets the changes and the names left alone (``params_file.AUTOPILOT_OWN``), ``confirm`` decides
    (None: go); before setting anything the vehicle's values of the parameters about to change go to
    ``backup`` (None: no backup). Each value is read back; one the vehicle did not take is in ``failed``."""
    wanted = read_params(path)  # a bad file is refused before anything connects
    link = await _open(connect, sysid)
    try:
        await _refuse_if_armed(link)
        now = await _read_all(link)
        todo, own = changes(now, wanted)
        res = ParamsResult(action, str(path), link.target_sysid, await link.autopilot_name(), len(wanted),
                           [c.record() for c in todo], left_alone=own)  # fmt: skip
        show(todo, own)
        if not todo:
            return res
        if confirm is not None and not confirm(todo):
            res.declined = True
            return res
        await _refuse_if_armed(link)  # the question may have taken a while
        if backup is not None:
            write_params(backup, {c.name: c.now for c in todo}, sysid=link.target_sysid or 1,
                         autopilot=res.autopilot)  # fmt: skip
            res.backup = str(backup)
        for c in todo:
            try:
                await link.set_param(c.name, c.new, SET_TIMEOUT_S)
                got = await link.get_param(c.name, "int" if isinstance(c.new, int) else "float")
            except Exception as exc:
                res.failed.append({"name": c.name, "why": str(exc) or type(exc).__name__})
                continue
            if got is None or not same_value(got, c.new):
                shown = "no answer" if got is None else format_value(got)
                res.failed.append({"name": c.name, "why": f"read back {shown}, not {format_value(c.new)}"})
            else:
                res.applied.append(c.name)
        return res
    finally:
        await link.close()
