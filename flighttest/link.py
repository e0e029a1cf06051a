"""The MAVLink link to the vehicle through MAVSDK 4 (``mavsdk.asyncio``), with a ``.tlog`` recorder.

Rules this module keeps (NOTES §4):

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
import math
import re
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flighttest.errors import FlighttestError

URL_RE = re.compile(r"^(udpin|udpout|tcpin|tcpout|udp|tcp|serial|serial_flowcontrol)://.+$")
URL_HELP = "udpin://0.0.0.0:14540, udpout://HOST:PORT, tcpout://HOST:PORT or serial:///dev/ttyUSB0:57600"
GCS_SYSID = 245  # QGroundControl uses 255; MAVSDK's ground-station default is 245


def check_url(url: str) -> str:
    if not URL_RE.match(url or ""):
        raise FlighttestError(f"bad --connect URL {url!r}: expected {URL_HELP}")
    if url.startswith(("udp", "tcp")) and not re.search(r":\d+$", url):
        raise FlighttestError(f"bad --connect URL {url!r}: a port is required ({URL_HELP})")
    if url.startswith("serial") and not re.search(r"://.+:\d+$", url):  # MAVSDK ≥ 3 needs the baud rate
        raise FlighttestError(f"bad --connect URL {url!r}: a baud rate is required (serial:///dev/ttyUSB0:57600)")
    return url


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
    rates_rps: tuple[float, float, float] = (math.nan,) * 3
    accel_frd_mps2: tuple[float, float, float] = (math.nan,) * 3
    t_imu: float | None = None
    wind_ned_mps: tuple[float, float, float] | None = None
    t_wind: float | None = None
    flight_mode: str = "UNKNOWN"
    armed: bool = False
    landed_state: str = "UNKNOWN"
    in_air: bool = False
    battery_percent: float = math.nan
    battery_v: float = math.nan
    health: dict[str, bool] = field(default_factory=dict)
    health_all_ok: bool = False
    connected: bool = True
    counts: dict[str, int] = field(default_factory=dict)
    first_t: dict[str, float] = field(default_factory=dict)

    @property
    def alt_m(self) -> float:
        """Height above home (the local frame's origin), m."""
        return -self.d_m

    def count(self, stream: str, t: float) -> None:
        self.counts[stream] = self.counts.get(stream, 0) + 1
        self.first_t.setdefault(stream, t)

    def rate_hz(self, stream: str, now: float) -> float:
        n, t0 = self.counts.get(stream, 0), self.first_t.get(stream)
        if t0 is None or n < 2 or now - t0 <= 0:
            return 0.0
        return (n - 1) / (now - t0)


Listener = Callable[[float], None]


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

        self._mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        if self.tlog_path is not None:
            from flighttest.tlog import TlogRecorder

            self._recorder = TlogRecorder(self.tlog_path).start()
        try:
            await self.call(self._mavsdk.add_any_connection(self.url, ForwardingOption.ON), "connect", 10.0)
            if self._recorder is not None:
                await self.call(
                    self._mavsdk.add_any_connection(self._recorder.forward_url, ForwardingOption.ON),
                    "connect tlog recorder", 10.0,
                )  # fmt: skip
        except MavsdkConnectionError as exc:
            raise FlighttestError(f"cannot open {self.url}: {exc}") from None
        first = await self._mavsdk.first_autopilot(self.connect_timeout_s)
        if first is None:
            raise FlighttestError(f"no autopilot answered on {self.url} within {self.connect_timeout_s:g} s")
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
        from mavsdk.asyncio.plugins.offboard import OffboardAsync
        from mavsdk.asyncio.plugins.param import ParamAsync
        from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

        self.telemetry = TelemetryAsync(self.system)
        self.action = ActionAsync(self.system)
        self.offboard = OffboardAsync(self.system)
        self.param = ParamAsync(self.system)

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
        self.system = None
        if self._recorder is not None:
            self._recorder.stop()
            self._on_event("tlog", {"messages": self._recorder.messages, "path": str(self._recorder.path)})
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

    # -- subscriptions -------------------------------------------------------------------------------
    async def _start_subscriptions(self) -> None:
        tel, st = self.telemetry, self.state
        hz = self.telemetry_hz
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

        def mode(m) -> None:
            old, st.flight_mode = st.flight_mode, m.name
            if old != m.name:
                for cb in self.on_mode:
                    cb(old, m.name)

        def armed(a) -> None:
            st.armed = bool(a)

        def landed(ls) -> None:
            st.landed_state = ls.name

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
            (tel.subscribe_flight_mode, mode),
            (tel.subscribe_armed, armed),
            (tel.subscribe_landed_state, landed),
            (tel.subscribe_in_air, in_air),
            (tel.subscribe_battery, battery),
            (tel.subscribe_health, health),
            (tel.subscribe_health_all_ok, health_ok),
            (self.system.is_connected_state, connection),
        ]
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

    # -- params --------------------------------------------------------------------------------------
    async def get_param(self, name: str, kind: str = "float") -> float | int | None:
        """A PX4 parameter, or None if the vehicle does not have it / does not answer."""
        getter = self.param.get_param_float if kind == "float" else self.param.get_param_int
        try:
            return await self.call(getter(name), f"param {name}", 5.0)
        except Exception:
            return None
