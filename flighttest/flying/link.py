"""The MAVLink link to the vehicle through MAVSDK 4 (``mavsdk.asyncio``), with a ``.tlog`` recorder.

Rules this module keeps (CONVENTIONS §4):

- ``Mavsdk`` is destroyed explicitly in ``close()``, never by the garbage collector, and never while
  a blocking C call is still running: every blocking call goes through ``call()``, which keeps the
  task until the C call returns even if its caller gave up waiting (cancelling an awaited
  ``run_in_executor`` does not stop the C call). ``close()`` waits for them, stops the
  subscriptions (their generators unsubscribe in ``finally``), destroys the plugins, then Mavsdk.
- More than one autopilot on the link is refused unless ``sysid`` says which one to fly.
- State telemetry is asked for at ``telemetry_hz`` (≥ 50 Hz for the guard). Each subscription runs
  in its own task and writes into ``TelemetryState``; listeners get each new sample on the loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import re
import time
from collections import deque
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from flighttest.errors import FlighttestError
from flighttest.flying.autopilot import (
    ARDUPILOT,
    PX4_RULES,
    AutopilotRules,
    arducopter_mode_name,
    arducopter_mode_number,
    rules_for,
)

# what the streamer calls on MAVSDK's synchronous offboard plugin (VehicleLink.offboard_setters)
OFFBOARD_SETTERS = ("set_position_velocity_acceleration_ned", "set_velocity_ned")
URL_RE = re.compile(r"^(udpin|udpout|tcpin|tcpout|serial|serial_flowcontrol)://.+$")
# MAVSDK 4's deprecated spellings: refused at once with the one to use (MAVSDK would take them, after a warning)
DEPRECATED_SCHEMES = {"udp": "udpin", "tcp": "tcpout"}
URL_HELP = "udpin://0.0.0.0:14540, udpout://HOST:PORT, tcpout://HOST:PORT or serial:///dev/ttyUSB0:57600"
# flighttest's own identity as a ground station: MAVSDK's 245 (component 190), not QGroundControl's 255, so
# both can share a link (mavlink-router) without answering for each other. ArduPilot's GCS failsafe watches
# only MAV_GCS_SYSID (default 255): its preflight tells the user to set it to this one.
GCS_SYSID = 245
GCS_COMPID = 190  # MAV_COMP_ID_MISSIONPLANNER
MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_DO_SET_MODE = 176
MAV_MODE_FLAG_CUSTOM_MODE_ENABLED = 1
SYS_STATUS_MSG_ID = 1
SCALED_PRESSURE_MSG_ID = 29
BARO_HZ = 10.0
# SYS_STATUS carries the sensor-health bits MAVSDK's health (and the preflight) is made of: ArduPilot
# streams nothing unless asked (../shared/ardupilot_sitl: without it MAVSDK's health stayed false)
SYS_STATUS_HZ = 2.0
AUTOPILOT_COMPID = 1  # MAV_COMP_ID_AUTOPILOT1
LISTEN_SCHEMES = ("udpin", "tcpin")
SERIAL_SCHEMES = ("serial", "serial_flowcontrol")
MAX_BAUD = 20_000_000  # beyond any UART a flight controller has (PX4 tops out at 3 Mbit/s)
RESOLVE_TIMEOUT_S = 3.0
_HOST_LABEL_RE = re.compile(r"^(?!-)[A-Za-z0-9-]{1,63}(?<!-)$")


def _bad(url: str, why: str) -> FlighttestError:
    shown = repr(url) if len(url) <= 120 else repr(url[:100]) + f"… ({len(url)} characters)"
    return FlighttestError(f"bad --connect URL {shown}: {why}")


def _split_host_port(url: str, rest: str) -> tuple[str, int]:
    host, sep, port = rest.rpartition(":")
    if not sep or not port:
        raise _bad(url, f"a port is required ({URL_HELP})")
    if not port.isdigit() or not port.isascii():
        raise _bad(url, f"port {port!r} is not a number")
    if not 1 <= int(port) <= 65535:
        raise _bad(url, f"port {int(port)} is out of range (1..65535)")
    if not host:
        raise _bad(url, "a host is required (udpin://0.0.0.0:PORT listens on every interface)")
    return host or "0.0.0.0", int(port)


def _is_ipv4(host: str) -> bool:
    import ipaddress

    try:
        ipaddress.IPv4Address(host)
    except ValueError:
        return False
    return True


def check_url(url: str) -> str:
    """The URL's syntax as MAVSDK 4 takes it, checked without touching the network or devices: one
    line naming what is wrong instead of MAVSDK's own log lines or a 15 s wait for nobody."""
    if not isinstance(url, str) or not url:
        raise _bad(str(url or ""), f"expected {URL_HELP}")
    # a pasted newline or tab would reach MAVSDK as part of the device name or port
    if any(c.isspace() or not c.isprintable() for c in url):
        raise _bad(url, "it contains whitespace or a control character")
    scheme = url.partition("://")[0]
    if scheme in DEPRECATED_SCHEMES:
        new = DEPRECATED_SCHEMES[scheme]
        rest = url.partition("://")[2]
        if new == "udpin" and rest.startswith(":"):
            rest = "0.0.0.0" + rest
        raise _bad(url, f"{scheme}:// is MAVSDK's old spelling: use {new}://{rest}")
    if not URL_RE.match(url):
        raise _bad(url, f"expected {URL_HELP}")
    scheme, _, rest = url.partition("://")
    if scheme in SERIAL_SCHEMES:  # MAVSDK ≥ 3 needs the baud rate
        device, sep, baud = rest.rpartition(":")
        if not sep or not device or not baud.isdigit() or not baud.isascii():
            raise _bad(url, "a device and a baud rate are required (serial:///dev/ttyUSB0:57600)")
        if not 50 <= int(baud) <= MAX_BAUD:
            raise _bad(url, f"baud rate {int(baud)} is out of range (50..{MAX_BAUD})")
        return url
    host, _port = _split_host_port(url, rest)
    if host.startswith("["):
        raise _bad(url, "IPv6 addresses are not supported by MAVSDK: use an IPv4 address or a host name")
    if scheme in LISTEN_SCHEMES:
        if not _is_ipv4(host):
            raise _bad(url, f"{scheme}:// listens on a local IPv4 address (0.0.0.0 = every interface), not {host!r}")
        return url
    if all(part.isdigit() for part in host.split(".")):
        if not _is_ipv4(host):
            raise _bad(url, f"{host!r} is not an IPv4 address")
    elif len(host) > 253 or not all(_HOST_LABEL_RE.match(p) for p in host.rstrip(".").split(".")):
        raise _bad(url, f"{host!r} is not a host name or IPv4 address")
    return url


def check_connection(url: str) -> str:
    """What ``check_url`` cannot see from the text: the host name resolves, the listening address is
    one of this machine's, the serial device exists and may be opened. Run before MAVSDK starts, so
    a link that cannot work is refused at once rather than after the connect timeout."""
    import os
    import socket
    import stat
    import threading

    check_url(url)
    scheme, _, rest = url.partition("://")
    if scheme in SERIAL_SCHEMES:
        device = rest.rpartition(":")[0]
        if not device.startswith("/"):
            if os.name == "posix":  # serial://dev/ttyUSB0 opens a relative path: two slashes, not three
                raise _bad(url, "the serial device must be a path such as /dev/ttyUSB0 (serial:///dev/ttyUSB0:57600)")
            return url  # COM3 on Windows: nothing to stat
        try:
            st = os.stat(device)
        except OSError as exc:
            raise _bad(url, f"serial device {device}: {exc.strerror}") from None
        if not stat.S_ISCHR(st.st_mode):
            raise _bad(url, f"{device} is not a serial device")
        if not os.access(device, os.R_OK | os.W_OK):
            raise _bad(url, f"no permission to open {device} (on Linux: add yourself to the dialout group)")
        return url
    host, port = _split_host_port(url, rest)
    if scheme in LISTEN_SCHEMES:
        kind = socket.SOCK_STREAM if scheme == "tcpin" else socket.SOCK_DGRAM
        try:  # port 0: only whether the address is ours, not whether the port is free right now
            with socket.socket(socket.AF_INET, kind) as s:
                s.bind((host, 0))
        except OSError as exc:
            raise _bad(url, f"cannot listen on {host} ({exc.strerror}): not an address of this machine") from None
        return url
    if _is_ipv4(host):
        return url
    # getaddrinfo cannot be interrupted: resolve in a daemon thread and stop waiting after a while
    found: list[Any] = []

    def resolve() -> None:
        try:
            found.append(socket.getaddrinfo(host, port, socket.AF_INET))
        except (OSError, UnicodeError) as exc:
            found.append(exc)

    t = threading.Thread(target=resolve, name="resolve", daemon=True)
    t.start()
    t.join(RESOLVE_TIMEOUT_S)
    if not found:
        raise _bad(url, f"host name {host!r} did not resolve within {RESOLVE_TIMEOUT_S:g} s")
    if isinstance(found[0], BaseException):
        why = getattr(found[0], "strerror", None) or str(found[0])
        raise _bad(url, f"host name {host!r} does not resolve ({why})")
    return url


# -- MAVSDK's own log -------------------------------------------------------------------------------
# MAVSDK's C++ core prints every log line (version banner, "trying to reconnect..." once a second)
# straight to stderr, which buries our one-line errors and the live panel. One process-wide
# subscription swallows them all and hands each to the links listening (their flight log); the
# last errors go into the message when a connection fails.
_log_sinks: list[Callable[[str, str], None]] = []
_log_installed = False


def quiet_mavsdk_log() -> None:
    """Route MAVSDK's log lines to ``_log_sinks`` instead of stderr (idempotent)."""
    global _log_installed
    if _log_installed:
        return
    from mavsdk.logging import log_subscribe

    def handler(level, message: str, file: str | None, line: int) -> bool:
        # runs on a MAVSDK thread; it must never raise (MAVSDK would print the error) or block
        try:
            for sink in tuple(_log_sinks):
                sink(getattr(level, "name", str(level)), message)
        except Exception:
            pass
        return True  # True: MAVSDK does not print it itself

    log_subscribe(handler)
    _log_installed = True


RATE_WINDOW_S = 1.0  # a stream's rate is judged over the last second


@dataclass
class TelemetryState:
    """Latest value of every stream and its monotonic arrival time (NaN / None until first seen)."""

    n_m: float = math.nan
    e_m: float = math.nan
    d_m: float = math.nan
    vn_mps: float = math.nan
    ve_mps: float = math.nan
    vd_mps: float = math.nan
    t_posvel: float | None = None
    q: tuple[float, float, float, float] = (math.nan,) * 4
    t_att: float | None = None
    t_att_vehicle_s: float | None = None  # the vehicle's own time of that attitude sample (its boot clock)
    rates_rps: tuple[float, float, float] = (math.nan,) * 3
    accel_frd_mps2: tuple[float, float, float] = (math.nan,) * 3
    t_imu: float | None = None
    wind_ned_mps: tuple[float, float, float] | None = None
    wind_accuracy_mps: float = math.nan  # the report's own horizontal accuracy (1 σ), NaN: not given
    t_wind: float | None = None
    flight_mode: str = "UNKNOWN"
    armed: bool = False
    t_armed: float | None = None  # arrival of the latest armed report (MAVSDK: every heartbeat, 1 Hz)
    armed_since_t: float | None = None  # arrival of the first report of the current armed value
    landed_state: str = "UNKNOWN"
    t_landed: float | None = None  # arrival of the latest landed-state report (EXTENDED_SYS_STATE)
    landed_since_t: float | None = None  # arrival of the first report of the current landed state
    in_air: bool = False
    battery_percent: float = math.nan
    battery_v: float = math.nan
    health: dict[str, bool] = field(default_factory=dict)
    health_all_ok: bool = False
    connected: bool = True
    counts: dict[str, int] = field(default_factory=dict)
    first_t: dict[str, float] = field(default_factory=dict)
    recent: dict[str, deque[float]] = field(default_factory=dict)  # arrivals over the last RATE_WINDOW_S

    @property
    def alt_m(self) -> float:
        """Height above home (the local frame's origin), m."""
        return -self.d_m

    def report_armed(self, armed: bool, t: float) -> None:
        if armed != self.armed or self.armed_since_t is None:
            self.armed_since_t = t
        self.armed, self.t_armed = armed, t

    def report_landed(self, landed_state: str, t: float) -> None:
        if landed_state != self.landed_state or self.landed_since_t is None:
            self.landed_since_t = t
        self.landed_state, self.t_landed = landed_state, t

    def count(self, stream: str, t: float) -> None:
        self.counts[stream] = self.counts.get(stream, 0) + 1
        self.first_t.setdefault(stream, t)
        recent = self.recent.setdefault(stream, deque())
        recent.append(t)
        while t - recent[0] > RATE_WINDOW_S:
            recent.popleft()

    def rate_hz(self, stream: str, now: float) -> float:
        """Samples per second over the last ``RATE_WINDOW_S`` (since the first, if that came later): the rate
        the autopilot sends now. An average since the connection counted the second before it took the rate
        asked of it (ArduCopter SITL: 39 Hz of 50, a flight refused: bench/RESULTS.md)."""
        t0 = self.first_t.get(stream)
        if t0 is None or now - t0 <= 0:
            return 0.0
        n = sum(1 for t in self.recent.get(stream, ()) if now - t < RATE_WINDOW_S)
        return n / min(RATE_WINDOW_S, now - t0)


Listener = Callable[[float], None]


class Link(Protocol):
    """What the mission runner flies through: ``VehicleLink`` over MAVSDK, or a scripted in-process
    autopilot (``sitl_fakes.scripted``) on a virtual clock. Listeners get the loop's time of each
    sample; commands raise ``TimeoutError`` when the vehicle does not answer within ``timeout_s``."""

    state: TelemetryState
    on_posvel: list[Listener]
    on_attitude: list[Listener]
    on_imu: list[Listener]
    on_mode: list[Callable[[str, str], None]]
    on_connection: list[Callable[[bool], None]]
    # False where the loop's clock is virtual: no wall-clock watchdog thread may judge the stream
    realtime: bool
    rules: AutopilotRules  # the autopilot's rules (flighttest.flying.autopilot), known once open

    async def open(self) -> None: ...
    async def close(self) -> None: ...
    async def wait_for(self, predicate: Callable[[TelemetryState], bool], timeout_s: float,
                       poll_s: float = 0.05) -> bool: ...  # fmt: skip
    async def arm(self, timeout_s: float, what: str = "arm") -> None: ...
    async def set_takeoff_altitude(self, alt_m: float, timeout_s: float, what: str = "...") -> None: ...
    async def takeoff(self, timeout_s: float, what: str = "takeoff") -> None: ...
    async def disarm(self, timeout_s: float, what: str = "disarm") -> None: ...
    async def land(self, timeout_s: float, what: str = "land") -> None: ...
    async def hold(self, timeout_s: float, what: str = "hold") -> None: ...
    async def start_offboard(self, timeout_s: float, what: str = "offboard start") -> None: ...
    async def stop_offboard(self, timeout_s: float, what: str = "offboard stop") -> None: ...
    async def set_mode(self, name: str, timeout_s: float) -> None: ...
    def offboard_setters(self) -> Any: ...
    async def get_param(self, name: str, kind: str = "float") -> float | int | None: ...
    async def get_all_params(self, timeout_s: float = 3.0) -> dict[str, float | int]: ...
    async def autopilot_name(self) -> str | None: ...


class VehicleLink:
    """One vehicle through one MAVSDK instance. ``async with VehicleLink(...) as link:``."""

    def __init__(
        self,
        url: str,
        sysid: int | None = None,
        tlog_path: Path | str | None = None,
        telemetry_hz: float = 50.0,
        connect_timeout_s: float = 15.0,
        discover_s: float = 1.5,
        on_event: Callable[[str, dict[str, Any]], None] | None = None,
    ) -> None:
        self.url = check_url(url)
        self.sysid = sysid
        self.tlog_path = Path(tlog_path) if tlog_path else None
        self.telemetry_hz = telemetry_hz
        self.connect_timeout_s = connect_timeout_s
        self.discover_s = discover_s
        self.state = TelemetryState()
        self.on_posvel: list[Listener] = []
        self.on_attitude: list[Listener] = []
        self.on_imu: list[Listener] = []
        self.on_mode: list[Callable[[str, str], None]] = []
        self.on_connection: list[Callable[[bool], None]] = []
        self._on_event = on_event or (lambda name, fields: None)
        self._mavsdk = None
        self._recorder = None
        self.system = None
        self.telemetry = self.action = self.offboard = self.param = None
        self._sub_tasks: list[asyncio.Task] = []
        self._inflight: set[asyncio.Task] = set()
        self.target_sysid: int | None = None
        self.autopilot_sysids: list[int] = []
        self.mavsdk_errors: deque[str] = deque(maxlen=3)  # MAVSDK's latest WARN/ERROR lines
        self._log_seen: dict[str, int] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self.realtime = True
        self.rules: AutopilotRules = PX4_RULES  # the autopilot's, once connected
        self.direct = None

    # -- lifecycle ---------------------------------------------------------------------------------
    async def __aenter__(self) -> VehicleLink:
        try:
            await self.open()
        except BaseException:
            await self.close()
            raise
        return self

    async def __aexit__(self, *exc) -> None:
        await self.close()

    async def open(self) -> None:
        from mavsdk.asyncio import ComponentType, Configuration, ForwardingOption, Mavsdk, MavsdkConnectionError

        check_connection(self.url)  # before MAVSDK starts: a link that cannot work fails in a moment
        quiet_mavsdk_log()
        self._loop = asyncio.get_running_loop()
        if self._on_mavsdk_log not in _log_sinks:
            _log_sinks.append(self._on_mavsdk_log)
        self._mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        if self.tlog_path is not None:
            from flighttest.flying.tlog_recorder import TlogRecorder

            self._recorder = TlogRecorder(self.tlog_path).start()
        try:
            await self.call(self._mavsdk.add_any_connection(self.url, ForwardingOption.ON), "connect", 10.0)
            if self._recorder is not None:
                await self.call(
                    self._mavsdk.add_any_connection(self._recorder.forward_url, ForwardingOption.ON),
                    "connect tlog recorder", 10.0,
                )  # fmt: skip
        except MavsdkConnectionError as exc:
            raise FlighttestError(f"cannot open {self.url}: {exc}{self._mavsdk_says()}") from None
        first = await self._mavsdk.first_autopilot(self.connect_timeout_s)
        if first is None:
            raise FlighttestError(
                f"no autopilot answered on {self.url} within {self.connect_timeout_s:g} s{self._mavsdk_says()}"
            )
        # other autopilots on the same link show up within a heartbeat period or so
        await asyncio.sleep(self.discover_s)
        systems = await self.call(self._mavsdk.get_systems(), "list systems", 5.0)
        autopilots = {}
        for s in [first, *systems]:
            if await s.has_autopilot():
                autopilots.setdefault(await s.get_system_id(), s)
        self.autopilot_sysids = sorted(autopilots)
        if self.sysid is None:
            if len(autopilots) > 1:
                ids = ", ".join(str(i) for i in self.autopilot_sysids)
                raise FlighttestError(
                    f"{len(autopilots)} autopilots answer on {self.url} (system ids {ids}): "
                    "refusing to fly; choose one with --sysid"
                )
            self.target_sysid, self.system = next(iter(autopilots.items()))
        else:
            if self.sysid not in autopilots:
                ids = ", ".join(str(i) for i in self.autopilot_sysids)
                raise FlighttestError(f"no autopilot with system id {self.sysid} on {self.url} (found: {ids})")
            self.target_sysid, self.system = self.sysid, autopilots[self.sysid]
        self._on_event("link", {"url": self.url, "sysid": self.target_sysid, "autopilots": self.autopilot_sysids})
        self._make_plugins()
        await self._start_subscriptions()

    def _make_plugins(self) -> None:
        from mavsdk.asyncio.plugins.action import ActionAsync
        from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
        from mavsdk.asyncio.plugins.offboard import OffboardAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        self.telemetry = TelemetryAsync(self.system)
        self.action = ActionAsync(self.system)
        self.offboard = OffboardAsync(self.system)
        self.param = ParamAsync(self.system)
        self.direct = MavlinkDirectAsync(self.system)

    def offboard_setters(self):
        """MAVSDK's synchronous offboard plugin under ``OffboardAsync``: its setters only store the
        setpoint and queue one message, so the streamer calls them on the loop, with no executor hop
        that could be left in flight when the link closes (``flighttest.flying.streamer``). The one place
        flighttest reaches under MAVSDK's asyncio wrapper; ``tests/test_link_api.py`` fails loudly if
        MAVSDK changes it."""
        plugin = getattr(self.offboard, "_plugin", None)
        if plugin is None or not all(callable(getattr(plugin, name, None)) for name in OFFBOARD_SETTERS):
            raise FlighttestError(
                "this MAVSDK has no synchronous offboard plugin under OffboardAsync: flighttest needs mavsdk 4.x "
                "(pip install -e . installs the version it was tested with)"
            )
        return plugin

    def _on_mavsdk_log(self, level: str, message: str) -> None:
        """A MAVSDK log line (on MAVSDK's thread): WARN and ERROR kept for error messages and, once per
        distinct text (repeats counted), written to the flight log from the event loop."""
        if level not in ("WARN", "ERROR"):
            return
        self.mavsdk_errors.append(message)
        n = self._log_seen[message] = self._log_seen.get(message, 0) + 1
        if n == 1 and len(self._log_seen) <= 100 and self._loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop is closed: nothing left to log into
                self._loop.call_soon_threadsafe(self._on_event, "mavsdk_log", {"level": level, "message": message})

    def _mavsdk_says(self) -> str:
        return f" (MAVSDK: {self.mavsdk_errors[-1]})" if self.mavsdk_errors else ""

    async def close(self) -> None:
        """Stop subscriptions, wait for blocking calls, destroy plugins and Mavsdk, stop the recorder."""
        for t in self._sub_tasks:
            t.cancel()
        if self._sub_tasks:
            await asyncio.gather(*self._sub_tasks, return_exceptions=True)
        self._sub_tasks.clear()
        if self._inflight:
            # MAVSDK's own timeouts end every blocking call within seconds; destroying under one
            # would hang the event loop's shutdown, so wait (generously) for them.
            done, pending = await asyncio.wait(set(self._inflight), timeout=30.0)
            if pending:
                self._on_event("warning", {"what": f"{len(pending)} MAVSDK calls still running at close"})
        for plugin in (self.offboard, self.action, self.param, self.telemetry):
            if plugin is not None:
                plugin.destroy()
        self.offboard = self.action = self.param = self.telemetry = None
        if self._mavsdk is not None:
            self._mavsdk.destroy()
            self._mavsdk = None
        if self._on_mavsdk_log in _log_sinks:
            _log_sinks.remove(self._on_mavsdk_log)
        repeats = {m: n for m, n in self._log_seen.items() if n > 1}
        if repeats:
            self._on_event("mavsdk_log_repeats", {"counts": repeats})
        self.system = None
        if self._recorder is not None:
            self._recorder.stop()
            self._on_event("tlog", {"messages": self._recorder.messages, "path": str(self._recorder.path),
                                    "write_errors": self._recorder.write_errors})  # fmt: skip
            self._recorder = None

    # -- blocking calls ----------------------------------------------------------------------------
    async def call(self, awaitable: Awaitable, what: str, timeout_s: float | None = None):
        """Await a (possibly blocking) MAVSDK call; the call is tracked until its C side returns,
        even when this waiter times out or is cancelled. Timeouts raise ``TimeoutError``."""
        task = asyncio.ensure_future(awaitable)
        self._inflight.add(task)
        task.add_done_callback(self._inflight.discard)
        if timeout_s is None:
            return await asyncio.shield(task)
        try:
            return await asyncio.wait_for(asyncio.shield(task), timeout_s)
        except TimeoutError:
            raise TimeoutError(f"{what}: no answer within {timeout_s:g} s") from None

    @property
    def calls_in_flight(self) -> int:
        return len(self._inflight)

    # -- commands: what the runner asks of the vehicle (``VehicleCommands``) --------------------------
    async def arm(self, timeout_s: float, what: str = "arm") -> None:
        await self.call(self.action.arm(), what, timeout_s)

    async def set_takeoff_altitude(self, alt_m: float, timeout_s: float, what: str = "set takeoff altitude") -> None:
        await self.call(self.action.set_takeoff_altitude(alt_m), what, timeout_s)

    async def takeoff(self, timeout_s: float, what: str = "takeoff") -> None:
        await self.call(self.action.takeoff(), what, timeout_s)

    async def disarm(self, timeout_s: float, what: str = "disarm") -> None:
        """Refused by PX4 and ArduCopter unless the vehicle has landed (MAVSDK's disarm is not forced)."""
        await self.call(self.action.disarm(), what, timeout_s)

    async def land(self, timeout_s: float, what: str = "land") -> None:
        await self.call(self.action.land(), what, timeout_s)

    async def hold(self, timeout_s: float, what: str = "hold") -> None:
        await self.call(self.action.hold(), what, timeout_s)

    async def start_offboard(self, timeout_s: float, what: str = "offboard start") -> None:
        await self.call(self.offboard.start(), what, timeout_s)

    async def stop_offboard(self, timeout_s: float, what: str = "offboard stop") -> None:
        await self.call(self.offboard.stop(), what, timeout_s)

    async def set_mode(self, name: str, timeout_s: float) -> None:
        """An ArduCopter mode by name (MAV_CMD_DO_SET_MODE with its custom mode): MAVSDK's own mode calls
        reach only the modes of its FlightMode list, and its arm turns LAND into BRAKE, where ArduCopter
        will not arm. Raises ``RuntimeError`` when refused."""
        if self.rules.name != ARDUPILOT:
            raise RuntimeError(f"set_mode({name}) is for ArduPilot; PX4's modes go through MAVSDK")
        ack = await self.send_command_long(MAV_CMD_DO_SET_MODE, f"mode {name}", timeout_s,
                                           MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, arducopter_mode_number(name))  # fmt: skip
        result = json.loads(ack.fields_json or "{}").get("result") if ack is not None else None
        if result not in (0, None):
            raise RuntimeError(f"mode {name}: refused (MAV_RESULT {result})")

    # -- subscriptions -------------------------------------------------------------------------------
    async def _start_subscriptions(self) -> None:
        tel, st = self.telemetry, self.state
        hz = self.telemetry_hz
        self.rules = rules_for(await self.autopilot_name())
        if self.rules.name == ARDUPILOT:
            await self.request_message_rate(SYS_STATUS_MSG_ID, SYS_STATUS_HZ, "SYS_STATUS")
            # the barometer in the log, for the estimate's error a build-up judges (PX4 sends ALTITUDE at 10 Hz
            # by itself; ArduCopter SITL's tlogs had none)
            await self.request_message_rate(SCALED_PRESSURE_MSG_ID, BARO_HZ, "SCALED_PRESSURE")
        for setter in (tel.set_rate_position_velocity_ned, tel.set_rate_attitude_quaternion, tel.set_rate_imu):
            try:
                await self.call(setter(hz), setter.__name__, 5.0)
            except Exception as exc:  # the preflight rate check reports what we actually get
                self._on_event("warning", {"what": f"{setter.__name__}({hz:g}) failed: {exc}"})
        for setter, r in ((tel.set_rate_battery, 2.0), (tel.set_rate_landed_state, 10.0)):
            try:
                await self.call(setter(r), setter.__name__, 5.0)
            except Exception as exc:
                self._on_event("warning", {"what": f"{setter.__name__}({r:g}) failed: {exc}"})

        def posvel(pv) -> None:
            t = time.monotonic()
            p, v = pv.position, pv.velocity
            st.n_m, st.e_m, st.d_m = p.north_m, p.east_m, p.down_m
            st.vn_mps, st.ve_mps, st.vd_mps = v.north_m_s, v.east_m_s, v.down_m_s
            st.t_posvel = t
            st.count("posvel", t)
            for cb in self.on_posvel:
                cb(t)

        def attitude(q) -> None:
            t = time.monotonic()
            st.q = (q.w, q.x, q.y, q.z)
            st.t_att = t
            st.t_att_vehicle_s = q.timestamp_us * 1e-6 if q.timestamp_us else None
            st.count("attitude", t)
            for cb in self.on_attitude:
                cb(t)

        def imu(m) -> None:
            t = time.monotonic()
            a, w = m.acceleration_frd, m.angular_velocity_frd
            st.accel_frd_mps2 = (a.forward_m_s2, a.right_m_s2, a.down_m_s2)
            st.rates_rps = (w.forward_rad_s, w.right_rad_s, w.down_rad_s)
            st.t_imu = t
            st.count("imu", t)
            for cb in self.on_imu:
                cb(t)

        def wind(w) -> None:
            t = time.monotonic()
            vals = (w.wind_x_ned_m_s, w.wind_y_ned_m_s, w.wind_z_ned_m_s)
            if all(math.isfinite(x) for x in vals):
                st.wind_ned_mps, st.t_wind = vals, t
                # PX4 leaves WIND_COV's horiz_accuracy 0 and puts a variance (m²/s²) in var_horiz, which MAVSDK
                # hands over as the "variability": whichever reading is larger, so never the kinder one
                var = w.horizontal_variability_stddev_m_s
                spread = max(var, math.sqrt(var)) if math.isfinite(var) and var > 0 else math.nan
                acc = w.horizontal_wind_speed_accuracy_m_s
                st.wind_accuracy_mps = acc if math.isfinite(acc) and acc > 0 else spread

        def set_mode(name: str) -> None:
            old, st.flight_mode = st.flight_mode, name
            if old != name:
                for cb in self.on_mode:
                    cb(old, name)

        def mode(m) -> None:
            set_mode(m.name)

        target = self.target_sysid

        def heartbeat(msg) -> None:  # ArduPilot: its own mode names (flighttest.flying.autopilot)
            if msg.system_id != target or msg.component_id != AUTOPILOT_COMPID:
                return
            custom_mode = json.loads(msg.fields_json).get("custom_mode")
            if custom_mode is not None:
                set_mode(arducopter_mode_name(custom_mode))

        def armed(a) -> None:
            st.report_armed(bool(a), time.monotonic())

        def landed(ls) -> None:
            st.report_landed(ls.name, time.monotonic())

        def in_air(a) -> None:
            st.in_air = bool(a)

        def battery(b) -> None:
            st.battery_percent, st.battery_v = b.remaining_percent, b.voltage_v

        def health(h) -> None:
            st.health = {k: bool(v) for k, v in vars(h).items() if k.startswith("is_")}

        def health_ok(ok) -> None:
            st.health_all_ok = bool(ok)

        def connection(c) -> None:
            st.connected = bool(c)
            for cb in self.on_connection:
                cb(st.connected)

        subs = [
            (tel.subscribe_position_velocity_ned, posvel),
            (tel.subscribe_attitude_quaternion, attitude),
            (tel.subscribe_imu, imu),
            (tel.subscribe_wind, wind),
            (tel.subscribe_armed, armed),
            (tel.subscribe_landed_state, landed),
            (tel.subscribe_in_air, in_air),
            (tel.subscribe_battery, battery),
            (tel.subscribe_health, health),
            (tel.subscribe_health_all_ok, health_ok),
            (self.system.is_connected_state, connection),
        ]
        if self.rules.reads_mode_from_heartbeat:

            def subscribe_heartbeat():
                return self.direct.subscribe_message("HEARTBEAT")

            subs.append((subscribe_heartbeat, heartbeat))
        else:
            subs.append((tel.subscribe_flight_mode, mode))
        for factory, handler in subs:
            self._sub_tasks.append(asyncio.create_task(self._pump(factory, handler), name=factory.__name__))

    async def _pump(self, factory, handler) -> None:
        gen = factory()
        try:
            async for item in gen:
                try:
                    handler(item)
                except Exception as exc:  # one bad listener must not end the stream
                    self._on_event("warning", {"what": f"{factory.__name__} handler: {exc!r}"})
        finally:
            await gen.aclose()

    async def wait_for(
        self, predicate: Callable[[TelemetryState], bool], timeout_s: float, poll_s: float = 0.05
    ) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate(self.state):
                return True
            await asyncio.sleep(poll_s)
        return predicate(self.state)

    async def send_command_long(self, command: int, what: str, timeout_s: float, *params: float):
        """A COMMAND_LONG through MAVSDK's MavlinkDirect (for what its plugins do not send); its final
        COMMAND_ACK as a ``MavlinkMessage``."""
        from mavsdk.plugins.mavlink_direct import MavlinkMessage

        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        fields = {"target_system": self.target_sysid, "target_component": AUTOPILOT_COMPID, "command": command,
                  "confirmation": 0, **{f"param{i + 1}": v for i, v in enumerate(p)}}  # fmt: skip
        cmd = MavlinkMessage("COMMAND_LONG", GCS_SYSID, GCS_COMPID, self.target_sysid, AUTOPILOT_COMPID,
                             json.dumps(fields))  # fmt: skip
        return await self.call(self.direct.send_command(cmd), what, timeout_s)

    async def request_message_rate(self, msg_id: int, rate_hz: float, what: str) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL for a message MAVSDK has no rate setter for (SYS_STATUS on ArduPilot);
        a failure is a warning: the preflight reports what actually arrives."""
        try:
            await self.send_command_long(MAV_CMD_SET_MESSAGE_INTERVAL, f"{what} rate", 5.0, msg_id, 1e6 / rate_hz)
            self._on_event("stream_requested", {"message": what, "rate_hz": rate_hz})
        except Exception as exc:
            self._on_event("warning", {"what": f"requesting {what} at {rate_hz:g} Hz failed: {exc}"})

    # -- params --------------------------------------------------------------------------------------
    async def get_param(self, name: str, kind: str = "float") -> float | int | None:
        """A PX4 parameter, or None if the vehicle does not have it / does not answer."""
        getter = self.param.get_param_float if kind == "float" else self.param.get_param_int
        try:
            return await self.call(getter(name), f"param {name}", 5.0)
        except Exception:
            return None

    async def set_param(self, name: str, value: float | int, timeout_s: float = 5.0) -> None:
        """PARAM_SET through MAVSDK, as an integer parameter for an ``int`` value; raises on no acknowledgement."""
        setter = self.param.set_param_int if isinstance(value, int) else self.param.set_param_float
        await self.call(setter(name, value), f"set param {name}", timeout_s)

    async def get_all_params(self, timeout_s: float = 3.0) -> dict[str, float | int]:
        """Every parameter of the vehicle (MAVLink PARAM_REQUEST_LIST through MAVSDK), name → value.

        For the per-flight parameter snapshot (``params.json``); bounded by ``timeout_s`` so a slow
        link does not hold up a flight (MAVSDK's own read goes on in the background and is waited
        for at ``close()``). Raises ``TimeoutError`` or MAVSDK's ``ParamError``; the caller decides."""
        all_params = await self.call(self.param.get_all_params(), "all params", timeout_s)
        out: dict[str, float | int] = {p.name: int(p.value) for p in all_params.int_params}
        out.update({p.name: float(p.value) for p in all_params.float_params})
        return out

    async def autopilot_name(self) -> str | None:
        """The autopilot, "PX4" or "ArduPilot", as its heartbeat says (None when MAVSDK cannot tell)."""
        try:
            ap = await self.system.autopilot_type()
        except Exception:
            return None
        return {"PX4": "PX4", "ARDUPILOT": "ArduPilot"}.get(getattr(ap, "name", ""))
