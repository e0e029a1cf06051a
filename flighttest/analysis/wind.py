"""The wind a log's analysis judges the air with (CONVENTIONS §1: ``v_air = v_ned − wind``).

Neither PX4 nor ArduPilot estimates the wind on a multicopter by default (PX4's EKF2 only with drag
fusion, ArduPilot's EKF3 only with its drag coefficients set: ../shared/wind_sitl), and in a 3 m/s wind a
vehicle's ground velocity says little about the air through its disk. Each log's wind is therefore the
first of, per log:

1. **what flighttest flew with** (``"logged: SOURCE"``): a flighttest folder's ``guard.csv`` wind
   (``wn/we/wd_mps``, its 1 σ ``wind_sd_mps``, ``wind_source``: "operator", "autopilot", both joined by
   "+", "flighttest", ...; :mod:`flighttest.flying.wind`). Rows the guard judged "assumed calm" are no
   measurement: they take the nearest measured row's wind, no surer than ``REPORT_SD_UNKNOWN_MPS``. A
   folder written before those columns whose wind is exact zeros throughout assumed calm too; any other
   wind it logged is used with that unknown accuracy (``"logged (source not recorded)"``).
2. **the autopilot's own estimate** in the log (``"autopilot: NAME"``, ``FlightLog.wind_reported``:
   ``WIND_COV``, ``WIND``, ``XKF2``, the ``wind``/``estimator_wind`` topics), only where it is one: a
   stream of exact zeros is what an estimator that does not estimate the wind sends. Its own accuracy
   where it gives one, else ``REPORT_SD_UNKNOWN_MPS`` (the live guard's rule,
   :func:`flighttest.flying.wind.autopilot_report`).
3. **flighttest's estimator** (``"flighttest estimate"``): :class:`flighttest.model.wind_estimate.WindFilter`
   run over the log's own specific force (``ax/ay_mps2``: ``FlightLog.accel_source``), attitude and
   velocity while the vehicle is airborne (:func:`airborne_mask`: the ground holds a vehicle against the
   wind, and its drag model would read that as calm), with the vehicle's drag model — the one the folder's
   ``meta.json`` vehicle summary recorded when no profile is given explicitly, else the profile's
   (``VehicleProfile.drag``). Post-flight the whole log is known, so a forward and a backward pass are
   combined (a two-filter smoother: the backward filter's prediction, before it takes the sample, fused
   with the forward filter's estimate), at ``ESTIMATE_RATE_HZ`` with the specific force averaged over
   each step. Its 1 σ is the smoother's own (the drag's scale error a state of both passes, its prior
   counted once), combined with what no state covers (an accelerometer bias through the drag's slope: the
   filter's ``model_sd``, on the smoothed estimate).
4. **assumed calm** (``"assumed calm"``): still air, its uncertainty unknown (``wind_sd_mps`` NaN: no
   worst case can be judged), and ``FlightLog.missing["wind"]`` says why.

:func:`resolve` chooses, :func:`apply` makes it the log's (``FlightLog.wind``: per state sample, NED
and 1 σ; the state's own wind columns keep what the log said), so every analysis of the log (exposure,
identify, the figures) judges the same air.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from flighttest.analysis.schema import FlightLog, resample
from flighttest.flying.wind import REPORT_SD_UNKNOWN_MPS, WIND_COVERAGE_SIGMAS
from flighttest.model.drag import DragModel
from flighttest.model.frames import ned_to_body
from flighttest.model.wind_estimate import WindFilter, model_sd, worse_axis_sd

ESTIMATE_RATE_HZ = 5.0  # the estimator's steps: the specific force averaged over each 0.2 s (bench/RESULTS.md)
MIN_AIRBORNE_S = 2.0  # less time in the air than this: nothing to estimate from
AIRBORNE_MIN_HEIGHT_M = 0.5  # above the ground seen at rest: clear of ground contact
LOGGED_MAX_GAP_S = 1.0  # guard.csv rows further apart than this are a gap
REPORT_MAX_GAP_S = 5.0  # an autopilot's wind report older than this is not the wind now (analysis: 1 Hz streams)
SOURCE_CALM = "assumed calm"
SOURCE_ESTIMATE = "flighttest estimate"

__all__ = ["WIND_COVERAGE_SIGMAS", "LogWind", "airborne_mask", "apply", "resolve"]


@dataclass
class LogWind:
    """The wind of one log, per state sample: NED m/s (n, 3) and its horizontal 1 σ (n,; NaN: unknown)."""

    source: str  # "logged: operator", "autopilot: WIND_COV", "flighttest estimate", "assumed calm", ...
    detail: str  # one line: where it came from and how sure it is
    ned_mps: np.ndarray
    sd_mps: np.ndarray
    notes: list[str] = field(default_factory=list)
    # the gusts' 1 σ the live guard allowed an updraft for (guard.csv ``gust_sd_mps``; zero where not logged)
    gust_sd_mps: np.ndarray | None = None

    @property
    def measured(self) -> bool:
        return self.source != SOURCE_CALM

    def over(self, sel: np.ndarray | None = None) -> dict[str, Any]:
        """``wind_ned_mps`` (the mean over the samples ``sel``), ``wind_sd_mps`` (the RMS of their 1 σ),
        ``wind_source``; the whole log when ``sel`` is None."""
        w = self.ned_mps if sel is None else self.ned_mps[sel]
        sd = self.sd_mps if sel is None else self.sd_mps[sel]
        ok = np.isfinite(w).all(axis=1)
        mean = [round(float(x), 3) for x in w[ok].mean(axis=0)] if ok.any() else [None, None, None]
        sd_ok = sd[np.isfinite(sd)]
        rms = round(float(np.sqrt(np.mean(sd_ok**2))), 3) if len(sd_ok) and ok.any() else None
        return {"wind_ned_mps": mean, "wind_sd_mps": rms, "wind_source": self.source}

    def describe(self, sel: np.ndarray | None = None) -> str:
        """``(wn, we, wd) m/s ± sd (source)`` in words."""
        o = self.over(sel)
        if o["wind_ned_mps"][0] is None:
            return f"unknown ({self.source})"
        n, e, d = o["wind_ned_mps"]
        speed = math.hypot(n, e)
        sd = f" ± {o['wind_sd_mps']:.2f}" if o["wind_sd_mps"] is not None else ""
        return f"{speed:.2f} m/s{sd} (N {n:+.2f}, E {e:+.2f}, D {d:+.2f}; {self.source})"


# -- where the vehicle is in the air ----------------------------------------------------------------
def airborne_mask(state: pd.DataFrame) -> np.ndarray:
    """Samples with the vehicle in the air: not reported on the ground (``landed`` 1 or disarmed) and at
    least ``AIRBORNE_MIN_HEIGHT_M`` above the ground: the median height while it was reported there (an
    estimator drifts on the ground by up to a metre), else home (the state's height, once
    :func:`flighttest.analysis.pipeline.prepare_state` has arbitrated it, is metres above home)."""
    n = len(state)
    h = -state["d_m"].to_numpy(float)
    landed = state["landed"].to_numpy(float) if "landed" in state else np.full(n, np.nan)
    armed = state["armed"].to_numpy(float) if "armed" in state else np.full(n, np.nan)
    ground_said = (landed == 1) | (armed == 0)
    fin = np.isfinite(h)
    if not fin.any():
        return np.zeros(n, bool)
    rest = ground_said & fin
    ground = float(np.median(h[rest])) if rest.sum() >= 10 else 0.0
    return fin & ~ground_said & (h > ground + AIRBORNE_MIN_HEIGHT_M)


# -- 1. what flighttest flew with ---------------------------------------------------------------------
def _nearest_fill(t: np.ndarray, values: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """``values`` with the rows not ``ok`` taken from the nearest ``ok`` row in time."""
    idx = np.flatnonzero(ok)
    pos = np.clip(np.searchsorted(t[idx], t), 1, len(idx) - 1) if len(idx) > 1 else np.zeros(len(t), int)
    if len(idx) > 1:
        left, right = idx[pos - 1], idx[pos]
        pick = np.where(np.abs(t - t[left]) <= np.abs(t[right] - t), left, right)
    else:
        pick = np.full(len(t), idx[0])
    out = values.copy()
    out[~ok] = values[pick[~ok]]
    return out


def _logged(log: FlightLog) -> LogWind | None:
    """The wind in a folder's ``guard.csv``, when it is a measurement (module docstring, 1.)."""
    g = log.guard
    if g is None or log.source != "flighttest-folder" or not {"t_s", "wn_mps", "we_mps", "wd_mps"} <= set(g):
        return None
    g = g.sort_values("t_s", kind="stable")
    t_g = g["t_s"].to_numpy(float)
    w_g = g[["wn_mps", "we_mps", "wd_mps"]].to_numpy(float)
    has_source = "wind_source" in g
    src = g["wind_source"].astype("string").fillna("").to_numpy(object) if has_source else None
    if has_source:
        measured = np.isin(src, ["", SOURCE_CALM], invert=True) & np.isfinite(w_g).all(axis=1)
    else:
        measured = np.isfinite(w_g).all(axis=1) & (w_g != 0.0).any(axis=1)
    if not measured.any() or (not has_source and not (w_g[measured] != 0.0).any()):
        return None
    sd_g = g["wind_sd_mps"].to_numpy(float) if "wind_sd_mps" in g else np.full(len(g), np.nan)
    sd_g = np.where(np.isfinite(sd_g) & (sd_g >= 0), sd_g, REPORT_SD_UNKNOWN_MPS)
    t = log.state["t_s"].to_numpy(float)
    tm = t_g[measured]
    wi = resample(tm, w_g[measured], t, LOGGED_MAX_GAP_S)
    si = resample(tm, sd_g[measured], t, LOGGED_MAX_GAP_S)
    gap = ~np.isfinite(wi).all(axis=1)
    if gap.all():
        return None  # no row near the telemetry: a guard.csv of another clock, not this flight's wind
    if gap.any():
        wi = _nearest_fill(t, wi, ~gap)
        si = np.where(gap, np.maximum(_nearest_fill(t, si, ~gap), REPORT_SD_UNKNOWN_MPS), si)
    if has_source:
        names = pd.Series(src[measured]).value_counts()
        source = "logged: " + "/".join(names.index)
        share = f"{measured.mean():.0%} of guard.csv's rows" + (
            f"; the {int((~measured).sum())} rows it judged in assumed calm take the nearest measured wind"
            if (~measured).any() else "")  # fmt: skip
    else:
        source, share = "logged (source not recorded)", "guard.csv of a folder written before wind_source"
    gust = None
    if "gust_sd_mps" in g:
        gg = g["gust_sd_mps"].to_numpy(float)
        ok = np.isfinite(gg)
        if ok.any():
            gust = np.nan_to_num(resample(t_g[ok], gg[ok], t, LOGGED_MAX_GAP_S), nan=0.0)
    return LogWind(source, f"the wind flighttest's guard flew with ({share})", wi, si, gust_sd_mps=gust)


# -- 2. the autopilot's own estimate ---------------------------------------------------------------
def _reported(log: FlightLog) -> tuple[LogWind | None, list[str]]:
    rep = log.wind_reported
    if rep is None:
        return None, []
    if not rep.estimating:
        return None, [f"the autopilot's wind ({rep.name}) is exact zeros throughout: its estimator did not "
                      "estimate the wind (a default multicopter setup), not a calm"]  # fmt: skip
    t = log.state["t_s"].to_numpy(float)
    ok = np.isfinite(rep.ned_mps).all(axis=1)
    sd = np.where(np.isfinite(rep.sd_mps), rep.sd_mps, REPORT_SD_UNKNOWN_MPS)
    wi = resample(rep.t_s[ok], rep.ned_mps[ok], t, REPORT_MAX_GAP_S)
    si = resample(rep.t_s[ok], sd[ok], t, REPORT_MAX_GAP_S)
    gap = ~np.isfinite(wi).all(axis=1)
    if gap.all():
        return None, [f"the autopilot's wind ({rep.name}) lies outside the telemetry's time: not used"]
    notes = []
    if gap.any():
        wi = _nearest_fill(t, wi, ~gap)
        si = np.where(gap, np.maximum(_nearest_fill(t, si, ~gap), REPORT_SD_UNKNOWN_MPS), si)
        notes.append(f"the autopilot's wind ({rep.name}) covers {1 - gap.mean():.0%} of the log: the rest takes "
                     "its nearest estimate")  # fmt: skip
    if rep.zero_samples:
        notes.append(f"{rep.zero_samples} {rep.name} sample(s) of exact zeros (no estimate) skipped")
    accuracy = "its own accuracy"
    if not np.isfinite(rep.sd_mps).any():
        accuracy = f"no accuracy given: ± {REPORT_SD_UNKNOWN_MPS:g}"
    return LogWind(f"autopilot: {rep.name}", f"the autopilot's own wind estimate ({rep.name}, {accuracy})", wi, si,
                   notes), []  # fmt: skip


# -- 3. flighttest's estimator ---------------------------------------------------------------------
def _model_sd(drag: DragModel, mass_kg: float, v: np.ndarray, q: np.ndarray, wind: np.ndarray,
              bias_mps2: float) -> np.ndarray:  # fmt: skip
    """``WindFilter.model_sd_mps`` at every step, vectorised: an accelerometer bias seen through the drag's
    weaker slope (and an assumed drag's error on the airspeed)."""
    air = v - wind
    bx, by, _ = ned_to_body(air[:, 0], air[:, 1], air[:, 2], q[:, 0], q[:, 1], q[:, 2], q[:, 3])
    sx, sy = drag.slope_n_per_mps(bx, by)
    return model_sd(drag, np.hypot(air[:, 0], air[:, 1]), bias_mps2, np.minimum(sx, sy) / mass_kg)


def _filter(drag: DragModel, mass_kg: float) -> WindFilter:
    """The log's filter: the accelerometer's bias held (variance 0) and in ``model_sd``, so that the smoother
    below fuses the three states (wn, we, ε) of its two passes."""
    return WindFilter(drag, mass_kg, bias_states=False)


def _steps(state: pd.DataFrame, use: np.ndarray, rate_hz: float) -> pd.DataFrame:
    """The airborne samples averaged over steps of 1/rate_hz: time, velocity, attitude, specific force."""
    cols = ["t_s", "vn_mps", "ve_mps", "vd_mps", "qw", "qx", "qy", "qz", "ax_mps2", "ay_mps2", "az_mps2"]
    s = state.loc[use, cols]
    step = np.floor(s["t_s"].to_numpy(float) * rate_hz).astype(np.int64)
    m = s.groupby(step, sort=True).mean()
    q = m[["qw", "qx", "qy", "qz"]].to_numpy(float)
    m[["qw", "qx", "qy", "qz"]] = q / np.linalg.norm(q, axis=1, keepdims=True)
    return m.reset_index(drop=True)


def _run(f: WindFilter, steps: pd.DataFrame, order: np.ndarray, sign: float, before: bool) -> np.ndarray:
    """Run ``f`` over ``steps`` in ``order`` (time × ``sign``); per step the state (wn, we, ε) and its 3×3
    covariance flattened (9), taken before the step's update (``before``: the backward pass's prediction) or
    after it."""
    # plain Python floats: indexing numpy arrays element by element costs as much as the filter itself
    t = (steps["t_s"].to_numpy(float) * sign).tolist()
    v = list(map(tuple, steps[["vn_mps", "ve_mps", "vd_mps"]].to_numpy(float).tolist()))
    q = list(map(tuple, steps[["qw", "qx", "qy", "qz"]].to_numpy(float).tolist()))
    a = list(map(tuple, steps[["ax_mps2", "ay_mps2", "az_mps2"]].to_numpy(float).tolist()))
    out = [None] * len(t)
    walk = f.process_sd_mps**2
    for k in order.tolist():
        if before:  # WindFilter.predict's random walk, without moving the filter's clock (its noise
            # adaptation measures the time between updates)
            grow = walk * max(t[k] - f.t_s, 0.0) if f.t_s is not None else 0.0
            p = f.p
            out[k] = (f.wn_mps, f.we_mps, f.scale_error, p[0][0] + grow, p[0][1], p[0][2], p[1][0],
                      p[1][1] + grow, p[1][2], *p[2][:3])  # fmt: skip
            f.update(t[k], v[k], q[k], a[k])
        else:
            f.update(t[k], v[k], q[k], a[k])
            out[k] = (f.wn_mps, f.we_mps, f.scale_error, *f.p[0][:3], *f.p[1][:3], *f.p[2][:3])
    return np.asarray(out, float)


def _without_scale(x: np.ndarray) -> np.ndarray:
    """A pass whose scale is held (variance 0) with the scale given unit variance and no correlation: fused
    with another such pass and their unit prior once, the wind fuses as a two-state filter's would."""
    y = x.copy()
    y[:, 2] = 0.0
    y[:, [5, 8, 9, 10]] = 0.0  # P02, P12, P20, P21 of the flattened 3×3 after the state's 3
    y[:, 11] = 1.0  # P22
    return y


def _fuse(fw: np.ndarray, bw: np.ndarray, prior_info: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two Gaussian estimates of (wn, we, ε) (rows: the state, its covariance flattened) fused by their
    information, the prior both started from counted once: the wind's means (n, 2) and its worse axis's
    1 σ (n,). A step whose fused information is not positive definite keeps the forward pass's."""
    pf, pb = fw[:, 3:].reshape(-1, 3, 3), bw[:, 3:].reshape(-1, 3, 3)
    ok = (np.linalg.det(pf) > 0) & (np.linalg.det(pb) > 0)
    eye = np.eye(3)
    i_f = np.linalg.inv(np.where(ok[:, None, None], pf, eye))
    i_b = np.linalg.inv(np.where(ok[:, None, None], pb, eye))
    info = i_f + i_b - prior_info
    ok &= np.linalg.eigvalsh(0.5 * (info + np.transpose(info, (0, 2, 1))))[:, 0] > 0
    cov = np.linalg.inv(np.where(ok[:, None, None], info, eye))
    rhs = np.einsum("nij,nj->ni", i_f, fw[:, :3]) + np.einsum("nij,nj->ni", i_b, bw[:, :3])
    mean = np.einsum("nij,nj->ni", cov, rhs)
    mean = np.where(ok[:, None], mean, fw[:, :3])
    cov = np.where(ok[:, None, None], cov, pf)
    return mean[:, :2], worse_axis_sd(cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1])


def estimate(state: pd.DataFrame, drag: DragModel, mass_kg: float, airborne: np.ndarray,
             rate_hz: float = ESTIMATE_RATE_HZ) -> tuple[np.ndarray, np.ndarray] | None:  # fmt: skip
    """flighttest's estimate of the wind at every state sample, (n, 3) NED and (n,) 1 σ; None when the
    log has too little airborne specific force, attitude and velocity to estimate from."""
    need = ["vn_mps", "ve_mps", "vd_mps", "qw", "qx", "qy", "qz", "ax_mps2", "ay_mps2"]
    use = airborne & np.isfinite(state[need].to_numpy(float)).all(axis=1)
    steps = _steps(state, use, rate_hz) if use.any() else None
    if steps is None or len(steps) < MIN_AIRBORNE_S * rate_hz:
        return None
    n = len(steps)
    fw = _run(_filter(drag, mass_kg), steps, np.arange(n), 1.0, before=False)
    bw = _run(_filter(drag, mass_kg), steps, np.arange(n)[::-1], -1.0, before=True)
    # the common prior both passes start from is the scale's (the wind's own wanders off within seconds); a
    # scale held at 0 (variance 0) is the same in both and fused as known
    scale_var = _filter(drag, mass_kg).p[2][2]
    if scale_var > 0:
        mean, filt_sd = _fuse(fw, bw, np.diag([0.0, 0.0, 1.0 / scale_var]))
    else:
        mean, filt_sd = _fuse(_without_scale(fw), _without_scale(bw), np.diag([0.0, 0.0, 1.0]))
    v = steps[["vn_mps", "ve_mps", "vd_mps"]].to_numpy(float)
    q = steps[["qw", "qx", "qy", "qz"]].to_numpy(float)
    wind3 = np.column_stack([mean, np.zeros(n)])
    sd = np.hypot(filt_sd, _model_sd(drag, mass_kg, v, q, wind3, _filter(drag, mass_kg).accel_bias_mps2))
    t_steps = steps["t_s"].to_numpy(float)
    t = state["t_s"].to_numpy(float)
    ned = np.column_stack([np.interp(t, t_steps, wind3[:, i]) for i in range(3)])
    return ned, np.interp(t, t_steps, sd)


def _drag_for(log: FlightLog, profile, from_meta: bool) -> tuple[DragModel | None, float, str]:
    """The drag model and mass the estimator uses, and where they came from."""
    veh = log.meta.get("vehicle") if isinstance(log.meta, dict) else None
    table = veh.get("drag") if isinstance(veh, dict) else None
    if from_meta and isinstance(table, dict):
        try:
            mass = veh.get("mass_kg")
            mass = float(mass) if isinstance(mass, int | float) and mass > 0 else profile.mass_kg
            return DragModel.from_table(table), mass, "meta.json's vehicle summary"
        except (ValueError, TypeError):
            pass
    return profile.drag, profile.mass_kg, f"profile {profile.name}"


def _estimated(log: FlightLog, profile, from_meta: bool, airborne: np.ndarray) -> tuple[LogWind | None, str]:
    if profile is None:
        return None, "no vehicle profile, so no drag model to estimate it from"
    drag, mass, where = _drag_for(log, profile, from_meta)
    if drag is None:
        return None, f"{where} has no drag model ([drag] or drag_n_per_mps) to estimate it from"
    need = ["vn_mps", "ve_mps", "vd_mps", "qw", "qx", "qy", "qz", "ax_mps2", "ay_mps2"]
    if not set(need) <= set(log.state) or not np.isfinite(log.state[["ax_mps2", "ay_mps2"]].to_numpy(float)).any():
        return None, "the log has no specific force (IMU) to estimate it from"
    if not np.isfinite(log.state["qw"].to_numpy(float)).any():
        return None, "the log has no attitude to estimate it from"
    got = estimate(log.state, drag, mass, airborne)
    if got is None:
        return None, f"less than {MIN_AIRBORNE_S:g} s airborne to estimate it from"
    ned, sd = got
    accel = log.accel_source or "the IMU"
    detail = (f"flighttest's estimator over the log's {accel} specific force, attitude and velocity while airborne, "
              f"drag {drag.source} ±{drag.rel_sd:.0%} ({where}), forward and backward")  # fmt: skip
    return LogWind(SOURCE_ESTIMATE, detail, ned, sd), ""


# -- the choice -------------------------------------------------------------------------------------
def resolve(log: FlightLog, profile=None, drag_from_meta: bool = True) -> LogWind:
    """The wind this log's analysis judges the air with (module docstring: the first source that has it).

    ``profile``: the vehicle's (its drag model and mass for flighttest's estimator; None: no estimate);
    ``drag_from_meta``: a folder's recorded drag model goes first (no profile given explicitly)."""
    n = len(log.state)
    notes: list[str] = []
    logged = _logged(log)
    if logged is not None:
        return logged
    reported, why_not = _reported(log)
    notes += why_not
    if reported is not None:
        reported.notes[:0] = notes
        return reported
    estimated, why_not_est = _estimated(log, profile, drag_from_meta, airborne_mask(log.state))
    if estimated is not None:
        estimated.notes[:0] = notes
        return estimated
    calm = np.zeros((n, 3))
    detail = f"still air assumed: no wind flighttest logged, none from the autopilot, and {why_not_est}"
    return LogWind(SOURCE_CALM, detail, calm, np.full(n, np.nan), notes)


def apply(log: FlightLog, wind: LogWind) -> LogWind:
    """Make ``wind`` the log's (``log.wind``; the state keeps what the log said); ``log.missing`` says
    whether the wind is unknown; returns ``wind``. Applying again replaces it."""
    log.wind = wind
    if wind.measured:
        log.missing.pop("wind", None)
    else:
        why = wind.detail.removeprefix("still air assumed: ")
        log.missing["wind"] = f"wind unknown: exposure computed in still air ({why})"
    return wind


def ensure(log: FlightLog, profile=None, drag_from_meta: bool = True) -> LogWind:
    """``log.wind``, resolved and applied first when it is not yet."""
    if log.wind is None:
        apply(log, resolve(log, profile, drag_from_meta))
    return log.wind
