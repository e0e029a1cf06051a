"""The live VRS guard and its abort ladder: pure decision logic, no I/O, testable without a vehicle.

``Guard.on_sample`` judges one telemetry sample (NED velocity, attitude, wind, altitude; the
streamer's commanded acceleration is logged beside it, not judged) and returns a ``Decision`` carrying
every input it used, so the flight log can replay why it acted. ``Guard.on_tick`` catches stale
telemetry between samples, by the phase of the flight (see "Stale telemetry" below).
``AbortLadder`` turns a trigger into the sequence recovery setpoint → Hold → Land and tells the
runner which command to send next; the runner only executes.

Frames and signs follow CONVENTIONS §1: NED, body FRD, ``w > 0`` means air flows up through the disk.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from enum import IntEnum

from flighttest.analysis.fluctuation import LIVE_MIN_SAMPLES, LIVE_MIN_SPAN_FRACTION, fluct_threshold, hover_baseline
from flighttest.flying.autopilot import PX4_RULES, AutopilotRules
from flighttest.model.aero import G_MPS2
from flighttest.model.frames import GuardRegion, disk_tilt_sin, worst_blade_velocity_mps

# Verdicts (guard.csv ``verdict``)
OK = "ok"
PREDICTED = "predicted"  # measured state allowed, the state a horizon ahead is not
MARGINAL = "marginal"  # measured inside the region by less than the clear-violation band
VIOLATION = "violation"  # measured inside the region beyond the band: acts on the first sample
STALE = "stale"
NON_FINITE = "non_finite"
FLOOR = "altitude_floor"
SPEED_CAP = "descent_speed_cap"
FLUCTUATION = "fluctuation"

# Actions (guard.csv ``action``)
NONE = "none"
ABORT = "abort"
# a verdict logged but not acted on: the region on probe flights; a short telemetry gap while PX4 flies
OBSERVE = "observe"

# -- Stale telemetry ---------------------------------------------------------------------------------
# A healthy link goes quiet for up to 173 ms when the machine or the flying process stalls, so the limit
# is a time with room over that, by phase (bench/RESULTS.md, "The stale rule"):
#
# - while flighttest flies the vehicle in offboard (OFFBOARD_PHASES), no state sample for
#   STALE_AFTER_S aborts; with the ticker's period on top (the telemetry period, 20 ms) a dead link is acted
#   on within 0.27 s, inside the 0.3 s budget of issue 11 (at the helix's 1.3 m/s, 0.35 m flown blind);
# - where PX4 flies by itself (AUTOPILOT_PHASES: arming, its takeoff, its Land, the Hold that ends
#   a --no-land flight) flighttest sends nothing the vehicle depends on, so a gap is logged (action
#   OBSERVE) and only one longer than AUTOPILOT_STALE_S acts (the runner starts the ladder at Hold;
#   at Land while landing). 1 s: PX4's own offboard-loss timeout (COM_OF_LOSS_T), well over any stall
#   seen; at PX4's takeoff climb (MPC_TKO_SPEED 1.5 m/s) 1.5 m unobserved, which the takeoff height
#   leaves room for;
# - ``stale_periods`` (telemetry periods) is the older spelling of the offboard limit: when given it
#   sets ``stale_after_s`` = ``stale_periods`` × the telemetry period (``GuardLimits``: the one place);
# - a velocity is judged only with an attitude at most ``stale_after_s`` older (a level attitude kept from
#   before a flare understates ``w``); position-velocity or attitude missing for VELOCITY_STALE_FACTOR ×
#   the limit is stale although the other stream flows;
# - a stream that keeps arriving but ever later is stale too: its lateness is how far the attitude's arrival
#   time less its vehicle timestamp has grown, at the stream's own cadence, above its least over the last
#   LATENCY_WINDOW_S. A step that comes with a gap in the arrivals (more than LATENCY_STEP_S) is the gap's,
#   which the rule above judges: a simulator starved by its host stops its own clock for as long, and its
#   data is as fresh as ever (bench/RESULTS.md, "The stale rule").
STALE_AFTER_S = 0.25
AUTOPILOT_STALE_S = 1.0
# the runner's phases (flighttest.flying.runner set_phase) in which flighttest streams offboard setpoints …
OFFBOARD_PHASES = frozenset({"climb", "settle", "stream"})
# … and those in which PX4 flies by itself; any other phase (before arming) is judged as offboard,
# with the guard disarmed
AUTOPILOT_PHASES = frozenset({"arm", "takeoff", "land", "hold"})


@dataclass(frozen=True)
class GuardLimits:
    """What the guard enforces; every threshold comes from the vehicle profile or the mission config."""

    region: GuardRegion
    telemetry_period_s: float = 0.02
    stale_after_s: float = STALE_AFTER_S  # offboard: no state sample this long aborts
    stale_periods: float | None = None  # the older spelling: when given, stale_after_s = this × the period
    autopilot_stale_s: float = AUTOPILOT_STALE_S  # PX4 flying itself: a gap this long acts
    horizon_s: float = 0.1  # the prediction's reach along the measured trend (missions' [guard] horizon_s)
    trend_window_s: float = 0.1  # the predictor's slope is taken over this much of the latest samples
    debounce_samples: int = 3
    clear_violation_mps: float = 0.05
    observe_region: bool = False
    min_alt_m: float | None = None
    max_descent_mps: float | None = None
    fluct_window_s: float = 0.5
    # fluctuation (the probe's onset detector): absolute limits, and/or a ratio to the hover
    # baseline the runner measures before streaming (never below the minimum std: a still
    # simulator hovers with no shake at all, and any ratio of zero is zero)
    max_rate_std_dps: float | None = None
    max_accel_std_mps2: float | None = None
    fluct_ratio: float | None = None
    fluct_min_rate_std_dps: float = 0.0
    fluct_min_accel_std_mps2: float = 0.0

    def __post_init__(self) -> None:
        if self.stale_periods is not None and self.telemetry_period_s > 0:
            object.__setattr__(self, "stale_after_s", self.stale_periods * self.telemetry_period_s)
        if not (self.telemetry_period_s > 0 and self.stale_after_s > 0 and self.horizon_s >= 0):
            raise ValueError("telemetry period, stale limit (s or periods) must be > 0 and horizon ≥ 0")
        if not (math.isfinite(self.trend_window_s) and 0.0 < self.trend_window_s <= 2.0):
            raise ValueError("trend_window_s must be in (0, 2] s")
        if self.autopilot_stale_s < self.stale_after_s:  # never stricter where PX4 flies than in offboard
            object.__setattr__(self, "autopilot_stale_s", self.stale_after_s)
        if self.debounce_samples < 1 or self.clear_violation_mps < 0 or self.fluct_window_s <= 0:
            raise ValueError("debounce_samples ≥ 1, clear_violation_mps ≥ 0, fluct_window_s > 0")
        if (self.fluct_ratio is not None and not self.fluct_ratio > 0) or min(
            self.fluct_min_rate_std_dps, self.fluct_min_accel_std_mps2
        ) < 0:
            raise ValueError("fluct_ratio > 0 and the minimum fluctuation stds ≥ 0")


@dataclass(frozen=True, slots=True)
class GuardSample:
    """One telemetry sample as the guard sees it. ``t_s`` is the monotonic arrival time."""

    t_s: float
    vn_mps: float
    ve_mps: float
    vd_mps: float
    qw: float
    qx: float
    qy: float
    qz: float
    alt_m: float
    wn_mps: float = 0.0
    we_mps: float = 0.0
    wd_mps: float = 0.0
    # commanded (feed-forward) acceleration of the setpoint being flown, NED
    an_cmd_mps2: float = 0.0
    ae_cmd_mps2: float = 0.0
    ad_cmd_mps2: float = 0.0
    # how far the wind may be off (the guard judges the worst air within it: flighttest.flying.wind)
    wind_radius_mps: float = 0.0
    att_age_s: float = 0.0  # the attitude paired with this velocity is this old
    updraft_mps: float = 0.0  # the updraft the gusts allow (flighttest.flying.wind: stated or measured)


@dataclass(frozen=True, slots=True)
class Decision:
    t_s: float
    verdict: str
    action: str
    reason: str
    w_mps: float = math.nan
    u_mps: float = math.nan
    margin_mps: float = math.nan
    predicted_margin_mps: float = math.nan
    sample: GuardSample | None = None

    @property
    def aborts(self) -> bool:
        return self.action == ABORT


def predicted_blade_velocity_mps(
    vn: float, ve: float, vd: float, an_cmd: float, ae_cmd: float, ad_cmd: float,
    wn: float = 0.0, we: float = 0.0, wd: float = 0.0, *, horizon_s: float,
) -> tuple[float, float]:  # fmt: skip
    """``(w, u)`` of a planned state: velocity advanced by the acceleration, disk tilted as that
    acceleration needs (thrust along −z_body, so ``z_body ∥ g − a``, NED). What the *plan* promises —
    the preflight checks a trajectory with it; the live guard predicts from the vehicle's measured
    response instead (``Guard``).

    Arguments in the order of every rotation helper (``flighttest.model.frames.blade_velocity_mps``):
    the velocity, then what sets the attitude (here the commanded acceleration, there the quaternion),
    then the wind. ``horizon_s`` is keyword-only so that a call with the arguments in another order fails
    rather than swapping them."""
    van = vn + an_cmd * horizon_s - wn
    vae = ve + ae_cmd * horizon_s - we
    vad = vd + ad_cmd * horizon_s - wd
    zn, ze, zd = -an_cmd, -ae_cmd, G_MPS2 - ad_cmd
    zn_norm = math.sqrt(zn * zn + ze * ze + zd * zd)
    if zn_norm < 1e-6:  # free fall commanded: no thrust direction, assume level
        zn, ze, zd, zn_norm = 0.0, 0.0, 1.0, 1.0
    w = (van * zn + vae * ze + vad * zd) / zn_norm
    speed2 = van * van + vae * vae + vad * vad
    u = math.sqrt(max(speed2 - w * w, 0.0))
    return w, u


class FluctuationDetector:
    """Standard deviation of a signal about its linear trend over a sliding time window.

    Fluctuation, not level and not the manoeuvre: a steady turn, a steady deceleration or the
    probe's slow sweep of the commanded acceleration (a trend across the window) do not count,
    the shaking the VRS brings does. The window holds a few tens of samples: recomputing the
    least-squares line on each sample costs microseconds and has none of the cancellation a
    running sum of ``t²`` suffers on a monotonic clock.

    The streaming form of ``flighttest.analysis.fluctuation.trailing_detrended_std``, which defines
    the measure for a whole series; kept in plain floats because it runs on the event loop for every
    IMU sample, where numpy's per-call cost is several times the arithmetic (that module's docstring).
    ``tests/test_fluctuation_tie.py`` feeds both the same samples and requires the same values.
    """

    def __init__(self, window_s: float) -> None:
        self.window_s = window_s
        self._buf: deque[tuple[float, float]] = deque()

    def add(self, t_s: float, value: float) -> float:
        if not math.isfinite(value):
            return math.nan
        self._buf.append((t_s, value))
        while self._buf and self._buf[0][0] < t_s - self.window_s:
            self._buf.popleft()
        return self.std()

    def std(self) -> float:
        n = len(self._buf)
        if n < LIVE_MIN_SAMPLES:
            return 0.0
        t0, t1 = self._buf[0][0], self._buf[-1][0]
        if t1 - t0 < LIVE_MIN_SPAN_FRACTION * self.window_s:
            return 0.0
        mt = sum(t for t, _ in self._buf) / n - t0
        mx = sum(x for _, x in self._buf) / n
        stt = sxt = sxx = 0.0
        for t, x in self._buf:
            dt, dx = t - t0 - mt, x - mx
            stt += dt * dt
            sxt += dt * dx
            sxx += dx * dx
        resid = sxx - (sxt * sxt / stt if stt > 0 else 0.0)
        return math.sqrt(max(resid, 0.0) / n)


VELOCITY_STALE_FACTOR = 2.0
LATENCY_WINDOW_S = 2.0
LATENCY_STEP_S = 0.05


class Guard:
    """Judges each sample; remembers only what debounce, staleness and fluctuation need."""

    def __init__(self, limits: GuardLimits) -> None:
        self.limits = limits
        self.last_sample_t: float | None = None  # newest state sample of any stream (staleness)
        self.last_velocity_t: float | None = None  # newest position-velocity sample
        self.last_attitude_t: float | None = None  # newest attitude sample
        self._latency: deque[tuple[float, float]] = deque()  # (arrival, arrival − vehicle time): increasing
        self._latency_last: float | None = None
        self._latency_steps = 0.0  # the latency's steps that came with gaps, left to the gap rule
        self.lateness_s = 0.0  # the latest attitude sample's lateness (module comment "Stale telemetry")
        self.max_gap_s = 0.0  # longest gap between state samples so far (the runner logs and resets it)
        self._suspect_run = 0
        self._trend: deque[tuple[float, float, float]] = deque()
        self._rate_std = [FluctuationDetector(limits.fluct_window_s) for _ in range(3)]
        self._accel_std = FluctuationDetector(limits.fluct_window_s)
        self.rate_std_dps = 0.0
        self.accel_std_mps2 = 0.0
        self.armed = True  # False: decisions are logged with action "none" (e.g. before streaming)
        # False: the altitude floor is not judged (on the ground, in takeoff and landing, where being
        # below it is the point); everything else still is
        self.floor_active = True
        # False: fluctuation is measured but never judged (takeoff, climb, landing shake by design)
        self.fluct_active = True
        self.baseline_rate_std_dps: float | None = None
        self.baseline_accel_std_mps2: float | None = None
        self._baseline: tuple[list[float], list[float]] | None = None

    # -- fluctuation inputs (IMU stream) ---------------------------------------------------------
    def start_baseline(self) -> None:
        """Collect the hover's fluctuation from now on (the settle before the probe streams)."""
        self._baseline = ([], [])

    def freeze_baseline(self) -> tuple[float | None, float | None]:
        """The hover baseline: median window std since ``start_baseline`` (None without samples)."""
        if self._baseline is not None:
            rates, accels = self._baseline
            self.baseline_rate_std_dps = hover_baseline(rates)
            self.baseline_accel_std_mps2 = hover_baseline(accels)
            self._baseline = None
        return self.baseline_rate_std_dps, self.baseline_accel_std_mps2

    def fluct_thresholds(self) -> tuple[float | None, float | None]:
        """Angular-rate (deg/s) and vertical-acceleration (m/s²) std that end the probe: the lowest of
        the absolute limit and ``fluct_ratio`` × baseline (floored); ``None`` = not judged."""
        lim = self.limits
        return (
            fluct_threshold(lim.max_rate_std_dps, lim.fluct_ratio, self.baseline_rate_std_dps,
                            lim.fluct_min_rate_std_dps),
            fluct_threshold(lim.max_accel_std_mps2, lim.fluct_ratio, self.baseline_accel_std_mps2,
                            lim.fluct_min_accel_std_mps2),
        )  # fmt: skip

    def on_rates(self, t_s: float, p_rps: float, q_rps: float, r_rps: float) -> Decision | None:
        stds = [d.add(t_s, math.degrees(v)) for d, v in zip(self._rate_std, (p_rps, q_rps, r_rps))]
        self.rate_std_dps = max((s for s in stds if math.isfinite(s)), default=0.0)
        if self._baseline is not None:
            self._baseline[0].append(self.rate_std_dps)
        lim = self.fluct_thresholds()[0]
        if self.fluct_active and lim is not None and self.rate_std_dps > lim:
            return self._fluct(t_s, f"angular-rate std {self.rate_std_dps:.1f} deg/s > {lim:.3g} deg/s"
                               + self._baseline_note(self.baseline_rate_std_dps, "deg/s"))  # fmt: skip
        return None

    def on_vertical_accel(self, t_s: float, a_down_mps2: float) -> Decision | None:
        s = self._accel_std.add(t_s, a_down_mps2)
        self.accel_std_mps2 = s if math.isfinite(s) else self.accel_std_mps2
        if self._baseline is not None:
            self._baseline[1].append(self.accel_std_mps2)
        lim = self.fluct_thresholds()[1]
        if self.fluct_active and lim is not None and self.accel_std_mps2 > lim:
            return self._fluct(t_s, f"vertical-acceleration std {self.accel_std_mps2:.2f} m/s² > {lim:.3g} m/s²"
                               + self._baseline_note(self.baseline_accel_std_mps2, "m/s²"))  # fmt: skip
        return None

    def _baseline_note(self, base: float | None, unit: str) -> str:
        return f" (hover baseline {base:.3g} {unit})" if base is not None else ""

    def _fluct(self, t_s: float, reason: str) -> Decision:
        return Decision(t_s, FLUCTUATION, ABORT if self.armed else NONE, reason)

    # -- state samples ---------------------------------------------------------------------------
    def note_state_sample(self, t_s: float) -> None:
        """A state sample of any stream (position-velocity, attitude) arrived at ``t_s``."""
        last = self.last_sample_t
        if last is None or t_s > last:
            if last is not None and t_s - last > self.max_gap_s:
                self.max_gap_s = t_s - last
            self.last_sample_t = t_s

    def note_attitude(self, t_s: float, t_vehicle_s: float | None = None) -> None:
        """An attitude sample arrived at ``t_s``, stamped ``t_vehicle_s`` by the vehicle (None: unstamped)."""
        self.note_state_sample(t_s)
        self.last_attitude_t = t_s
        if t_vehicle_s is None or not math.isfinite(t_vehicle_s):
            return
        raw = t_s - t_vehicle_s
        if self._latency_last is not None and raw - self._latency_last > LATENCY_STEP_S:
            self._latency_steps += raw - self._latency_last
        self._latency_last = raw
        lat, q = raw - self._latency_steps, self._latency
        while q and q[-1][1] >= lat:  # a monotonic queue: its front is the window's least latency
            q.pop()
        q.append((t_s, lat))
        while q[0][0] < t_s - LATENCY_WINDOW_S:
            q.popleft()
        self.lateness_s = lat - q[0][1]

    def _extrapolate(self, t_s: float, w: float, u: float) -> tuple[float, float]:
        """``(w, u)`` ``horizon_s`` ahead along the slope from the oldest sample within the trend window
        (a real estimate's velocity noise is slow — PX4: correlated over 1.5 s — so a 0.1 s slope is
        the vehicle's motion, not noise)."""
        lim = self.limits
        trend = self._trend
        trend.append((t_s, w, u))
        while len(trend) > 1 and t_s - trend[0][0] > lim.trend_window_s:
            trend.popleft()
        t0, w0, u0 = trend[0]
        span = t_s - t0
        if span < 0.5 * lim.trend_window_s:
            return w, u
        k = lim.horizon_s / span
        return w + k * (w - w0), max(u + k * (u - u0), 0.0)

    def on_sample(self, s: GuardSample) -> Decision:
        lim = self.limits
        self.note_state_sample(s.t_s)
        self.last_velocity_t = s.t_s
        act = ABORT if self.armed else NONE
        values = (s.vn_mps, s.ve_mps, s.vd_mps, s.qw, s.qx, s.qy, s.qz, s.alt_m, s.wn_mps, s.we_mps, s.wd_mps)
        if not all(math.isfinite(v) for v in values):
            self._suspect_run = 0
            return Decision(s.t_s, NON_FINITE, act, "non-finite telemetry", sample=s)
        if not math.isfinite(s.att_age_s) or s.att_age_s > lim.stale_after_s:
            self._suspect_run = 0
            return Decision(s.t_s, STALE, act, f"attitude {s.att_age_s * 1000:.0f} ms old: velocity not judged "
                            f"with it (> {lim.stale_after_s * 1000:.0f} ms)", sample=s)  # fmt: skip
        qn = math.sqrt(s.qw * s.qw + s.qx * s.qx + s.qy * s.qy + s.qz * s.qz)
        if abs(qn - 1.0) > 0.05:
            return Decision(s.t_s, NON_FINITE, act, f"attitude quaternion norm {qn:.3f} ≠ 1", sample=s)
        qw, qx, qy, qz = s.qw / qn, s.qx / qn, s.qy / qn, s.qz / qn
        _, w, u, _ = lim.region.check(s.vn_mps, s.ve_mps, s.vd_mps, qw, qx, qy, qz, s.wn_mps, s.we_mps, s.wd_mps)
        # a horizon ahead, from the vehicle's own response: (w, u) extrapolated along their measured trend
        # over the last trend_window_s. Not from the command: a real autopilot's tilt and descent trail a
        # demanding plan by tenths of a second (bench/RESULTS.md,
        # "Flying the plan PX4 flies: helix and vertical on PX4 SITL and on the fake (issue 11)").
        w, u = float(w), float(u)
        wp, up = self._extrapolate(s.t_s, w, u)
        # both judged at the worst air the wind's uncertainty and the gusts allow; w and u are logged as estimated
        tilt = float(disk_tilt_sin(qw, qx, qy, qz))
        worst = (tilt, s.wind_radius_mps, s.updraft_mps)
        margin = float(lim.region.margin(*worst_blade_velocity_mps(w, u, *worst)))
        pmargin = float(lim.region.margin(*worst_blade_velocity_mps(wp, up, *worst)))

        def dec(verdict: str, action: str, reason: str) -> Decision:
            return Decision(s.t_s, verdict, action, reason, w, u, margin, pmargin, s)

        # hard limits first: they hold in observe mode too
        if self.floor_active and lim.min_alt_m is not None and s.alt_m < lim.min_alt_m:
            return dec(FLOOR, act, f"altitude {s.alt_m:.2f} m below floor {lim.min_alt_m:g} m")
        if lim.max_descent_mps is not None and s.vd_mps > lim.max_descent_mps:
            return dec(SPEED_CAP, act, f"descent {s.vd_mps:.2f} m/s above cap {lim.max_descent_mps:g} m/s")

        region_act = OBSERVE if lim.observe_region and self.armed else act
        if margin < -lim.clear_violation_mps:
            self._suspect_run = 0
            return dec(VIOLATION, region_act, f"in guard region: w={w:.2f} m/s, u={u:.2f} m/s")
        # a prediction is a guess: only one clearly inside (beyond the clear-violation band) counts
        if margin < 0.0 or pmargin < -lim.clear_violation_mps:
            self._suspect_run += 1
            verdict = MARGINAL if margin < 0.0 else PREDICTED
            if self._suspect_run >= lim.debounce_samples:
                why = (
                    f"{verdict} for {self._suspect_run} samples: w={w:.2f} m/s, u={u:.2f} m/s, "
                    f"predicted w={wp:.2f} m/s, u={up:.2f} m/s"
                )
                return dec(verdict, region_act, why)
            return dec(verdict, NONE, f"debounce {self._suspect_run}/{lim.debounce_samples}")
        self._suspect_run = 0
        return dec(OK, NONE, "")

    def on_tick(self, now_s: float, phase: str | None = None) -> Decision | None:
        """Stale telemetry: no state sample of any stream for ``stale_after_s`` (the streams arrive
        interleaved, so one late message alone is not a dead link); and, as a second line, no velocity
        for ``VELOCITY_STALE_FACTOR`` times that (the region cannot be judged without it, even while
        attitude keeps coming). ``None`` while fresh.

        ``phase`` is the runner's (module comment "Stale telemetry"): in ``AUTOPILOT_PHASES`` PX4
        flies itself and the decision is ``OBSERVE`` (log it) until the gap passes
        ``autopilot_stale_s``, then ``ABORT`` whether or not the guard is armed (its region verdicts
        are off while PX4 lands; staleness is not). Anywhere else (offboard, or ``None``) it is
        ``ABORT`` when the guard is armed, else ``NONE``."""
        if self.last_sample_t is None:
            return None
        lim = self.limits
        age = now_s - self.last_sample_t
        v_age = now_s - self.last_velocity_t if self.last_velocity_t is not None else -math.inf
        a_age = now_s - self.last_attitude_t if self.last_attitude_t is not None else -math.inf
        # the age that counts: the silence itself, or the lateness of what arrives
        age = max(age, self.lateness_s)
        if phase in AUTOPILOT_PHASES:
            acts = age > lim.autopilot_stale_s or max(v_age, a_age) > VELOCITY_STALE_FACTOR * lim.autopilot_stale_s
            action, after = (ABORT, lim.autopilot_stale_s) if acts else (OBSERVE, lim.stale_after_s)
            where = f" in {phase}: the autopilot flies itself"
        else:
            action, after, where = (ABORT if self.armed else NONE), lim.stale_after_s, ""
        one_ms = VELOCITY_STALE_FACTOR * after * 1000
        if self.lateness_s > after and now_s - self.last_sample_t <= after:
            why = f"telemetry arrives {self.lateness_s * 1000:.0f} ms late (> {after * 1000:.0f} ms)"
        elif age > after:
            why = f"no telemetry for {age * 1000:.0f} ms (> {after * 1000:.0f} ms)"
        elif v_age > VELOCITY_STALE_FACTOR * after:
            why = f"no position-velocity telemetry for {v_age * 1000:.0f} ms (> {one_ms:.0f} ms)"
        elif a_age > VELOCITY_STALE_FACTOR * after:
            why = f"no attitude telemetry for {a_age * 1000:.0f} ms (> {one_ms:.0f} ms)"
        else:
            return None
        return Decision(now_s, STALE, action, why + where)


def stale_rung(phase: str) -> Rung:
    """Where the ladder starts on stale telemetry: Recover in offboard (flighttest flies the vehicle: level,
    arrest the sink), Hold where PX4 flies itself (its takeoff, its Hold: stop there), Land while landing
    (PX4 goes on landing; the ladder keeps asking it to, and watches)."""
    if phase == "land":
        return Rung.LAND
    if phase in AUTOPILOT_PHASES:
        return Rung.HOLD
    return Rung.RECOVER


# -- the abort ladder --------------------------------------------------------------------------------


class Rung(IntEnum):
    NOMINAL = 0
    RECOVER = 1  # recovery setpoint: level, arrest the sink, lateral speed away from obstacles
    HOLD = 2
    LAND = 3
    DONE = 4


# commands the ladder asks the runner to send
CMD_RECOVER = "recover"
CMD_HOLD = "hold"
CMD_LAND = "land"
CMD_DISARM = "disarm"  # on the ground and still armed (the autopilot refuses it in the air)

# PX4's modes in which a person flies the vehicle: seen during the ladder, flighttest stops sending anything
# (README "Aborting by hand": the pilot took over); each autopilot's own are its rules'
PILOT_MODES = PX4_RULES.pilot_modes


@dataclass(frozen=True)
class LadderTiming:
    recover_max_s: float = 2.0  # give up on the recovery setpoint after this
    arrested_vd_mps: float = 0.3  # sink counts as arrested below this descent rate …
    arrested_for_s: float = 0.3  # … held this long
    hold_confirm_s: float = 3.0  # Hold must show in the flight mode within this, else Land
    hold_dwell_s: float = 2.0  # time in Hold before landing
    land_retry_s: float = 3.0  # re-send Land if the mode does not show it (or cannot be seen)
    land_min_resend_s: float = 0.5  # a newly stale link re-sends Land at once, but not more often than this
    disarm_grace_s: float = 3.0  # on the ground and armed this long (on top of the evidence's 3 s): disarm
    link_give_up_s: float = 5.0  # link lost and nothing heard this long: the vehicle's failsafe is in charge
    land: bool = True  # False (--no-land): the ladder ends in Hold


@dataclass
class LadderObservation:
    t_s: float
    vd_mps: float = math.nan
    region_ok: bool = True
    telemetry_fresh: bool = True
    mode: str = ""  # the autopilot's mode name (flighttest.flying.autopilot), e.g. "HOLD" / "BRAKE", "LAND"
    landed: bool = False  # disarmed on the ground, on evidence (flighttest.flying.ground)
    armed: bool = True  # as last reported: a disarm before the evidence confirms it
    on_ground: bool = False  # on the ground, armed or not, on evidence
    link_ok: bool = True
    heard_age_s: float = 0.0  # since anything was last heard from the vehicle (a state sample)


@dataclass
class AbortLadder:
    """State machine recovery → Hold → Land. ``trigger`` and ``step`` return the command to send now
    (or ``None``); rungs only go up. The first trigger's reason is *the* abort reason."""

    timing: LadderTiming = field(default_factory=LadderTiming)
    rules: AutopilotRules = PX4_RULES  # which modes hold, land, and mean a pilot (set once the vehicle is known)
    rung: Rung = Rung.NOMINAL
    reason: str = ""
    entered_t: float = 0.0
    _arrested_since: float | None = None
    _hold_seen_t: float | None = None
    _last_land_t: float = -math.inf
    _last_disarm_t: float = -math.inf
    _on_ground_since: float | None = None
    _land_watch: str = ""  # in Land: "" (telemetry fine), "telemetry stale" or "link lost"
    # in Land: the autopilot brings the vehicle down (or home) by itself and the ladder only watches; a mode
    # seen outside its own ones (fresh telemetry) for land_retry_s ends the watching: Land is sent then
    following: bool = False
    _strange_mode_since: float | None = None
    history: list[tuple[float, str, str]] = field(default_factory=list)

    @property
    def active(self) -> bool:
        return self.rung != Rung.NOMINAL

    @property
    def done(self) -> bool:
        return self.rung == Rung.DONE

    def trigger(self, t_s: float, reason: str, first: Rung = Rung.RECOVER) -> str | None:
        if not self.reason:
            self.reason = reason
        if self.rung >= first:
            return None
        return self._enter(t_s, first, reason)

    def follow(self, t_s: float, reason: str) -> None:
        """The autopilot took the vehicle into one of its own failsafe modes: the ladder's Land rung, sending
        nothing while it stays in them."""
        if not self.reason:
            self.reason = reason
        if self.rung < Rung.LAND:
            self._enter(t_s, Rung.LAND, reason)
        self.following = True
        self._strange_mode_since = None

    def escalate(self, t_s: float, why: str) -> str | None:
        """Skip to the next rung now (a second Ctrl-C, a failed command)."""
        if self.rung in (Rung.NOMINAL, Rung.LAND, Rung.DONE):
            return None
        nxt = Rung(self.rung + 1)
        if nxt == Rung.LAND and not self.timing.land:
            return None
        return self._enter(t_s, nxt, why)

    def _enter(self, t_s: float, rung: Rung, why: str) -> str | None:
        self.rung = rung
        self.entered_t = t_s
        self._arrested_since = None
        self._hold_seen_t = None
        self.history.append((t_s, rung.name, why))
        if rung == Rung.RECOVER:
            return CMD_RECOVER
        if rung == Rung.HOLD:
            return CMD_HOLD
        if rung == Rung.LAND:
            self._last_land_t = t_s
            return None if self.following else CMD_LAND
        return None

    def finish(self, t_s: float, why: str) -> None:
        """End the ladder here (``DONE``): the pilot has the vehicle, it is on the ground, or the
        ladder ran out of time. Nothing more is commanded."""
        self._enter(t_s, Rung.DONE, why)

    def note(self, t_s: float, why: str) -> None:
        """A decision that keeps the rung (re-sending Land, telemetry lost or back): into the history."""
        self.history.append((t_s, self.rung.name, why))

    def step(self, ob: LadderObservation) -> str | None:
        tm, t = self.timing, ob.t_s
        if self.rung in (Rung.NOMINAL, Rung.DONE):
            return None
        # on every rung: a pilot mode means a person has the sticks, and anything sent would fight them
        if ob.mode in self.rules.pilot_modes:
            return self._enter(t, Rung.DONE, f"pilot took over ({ob.mode}): sending nothing more")
        # nothing can reach the vehicle any more: PX4's own failsafe (offboard loss, data-link loss) flies it
        if not ob.link_ok and ob.heard_age_s > tm.link_give_up_s:
            why = f"link lost and nothing heard for {ob.heard_age_s:.1f} s (> {tm.link_give_up_s:g} s)"
            return self._enter(t, Rung.DONE, f"{why}: the vehicle's own failsafe is in charge")
        # the autopilot chose to land or return by itself: follow it, send nothing
        if ob.mode in self.rules.failsafe_modes and not self.following and self.rung < Rung.LAND:
            self.follow(t, f"autopilot in {ob.mode}: following it")
            return None
        if self.rung == Rung.RECOVER:
            arrested = ob.telemetry_fresh and ob.region_ok and ob.vd_mps <= tm.arrested_vd_mps
            if arrested:
                self._arrested_since = t if self._arrested_since is None else self._arrested_since
                if t - self._arrested_since >= tm.arrested_for_s:
                    return self._enter(t, Rung.HOLD, "sink arrested")
            else:
                self._arrested_since = None
            if t - self.entered_t >= tm.recover_max_s:
                return self._enter(t, Rung.HOLD, f"recovery not confirmed within {tm.recover_max_s:g} s")
        elif self.rung == Rung.HOLD:
            if ob.landed:
                return self._enter(t, Rung.DONE, "on the ground")
            if ob.on_ground and tm.land:  # still armed on the ground: Land, then disarm
                return self._enter(t, Rung.LAND, "on the ground, armed")
            if ob.mode == self.rules.hold_mode:
                self._hold_seen_t = t if self._hold_seen_t is None else self._hold_seen_t
                if not tm.land:
                    return self._enter(t, Rung.DONE, "holding (--no-land)")
                if t - self._hold_seen_t >= tm.hold_dwell_s:
                    return self._enter(t, Rung.LAND, "hold dwell over")
            elif t - self.entered_t >= tm.hold_confirm_s:
                why = f"Hold not confirmed within {tm.hold_confirm_s:g} s (mode {ob.mode or 'unknown'})"
                if not tm.land:
                    return self._enter(t, Rung.DONE, why)
                return self._enter(t, Rung.LAND, why)
        elif self.rung == Rung.LAND:
            return self._step_land(ob)
        return None

    def _step_land(self, ob: LadderObservation) -> str | None:
        """Land keeps watching: with stale telemetry or a lost link PX4 is (most likely) landing on its
        own and there is nothing better to ask for, so Land is re-sent — at once when it starts, then
        every ``land_retry_s`` — and each change is noted; ``step`` gives up on a link gone for good."""
        tm, t = self.timing, ob.t_s
        if ob.landed:
            return self._enter(t, Rung.DONE, "landed")
        watch = "link lost" if not ob.link_ok else "telemetry stale" if not ob.telemetry_fresh else ""
        # on the ground and still armed: after a flight the autopilot disarms by itself (PX4: COM_DISARM_LAND,
        # 2 s after its land detector); after none it does not (PX4 only after COM_DISARM_PRFLT, 10 s), so ask
        if not ob.on_ground:
            self._on_ground_since = None
        elif self._on_ground_since is None:
            self._on_ground_since = t
        if ob.on_ground and not watch:
            if t - self._on_ground_since < tm.disarm_grace_s or t - self._last_disarm_t < tm.land_retry_s:
                return None  # nothing more to land
            self._last_disarm_t = t
            self.note(t, "on the ground, still armed: disarming")
            return CMD_DISARM
        if self.following:
            if watch or ob.mode in self.rules.failsafe_modes:
                self._strange_mode_since = None
                return None  # what the autopilot flies by itself is not overridden, seen or not
            self._strange_mode_since = t if self._strange_mode_since is None else self._strange_mode_since
            if t - self._strange_mode_since < tm.land_retry_s:
                return None
            self.following = False
            self._last_land_t = t
            self.note(t, f"the autopilot left its own modes for {ob.mode or 'unknown'}: sending Land")
            return CMD_LAND
        if watch != self._land_watch:
            was, self._land_watch = self._land_watch, watch
            if not watch:
                self.note(t, f"{was} during Land is over: telemetry back (mode {ob.mode or 'unknown'})")
            elif t - self._last_land_t >= tm.land_min_resend_s:
                self._last_land_t = t
                self.note(t, f"{watch} during Land: re-sending Land")
                return CMD_LAND
            else:
                self.note(t, f"{watch} during Land: Land was just sent, re-sending in {tm.land_retry_s:g} s")
        # reported disarmed, not yet confirmed (ground.DISARM_HELD_S): PX4 leaves Land for Hold as it disarms, and
        # a Land sent then left PX4 SITL disarmed in Land, where it will not arm (the next flight refused)
        if not ob.armed and not watch:
            return None
        # the mode cannot be trusted while the telemetry is stale: keep asking
        if (watch or ob.mode != self.rules.land_mode) and t - self._last_land_t >= tm.land_retry_s:
            self._last_land_t = t
            self.note(t, f"re-sending Land ({watch or 'mode ' + (ob.mode or 'unknown')})")
            return CMD_LAND
        return None
