"""Which height to believe: every height source of a log checked against the ground and each other.

Real logs disagree with themselves. An ArduCopter 4.5 ``.BIN`` had every EKF height (CTUN.Alt, POS,
XKF1) 4–12 m below home for the whole flight, on the ground too, while BARO.Alt showed the real
climb and descent; an ArduCopter 3.4 ``.tlog`` had LOCAL_POSITION_NED and GLOBAL_POSITION_INT run on
down to 7.6–8.0 m below home after a hard landing and come back later, with the vehicle armed on the
ground, while SCALED_PRESSURE fell about 9 m in 2 s and stayed there (timed on the estimator: one
16.7 m descent lasting 39.9 s). Descents timed on such a height are fiction, so :func:`arbitrate`
picks the height to time them on. The rules, with every threshold in :class:`HeightConfig`:

**Witnesses.** Sources are grouped by what produced them (:func:`witness`): one estimator's streams
(local and global position, VFR_HUD, POS/CTUN/XKF, vehicle_local/global_position) are one witness,
the barometers another, GPS and a rangefinder each their own. Two outputs of one producer are one
opinion: they never make a consensus or a referee for each other, and they count once in a median.

**Ground windows.** Before take-off and after landing the vehicle stands at home height. Where the
log has the armed flag anywhere, the ground windows are the samples *disarmed* before the first armed
sample and after the last one. A vehicle armed for the whole log has none (it may have started in the
air); a log never seen armed has its leading and trailing disarmed runs (all of it, if it is
disarmed throughout: one ground window). Where the flag is unknown throughout, a ground window is
the stretch at the log's start (or end) where the vehicle is still — speed below
``still_speed_mps``, every non-GPS height quiet within ``still_band_m`` over a second, motors (where
logged) below ``idle_motor_max`` — for at least ``min_ground_s``, and at the lowest level of the
flight by at least one non-GPS source (its height there within ``ground_tol_m`` of its own 2nd
percentile; the minimum over the sources, as a drifting estimator may read the ground high): a hover
is still too, but it is neither at idle nor the lowest the vehicle went.

**Referencing.** Each source is referred to home: its median over the pre-take-off window is
subtracted (else the post-landing window's). A source that claims home = 0 (``home_relative``) but
has no ground window is taken as logged, and so is a rangefinder (its datum is the ground below; most
read nothing valid on the ground); any other source without one is aligned to the estimator by the
median of their difference, and said so.

**Checks.** Per source, on the state clock (each stream interpolated across gaps up to
``max_gap_s`` or three of its periods; rangefinder samples only where valid, below
``rangefinder_max_m``; every source but the estimator under a running median of ``smooth_s`` against
spikes — the estimator stays raw, its jumps are what is looked for):

- *ground error*: |median height| in the ground windows — raw for home-relative sources where home
  was set (before take-off, else after landing: they must read ≈ 0 there), and in the post-landing
  window after referencing at the pre-take-off one (the drift over the flight);
- *below ground*: how far the referenced height goes below 0 outside the ground windows;
- *disagreement*: the difference from the consensus of the other witnesses' sources that passed the
  ground check: the median over the estimator and barometer witnesses (each its own streams' median),
  else over the rangefinders, else over GPS — each instant falling back to the next tier where the
  first has no sample. Spans where it exceeds the tolerance (``disagree_tol_m``, ``gps_tol_m`` where
  GPS is involved, plus ``lag_s`` × the consensus' climb or sink rate: streams lag each other by a few
  tenths of a second, 1 Hz messages are timed on arrival, and a 5 m/s descent turns 0.4 s of lag
  into 2 m) are extended to where the difference is back within ``edge_m`` of its level over
  ``edge_window_s`` next to the span, then on outwards while its 1 s mean still closes in at
  ``edge_rate_mps`` or faster (up to ``edge_walk_s``; the level next to a span may sit on a slow ramp,
  and a smooth excursion is over where it stops approaching, not at the band), and back in to the
  first sample within ``edge_floor_m`` of the level beyond; spans closer than ``merge_gap_s`` are one.
  **The ground outranks an estimator**: a span is blamed on an estimator, whatever a referee says,
  where the estimator is more than ``below_ground_tol_m`` below the ground while the vehicle stands
  on it — disarmed, its land detector saying landed, or the barometers at rest (quiet within
  ``still_band_m`` over a second for at least ``min_ground_s``) within ``ground_tol_m`` of home or of
  the lowest level they rest at (:func:`_ground_rest`) — or while the consensus stays above it, the
  difference out of tolerance (the ground is at home, or where the barometers rest when that is
  lower: a landing below home or a barometer that drifted low does not excuse an estimator below
  both). Otherwise a span is **not** blamed on the source when the consensus is the one that went
  below the ground while the source did not, or when a referee (rangefinder, else GPS, not used in
  the consensus) sits closer to the source than to the consensus. (On the ArduCopter 3.4 ``.tlog`` a
  GPS referee cleared the 7.6 m excursion: the GPS altitude can sink with an estimator that fuses
  GPS vertical velocity.)

A source is **consistent** when it could be referenced, its ground error is within ``ground_tol_m``
(``gps_tol_m`` for GPS), and its blamed disagreement spans and below-ground spans each cover at most
``max_bad_fraction`` of the time outside the ground windows: a few short spans are glitches of an
otherwise good source, most of the flight is a bad source.

**Choice.** The state's estimator (the first source) when it is consistent; else the first consistent
source by kind estimator > baro > gps > rangefinder; when none is consistent the estimator is kept
and a note says so. The trusted source's blamed spans become glitches of kind ``"disagreement"``
(with what every source, referenced to home, said at the worst instant) and its height there is
**bridged** with the consensus, offset so that it joins the source's own height at both ends, so a
descent the estimator invented is not reported. With only two sources and no referee a span cannot
be attributed by a third opinion: it is blamed on the estimator unless the other one is the one below
the ground, and the note says so.

**Vertical rate.** When another source is trusted the state's ``vd_mps`` is kept if it agrees with
that height's rate (1 s means, 90th percentile of the difference within ``vd_tol_mps`` and its median
within ``vd_bias_mps``: an estimator whose height drifts 8 m over a 30 s flight has its velocity biased
by 0.27 m/s, a third of a typical ``w_allow``, while the six PX4 reference flights' velocities sit
within 0.06 m/s of their barometers' rate on the median), else it is replaced by :func:`vertical_rate`
of the trusted height (the derivative of its centred moving average over ``vd_smooth_s``); inside
bridged spans it is always replaced (see :func:`apply`).

Why these tolerances: real PX4 (SIH, ``../shared/px4_sih``) has its height 0.3–0.7 m off the truth in
flight and drifting up to 1.6 m on the ground after landing; barometers drift slowly and read up to
about a metre low in ground effect; GPS altitude is noisy by ±2–3 m. In the six reference PX4 flights
(``.ulg`` and our folders' ``.tlog``) the estimator's ground error is 0.2–1.0 m (drift after landing;
a raw check after landing would add the EKF origin's 0.5 m offset from home and reach 1.5 m) and the
sources disagree by at most 1.0 m (GLOBAL_POSITION_INT's 1 Hz-quantised altitude up to 2.3 m against
LOCAL_POSITION_NED, but two estimator streams are never compared). So a 2.5 m ground tolerance
passes PX4's drift of up to 1.6 m and fails the ``.BIN``'s 4 m; 2.5 m of disagreement passes PX4's
in-flight error plus a barometer's and flags the ``.tlog``'s 7.5 m; 2 m below the ground in flight is
more than ground effect and PX4's error together; GPS gets 6 m (about twice its noise) and serves as
a referee and a last resort rather than a voter.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, fields

import numpy as np
import pandas as pd

from flighttest.analysis.schema import HeightSource, motor_columns, resample
from flighttest.analysis.segment import GLITCH_COLUMNS, true_runs
from flighttest.analysis.segment import samples_in as _window
from flighttest.errors import FlighttestError

KIND_RANK = {"estimator": 0, "baro": 1, "gps": 2, "rangefinder": 3}
SOURCE_COLUMNS = ["name", "kind", "consistent", "ground_error_m", "below_ground_m", "max_disagreement_m", "reason"]


@dataclass(frozen=True)
class HeightConfig:
    """Thresholds of the arbitration (module docstring says how each is used and why its default)."""

    ground_tol_m: float = 2.5  # |height at home| on the ground beyond this: the source is wrong
    below_ground_tol_m: float = 2.0  # a referenced height this far below 0 in flight went through the ground
    disagree_tol_m: float = 2.5  # farther than this from the consensus: a disagreement span
    gps_tol_m: float = 6.0  # the same two tolerances where GPS altitude takes part (±2–3 m noise)
    lag_s: float = 0.5  # streams' relative latency: the disagreement tolerance grows by this × the climb/sink rate
    max_bad_fraction: float = 0.25  # spans covering more of the flight than this: inconsistent, not glitches
    edge_m: float = 0.5  # a span extends to where the difference is back within this of its level around it
    edge_window_s: float = 5.0  # ... that level: the median difference over this long before / after the span
    edge_rate_mps: float = 0.1  # ... then on while its 1 s mean still closes in at least this fast (a ramp) ...
    edge_walk_s: float = 60.0  # ... at most this far (a ramp's start, not the other end of the flight) ...
    edge_floor_m: float = 0.1  # ... to the first sample within this of the level found beyond it
    merge_gap_s: float = 1.0  # spans closer than this are one span
    smooth_s: float = 0.5  # running median on every source but the estimator, against spikes
    max_gap_s: float = 1.0  # a stream is interpolated across gaps up to this (or three of its periods)
    rangefinder_max_m: float = 40.0  # rangefinder readings at or beyond this are out of range
    still_speed_mps: float = 0.3  # armed flag unknown: still = slower than this ...
    still_band_m: float = 0.5  # ... every non-GPS height within this over a second ...
    idle_motor_max: float = 0.3  # ... motors (where logged) below this (hover is about 0.4–0.6) ...
    min_ground_s: float = 2.0  # ... for at least this long at the log's start or end
    vd_tol_mps: float = 0.5  # estimator vd this far (90th percentile) from the trusted height's rate: unusable
    vd_bias_mps: float = 0.1  # ... or this far on the median: the estimator's height drift is in its velocity too
    vd_smooth_s: float = 0.5  # vertical rate from a height: derivative of its centred moving average over this

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, int | float) and np.isfinite(value) and value > 0):
                raise FlighttestError(f"height threshold {f.name} must be a finite number > 0 (got {value!r})")
        if self.max_bad_fraction > 1:
            raise FlighttestError(f"height threshold max_bad_fraction must be at most 1 (got {self.max_bad_fraction})")


@dataclass
class HeightArbitration:
    """What :func:`arbitrate` decided. Arrays are on the state clock (one value per state row)."""

    source: str  # name of the trusted source
    kind: str
    height_m: np.ndarray  # trusted height, up-positive metres above home, glitch spans bridged
    sources: pd.DataFrame  # one row per source, columns SOURCE_COLUMNS
    glitches: pd.DataFrame  # the trusted source's disagreement spans, columns GLITCH_COLUMNS
    bridged: np.ndarray  # bool: samples whose height comes from the consensus
    ground: np.ndarray  # bool: samples in a ground window (before take-off / after landing)
    is_estimator: bool  # the trusted source is the state's own (the first source)
    vd_usable: bool  # the state's vd_mps agrees with the trusted height's rate (always True for the estimator)
    notes: list[str] = field(default_factory=list)

    @property
    def changes_state(self) -> bool:
        """Whether the state's d_m must change (another source trusted, or spans bridged)."""
        return not self.is_estimator or bool(self.bridged.any())

    def records(self) -> list[dict]:
        """``height_sources`` for ``--json``."""
        return self.sources.to_dict("records")


def _nanmedian(a: np.ndarray, axis: int | None = None) -> np.ndarray | float:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows are NaN, as they should be
        return np.nanmedian(a, axis=axis)


def _nanmax(a: np.ndarray) -> float:
    a = np.asarray(a, float)
    return float(np.nanmax(a)) if np.isfinite(a).any() else float("nan")


def _tier_median(cols: list[np.ndarray], n: int) -> np.ndarray:
    """Row-wise median ignoring NaN (np.nanmedian over a few columns is far slower: an hour at 50 Hz)."""
    if not cols:
        return np.full(n, np.nan)
    if len(cols) == 1:
        return cols[0]
    if len(cols) == 2:
        a, b = cols
        return np.where(np.isnan(a), b, np.where(np.isnan(b), a, 0.5 * (a + b)))
    a = np.sort(np.column_stack(cols), axis=1)  # NaN sort last
    cnt = np.isfinite(a).sum(axis=1)
    lo = np.take_along_axis(a, (np.maximum(cnt - 1, 0) // 2)[:, None], axis=1)[:, 0]
    hi = np.take_along_axis(a, np.minimum(cnt // 2, a.shape[1] - 1)[:, None], axis=1)[:, 0]
    return np.where(cnt > 0, 0.5 * (lo + hi), np.nan)


def vertical_rate(t: np.ndarray, h: np.ndarray, smooth_s: float) -> np.ndarray:
    """Descent rate (down-positive, like ``vd_mps``) from an up-positive height: the derivative of its
    centred moving average over ``smooth_s`` (a barometer's noise differentiated raw would swamp it)."""
    n = _window(t, smooth_s)
    hs = pd.Series(h).rolling(n, center=True, min_periods=1).mean().to_numpy()
    return -np.gradient(hs, t) if len(t) > 1 else np.zeros_like(h)


def _on_clock(src: HeightSource, t: np.ndarray, cfg: HeightConfig, smooth: bool) -> np.ndarray:
    ts = np.asarray(src.t_s, float)
    alt = np.asarray(src.alt_m, float)
    ok = np.isfinite(ts) & np.isfinite(alt)
    if src.kind == "rangefinder":
        ok &= (alt < cfg.rangefinder_max_m) & (alt > -1.0)
    ts, alt = ts[ok], alt[ok]
    if len(ts) == 0:
        return np.full(len(t), np.nan)
    order = np.argsort(ts, kind="stable")
    ts, alt = ts[order], alt[order]
    if smooth and len(ts) > 2:
        n = _window(ts, cfg.smooth_s) | 1
        alt = pd.Series(alt).rolling(n, center=True, min_periods=1).median().to_numpy()
    if len(ts) == len(t) and np.array_equal(ts, t):
        return alt  # already on the state clock (the estimator, usually)
    period = float(np.median(np.diff(ts))) if len(ts) > 1 else 0.0
    return resample(ts, alt, t, max(cfg.max_gap_s, 3 * period))


def _edge_runs(mask: np.ndarray, from_start: bool) -> np.ndarray:
    """The leading (or trailing) run of ``mask`` as a mask."""
    out = np.zeros(len(mask), dtype=bool)
    m = mask if from_start else mask[::-1]
    n = int(np.argmin(m)) if not m.all() else len(m)
    if from_start:
        out[:n] = True
    else:
        out[len(mask) - n :] = True
    return out


def ground_windows(
    state: pd.DataFrame, raw: list[np.ndarray], kinds: list[str], cfg: HeightConfig
) -> tuple[np.ndarray, np.ndarray, str]:
    """(pre-take-off mask, post-landing mask, how they were found) on the state clock (module docstring)."""
    t = state["t_s"].to_numpy(float)
    n = len(t)
    armed = state["armed"].to_numpy(float) if "armed" in state else np.full(n, np.nan)
    if np.isfinite(armed).any():
        on = armed == 1
        off = armed == 0
        if not on.any():  # disarmed where known: the leading and the trailing disarmed runs
            pre = _edge_runs(off, from_start=True)
            post = np.zeros(n, dtype=bool) if pre.all() else _edge_runs(off, from_start=False)
            return pre, post, "armed flag (never seen armed)"
        idx = np.arange(n)
        first, last = int(np.argmax(on)), n - 1 - int(np.argmax(on[::-1]))
        return off & (idx < first), off & (idx > last), "armed flag"
    # armed unknown: still, quiet, at idle and at the lowest level, at the start or the end of the log
    win = _window(t, 1.0)
    vel = state[["vn_mps", "ve_mps", "vd_mps"]].to_numpy(float) if "vd_mps" in state else np.full((n, 3), np.nan)
    speed = np.sqrt(np.nansum(vel**2, axis=1))  # no velocity at all: the heights' quiet decides
    quiet = pd.Series(speed).rolling(win, center=True, min_periods=1).max().to_numpy() < cfg.still_speed_mps
    for h, kind in zip(raw, kinds):
        if kind == "gps" or not np.isfinite(h).any():
            continue
        s = pd.Series(h).rolling(win, center=True, min_periods=1)
        span = (s.max() - s.min()).to_numpy()
        quiet &= ~(span > cfg.still_band_m)  # NaN (no sample) does not break stillness
    motors = motor_columns(state)
    if motors:
        m = _tier_median([state[c].to_numpy(float) for c in motors], n)
        quiet &= ~(m > cfg.idle_motor_max)
    windows = []
    for from_start in (True, False):
        w = _edge_runs(quiet, from_start)
        if not w.any() or t[w].max() - t[w].min() < cfg.min_ground_s:
            windows.append(np.zeros(n, dtype=bool))
            continue
        levels = []
        for h, kind in zip(raw, kinds):
            if kind == "gps" or np.isfinite(h[w]).sum() < 3:
                continue
            levels.append(_nanmedian(h[w]) - np.nanpercentile(h, 2))
        low = bool(levels) and float(np.min(levels)) <= cfg.ground_tol_m
        windows.append(w if low else np.zeros(n, dtype=bool))
    return windows[0], windows[1], "stillness at the log's start/end (armed flag unknown)"


@dataclass
class _Src:
    src: HeightSource
    t: np.ndarray  # the state clock
    raw: np.ndarray  # as logged, on the state clock (smoothed unless the estimator)
    h: np.ndarray = field(default_factory=lambda: np.empty(0))  # referenced to home
    referenced: str | None = None  # how, or None when it cannot be
    ground_error_m: float = float("nan")
    below_ground_m: float = float("nan")
    max_disagreement_m: float = float("nan")
    below_fraction: float = 0.0
    bad_fraction: float = 0.0
    ground_ok: bool = False
    consensus: np.ndarray | None = None
    spans: list[tuple[int, int]] = field(default_factory=list)  # blamed disagreement spans
    offsets: list[list[float]] = field(default_factory=list)  # ... the difference's level before / after each
    cleared: int = 0  # disagreement spans not blamed on this source
    grounded: int = 0  # blamed spans where it went below the ground while the ground said otherwise
    judged_by: list[str] = field(default_factory=list)  # the sources its consensus came from
    refereed: bool = False  # a referee (rangefinder / GPS) outside the consensus was there to ask
    reasons: list[str] = field(default_factory=list)


def witness(src: HeightSource) -> str:
    """What produced a source. One estimator's streams (local and global position, VFR_HUD, POS/CTUN/XKF,
    vehicle_local/global_position) are one witness, the barometers another, GPS and rangefinders each
    their own: two outputs of one producer are one opinion, never a consensus or a referee for each other."""
    return src.kind


def _witness_median(group: list[_Src], n: int) -> np.ndarray:
    """Median over witnesses of each witness's own median: an estimator's two streams are one vote."""
    by: dict[str, list[np.ndarray]] = {}
    for s in group:
        by.setdefault(witness(s.src), []).append(s.h)
    return _tier_median([_tier_median(cols, n) for cols in by.values()], n)


def _tol(kind: str, cfg: HeightConfig) -> float:
    return cfg.gps_tol_m if kind == "gps" else cfg.ground_tol_m


def _reference(s: _Src, pre: np.ndarray, post: np.ndarray) -> None:
    for win, where in ((pre, "before take-off"), (post, "after landing")):
        if np.isfinite(s.raw[win]).sum() >= 3:
            s.h = s.raw - _nanmedian(s.raw[win])
            s.referenced = f"referenced to its median {where}"
            return
    if s.src.home_relative:
        s.h = s.raw.copy()
        s.referenced = "home-relative, taken as logged (no ground window)"
    elif s.src.kind == "rangefinder":
        # it measures the height above the ground below (home, on a flat field); most read nothing valid
        # on the ground (below their minimum range), and aligning one to the estimator instead would
        # carry the estimator's fault into the referee that should expose it
        s.h = s.raw.copy()
        s.referenced = "height above the ground below, taken as logged (no valid reading on the ground)"


def _ground_checks(s: _Src, pre: np.ndarray, post: np.ndarray, flying: np.ndarray, cfg: HeightConfig) -> None:
    errs: list[tuple[float, str]] = []
    if s.src.home_relative:
        # home is where it was set: before take-off (after landing only when the log starts in the air);
        # after landing the referenced check below measures the drift without counting that offset twice
        for win, where in ((pre, "before take-off"), (post, "after landing")):
            if np.isfinite(s.raw[win]).sum() >= 3:
                v = float(_nanmedian(s.raw[win]))
                errs.append((abs(v), f"reads {v:+.1f} m at home {where} (home-relative: should be 0)"))
                break
    if s.referenced and "before take-off" in s.referenced and np.isfinite(s.h[post]).sum() >= 3:
        v = float(_nanmedian(s.h[post]))
        errs.append((abs(v), f"comes back {v:+.1f} m off home after landing"))
    if errs:
        s.ground_error_m = max(e for e, _ in errs)
        s.reasons.extend(why for e, why in errs if e > _tol(s.src.kind, cfg))
    fly_h = s.h[flying]
    if np.isfinite(fly_h).any():
        s.below_ground_m = max(0.0, -float(np.nanmin(fly_h)))
        n_fly = max(int(np.isfinite(fly_h).sum()), 1)
        s.below_fraction = float((fly_h < -cfg.below_ground_tol_m).sum()) / n_fly
        if s.below_fraction > cfg.max_bad_fraction:
            s.reasons.append(
                f"{s.below_ground_m:.1f} m below the ground for {100 * s.below_fraction:.0f}% of the flight"
            )
    else:
        s.below_ground_m = 0.0 if not flying.any() else float("nan")
    s.ground_ok = bool(s.referenced) and not s.reasons


def _long_runs(t: np.ndarray, mask: np.ndarray, min_s: float) -> np.ndarray:
    """``mask`` with its True runs shorter than ``min_s`` cleared."""
    runs = np.array(true_runs(mask), dtype=int).reshape(-1, 2)
    runs = runs[t[runs[:, 1]] - t[runs[:, 0]] >= min_s]
    step = np.zeros(len(mask) + 1, dtype=int)
    np.add.at(step, runs[:, 0], 1)
    np.add.at(step, runs[:, 1] + 1, -1)
    return np.cumsum(step[:-1]) > 0


def _ground_rest(state: pd.DataFrame, srcs: list[_Src], cfg: HeightConfig) -> tuple[np.ndarray, np.ndarray]:
    """(on the ground, the ground's height above home there) on the state clock, from the witnesses an
    estimator cannot overrule: disarmed, a landed state on the ground, or the barometers at rest (quiet
    within ``still_band_m`` over a second for at least ``min_ground_s``) at their ground level: within
    ``ground_tol_m`` of home, or of the lowest level they rest at in the log (a barometer that drifted
    low over a long flight; a hover rests higher than the ground it later lands on). The ground is at
    home, or where the barometers rest when that is lower (an estimator is then below the ground only
    below both)."""
    t = state["t_s"].to_numpy(float)
    n = len(t)
    on = np.zeros(n, dtype=bool)
    for col, ground_value in (("armed", 0.0), ("landed", 1.0)):
        if col in state:
            on |= state[col].to_numpy(float) == ground_value
    floor = np.zeros(n)
    baros = [s for s in srcs if s.src.kind == "baro" and s.ground_ok]
    if baros:
        hb = _witness_median(baros, n)
        roll = pd.Series(hb).rolling(_window(t, 1.0), center=True, min_periods=1)
        quiet = _long_runs(t, (roll.max() - roll.min()).to_numpy() <= cfg.still_band_m, cfg.min_ground_s)
        if quiet.any():
            run = np.cumsum(np.diff(np.concatenate([[0], quiet.astype(np.int8)])) == 1)
            lowest = float(pd.Series(hb[quiet]).groupby(run[quiet]).median().min())
            rest = quiet & ((np.abs(hb) <= cfg.ground_tol_m) | (hb - lowest <= cfg.ground_tol_m))
            on |= rest
            floor = np.where(rest, np.minimum(hb, 0.0), 0.0)
    return on, floor


def _consensus(i: int, srcs: list[_Src], cfg: HeightConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """(consensus, tolerance, referee, who) for source i from the ground-checked others (module docstring)."""
    me = srcs[i]
    n = len(me.raw)
    mine = witness(me.src)
    others = [s for j, s in enumerate(srcs) if j != i and s.ground_ok and witness(s.src) != mine]
    t1 = [s for s in others if s.src.kind in ("estimator", "baro")]
    t2 = [s for s in others if s.src.kind == "rangefinder"]
    t3 = [s for s in others if s.src.kind == "gps"]
    m1, m2, m3 = (_witness_median(tier, n) for tier in (t1, t2, t3))
    tol_me = cfg.gps_tol_m if me.src.kind == "gps" else cfg.disagree_tol_m
    cons = m1.copy()
    tol = np.full(n, tol_me)
    use2 = ~np.isfinite(cons) & np.isfinite(m2)
    cons[use2] = m2[use2]
    use3 = ~np.isfinite(cons) & np.isfinite(m3)
    cons[use3] = m3[use3]
    tol[use3] = cfg.gps_tol_m
    # streams lag each other (filters, 1 Hz messages timed on arrival): moving fast they differ more
    known = np.isfinite(cons)
    if known.sum() >= 2:
        tol += cfg.lag_s * np.abs(vertical_rate(me.t, _fill(me.t, cons), cfg.vd_smooth_s))
    referee = np.where(np.isfinite(m2), m2, m3)
    referee[~np.isfinite(m1)] = np.nan  # a referee only where it is not itself the consensus
    who = [s.src.name for s in (t1 or t2 or t3)]
    return cons, tol, referee, who


def _around(diff: np.ndarray, t: np.ndarray, a: int, b: int, bad: np.ndarray, cfg: HeightConfig) -> list[np.ndarray]:
    """Indices with a usable difference within ``edge_window_s`` before and after the span [a, b]."""
    lo = int(np.searchsorted(t, t[a] - cfg.edge_window_s))
    hi = int(np.searchsorted(t, t[b] + cfg.edge_window_s, side="right"))
    out = []
    for idx in (np.arange(lo, a), np.arange(b + 1, hi)):
        out.append(idx[~bad[idx] & np.isfinite(diff[idx])])
    return out


def _levels(diff: np.ndarray, t: np.ndarray, a: int, b: int, bad: np.ndarray, cfg: HeightConfig) -> list[float]:
    """The difference's level (median) before and after the span; NaN where there is none."""
    return [float(_nanmedian(diff[idx])) if len(idx) else float("nan") for idx in _around(diff, t, a, b, bad, cfg)]


def _extend(
    diff: np.ndarray, smooth: np.ndarray, t: np.ndarray, a: int, b: int, bad: np.ndarray, cfg: HeightConfig
) -> tuple[int, int]:
    """Grow the span [a, b] to where the difference is back at its level outside it (module docstring)."""
    before, after = _around(diff, t, a, b, bad, cfg)
    lag = _window(t, 1.0)
    n = len(t)
    for side, idx in ((-1, before), (1, after)):
        if not len(idx):
            continue
        level = _nanmedian(diff[idx])
        back = idx[np.abs(diff[idx] - level) <= cfg.edge_m]
        if not len(back):
            continue
        # a smooth excursion is over where it stops approaching, not at the band, and the level next to
        # the span may sit on a slow ramp (an estimator sinking at 0.2 m/s for half a minute): follow the
        # approach outwards a second at a time on the 1 s mean (sample-to-sample steps drown in the
        # sensors' noise), then come back in to the first sample at the level found beyond the ramp
        # (the 1 s mean smears a sharp edge by half a second)
        k = int(back[-1]) if side < 0 else int(back[0])
        sign = np.sign(_nanmedian(diff[a : b + 1]) - level)
        reach = int(np.searchsorted(t, t[k] + side * cfg.edge_walk_s, side="left" if side < 0 else "right"))
        run = np.arange(k, max(reach, 0) - 1, -1) if side < 0 else np.arange(k, min(reach, n))
        ahead = np.clip(run + side * lag, 0, n - 1)
        with np.errstate(invalid="ignore"):
            closing = sign * (smooth[run] - smooth[ahead]) >= cfg.edge_rate_mps * np.abs(t[run] - t[ahead])
        stop = np.flatnonzero(~closing)
        run = run[: stop[0] + 1] if len(stop) else run
        lo = int(np.searchsorted(t, t[run[-1]] - cfg.edge_window_s))
        hi = int(np.searchsorted(t, t[run[-1]] + cfg.edge_window_s, side="right"))
        beyond = np.arange(lo, run[-1] + 1) if side < 0 else np.arange(run[-1], hi)
        beyond = beyond[~bad[beyond] & np.isfinite(diff[beyond])]
        outer = _nanmedian(diff[beyond]) if len(beyond) else level
        at = np.flatnonzero(np.abs(diff[run] - outer) <= cfg.edge_floor_m)
        k = int(run[at[0]]) if len(at) else int(run[-1])
        if side < 0:
            a = k + 1
        else:
            b = k - 1
    return a, b


def _disagreement(
    i: int,
    srcs: list[_Src],
    t: np.ndarray,
    flying: np.ndarray,
    rest: tuple[np.ndarray, np.ndarray],
    cfg: HeightConfig,
) -> None:
    s = srcs[i]
    if not s.referenced:
        return
    cons, tol, referee, who = _consensus(i, srcs, cfg)
    valid = flying & np.isfinite(cons) & np.isfinite(s.h)
    if not valid.any():
        return
    s.consensus = cons
    s.judged_by = who
    s.refereed = bool(np.isfinite(referee[valid]).any())
    diff = s.h - cons
    s.max_disagreement_m = _nanmax(np.abs(diff[valid]))
    bad = valid & (np.abs(diff) > tol)
    # an estimator below the ground, out of tolerance with the others, where the vehicle stood on the
    # ground or the independent heights stayed above it went through the ground: neither its sibling
    # streams nor a referee can vouch for it (the tolerance keeps a lagging barometer crossing the line
    # a moment after the estimator at a landing from counting)
    on, floor = rest
    sunk = np.zeros(len(t), dtype=bool)
    if s.src.kind == "estimator":
        deep = floor - cfg.below_ground_tol_m
        with np.errstate(invalid="ignore"):
            sunk = bad & (s.h < deep) & (on | (cons >= deep))
    spans: list[list[int]] = []
    smooth = pd.Series(diff).rolling(_window(t, 1.0), center=True, min_periods=1).mean().to_numpy()
    for a, b in true_runs(bad):
        a, b = _extend(diff, smooth, t, int(a), int(b), bad, cfg)
        if spans and t[a] - t[spans[-1][1]] < cfg.merge_gap_s:
            spans[-1][1] = max(b, spans[-1][1])
        else:
            spans.append([a, b])
    n_fly = max(int(valid.sum()), 1)
    blamed_n = 0
    for a, b in spans:
        sl = slice(a, b + 1)
        if sunk[sl].any():
            s.grounded += 1
        elif _cleared(s.h[sl], cons[sl], referee[sl], cfg):
            s.cleared += 1
            continue
        s.spans.append((a, b))
        s.offsets.append(_levels(diff, t, a, b, bad, cfg))
        blamed_n += int(valid[sl].sum())
    s.bad_fraction = blamed_n / n_fly
    if s.spans:
        dur = sum(t[b] - t[a] for a, b in s.spans)
        msg = (
            f"disagrees with {', '.join(who)} by up to {s.max_disagreement_m:.1f} m in {len(s.spans)} span(s), "
            f"{dur:.1f} s ({100 * s.bad_fraction:.0f}% of the flight)"
        )
        if s.bad_fraction > cfg.max_bad_fraction:
            s.reasons.append(msg)


def _cleared(me: np.ndarray, cons: np.ndarray, referee: np.ndarray, cfg: HeightConfig) -> bool:
    """A disagreement span not blamed on the source: the consensus is the one that went below the
    ground, or the referee (sampled over at least half the span) sits closer to the source."""
    c_low = np.isfinite(cons).any() and np.nanmin(cons) < -cfg.below_ground_tol_m
    me_low = np.isfinite(me).any() and np.nanmin(me) < -cfg.below_ground_tol_m
    if c_low and not me_low:
        return True
    if np.isfinite(referee).sum() * 2 >= len(referee):
        return bool(_nanmedian(np.abs(me - referee)) < _nanmedian(np.abs(cons - referee)))
    return False


def _bridge(s: _Src, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Trusted height with its blamed spans replaced by the consensus, offset by the source's level
    against the consensus before and after the span (interpolated across it) so that it joins both ends."""
    h = s.h.copy()
    mask = np.zeros(len(h), dtype=bool)
    if s.consensus is None:
        return h, mask
    cons = s.consensus
    for (a, b), (off_a, off_b) in zip(s.spans, s.offsets):
        off_a = off_b if not np.isfinite(off_a) else off_a
        off_b = off_a if not np.isfinite(off_b) else off_b
        sl = slice(a, b + 1)
        if not np.isfinite(off_a):
            off = np.zeros(b - a + 1)
        else:
            f = (t[sl] - t[a]) / max(t[b] - t[a], 1e-9)
            off = off_a + (off_b - off_a) * f
        h[sl] = cons[sl] + off
        mask[sl] = True
    return h, mask


def _glitch_rows(s: _Src, srcs: list[_Src], t: np.ndarray) -> pd.DataFrame:
    rows = []
    cons = s.consensus if s.consensus is not None else np.full(len(t), np.nan)  # spans exist only with one
    for a, b in s.spans:
        sl = slice(a, b + 1)
        dev = np.abs(s.h[sl] - cons[sl])
        k = a + int(np.nanargmax(dev)) if np.isfinite(dev).any() else a
        said = {o.src.name: round(float(o.h[k]), 3) for o in srcs if o.referenced and np.isfinite(o.h[k])}
        rows.append(
            {
                "start_s": float(t[a]),
                "end_s": float(t[b]),
                "duration_s": float(t[b] - t[a]),
                "max_jump_m": _nanmax(dev),
                "kind": "disagreement",
                "source": s.src.name,
                "sources": said,
            }
        )
    return pd.DataFrame(rows, columns=GLITCH_COLUMNS)


def _vd_usable(state: pd.DataFrame, t: np.ndarray, h: np.ndarray, ok: np.ndarray, cfg: HeightConfig) -> bool:
    """The state's vd agrees with the trusted height's rate (1 s means, 90th percentile within vd_tol_mps,
    median within vd_bias_mps)."""
    col = "vd_est_mps" if "vd_est_mps" in state else "vd_mps"
    vd = state[col].to_numpy(float)
    n = _window(t, 1.0)
    vd_s = pd.Series(vd).rolling(n, center=True, min_periods=1).mean().to_numpy()
    vh = pd.Series(vertical_rate(t, h, cfg.vd_smooth_s)).rolling(n, center=True, min_periods=1).mean().to_numpy()
    diff = (vd_s - vh)[ok]
    diff = diff[np.isfinite(diff)]
    if not len(diff):
        return False
    return float(np.percentile(np.abs(diff), 90)) <= cfg.vd_tol_mps and abs(float(np.median(diff))) <= cfg.vd_bias_mps


def _fill(t: np.ndarray, h: np.ndarray) -> np.ndarray:
    ok = np.isfinite(h)
    if ok.all() or not ok.any():
        return h
    out = h.copy()
    out[~ok] = np.interp(t[~ok], t[ok], h[ok])
    return out


def arbitrate(state: pd.DataFrame, sources: list[HeightSource], cfg: HeightConfig | None = None) -> HeightArbitration:
    """Check every height source against the ground and each other and choose the one to trust.

    ``sources[0]`` is the state's own (the estimator ``d_m`` came from); with no sources the state's
    ``d_m`` stands in for it. With a single source nothing can be cross-checked: the arbitration
    reports its ground checks and changes nothing."""
    cfg = cfg or HeightConfig()
    t = state["t_s"].to_numpy(float)
    n = len(t)
    if not sources:
        sources = [HeightSource("state.d_m", "estimator", t, -state["d_m"].to_numpy(float))]
    srcs = [_Src(s, t, _on_clock(s, t, cfg, smooth=k > 0)) for k, s in enumerate(sources)]
    pre, post, how = ground_windows(state, [s.raw for s in srcs], [s.src.kind for s in srcs], cfg)
    ground = pre | post
    flying = ~ground
    notes: list[str] = []
    for s in srcs:
        _reference(s, pre, post)
    est = srcs[0]
    anchor = est if est.referenced else next((s for s in srcs if s.referenced), None)
    for s in srcs:
        if s.referenced:
            continue
        if anchor is not None and np.isfinite(s.raw - anchor.h).any():
            s.h = s.raw - _nanmedian(s.raw - anchor.h)
            s.referenced = f"aligned to {anchor.src.name} (no ground window)"
        else:
            s.h = np.full(n, np.nan)
            s.reasons.append("no samples" if not np.isfinite(s.raw).any() else "cannot be referenced to home")
    for s in srcs:
        _ground_checks(s, pre, post, flying, cfg)
    if len(srcs) > 1:
        rest = _ground_rest(state, srcs, cfg)
        for i in range(len(srcs)):
            _disagreement(i, srcs, t, flying, rest, cfg)
    consistent = [bool(s.referenced) and not s.reasons for s in srcs]
    if consistent[0] or len(srcs) == 1:
        pick = 0
    else:
        ranked = sorted((KIND_RANK[s.src.kind], k) for k, s in enumerate(srcs) if consistent[k])
        pick = ranked[0][1] if ranked else 0
        if not ranked:
            notes.append(f"no height source is consistent with the ground and the others: kept {est.src.name}")
    trusted = srcs[pick]
    if len(srcs) == 1:
        height, bridged = trusted.h.copy(), np.zeros(n, dtype=bool)
        glitches = pd.DataFrame(columns=GLITCH_COLUMNS)
        if not consistent[0]:
            notes.append(f"{est.src.name}: {'; '.join(est.reasons)} (the only height source: kept)")
    else:
        height, bridged = _bridge(trusted, t)
        glitches = _glitch_rows(trusted, srcs, t)
        if pick != 0:
            notes.append(
                f"height from {trusted.src.name} ({trusted.src.kind}): {est.src.name} "
                f"{'; '.join(est.reasons) or 'is not consistent'}"
            )
        if len(glitches):
            alone = len(trusted.judged_by) == 1 and not trusted.refereed
            notes.append(
                f"{len(glitches)} span(s) where {trusted.src.name} disagrees with {', '.join(trusted.judged_by)}: "
                "flagged as estimator glitches and bridged with them"
                + (" (no third source to referee: the estimator is presumed wrong)" if alone else "")
            )
        if trusted.grounded:
            notes.append(
                f"{trusted.grounded} of them with {trusted.src.name} below the ground while the vehicle stood on it "
                "(disarmed, landed, or the barometer at rest there) or every independent height stayed above it: "
                "the ground outranks an estimator and any referee"
            )
        if trusted.cleared:
            notes.append(
                f"{trusted.src.name} disagreed with {', '.join(trusted.judged_by)} in {trusted.cleared} span(s) "
                "where the referee or the ground sided with it: kept as it was"
            )
    if not np.isfinite(height).any():
        height = -state["d_m"].to_numpy(float)
    height = _fill(t, height)
    if len(srcs) > 1 and not ground.any():
        notes.append("no ground window (armed flag and stillness): heights not checked against the ground")
    elif len(srcs) > 1 and pick != 0:
        notes.append(f"ground windows from the {how}")
    vd_ok = True if pick == 0 else _vd_usable(state, t, height, flying & ~bridged, cfg)
    table = pd.DataFrame(
        [
            {
                "name": s.src.name,
                "kind": s.src.kind,
                "consistent": consistent[k],
                "ground_error_m": s.ground_error_m,
                "below_ground_m": s.below_ground_m,
                "max_disagreement_m": s.max_disagreement_m,
                "reason": "; ".join(s.reasons)
                or ("consistent" + (f", {len(s.spans)} short disagreement span(s)" if s.spans else "")),
            }
            for k, s in enumerate(srcs)
        ],
        columns=SOURCE_COLUMNS,
    )
    return HeightArbitration(
        source=trusted.src.name,
        kind=trusted.src.kind,
        height_m=height,
        sources=table,
        glitches=glitches,
        bridged=bridged,
        ground=ground,
        is_estimator=pick == 0,
        vd_usable=vd_ok,
        notes=notes,
    )


def apply(state: pd.DataFrame, arb: HeightArbitration, cfg: HeightConfig | None = None) -> None:
    """Put the trusted height into ``state`` (in place) for the segmentation.

    Nothing changes when the estimator is trusted and nothing was bridged. Otherwise the original
    columns are kept as ``d_est_m`` / ``vd_est_mps`` (plots show both) and:

    - another source trusted: ``d_m = −height`` (so ``d_m`` is now relative to home); ``vd_mps``
      becomes the trusted height's rate (:func:`vertical_rate`) when the estimator's vertical
      velocity disagrees with it (``arb.vd_usable`` false), else stays the estimator's;
    - the estimator trusted with bridged spans: ``d_m`` there becomes the bridged height in the
      estimator's own datum, and ``vd_mps`` there (and half a smoothing window around) the bridged
      height's rate: the estimator's velocity went with its height.
    """
    cfg = cfg or HeightConfig()
    if not arb.changes_state:
        return
    t = state["t_s"].to_numpy(float)
    if "d_est_m" not in state:
        state["d_est_m"] = state["d_m"].to_numpy(float)
        state["vd_est_mps"] = state["vd_mps"].to_numpy(float)
    d0 = state["d_est_m"].to_numpy(float)
    vd0 = state["vd_est_mps"].to_numpy(float)
    h = arb.height_m
    rate = vertical_rate(t, h, cfg.vd_smooth_s)
    if arb.is_estimator:
        datum = _nanmedian((-d0 - h)[~arb.bridged])
        datum = 0.0 if not np.isfinite(datum) else float(datum)
        d = d0.copy()
        d[arb.bridged] = -(h[arb.bridged] + datum)
        near = pd.Series(arb.bridged).rolling(_window(t, cfg.vd_smooth_s) | 1, center=True, min_periods=1).max()
        near = near.to_numpy().astype(bool)
        vd = vd0.copy()
        vd[near] = rate[near]
    else:
        d = -h
        vd = vd0.copy() if arb.vd_usable else rate
    state["d_m"] = d
    state["vd_mps"] = vd
