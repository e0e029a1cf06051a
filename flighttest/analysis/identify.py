"""Identify the VRS onset from a probe flight: the descent speed where the shaking starts.

The model: below the onset the vehicle shakes as it does in hover; past it the ring vortex adds a
fluctuation whose amplitude grows with the depth into the region (the paper's probe, and the fake's
truth: thrust fluctuation ``σ ∝ w − onset``). Independent shaking adds in *variance*, so the
expected fluctuation power at descent speed ``w`` is a hinge

    E[P](w) = β0 + β1 · (w − w0)₊²            (β0: hover, β1 ≥ 0: growth, w0: the onset)

and the onset is where the fitted rise meets the hover level — extrapolated back from the rise,
not where a threshold is crossed (a threshold fires only once the rise has grown to it, which
puts the onset high by the speed the rise needs to get there).

``P`` is, per sample, the mean over the body rates p, q, r (the vertical acceleration when the log
has no rates: the probe commands vertical acceleration but no rotation, so the rates carry the
ring vortex's rocking and little else) of the squared high-passed signal (its second difference, so the probe's own
commanded acceleration does not count and shaking does not leak to neighbouring speeds) divided by
that signal's hover variance (floored far below real sensor noise, ``RATE_FLOOR_RADPS``, ``ACCEL_FLOOR_MPS2``). It is
averaged over a centred window of ``window_s`` to tame its chi-square scatter, and the speed term
``(w − w0)₊²`` is averaged over the same window, so the window smears model and data alike and
does not bias ``w0``. ``w`` is the blade-frame, air-relative descent speed the guard uses.

``P`` is one of flighttest's three fluctuation measures and stays its own (the live guard's std
about a trailing line would smear the rise over its half-second window and is not gamma-like;
:mod:`flighttest.analysis.fluctuation` sets the three side by side); ``tests/test_fluctuation_tie.py``
holds its onset to the live guard's and the post-flight metric's on one signal.

The fit is a gamma GLM with identity link (a windowed mean of squares is gamma-like: its scatter
grows with its mean), by iteratively reweighted least squares for each ``w0`` on a grid of
``step_mps``, keeping the ``w0`` of least deviance. Only the probe's own samples are used: from a
flighttest log the ``settle`` and ``stream`` phases up to the first abort (the recovery manoeuvre
shakes the vehicle by design) and up to the last setpoint (the landing is not the probe's),
otherwise every airborne sample. :func:`sweep_fluctuation` gives the same fluctuation per sample
of the sweep alone, on the RMS × hover scale of ``threshold_ratio``, for the report's probe plot.

The stated **uncertainty** is the spread of a residual block bootstrap (the fitted curve times
the data's own relative scatter, resampled in blocks of ``block_s`` because neighbouring samples
are correlated, each from within ``local_s`` of where it goes because the scatter changes along the
flight) combined with the speed resolution (the grid step and the speed change over the two
telemetry periods the signal needs near the onset) and with the **velocity estimate's error**: ``w``
is the autopilot's estimate, off by ``velocity_sd_mps`` (1 σ) and correlated over ``velocity_tau_s``,
so a sweep that passes the onset once reads it off by that much whatever the fit's precision; passes
farther apart than ``velocity_tau_s`` average it down by √passes.
An onset is reported only when the fluctuation at the fastest descent flown is at least
``threshold_ratio`` times the hover's (in RMS), both as fitted and in the data there (the fastest
``min_samples_above`` samples); otherwise the probe never reached it. The fit alone is not enough: a
hinge steep enough to pass one gust at the sweep's top reads 2.2× there where the data shows 1.4×
(ArduCopter SITL in turbulence, bench/RESULTS.md, "An onset the data did not show").

**Identify refuses to invent** (every later plan and flight would trust what it stores):

- *Only a probe's sweep* (:func:`check_probe`). A flighttest log folder must say it flew the probe
  (``meta.json`` mission, or the trajectory's kind) and hold the sweep: a ``stream`` phase in
  ``setpoints.csv``, its ``events.jsonl`` (where an abort cut the sweep short), and telemetry
  covering the sweep from start to end without a gap longer than ``MAX_SWEEP_GAP_S`` — a vertical or
  helix folder, or a damaged probe folder, is :class:`NotAProbe`. Another program's log (``.tlog``,
  ``.ulg``, ``.bin``) records no mission: it is taken as the probe the user says it is, and the fit
  must then convince on its own (below).
- *Physically plausible* (:func:`implausible`): strictly above the guard margin and a third of
  Onera's straight-down VRS entry, at most 1.5× Onera's TWS entry
  (:func:`flighttest.model.profiles.plausible_w_allow_range`: 0.045–0.62 v_h with the default ε), not at
  the slowest descent fitted (a rise from the first descending sample is shaking that grows with
  speed, not an onset), and known to within ``MAX_RELATIVE_UNCERTAINTY`` of itself — else
  :class:`ImplausibleOnset`, one line saying why.
- *No onset up to the top speed* (:class:`NoOnset`) is a result, not a failure: the sweep was flown
  and stayed quiet up to ``lower_bound_mps``, so the onset lies above it; callers keep the prior
  ``w_allow``.
- *Not in more wind than it can correct for* (:class:`WindyProbe`, an :class:`ImplausibleOnset`). ``w``
  is air-relative with the log's wind (:mod:`flighttest.analysis.wind`: what flighttest flew with, the
  autopilot's estimate, or flighttest's own from the IMU's drag), and every result says the wind the
  probe was flown in ("the onset found is for that air"). The correction has two limits, each held to
  the identification's own tolerance, ``MAX_RELATIVE_UNCERTAINTY`` (25 %) of the onset, at the samples
  the onset is read from (descending within ``ONSET_BAND_MPS`` of it):

  1. *the wind's uncertainty*: a horizontal wind error δ moves ``w`` by ``sin(tilt)·δ``
     (:func:`flighttest.model.frames.worst_blade_velocity_mps`), so the onset is uncertain by
     ``sin(tilt)·σ_wind`` besides the fit's own spread — added to its uncertainty in quadrature
     (``wind_uncertainty_mps``), and alone beyond the tolerance the probe is refused;
  2. *the in-plane air*: a probe holding its position in wind has the wind across its disk (``u``), and
     in-plane air moves the VRS entry itself (Onera's criterion, the model the guard's region comes
     from: at ``v_h`` 5.6 m/s, 1 m/s of it moves the straight-down entry by 3 %, 3 m/s by 28 %). The
     onset stored is the profile's straight-down ``w_allow``: where the model says the probe's
     in-plane air moved it by more than the tolerance (``onera_shift_mps``), the onset found is not that
     one, and the probe is refused. A quieter day, or a probe flown into the wind, fixes both.
  A log whose wind is unknown (still air assumed) is identified as before, and says so.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from flighttest.analysis import wind as wind_mod
from flighttest.analysis.exposure import velocity_track
from flighttest.analysis.fluctuation import FluctuationConfig, hover_mask
from flighttest.analysis.pipeline import prepare_state
from flighttest.analysis.schema import RATES, FlightLog
from flighttest.errors import FlighttestError
from flighttest.inputs import MAX_SPEED_MPS, display_path, shown
from flighttest.model import aero
from flighttest.model.frames import disk_tilt_sin
from flighttest.model.profiles import VehicleProfile, plausible_w_allow_range

PROBE_PHASES = ("settle", "stream")
# Per-sample noise floors of the differenced signals: far below any real gyro's or accelerometer's
# noise, they only keep a simulator's perfectly still hover from a zero variance. A floor near real
# sensor noise would hide the first, small part of the rise and push the fit's onset up.
RATE_FLOOR_RADPS = 1e-4
ACCEL_FLOOR_MPS2 = 1e-3


@dataclass(frozen=True)
class IdentifyConfig:
    threshold_ratio: float = 2.0  # fitted RMS fluctuation at the top speed ≥ this × hover, else no onset
    window_s: float = 0.2  # averaging window of the fluctuation power
    step_mps: float = 0.005  # onset grid
    min_samples_above: int = 10  # a candidate onset needs this many samples faster than it
    n_boot: int = 100
    block_s: float = 1.0
    local_s: float = 2.0  # a bootstrap block is drawn from within this of where it goes (local block bootstrap)
    # the velocity estimate's vertical error, 1 σ, and its correlation time: PX4 SIH's EKF2 against SIH's
    # truth (bench/RESULTS.md, "The estimate's error in the onset"); ArduCopter SITL's EKF3 reads 0.015 m/s
    # with SITL's ideal sensors, which a real GNSS does not give it
    velocity_sd_mps: float = 0.16
    velocity_tau_s: float = 3.0
    min_speed_mps: float = 0.05  # the fit needs descending samples faster than this
    irls_iterations: int = 6


MAX_RELATIVE_UNCERTAINTY = 0.25  # an onset known to worse than ±25 % of itself is not one to fly by
# A blade-frame descent speed beyond any flight test's (flighttest.inputs.MAX_SPEED_MPS) is damaged telemetry,
# not a sample of the sweep: one such sample would also stretch the onset grid to its speed.
MAX_PROBE_SPEED_MPS = MAX_SPEED_MPS
# The fit's grid of candidate onsets times the samples it windows: a probe at 50 Hz is ~1e6 cells; beyond
# this the fit (a hundred bootstrap refits) would take most of an hour and gigabytes
MAX_FIT_CELLS = 20_000_000
PROVENANCE_PATH_CHARS = 400  # of the probe log's path in a stored w_allow's source line (within 2000 chars)
# a refused onset contradicts the prior only when the prior lies beyond this many of its σ above it: at one
# σ, the estimate's own error (0.16 m/s) stopped a campaign whose prior was the truth (the fake's x500,
# 0.635 ± 0.175 read for 0.848)
AGREES_SIGMAS = 2.0
ONSET_BAND_MPS = 0.1  # the samples an onset is read from: descending within this of it
RESOLUTION_SAMPLES = 5  # the speed resolution is the speed's rate at this many samples just past the onset
MAX_SWEEP_GAP_S = 1.0  # a telemetry gap this long inside the sweep: the log is damaged, not a slow link


class NotAProbe(FlighttestError):
    """The log does not hold a probe flight's sweep (another mission, or a damaged probe folder)."""


class ImplausibleOnset(FlighttestError):
    """The fit found a rise the model cannot explain as a VRS onset for this vehicle: nothing to store.
    ``w_onset_mps`` ± ``uncertainty_mps``: what the fit found; ``reasons``: why it is refused."""

    def __init__(self, message: str, w_onset_mps: float = math.nan, uncertainty_mps: float = math.nan,
                 reasons: tuple[str, ...] = ()) -> None:  # fmt: skip
        super().__init__(message)
        self.w_onset_mps, self.uncertainty_mps, self.reasons = w_onset_mps, uncertainty_mps, reasons

    def agrees_with(self, w_allow_mps: float) -> bool:
        """The refused onset's band (``AGREES_SIGMAS`` of its uncertainty) reaches ``w_allow_mps`` (or
        beyond): the probe does not say it is lower."""
        return math.isfinite(self.w_onset_mps + self.uncertainty_mps) and \
            self.w_onset_mps + AGREES_SIGMAS * self.uncertainty_mps >= w_allow_mps  # fmt: skip


def untrusted_onset_line(bad: ImplausibleOnset, prior_mps: float) -> str:
    """What the campaign says when the probe's onset is refused but does not contradict the prior."""
    return (f"the probe's onset {bad.w_onset_mps:.3f} ± {bad.uncertainty_mps:.3f} m/s is not trusted "
            f"({'; '.join(bad.reasons)}): w_allow stays at prior {prior_mps:.3f} m/s, "
            f"inside {AGREES_SIGMAS:g} σ of it")  # fmt: skip


def windy_probe_line(bad: ImplausibleOnset, prior_mps: float) -> str:
    """What the campaign says when a probe flown in too much wind measured no onset at all."""
    return (f"the probe measured no onset in its air ({'; '.join(bad.reasons)}): w_allow stays at prior "
            f"{prior_mps:.3f} m/s")  # fmt: skip


class WindyProbe(ImplausibleOnset):
    """The probe was flown in more wind than identify can correct for (module docstring): the fit's onset
    ``w_onset_mps`` ± ``uncertainty_mps`` is for air it cannot vouch for; ``wind`` describes it."""

    def __init__(self, message: str, w_onset_mps: float, uncertainty_mps: float, reasons: tuple[str, ...],
                 wind: dict) -> None:  # fmt: skip
        super().__init__(message, w_onset_mps, uncertainty_mps, reasons)
        self.wind = wind


@dataclass(frozen=True)
class ProbeWind:
    """The air the probe was flown in, at the samples an onset is read from: the wind (its mean there, 1 σ,
    source), the in-plane air ``u`` across the disk, the tilt's sine, and what they do to the onset."""

    wind_ned_mps: tuple[float, float, float] | None
    wind_sd_mps: float | None  # NaN/None: unknown (still air assumed)
    wind_source: str | None
    in_plane_air_mps: float  # median u there
    tilt_sin: float  # median sin(tilt) there
    wind_uncertainty_mps: float  # sin(tilt)·σ_wind: what the wind's uncertainty does to w there (NaN: unknown)
    onera_shift_mps: float  # how far Onera's VRS entry at that u lies from the straight-down one

    @property
    def speed_mps(self) -> float:
        w = self.wind_ned_mps
        return math.hypot(w[0], w[1]) if w is not None else math.nan

    def note(self, what: str = "the onset found") -> str:
        """"flown in X m/s of wind (source): the onset found is for that air" with what the air was."""
        if self.wind_source is None:
            return "wind not resolved"
        if self.wind_ned_mps is None or not math.isfinite(self.speed_mps):
            return f"wind unknown ({self.wind_source}): {what} assumes still air"
        known = self.wind_sd_mps is not None and math.isfinite(self.wind_sd_mps)
        sd = f" ± {self.wind_sd_mps:.2f}" if known else ""
        return (f"flown in {self.speed_mps:.2f}{sd} m/s of wind ({self.wind_source}): {what} is for that "
                f"air ({self.in_plane_air_mps:.2f} m/s across the disk; its uncertainty adds "
                f"±{self.wind_uncertainty_mps:.3f} m/s; Onera puts the straight-down entry "
                f"{self.onera_shift_mps:+.3f} m/s from there)")  # fmt: skip

    def summary(self, what: str = "the onset found") -> dict:
        speed = self.speed_mps
        return {"wind_ned_mps": list(self.wind_ned_mps) if self.wind_ned_mps else None,
                "wind_speed_mps": speed if math.isfinite(speed) else None,
                "wind_sd_mps": self.wind_sd_mps, "wind_source": self.wind_source,
                "in_plane_air_mps": self.in_plane_air_mps, "wind_uncertainty_mps": self.wind_uncertainty_mps,
                "onera_shift_mps": self.onera_shift_mps, "wind_note": self.note(what)}  # fmt: skip


def onera_entry_n(v_H_n: float, profile: VehicleProfile, step_n: float = 0.0005) -> float:
    """The descent ``w/v_h`` at which Onera's criterion (the profile's ``k``, ``ε_vrs``) enters the VRS with
    in-plane air ``v_H_n``: the slowest descent with ``ε ≤ ε_vrs`` (NaN: none up to 1 v_h)."""
    wn = np.arange(0.0, 1.0, step_n)
    eps = aero.onera_epsilon_n(np.full_like(wn, abs(v_H_n)), -wn, profile.vrs.onera_k)
    inside = np.flatnonzero(eps <= profile.vrs.eps_vrs)
    return float(wn[inside[0]]) if len(inside) else math.nan


def probe_wind(log: FlightLog, profile: VehicleProfile, ps: ProbeSamples, w0_mps: float) -> ProbeWind:
    """The air the probe was flown in at the samples near ``w0_mps`` (all its descending samples when none)."""
    wind = log.wind
    near = ps.use & (np.abs(ps.w_mps - w0_mps) <= ONSET_BAND_MPS) if math.isfinite(w0_mps) else ps.use
    if not near.any():
        near = ps.use & (ps.w_mps > 0)
    if not near.any():
        near = ps.use
    u = float(np.nanmedian(ps.u_mps[near])) if near.any() else math.nan
    tilt = float(np.nanmedian(ps.tilt_sin[near])) if near.any() else math.nan
    if wind is None:
        return ProbeWind(None, None, None, u, tilt, math.nan, math.nan)
    o = wind.over(near)
    ned = tuple(o["wind_ned_mps"]) if o["wind_ned_mps"][0] is not None else None
    sd = o["wind_sd_mps"]
    sd_w = float(np.sqrt(np.nanmean((ps.tilt_sin[near] * wind.sd_mps[near]) ** 2))) if sd is not None else math.nan
    v_h = profile.v_h_mps
    shift = (onera_entry_n(0.0, profile) - onera_entry_n(u / v_h, profile)) * v_h if math.isfinite(u) else math.nan
    return ProbeWind(ned, sd if sd is not None else math.nan, wind.source, u, tilt, sd_w, shift)


def windy(pw: ProbeWind, w0_mps: float) -> list[str]:
    """Why the probe was flown in more wind than identify can correct for (empty: it was not)."""
    tol = MAX_RELATIVE_UNCERTAINTY * w0_mps
    why = []
    share = f"more than {MAX_RELATIVE_UNCERTAINTY:.0%} of the onset ({tol:.3f} m/s)"
    if math.isfinite(pw.wind_uncertainty_mps) and pw.wind_uncertainty_mps > tol:
        tilt_deg = math.degrees(math.asin(min(max(pw.tilt_sin, 0.0), 1.0)))
        why.append(f"the wind's uncertainty (± {pw.wind_sd_mps:.2f} m/s, {pw.wind_source}) through a {tilt_deg:.0f}° "
                   f"tilt makes w there uncertain by ±{pw.wind_uncertainty_mps:.3f} m/s, {share}")  # fmt: skip
    if math.isfinite(pw.onera_shift_mps) and abs(pw.onera_shift_mps) > tol:
        why.append(f"{pw.in_plane_air_mps:.2f} m/s of air across the disk moves Onera's VRS entry by "
                   f"{abs(pw.onera_shift_mps):.3f} m/s from the straight-down one, {share}: the onset found is "
                   "not the straight-down w_allow")  # fmt: skip
    return why


class NoOnset(FlighttestError):
    """The sweep was flown and its fluctuation stayed below ``threshold_ratio`` × hover: the onset lies above
    ``lower_bound_mps`` (the speed the sweep reached with at least ``min_samples_above`` samples). A
    result, not bad input: the prior ``w_allow`` stays. Its message keeps the words "no onset found"."""

    def __init__(self, message: str, *, lower_bound_mps: float, v_h_mps: float, threshold_ratio: float,
                 max_speed_mps: float, rise_ratio: float, samples: int, signals: tuple[str, ...],
                 evidence: str, wind: ProbeWind | None = None,
                 observed_rise_ratio: float = math.nan) -> None:  # fmt: skip
        super().__init__(message)
        self.wind = wind
        self.observed_rise_ratio = observed_rise_ratio
        self.lower_bound_mps = lower_bound_mps
        self.v_h_mps = v_h_mps
        self.threshold_ratio = threshold_ratio
        self.max_speed_mps = max_speed_mps
        self.rise_ratio = rise_ratio
        self.samples = samples
        self.signals = signals
        self.evidence = evidence

    def summary(self) -> dict:
        return {
            "onset_found": False, "w_onset_mps": None, "uncertainty_mps": None,
            "w_onset_lower_bound_mps": self.lower_bound_mps,
            "w_onset_lower_bound_n": self.lower_bound_mps / self.v_h_mps, "v_h_mps": self.v_h_mps,
            "threshold_ratio": self.threshold_ratio, "max_speed_mps": self.max_speed_mps,
            "rise_ratio": self.rise_ratio,
            "observed_rise_ratio": self.observed_rise_ratio if math.isfinite(self.observed_rise_ratio) else None,
            "samples": self.samples, "signals": list(self.signals),
            "probe_evidence": self.evidence, "reason": str(self),
            **(self.wind.summary("the lower bound") if self.wind is not None else {}),
        }  # fmt: skip


def no_onset_line(lower_bound_mps: float, prior_mps: float) -> str:
    """What ``identify`` and the campaign say when the probe stayed quiet up to its top speed. The prior
    ``w_allow`` stays: a quiet sweep bounds the onset from below but does not locate it, and only a
    located onset is stored."""
    if prior_mps <= lower_bound_mps:
        why = "the prior is conservative"
    else:
        why = "the sweep did not reach the prior, which stays unverified above that"
    return (f"no onset up to {lower_bound_mps:.2f} m/s: w_allow stays at prior {prior_mps:.3f} m/s "
            f"(it is at least {lower_bound_mps:.2f}; {why})")  # fmt: skip


def _events_t(log: FlightLog, name: str) -> list[float]:
    out = []
    for e in log.events or []:
        t = e.get("t_s")
        if e.get("event") == name and isinstance(t, int | float) and not isinstance(t, bool) and math.isfinite(t):
            out.append(float(t))
    return out


def check_probe(log: FlightLog) -> str:
    """One line saying why this log can be fitted as a probe's sweep, or :class:`NotAProbe` saying why not
    (module docstring: a flighttest folder must be a probe's and hold the whole sweep; another program's
    log records no mission and is taken on the user's word)."""
    if log.source != "flighttest-folder":
        if log.path.name == "flight.tlog" and (log.path.parent / "meta.json").is_file():
            # the tlog alone would hide what the folder says it flew
            raise NotAProbe(f"{log.path}: the tlog of a flighttest log folder: give the folder "
                            f"({log.path.parent}), which says which mission it flew")  # fmt: skip
        return f"{log.source} log (no mission recorded): taken as the probe flight it was given as"
    traj = log.meta.get("trajectory_meta")
    kind = traj.get("kind") if isinstance(traj, dict) else None
    mission = log.mission_name
    if mission != "probe" and kind != "probe":
        if mission is None and kind is None:
            raise NotAProbe(f"{log.name}: the log folder does not say which mission it flew (no readable "
                            "meta.json or trajectory.json): identify needs a probe flight's folder "
                            "(flighttest fly probe)")  # fmt: skip
        raise NotAProbe(f"{log.name}: a {shown(mission or kind)} flight, not a probe: identify needs the probe's "
                        "sweep (flighttest fly probe)")  # fmt: skip
    sp = log.setpoints
    phase = sp["phase"].astype(str) if sp is not None and "phase" in sp and "t_s" in sp else None
    t_sp = pd.to_numeric(sp["t_s"], errors="coerce").to_numpy(float) if phase is not None else np.array([])
    stream = (phase == "stream").to_numpy() & np.isfinite(t_sp) if phase is not None else np.array([], bool)
    if not stream.any():
        raise NotAProbe(f"{log.name}: probe folder without its sweep (setpoints.csv has no 'stream' phase): "
                        "damaged, or the sweep was never flown")  # fmt: skip
    if not log.events:
        raise NotAProbe(f"{log.name}: probe folder without events.jsonl: where the sweep ended (an abort) is "
                        "unknown, so its samples cannot be told from the recovery's")  # fmt: skip
    t0, t1 = float(t_sp[stream].min()), float(t_sp[stream].max())
    aborts = [t for t in _events_t(log, "abort") if t >= t0]
    if aborts:
        t1 = min(t1, min(aborts))
    t = log.state["t_s"].to_numpy(float)
    t = t[np.isfinite(t)]
    if not len(t) or t.max() < t1 - MAX_SWEEP_GAP_S or t.min() > t0 + MAX_SWEEP_GAP_S:
        span = f"{t.min():.1f}–{t.max():.1f} s" if len(t) else "nothing"
        raise NotAProbe(f"{log.name}: the telemetry covers {span}, not the sweep's {t0:.1f}–{t1:.1f} s "
                        "(flight.tlog truncated or damaged)")  # fmt: skip
    inside = np.sort(t[(t >= t0) & (t <= t1)])
    edges = np.concatenate([[t0], inside, [t1]])
    gaps = np.diff(edges)
    k = int(np.argmax(gaps))
    if gaps[k] > MAX_SWEEP_GAP_S:
        raise NotAProbe(f"{log.name}: a {gaps[k]:.1f} s gap in the telemetry during the sweep (at {edges[k]:.1f} s): "
                        "flight.tlog damaged")  # fmt: skip
    return f"flighttest probe folder: the sweep {t0:.1f}–{t1:.1f} s" + (" (up to the abort)" if aborts else "")


def implausible(w0_mps: float, unc_mps: float, profile: VehicleProfile, slowest_mps: float) -> list[str]:
    """Why an onset of ``w0 ± unc`` cannot be this vehicle's VRS onset (empty: it can). ``slowest_mps``:
    the first onset the grid tried (a fit that lands there found no quiet descent below the rise)."""
    lo, hi = plausible_w_allow_range(profile)
    why = []
    if not (math.isfinite(w0_mps) and math.isfinite(unc_mps)):
        return ["not a finite number"]
    if w0_mps <= slowest_mps:
        why.append(f"the rise starts at the slowest descent fitted ({slowest_mps:.2f} m/s): no quiet descent below it")
    if w0_mps <= profile.vrs.margin_mps:
        why.append(f"not above the guard margin {profile.vrs.margin_mps:.2f} m/s")
    elif w0_mps <= lo:
        why.append(f"below {lo:.3f} m/s, a third of Onera's VRS entry ({lo / profile.v_h_mps:.3f} v_h)")
    if w0_mps > hi:
        why.append(f"above {hi:.3f} m/s, 1.5× Onera's TWS entry ({hi / profile.v_h_mps:.3f} v_h)")
    if unc_mps >= w0_mps:
        why.append("its uncertainty is as large as the value")
    elif unc_mps > MAX_RELATIVE_UNCERTAINTY * w0_mps:
        why.append(f"its uncertainty is {unc_mps / w0_mps:.0%} of the value (at most {MAX_RELATIVE_UNCERTAINTY:.0%})")
    return why


@dataclass(frozen=True)
class Onset:
    w_onset_mps: float
    uncertainty_mps: float
    w_onset_n: float
    uncertainty_n: float
    v_h_mps: float
    threshold_ratio: float
    max_speed_mps: float
    samples: int
    rise_ratio: float  # fitted RMS fluctuation at max_speed_mps / hover's
    bootstrap_sd_mps: float  # the replicates' plain standard deviation, their far tail and all
    bootstrap_spread_mps: float  # half the width of their central 68 %: what the uncertainty takes
    resolution_mps: float
    signals: tuple[str, ...]
    bins: pd.DataFrame  # fluctuation power (data and fit) binned by speed, for plots and reports
    probe_evidence: str = ""  # check_probe's line: why this log was taken as a probe's sweep
    wind: ProbeWind | None = None  # the air the probe was flown in (uncertainty_mps includes its share)
    estimate_error_mps: float = 0.0  # the velocity estimate's share of uncertainty_mps (velocity_sd_mps/√passes)
    onset_passes: int = 1  # the sweep's passes through the onset band, farther apart than velocity_tau_s
    observed_rise_ratio: float = math.nan  # the fastest samples' own RMS fluctuation / the fitted hover's

    def summary(self) -> dict:
        d = asdict(self)
        d.pop("bins")
        d.pop("wind")
        d["signals"] = list(self.signals)
        d["onset_found"] = True
        d.update(self.wind.summary() if self.wind is not None else {})
        return d

    def provenance(self, log_path: Path | str, by: str) -> str:
        """The ``source`` line stored with the identified ``w_allow`` in a profile."""
        today = dt.date.today().isoformat()
        where = display_path(Path(log_path).resolve())
        if len(where) > PROVENANCE_PATH_CHARS:  # the profile's text field is bounded; the path's ends say most
            keep = PROVENANCE_PATH_CHARS // 2
            where = f"{where[:keep]}…{where[-keep:]}"
        return (
            f"identified {today} by {by} from probe log {where}: onset "
            f"{self.w_onset_mps:.3f} ± {self.uncertainty_mps:.3f} m/s ({self.w_onset_n:.4f} v_h), "
            f"hinge fit of fluctuation power vs descent rate (rise {self.rise_ratio:.1f}× hover)"
        )


def _high_passed(x: np.ndarray) -> np.ndarray:
    """Backward first difference over √2 (white noise keeps its variance): it removes anything slower
    than a few samples — the probe's commanded acceleration, a steady rate — and, unlike subtracting a
    centred moving average, never spreads a sample's shaking onto earlier samples (where the strong
    shaking past the onset would leak back onto the quiet speeds below it). For body rates it is the
    angular acceleration, which shows a disturbance torque at once rather than after the rate builds."""
    hp = np.full(len(x), np.nan)
    hp[1:] = np.diff(x) / math.sqrt(2.0)
    return pd.Series(hp).bfill().to_numpy()


def _centred_mean(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving mean along the last axis, ignoring NaN (edges: as much window as there is)."""
    frame = pd.DataFrame(np.atleast_2d(x).T)
    out = frame.rolling(n, center=True, min_periods=1).mean().to_numpy().T
    return out if np.ndim(x) > 1 else out[0]


def fluctuation_power(state: pd.DataFrame, hover: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Per-sample squared high-passed signals over their hover variance, averaged over the signals."""
    parts, names = [], []
    for col, floor in [*((c, RATE_FLOOR_RADPS) for c in RATES), ("ad_mps2", ACCEL_FLOOR_MPS2)]:
        x = state[col].to_numpy(float) if col in state else np.full(len(state), np.nan)
        if np.isfinite(x).mean() < 0.9 or (col == "ad_mps2" and names):
            continue  # with body rates, leave out the vertical acceleration: the probe commands it
        hp2 = _high_passed(np.nan_to_num(x, nan=float(np.nanmedian(x)))) ** 2
        base = float(np.median(hp2[hover])) if hover.any() else float(np.median(hp2))
        # the floor keeps a perfectly still hover (a simulator) from dividing by zero, and keeps P > 0
        parts.append((hp2 + floor**2) / (base + floor**2))
        names.append(col)
    if not parts:
        raise FlighttestError("no fluctuation signal (needs body rates or vertical acceleration)")
    return np.mean(parts, axis=0), names


def _fit_grid(y: np.ndarray, z: np.ndarray, iterations: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gamma GLM ``y ≈ b0 + b1·z`` (identity link, b0 > 0, b1 ≥ 0) for each row of ``z``: returns
    ``b0, b1, deviance`` per row."""
    g = z.shape[0]
    b0 = np.full(g, float(np.mean(y)))
    b1 = np.zeros(g)
    yy = y[None, :]
    for _ in range(iterations):
        mu = np.maximum(b0[:, None] + b1[:, None] * z, 1e-12)
        wgt = 1.0 / mu**2
        sw, swz, swzz = wgt.sum(1), (wgt * z).sum(1), (wgt * z * z).sum(1)
        swy, swzy = (wgt * yy).sum(1), (wgt * z * yy).sum(1)
        det = sw * swzz - swz**2
        ok = det > 1e-12 * np.maximum(sw * swzz, 1e-300)
        nb1 = np.where(ok, (sw * swzy - swz * swy) / np.where(ok, det, 1.0), 0.0)
        nb0 = np.where(ok, (swy - nb1 * swz) / sw, swy / sw)
        flat = nb1 < 0  # no rise: the hover level alone
        nb1 = np.where(flat, 0.0, nb1)
        nb0 = np.where(flat, swy / sw, nb0)
        b0, b1 = np.maximum(nb0, 1e-12), nb1
    mu = np.maximum(b0[:, None] + b1[:, None] * z, 1e-12)
    dev = 2.0 * ((yy - mu) / mu - np.log(yy / mu)).sum(1)
    return b0, b1, dev


def _onset_from(y, zs, grid, iterations) -> tuple[float, float, float, int]:
    b0, b1, dev = _fit_grid(y, zs, iterations)
    dev = np.where(b1 > 0, dev, np.inf)
    if not np.isfinite(dev).any():
        return math.nan, math.nan, math.nan, -1
    k = int(np.argmin(dev))
    return float(grid[k]), float(b0[k]), float(b1[k]), k


def _probe_mask(log: FlightLog, t: np.ndarray, phases: tuple[str, ...] = PROBE_PHASES) -> np.ndarray | None:
    """Samples in the given mission phases (the probe's settle/stream by default) before the first abort
    and no later than the last setpoint streamed (flighttest logs only). The mission stops writing
    setpoints when it hands over to the autopilot's landing, so without that end the last phase
    written (the settle after the sweep) would run on through the landing."""
    sp = log.setpoints
    if sp is None or len(sp) == 0 or "phase" not in sp:
        return None
    sp = sp.sort_values("t_s")
    t_sp = sp["t_s"].to_numpy(float)
    idx = np.searchsorted(t_sp, t, side="right") - 1
    phase = np.where(idx >= 0, sp["phase"].to_numpy(object)[np.clip(idx, 0, None)], "")
    period = float(np.median(np.diff(t_sp))) if len(t_sp) > 1 else 0.0
    mask = np.isin(phase, phases) & (t <= t_sp[-1] + 2.0 * period)
    aborts = [float(e["t_s"]) for e in (log.events or []) if e.get("event") == "abort" and "t_s" in e]
    if aborts:
        mask &= t < min(aborts)
    return mask if mask.any() else None


@dataclass(frozen=True)
class ProbeSamples:
    """What the fit works on, per state sample: the windowed fluctuation power of the selected samples
    (NaN elsewhere) and the blade-frame descent speed."""

    t_s: np.ndarray
    w_mps: np.ndarray
    power: np.ndarray  # windowed over the selected samples only
    use: np.ndarray  # finite, no glitch, airborne, and (flighttest logs) the probe's phases before an abort
    hover: np.ndarray  # the hover samples the power is normalised by (fluctuation.hover_mask)
    phased: bool  # True when the log's own mission phases chose the samples
    dt_s: float
    n_win: int
    signals: tuple[str, ...]
    u_mps: np.ndarray = field(default_factory=lambda: np.empty(0))  # air-relative in-plane speed
    tilt_sin: np.ndarray = field(default_factory=lambda: np.empty(0))  # sin of the disk's tilt


def probe_samples(log: FlightLog, profile: VehicleProfile, cfg: IdentifyConfig) -> ProbeSamples:
    state = log.state
    if "glitch" not in state:  # not analysed yet: the trusted height and its glitch flags, as analyse has them
        prepare_state(log)
    t = state["t_s"].to_numpy(float)
    if len(t) < 10:
        raise FlighttestError(f"{log.name}: too few samples to identify an onset ({len(t)})")
    dt = max(float(np.median(np.diff(t))), 1e-6)
    n_win = max(3, round(cfg.window_s / dt))
    hover = hover_mask(state, FluctuationConfig())
    try:
        power, signals = fluctuation_power(state, hover)
    except FlighttestError as exc:
        raise FlighttestError(f"{log.name}: {exc}") from None
    wind = wind_mod.ensure(log, profile, drag_from_meta=False)  # w air-relative, as analyse judges it
    track = velocity_track(state, profile, wind)
    w_all = track["w_mps"].to_numpy(float)
    q = state[["qw", "qx", "qy", "qz"]].to_numpy(float)
    tilt = np.where(np.isfinite(q).all(axis=1), disk_tilt_sin(q[:, 0], q[:, 1], q[:, 2], q[:, 3]), 0.0)
    h = -state["d_m"].to_numpy(float)
    physical = np.abs(np.nan_to_num(w_all, nan=np.inf)) <= MAX_PROBE_SPEED_MPS
    use = np.isfinite(power) & physical & ~state["glitch"].to_numpy(bool) & (h > np.nanmin(h) + 0.5)
    probe = _probe_mask(log, t)
    if probe is not None:
        use &= probe
    # windows average over selected samples only: the recovery's shaking must not leak back in
    y_all = _centred_mean(np.where(use, power, np.nan), n_win)
    return ProbeSamples(t, w_all, y_all, use, hover, probe is not None, dt, n_win, tuple(signals),
                        track["u_mps"].to_numpy(float), tilt)  # fmt: skip


def identify_onset(log: FlightLog, profile: VehicleProfile, cfg: IdentifyConfig | None = None) -> Onset:
    cfg = cfg or IdentifyConfig()
    evidence = check_probe(log)  # before any fit: an onset comes only from a probe's sweep
    ps = probe_samples(log, profile, cfg)
    t, w_all, y_all, use, dt, n_win = ps.t_s, ps.w_mps, ps.power, ps.use, ps.dt_s, ps.n_win
    descending = use & (w_all > cfg.min_speed_mps)
    if descending.sum() < 3 * cfg.min_samples_above:
        # a probe held in wind leans into it, and the air meets its disk from below: on PX4 SITL in 3 m/s
        # (17.6° of lean) a 1.07 m/s descent was 0.21 m/s through the disk, and the sweep never reached one
        pw = probe_wind(log, profile, ps, math.nan)
        if why := windy(pw, profile.w_allow_mps):
            raise WindyProbe(f"{log.name}: probe {pw.note('the sweep')}; its air-relative descent passed "
                             f"{cfg.min_speed_mps:g} m/s in {int(descending.sum())} samples: no onset to find; "
                             "refused: " + "; ".join(why) + " (nothing stored)",
                             math.nan, math.nan, tuple(why), pw.summary("the sweep"))  # fmt: skip
        raise FlighttestError(f"{log.name}: too few descending samples to identify an onset ({int(descending.sum())})")
    w_top = float(w_all[descending].max())
    w_sorted = np.sort(w_all[use])
    hi = w_sorted[-cfg.min_samples_above] if len(w_sorted) > cfg.min_samples_above else w_top
    grid = np.arange(cfg.min_speed_mps, max(hi, cfg.min_speed_mps + cfg.step_mps), cfg.step_mps)
    # the model's speed term, windowed exactly like the data: over the span of the selected samples and a
    # window either side (every window of a selected sample lies inside), then selected
    w_filled = np.nan_to_num(w_all, nan=0.0)
    used = np.flatnonzero(use)
    span = slice(max(int(used[0]) - n_win, 0), int(used[-1]) + n_win + 1)
    cells = len(grid) * (span.stop - span.start)
    if cells > MAX_FIT_CELLS:
        raise FlighttestError(
            f"{log.name}: {span.stop - span.start:,} samples ({t[span][-1] - t[span][0]:.0f} s) with descents up to "
            f"{hi:.2f} m/s are more than identify fits ({cells:,} sample-speed cells, at most {MAX_FIT_CELLS:,}): "
            "give it the probe flight's log alone"
        )
    excess2 = np.maximum(w_filled[None, span] - grid[:, None], 0.0) ** 2
    zs = _centred_mean(np.where(use[None, span], excess2, np.nan), n_win)[:, use[span]]
    y = y_all[use]
    w0, b0, b1, k = _onset_from(y, zs, grid, cfg.irls_iterations)
    rise = math.sqrt((b0 + b1 * max(w_top - w0, 0.0) ** 2) / b0) if math.isfinite(w0) else 1.0
    fastest = np.argsort(np.where(use, w_all, -np.inf))[-cfg.min_samples_above:]
    observed = math.sqrt(float(np.nanmean(y_all[fastest])) / b0) if math.isfinite(w0) else math.nan
    if not math.isfinite(w0) or rise < cfg.threshold_ratio or observed < cfg.threshold_ratio:
        # the lower bound: the speed at least min_samples_above quiet samples reached (one fast sample
        # of noise in w must not raise it)
        bound = float(min(hi, w_top))
        unseen = math.isfinite(w0) and rise >= cfg.threshold_ratio
        if unseen:
            why = (f"the fit's rise to {rise:.1f}× hover at the top is not in the data there ({observed:.1f}× "
                   f"over the {cfg.min_samples_above} fastest samples)")  # fmt: skip
        else:
            why = f"fluctuation never rose above {cfg.threshold_ratio:g}× hover up to {bound:.2f} m/s descent"
        raise NoOnset(
            f"{log.name}: {why}: no onset found (w_allow is at least {bound:.2f} m/s)",
            lower_bound_mps=bound, v_h_mps=profile.v_h_mps, threshold_ratio=cfg.threshold_ratio,
            max_speed_mps=w_top, rise_ratio=rise, samples=int(use.sum()), signals=ps.signals, evidence=evidence,
            wind=probe_wind(log, profile, ps, bound), observed_rise_ratio=observed,
        )  # fmt: skip
    # residual block bootstrap: the speeds flown stay as they were (the few samples past the onset
    # are the design, not something to resample away); the multiplicative scatter y/μ is resampled
    # in blocks of consecutive samples, which keeps its correlation, each drawn from within local_s of
    # where it goes: a blip in a still hover moved onto the sweep read as an onset in 18 of 100
    # replicates (bench/RESULTS.md, "The probe's uncertainty")
    rng = np.random.default_rng(0)
    n = len(y)
    mu = b0 + b1 * zs[k]
    ratio = y / mu
    block = max(1, round(cfg.block_s / dt))
    n_blocks = math.ceil(n / block)
    reach = max(round(cfg.local_s / dt), block)
    home = np.arange(n_blocks) * block
    lo = np.clip(home - reach, 0, max(n - block, 0))
    hi = np.clip(home + reach, 0, max(n - block, 0))
    boots = []
    for _ in range(cfg.n_boot):
        starts = rng.integers(lo, hi + 1)
        pick = (starts[:, None] + np.arange(block)[None, :]).ravel()[:n]
        boots.append(_onset_from(mu * ratio[pick], zs, grid, cfg.irls_iterations)[0])
    boots = np.asarray(boots)
    finite = boots[np.isfinite(boots)]
    boot_sd = float(np.std(finite)) if len(finite) > 1 else 0.0
    # the spread is the central 68 % interval's half-width, not the standard deviation: a few replicates
    # in a hundred jump to the slowest speeds (a block of past-the-onset scatter resampled onto them),
    # and on a PX4-like estimate those alone made the fake's onset, read 0.950 where it is 0.95, ±0.19
    # (20 %, near refusal), where the central replicates span ±0.07
    spread = float(np.subtract(*np.percentile(finite, [84.0, 16.0]))) / 2.0 if len(finite) > 1 else 0.0
    # speed resolution: the grid (uniform, /√12), and how far w moves in the two sample periods the
    # fluctuation signal needs (the difference, and the alignment of the IMU and position streams),
    # taken as a uniform error of that half-width (/√3)
    # just past the onset, where the rise is seen: the few samples nearest above it (a fast sweep can jump a
    # fixed band between two samples, and an empty band read as no resolution at all: ±0.005 m/s, CI of b383b95)
    past = np.flatnonzero(use & (w_all >= w0))
    near = past[np.argsort(w_all[past] - w0)[:RESOLUTION_SAMPLES]]
    dw = np.abs(np.gradient(w_filled, t))[near] * 2.0 * dt
    lag_w = float(np.median(dw)) if len(dw) else 0.0
    resolution = math.sqrt(cfg.step_mps**2 / 12.0 + lag_w**2 / 3.0)
    # the velocity estimate's error moves every sample of one pass through the onset alike: the fit cannot
    # see it, and a local bootstrap trusted onsets it had pulled 0.16-0.2 m/s low (bench/RESULTS.md)
    t_band = t[use & (np.abs(w_all - w0) <= ONSET_BAND_MPS)]
    passes = 1 + int(np.sum(np.diff(t_band) > cfg.velocity_tau_s)) if len(t_band) > 1 else 1
    estimate_unc = cfg.velocity_sd_mps / math.sqrt(passes)
    pw = probe_wind(log, profile, ps, w0)
    wind_unc = pw.wind_uncertainty_mps if math.isfinite(pw.wind_uncertainty_mps) else 0.0
    unc = math.sqrt(spread**2 + resolution**2 + wind_unc**2 + estimate_unc**2)
    if why := windy(pw, w0):
        raise WindyProbe(f"{log.name}: probe {pw.note()}; refused: " + "; ".join(why) + " (nothing stored)",
                         w0, unc, tuple(why), pw.summary())  # fmt: skip
    why = implausible(w0, unc, profile, float(grid[0]))
    if why:
        raise ImplausibleOnset(f"{log.name}: onset {w0:.3f} ± {unc:.3f} m/s is not a plausible VRS onset for "
                               f"{profile.name}: " + "; ".join(why) + " (nothing stored)",
                               w0, unc, tuple(why))  # fmt: skip
    v_h = profile.v_h_mps
    return Onset(
        w_onset_mps=w0,
        uncertainty_mps=unc,
        w_onset_n=w0 / v_h,
        uncertainty_n=unc / v_h,
        v_h_mps=v_h,
        threshold_ratio=cfg.threshold_ratio,
        max_speed_mps=w_top,
        samples=int(use.sum()),
        rise_ratio=rise,
        observed_rise_ratio=observed,
        bootstrap_sd_mps=boot_sd,
        bootstrap_spread_mps=spread,
        resolution_mps=resolution,
        signals=ps.signals,
        bins=_bins(w_all[use], y, b0, b1, w0),
        probe_evidence=evidence,
        wind=pw,
        estimate_error_mps=estimate_unc,
        onset_passes=passes,
    )


def _bins(w: np.ndarray, y: np.ndarray, b0: float, b1: float, w0: float, width: float = 0.05) -> pd.DataFrame:
    """Mean power per speed bin with the fitted hinge at the bin centres; the fit's coefficients ride
    along in ``attrs`` (``b0``, ``b1``, ``w0_mps``) so a plot can draw the hinge at any speed."""
    b = np.floor(w / width).astype(np.int64)
    g = pd.DataFrame({"b": b, "p": y}).groupby("b")["p"].agg(["mean", "size"])
    centers = (g.index.to_numpy() + 0.5) * width
    out = pd.DataFrame({
        "w_mps": centers, "power_mean": g["mean"].to_numpy(), "samples": g["size"].to_numpy(),
        "power_fit": b0 + b1 * np.maximum(centers - w0, 0.0) ** 2,
    })  # fmt: skip
    out.attrs.update(b0=float(b0), b1=float(b1), w0_mps=float(w0))
    return out


LANDING_MODES = ("LAND", "RTL")  # substrings of the mode names PX4 and ArduPilot land in


def _is_landing(state: pd.DataFrame, start_s: float, end_s: float, end_alt_m: float | None = None) -> bool:
    """A descent that ends the flight: the vehicle never climbs a metre above where it ended (an
    estimator drifting on the ground stays well inside that), or it descends in a landing mode."""
    t = state["t_s"].to_numpy(float)
    h = -state["d_m"].to_numpy(float)
    if end_alt_m is None or not math.isfinite(end_alt_m):
        end_alt_m = float(np.interp(end_s, t, h))
    after = t > end_s
    stays_down = not after.any() or float(np.nanmax(h[after])) < end_alt_m + 1.0
    inside = (t >= start_s) & (t <= end_s)
    modes = state["mode"].astype(str).to_numpy()[inside] if "mode" in state else np.array([], str)
    return stays_down or any(m in mode.upper() for mode in set(modes) for m in LANDING_MODES)


def sweep_fluctuation(
    log: FlightLog,
    profile: VehicleProfile,
    cfg: IdentifyConfig | None = None,
    descents: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """The probe's sweep, sample by sample, with the fluctuation :func:`identify_onset` fits, for a
    plot a person reads the onset off.

    Columns: ``t_s``, ``w_mps`` (blade-frame, air-relative descent speed), ``w_n`` (``w / v_h``) and
    ``fluct_ratio``: the RMS fluctuation × hover, ``sqrt(P / P_hover)`` with ``P`` the windowed power
    identify fits and ``P_hover`` its mean over the hover samples — the same RMS scale as identify's
    ``threshold_ratio`` and ``rise_ratio``, so hover reads 1 and the detector's threshold 2.

    Only the sweep: in a flighttest log the ``stream`` phase up to the first abort (not the hover
    before it, the recovery or the landing); in any other log (no phases) the samples from the start of
    the first descent to the end of the last one that is not the landing (``descents``: the analysis'
    table, found here when not given). In both, only descending samples (``w > min_speed_mps``).
    ``attrs``: ``selection`` (one line saying which rule chose the samples), ``phased``,
    ``hover_power``, ``hover_samples``, ``hover_from``, ``signals``."""
    cfg = cfg or IdentifyConfig()
    ps = probe_samples(log, profile, cfg)
    t = ps.t_s
    ref, hover_from = ps.use & ps.hover, "hover samples"
    if ref.sum() < ps.n_win:
        ref, hover_from = ps.use & (np.abs(ps.w_mps) < cfg.min_speed_mps), "slowest samples (no hover found)"
    if ref.sum() < ps.n_win:
        ref, hover_from = ps.use, "whole flight (no hover found)"
    hover_power = float(np.nanmean(ps.power[ref])) if ref.any() else math.nan
    stream = _probe_mask(log, t, ("stream",)) if ps.phased else None
    if stream is not None:
        sweep = stream
        aborted = any(e.get("event") == "abort" for e in log.events or [])
        selection = "sweep: the stream phase" + (" up to the abort" if aborted else "") + ", descending samples only"
    elif ps.phased:
        sweep = np.zeros(len(t), bool)
        selection = "no stream phase before the first abort: the sweep was not flown"
    else:
        if descents is None:
            descents = prepare_state(log).descents
        kept = [
            r
            for r in descents.itertuples()
            if not _is_landing(log.state, r.start_s, r.end_s, getattr(r, "end_alt_m", None))
        ]
        if kept:
            sweep = (t >= min(r.start_s for r in kept)) & (t <= max(r.end_s for r in kept))
            selection = (
                f"no flight phases in this log: sweep taken from the first descent to the last before landing "
                f"({kept[0].start_s:.1f}–{kept[-1].end_s:.1f} s, {len(kept)} descents), descending samples only"
            )
        else:
            sweep = np.zeros(len(t), bool)
            selection = "no flight phases in this log and no descent but the landing: no sweep"
    sel = ps.use & sweep & (ps.w_mps > cfg.min_speed_mps) & np.isfinite(ps.power)
    ratio = np.sqrt(ps.power[sel] / hover_power) if hover_power > 0 else np.full(int(sel.sum()), np.nan)
    out = pd.DataFrame({
        "t_s": t[sel], "w_mps": ps.w_mps[sel], "w_n": ps.w_mps[sel] / profile.v_h_mps, "fluct_ratio": ratio,
    })  # fmt: skip
    out.attrs.update(selection=selection, phased=ps.phased, hover_power=hover_power,
                     hover_samples=int(ref.sum()), hover_from=hover_from, signals=list(ps.signals))  # fmt: skip
    return out
