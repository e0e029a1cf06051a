"""Command line and main loop of the fake vehicle (``python -m sitl_fakes`` and ``flighttest sim``).

One thread: wait on the socket until the next physics deadline (``select``), handle what arrived,
run the physics steps that are due (deadline pacing on ``time.monotonic``), send the telemetry that
is due. Stops on SIGINT/SIGTERM, and when its parent process dies.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import select
import signal
import sys
import time
from pathlib import Path

from flighttest.errors import FlighttestError
from flighttest.model.profiles import load_profile
from sitl_fakes import ardupilot, px4
from sitl_fakes.disturbance import VrsTruth, default_onset_mps
from sitl_fakes.drag import parse_truth_drag
from sitl_fakes.estimator import EstimateError
from sitl_fakes.link import Link, PortInUse
from sitl_fakes.telemetry import Telemetry
from sitl_fakes.truthlog import TruthLog
from sitl_fakes.vehicle import FakeConfig, FakePx4

DEFAULT_PORT = 14580
PARENT_POLL_S = 0.5
MAX_CATCH_UP_S = 0.25


AUTOPILOTS = ("px4", "ardupilot")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--vehicle", default="x500", help="vehicle profile name or .toml path (default x500)")
    p.add_argument("--autopilot", choices=AUTOPILOTS, default="px4",
                   help="personality: px4 (PX4 v1.15 multicopter, default) or ardupilot (ArduCopter master 2026)")
    p.add_argument("--ekf-delay-s", type=float, default=None, metavar="S",
                   help=f"ardupilot: seconds from boot until the EKF has its origin and arming is allowed "
                        f"(default {ardupilot.EKF_DELAY_S:g}, as ArduCopter SITL)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT,
                   help=f"UDP port to listen on (default {DEFAULT_PORT}; 0 = any free port, printed on the first line)")
    p.add_argument("--bind", default="0.0.0.0", help="address to bind (default 0.0.0.0)")
    p.add_argument("--peer", action="append", default=[], metavar="HOST:PORT",
                   help="also send to a listening client, e.g. MAVSDK udpin://0.0.0.0:14540 (repeatable)")
    p.add_argument("--truth-log", type=Path, default=None, metavar="FILE", help="write the ground truth CSV here")
    p.add_argument("--truth-rate-hz", type=float, default=0.0,
                   help="state rows per second in the truth log (default: every physics step)")
    p.add_argument("--truth-onset", type=float, default=None, metavar="W_MPS",
                   help="true straight-down VRS onset: descent rate w through the disk in m/s "
                        "(default: Onera's boundary for the vehicle's v_h)")
    p.add_argument("--truth-cone-deg", type=float, default=20.0,
                   help="true cone: disturbed where w > max(onset, tan(cone)*u) (default 20)")
    p.add_argument("--truth-severity", type=float, default=1.0,
                   help="scales thrust loss and fluctuation (default 1, 0 = no VRS effect)")
    p.add_argument("--seed", type=int, default=0, help="random seed of fluctuations and gusts (default 0)")
    p.add_argument("--wind-ned", nargs="+", default=["0,0,0"], metavar="N E D",
                   help="steady wind in m/s, NED: 'N E D' (as flighttest fly takes it) or 'N,E,D' (default 0 0 0)")
    p.add_argument("--gust-mps", type=float, default=0.0,
                   help="turbulence standard deviation in m/s, horizontal (vertical: half) (default 0)")
    p.add_argument("--gust-tau-s", type=float, default=None, metavar="S",
                   help="one correlation time for the turbulence (default: Dryden's, from the height and airspeed)")
    p.add_argument("--truth-drag", default=None, metavar="LIN,QUAD",
                   help="the airframe's true drag per body axis: LIN,QUAD or LX,LY,LZ,QX,QY,QZ in N/(m/s) and "
                        "N/(m/s)^2, linear term constant (default: the vehicle's, sitl_fakes/drag.py)")
    p.add_argument("--physics-hz", type=float, default=250.0, help="physics rate (default 250)")
    p.add_argument("--telemetry-hz", type=float, default=50.0,
                   help="default rate of LOCAL_POSITION_NED, ATTITUDE_QUATERNION, ODOMETRY (default 50)")
    p.add_argument("--crash-speed-mps", type=float, default=2.5,
                   help="a touchdown faster than this is a crash (default 2.5)")
    p.add_argument("--gps-delay-s", type=float, default=0.0,
                   help="no valid position (arming denied) for this long after start (default 0)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="autopilot parameter value at boot, e.g. MIS_TAKEOFF_ALT=1.5 (PX4) or MAV1_EXT_STAT=2 "
                        "(ArduPilot) (repeatable)")
    p.add_argument("--sysid", type=int, default=1,
                   help="MAVLink system id (default 1; give two fakes different ids to test vehicle selection)")
    p.add_argument("--duration-s", type=float, default=0.0, help="exit after this long (default: run until stopped)")
    p.add_argument("--estimate-error", type=float, default=1.0, metavar="SCALE",
                   help="scales the estimate's offset from the truth (PX4 SIH's EKF2 of today, or with --autopilot "
                        "ardupilot ArduCopter SITL's EKF3; default 1, 0 = a perfect estimator, 8 = about "
                        "PX4's EKF2 of 2026-03)")
    p.add_argument("--telemetry-gap-rate-hz", type=float, default=0.1, metavar="HZ",
                   help="how often the telemetry goes quiet for 50-100 ms, as real links do "
                        "(default 0.1 per second; 0 = never)")


def _parse_triple(text: str, what: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(x) for x in text.split(","))
    except ValueError:
        raise FlighttestError(f"{what}: expected three numbers N,E,D (got {text!r})") from None
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise FlighttestError(f"{what}: expected three finite numbers N,E,D (got {text!r})")
    return vals  # type: ignore[return-value]


def _parse_peer(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise FlighttestError(f"--peer: expected HOST:PORT (got {text!r})")
    return host, int(port)


def build_config(args: argparse.Namespace) -> FakeConfig:
    profile = load_profile(args.vehicle)
    positive = {"--physics-hz": args.physics_hz, "--telemetry-hz": args.telemetry_hz,
                "--crash-speed-mps": args.crash_speed_mps}  # fmt: skip
    for name, value in positive.items():
        if not (math.isfinite(value) and value > 0):
            raise FlighttestError(f"{name} must be a positive number (got {value})")
    if args.physics_hz < 50:
        raise FlighttestError(f"--physics-hz must be ≥ 50 (got {args.physics_hz})")
    for name, value in {"--gust-mps": args.gust_mps, "--gps-delay-s": args.gps_delay_s,
                        "--truth-rate-hz": args.truth_rate_hz, "--duration-s": args.duration_s,
                        "--estimate-error": args.estimate_error,
                        "--telemetry-gap-rate-hz": args.telemetry_gap_rate_hz}.items():  # fmt: skip
        if not (math.isfinite(value) and value >= 0):
            raise FlighttestError(f"{name} must be ≥ 0 (got {value})")
    if not 0 <= args.port < 65536:
        raise FlighttestError(f"--port must be 0..65535 (got {args.port})")
    ekf_delay = getattr(args, "ekf_delay_s", None)
    if ekf_delay is not None:
        if getattr(args, "autopilot", "px4") != "ardupilot":
            raise FlighttestError("--ekf-delay-s is an ArduPilot option (--autopilot ardupilot)")
        if not (math.isfinite(ekf_delay) and ekf_delay >= 0):
            raise FlighttestError(f"--ekf-delay-s must be ≥ 0 (got {ekf_delay})")
    onset = default_onset_mps(profile.v_h_mps) if args.truth_onset is None else args.truth_onset
    try:
        truth = VrsTruth(onset, args.truth_cone_deg, args.truth_severity, args.seed, profile.v_h_mps)
    except ValueError as exc:
        raise FlighttestError(f"truth: {exc}") from None
    gust_tau = getattr(args, "gust_tau_s", None)
    if gust_tau is not None and not (math.isfinite(gust_tau) and gust_tau > 0):
        raise FlighttestError(f"--gust-tau-s must be a positive number (got {gust_tau})")
    drag_text = getattr(args, "truth_drag", None)
    try:
        drag = parse_truth_drag(drag_text) if drag_text is not None else None
    except ValueError as exc:
        raise FlighttestError(f"--truth-drag: {exc}") from None
    home, error, extra = {}, EstimateError(), {}
    if getattr(args, "autopilot", "px4") == "ardupilot":  # ArduCopter SITL's home (the reference flights')
        error = ardupilot.SITL_ESTIMATE_ERROR
        home = {"home_lat_deg": ardupilot.HOME_LAT_DEG, "home_lon_deg": ardupilot.HOME_LON_DEG,
                "home_alt_m": ardupilot.HOME_ALT_M}  # fmt: skip
        extra["imu_noise_mps2"] = ardupilot.SITL_IMU_NOISE_MPS2
    return FakeConfig(
        **home,
        profile=profile,
        truth=truth,
        wind_ned=_parse_triple(",".join(args.wind_ned), "--wind-ned"),
        gust_mps=args.gust_mps,
        gust_tau_s=gust_tau,
        truth_drag=drag,
        **extra,
        seed=args.seed,
        crash_speed_mps=args.crash_speed_mps,
        gps_delay_s=args.gps_delay_s,
        telemetry_hz=args.telemetry_hz,
        estimate_error=error.scaled(args.estimate_error),
        telemetry_gap_rate_hz=args.telemetry_gap_rate_hz,
    )


def _apply_params(vehicle: FakePx4, items: list[str]) -> None:
    ardu = getattr(vehicle, "autopilot", "px4") == "ardupilot"
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or name not in vehicle.params:
            which = "ArduPilot" if ardu else "PX4"
            raise FlighttestError(f"--param: expected NAME=VALUE with a known {which} parameter (got {item!r})")
        param = vehicle.params[name]
        try:
            if ardu:
                number = float(value)
                if param.type in ardupilot.INT_TYPES:
                    if number != int(number):
                        raise ValueError(value)
                    number = int(number)
                param.value = number
            else:
                param.value = int(value) if param.type == px4.PARAM_INT32 else float(value)
        except (ValueError, OverflowError):
            raise FlighttestError(f"--param {name}: not a number ({value!r})") from None
        if isinstance(param.value, float) and not math.isfinite(param.value):
            raise FlighttestError(f"--param {name}: must be finite")


class _Stop:
    def __init__(self):
        self.reason = ""

    def __call__(self, signum, frame):
        self.reason = signal.Signals(signum).name


def run(args: argparse.Namespace) -> int:
    cfg = build_config(args)
    peers = [_parse_peer(p) for p in args.peer]
    try:
        if not 1 <= args.sysid <= 254:
            raise FlighttestError(f"--sysid must be 1..254 (got {args.sysid})")
        link = Link(args.port, args.bind, peers, sysid=args.sysid)
    except PortInUse as exc:
        raise FlighttestError(str(exc)) from None
    except OSError as exc:
        raise FlighttestError(f"--peer/--bind: {exc}") from None
    t0 = time.monotonic()
    try:
        log = TruthLog(args.truth_log, t0)
    except OSError as exc:
        link.close()
        raise FlighttestError(f"--truth-log {args.truth_log}: cannot write ({exc.strerror})") from None
    truth_hz = args.truth_rate_hz or args.physics_hz
    if args.autopilot == "ardupilot":
        # imported here: the PX4 personality's start-up does not load ArduCopter's modules
        from sitl_fakes.ardupilot_telemetry import ArduPilotTelemetry
        from sitl_fakes.ardupilot_vehicle import FakeArduCopter

        ekf_delay = ardupilot.EKF_DELAY_S if args.ekf_delay_s is None else args.ekf_delay_s
        vehicle: FakePx4 = FakeArduCopter(cfg, link, log, t0, ekf_delay_s=ekf_delay)
        _apply_params(vehicle, args.param)  # before the telemetry: MAV1_* stream rates are read at boot
        vehicle.telemetry = ArduPilotTelemetry(vehicle, cfg.telemetry_hz, truth_hz)
    else:
        vehicle = FakePx4(cfg, link, log, t0)
        _apply_params(vehicle, args.param)
        vehicle.telemetry = Telemetry(vehicle, cfg.telemetry_hz, truth_hz)
    stop = _Stop()
    for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):  # SIGHUP: the shell that started it closed
        signal.signal(sig, stop)
    print(f"connect: udpout://127.0.0.1:{link.port}", flush=True)
    t = cfg.truth
    personality = " (ardupilot)" if args.autopilot == "ardupilot" else ""  # PX4's lines carry no tag
    print(
        f"sitl_fakes: {cfg.profile.name}{personality} v_h={cfg.profile.v_h_mps:.3f} m/s "
        f"truth onset={t.onset_mps:.3f} m/s "
        f"cone={t.cone_deg:g} deg severity={t.severity:g} seed={t.seed} truth_log={args.truth_log}",
        file=sys.stderr,
        flush=True,
    )
    vehicle.event(
        "event",
        f"start vehicle={cfg.profile.name}{personality.replace(' (', ' autopilot=').rstrip(')')} "
        f"onset_mps={t.onset_mps:.4f} cone_deg={t.cone_deg} "
        f"severity={t.severity} seed={t.seed} wind_ned={cfg.wind_ned} gust_mps={cfg.gust_mps} "
        f"gust_tau_s={cfg.gust_tau_s if cfg.gust_tau_s is not None else 'dryden'} "
        f"drag=({vehicle.body.drag.describe()})",
    )
    try:
        _loop(vehicle, link, log, 1.0 / args.physics_hz, stop, args.duration_s)
    finally:
        vehicle.event("event", f"stop ({stop.reason or 'end'})")
        log.close()
        link.close()
        why = STOP_WHY.get(stop.reason, stop.reason or "an error")
        print(f"sitl_fakes: stopped after {time.monotonic() - t0:.0f} s: {why}", file=sys.stderr, flush=True)
    return 0


STOP_WHY = {"SIGHUP": "SIGHUP (the terminal or shell that started it closed; `nohup` or `setsid` keeps it running)",
            "SIGINT": "SIGINT (Ctrl-C)", "SIGTERM": "SIGTERM (asked to stop)",
            "duration reached": "--duration-s reached"}  # fmt: skip


def _loop(vehicle: FakePx4, link: Link, log: TruthLog, dt: float, stop: _Stop, duration_s: float) -> None:
    # the launcher's pid (FakeVehicle): a parent that exited while this process started up is already gone
    parent = int(os.environ.get("SITL_FAKES_PARENT_PID") or os.getppid())
    next_step = time.monotonic()
    next_parent_check = next_step + PARENT_POLL_S
    end = next_step + duration_s if duration_s > 0 else math.inf
    telemetry = vehicle.telemetry
    while not stop.reason:
        now = time.monotonic()
        wait = next_step - now
        if wait > 0:
            with contextlib.suppress(InterruptedError):
                select.select([link.sock], [], [], wait)
        for msg, addr in link.receive():
            vehicle.now = time.monotonic()
            vehicle.handle(msg, addr)
        now = time.monotonic()
        if now - next_step > MAX_CATCH_UP_S:  # stalled (suspended, overloaded): do not fast-forward
            vehicle.event("event", f"overrun: {now - next_step:.3f} s behind, skipping")
            next_step = now
        while now >= next_step:
            vehicle.step(dt, next_step)
            next_step += dt
        telemetry.tick(now)
        if now >= next_parent_check:
            next_parent_check = now + PARENT_POLL_S
            if os.getppid() != parent:
                stop.reason = "parent died"
            if now - log.last_flush >= 1.0:
                log.flush(now)
        if now >= end:
            stop.reason = "duration reached"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m sitl_fakes",
        description="A fake PX4 (or, --autopilot ardupilot, ArduCopter) quadcopter with VRS/WBS physics and a "
                    "ground-truth log (see sitl_fakes/README.md).",
    )
    add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run(args)
    except FlighttestError as exc:
        print(f"sitl_fakes: error: {exc}", file=sys.stderr)
        return exc.exit_code
