"""One log in, the per-descent table out: load → heights → segment → wind → exposure → fluctuation → context.

The height comes first: :func:`flighttest.analysis.heights.arbitrate` checks every height source the
log carries against the ground and each other, and where the state's own estimator cannot be trusted
(or has spans that disagree with the others) :func:`flighttest.analysis.heights.apply` puts the
trusted height into ``state.d_m`` (the original kept as ``d_est_m``/``vd_est_mps``) before the
descents are found, so descents, rates and exposure come from a height that agrees with the ground.
The glitch table joins the segmentation's altitude ``"jump"`` spans and the arbitration's
``"disagreement"`` spans (columns ``segment.GLITCH_COLUMNS``). :func:`prepare_state` is that first
part on its own (heights, descents, glitches), for everything else that needs the trusted height
(:mod:`flighttest.analysis.identify`).

Then the wind: :mod:`flighttest.analysis.wind` chooses the log's (what flighttest flew with, the
autopilot's estimate, flighttest's own estimator over the log, or calm) and puts it into the state, so
the exposure is air-relative; each descent carries the wind it was judged with (``wind_n/e/d_mps``,
``wind_sd_mps``, ``wind_source``), and the summary the log's (``wind_ned_mps``, ``wind_sd_mps``,
``wind_source``, ``wind_detail``) and the exposure over all the time airborne (``airborne_exposure``:
the guard region can be entered outside any descent, as a helix aborted 0.3 s into its descent was).

A flighttest flight's **main descent** is one row whatever phases it crossed: from the stream start
until the end height was reached and settled (:mod:`flighttest.analysis.descent_time`, the rule the
runner timed it with live), or the end of its window (the abort, the landing) when it was not. The
segmentation finds the other descents around it (the landing, the abort ladder's) and never cuts it
(``segment.find_descents``'s ``exclude``). Its figures, with the plan timed by the same rule, are
``Analysis.main`` (``descent_time.MAIN_DESCENT_KEYS``); logs of other programs have the segmentation's
main descent there (``compare.primary_descent``, basis "log segment").

A flight is judged with the vehicle it flew with: its ``meta.json`` vehicle summary (``w_allow``, cone,
margin, v_h) over the profile of that name, unless a profile is given (``--vehicle``) or today's is
asked for (``profile_now``); ``Analysis.judged_with`` says which.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from flighttest.analysis import descent_time as dtime
from flighttest.analysis import plan_track
from flighttest.analysis import wind as wind_mod
from flighttest.analysis.compare import abort_time_s, main_record, no_main_descent_why, primary_descent
from flighttest.analysis.descent_time import TIMED_EVENT, is_abort_phase
from flighttest.analysis.exposure import EXPOSURE_COLUMNS, descent_exposure, exposure_over, velocity_track
from flighttest.analysis.fluctuation import FluctuationConfig, fluctuation
from flighttest.analysis.heights import HeightArbitration, HeightConfig, apply, arbitrate
from flighttest.analysis.loaders import load_log
from flighttest.analysis.params import relevant
from flighttest.analysis.schema import FlightLog
from flighttest.analysis.segment import GLITCH_COLUMNS, SegmentConfig, find_descents
from flighttest.errors import FlighttestError
from flighttest.inputs import display_path
from flighttest.model.profiles import SHIPPED_DIR, VehicleProfile, load_profile, profile_as_flown
from flighttest.planner.optimum import EFFICIENCY_KEYS, efficiency, logged_optimum_s


@dataclass
class Analysis:
    log: FlightLog
    descents: pd.DataFrame
    glitches: pd.DataFrame
    track: pd.DataFrame | None
    fluct: pd.DataFrame
    baselines: dict[str, float]
    profile: VehicleProfile | None
    notes: list[str] = field(default_factory=list)
    heights: HeightArbitration | None = None  # which height the descents were timed on, and why
    airborne: dict | None = None  # exposure over every sample airborne (EXPOSURE_COLUMNS + airborne_s)
    main: dict | None = None  # the main descent (descent_time.MAIN_DESCENT_KEYS), None: the log has none
    main_note: str | None = None  # why there is no main descent (None when there is one)
    judged_with: dict | None = None  # which profile judged the flight (resolve_profile)
    plan: pd.DataFrame | None = None  # the plan on the log's clock (plan_track.plan_on_log)
    tracking: pd.DataFrame | None = None  # flown − planned position over the plan (plan_track.tracking_error)

    def tracking_summary(self) -> dict | None:
        s = plan_track.summarise(self.tracking) if self.tracking is not None and len(self.tracking) else None
        return s.record() if s is not None else None

    @property
    def wind(self) -> wind_mod.LogWind | None:
        return self.log.wind

    def wind_summary(self) -> dict:
        """``wind_ned_mps`` (mean while airborne), ``wind_sd_mps``, ``wind_source``, ``wind_detail``."""
        w = self.log.wind
        if w is None:
            return {"wind_ned_mps": None, "wind_sd_mps": None, "wind_source": None, "wind_detail": None}
        air = wind_mod.airborne_mask(self.log.state)
        return {**w.over(air if air.any() else None), "wind_detail": w.detail}

    def summary(self) -> dict:
        """What ``--json`` prints per log."""
        h = self.heights
        descents = self.descents.drop(columns=["log", "source"], errors="ignore").to_dict("records")
        for d in descents:  # the wind as one vector, as the log's is
            d["wind_ned_mps"] = [d.pop(c, None) for c in DESCENT_WIND[:3]]
        return {
            "log": str(self.log.path),
            "source": self.log.source,
            "vehicle": self.profile.name if self.profile else None,
            "judged_with": self.judged_with,
            "outcome": flight_summary(self.log.meta).get("outcome"),
            "abort_reason": flight_summary(self.log.meta).get("abort_reason"),
            "main_descent": self.main,
            **{k: (self.main or {}).get(k) for k in EFFICIENCY_KEYS},  # hover to hover against the optimum
            "main_descent_note": self.main_note,
            "tracking_error": self.tracking_summary(),
            "duration_s": float(self.log.state["t_s"].iloc[-1]),
            "height_source": h.source if h else None,
            "height_sources": h.records() if h else [],
            "attitude_source": self.log.attitude_source,
            "params": relevant(self.log.params),  # the ones that shape these tests (flighttest.analysis.params)
            "params_source": self.log.params_source,
            **self.wind_summary(),
            "airborne_exposure": self.airborne,
            "descents": descents,
            "glitches": self.glitches.to_dict("records"),
            "missing": self.log.missing,
            "notes": self.notes,
        }


# the wind each descent was judged with: its mean over the descent (and its horizontal speed), the RMS of
# its 1 σ, its source
DESCENT_WIND = ["wind_n_mps", "wind_e_mps", "wind_d_mps", "wind_speed_mps", "wind_sd_mps", "wind_source"]


def descent_wind(wind: wind_mod.LogWind | None, sel: np.ndarray) -> dict:
    """``DESCENT_WIND`` over the samples ``sel``."""
    if wind is None or not sel.any():
        return dict.fromkeys(DESCENT_WIND)
    o = wind.over(sel)
    n, e, d = o["wind_ned_mps"]
    speed = math.hypot(n, e) if n is not None else None
    return dict(zip(DESCENT_WIND, [n, e, d, speed, o["wind_sd_mps"], o["wind_source"]]))


def flight_summary(meta: dict | None) -> dict:
    """A flighttest folder's ``summary.json`` as the loader put it in ``meta`` (``{}`` for other logs)."""
    s = meta.get("summary") if isinstance(meta, dict) else None
    return s if isinstance(s, dict) else {}


JUDGED_FLOWN, JUDGED_NOW, JUDGED_GIVEN = "as flown", "today's profile", "given"


def _judged(profile: VehicleProfile, basis: str, flown_w: float | None) -> dict:
    return {"basis": basis, "vehicle": profile.name, "w_allow_mps": round(profile.w_allow_mps, 4),
            "w_allow_source": profile.w_allow_source, "flown_w_allow_mps": flown_w}  # fmt: skip


def _todays(name: str, flown: dict | None) -> VehicleProfile:
    """The profile the flight was flown with as it is today: the file it was loaded from where that was a
    file of its own (a campaign's copy) and still loads as the same vehicle, else the profile of that name
    (a shipped profile's name finds the user's copy first, where ``identify --write-profile`` writes)."""
    path = flown.get("path") if flown else None
    shipped = isinstance(path, str) and Path(path).resolve().parent == SHIPPED_DIR.resolve()
    if isinstance(path, str) and path.endswith(".toml") and not shipped and Path(path).is_file():
        try:
            prof = load_profile(path)
        except FlighttestError:
            prof = None
        if prof is not None and prof.name == name:
            return prof
    return load_profile(name)


def resolve_profile(
    log: FlightLog, vehicle: str | None, profile_now: bool = False
) -> tuple[VehicleProfile | None, list[str], dict | None]:
    """(profile, notes, judged_with): the one to judge the flight with. ``vehicle`` given: that one
    (basis "given"). Else the log's own (``meta.json``): its vehicle summary over the profile of that
    name, so a profile rewritten since (``identify --write-profile``) does not re-judge the flight
    (basis "as flown"); with ``profile_now``, the profile as it is today (basis "today's profile").
    ``judged_with`` also carries the ``w_allow`` the flight flew with (None when the log does not say)."""
    flown = log.meta.get("vehicle") if isinstance(log.meta.get("vehicle"), dict) else None
    flown_w = flown.get("w_allow_mps") if flown else None
    flown_w = float(flown_w) if isinstance(flown_w, int | float) and math.isfinite(flown_w) else None
    if vehicle:
        prof = load_profile(vehicle)
        return prof, [], _judged(prof, JUDGED_GIVEN, flown_w)
    if not log.vehicle_name:
        return None, ["no vehicle profile (give --vehicle): VRS exposure not computed"], None
    try:
        today = _todays(log.vehicle_name, flown)
    except FlighttestError as exc:
        return None, [f"vehicle from the log unusable ({exc}); exposure needs --vehicle"], None
    if profile_now or flown is None:
        notes = [] if profile_now else ["the log does not say what the vehicle flew with: judged with today's profile"]
        return today, notes, _judged(today, JUDGED_NOW, flown_w)
    try:
        prof = profile_as_flown(today, flown, f"{log.name}/meta.json")
    except FlighttestError as exc:
        return today, [f"judged with today's profile: {exc}"], _judged(today, JUDGED_NOW, flown_w)
    return prof, [], _judged(prof, JUDGED_FLOWN, flown_w)


def _context(log: FlightLog, descents: pd.DataFrame) -> pd.DataFrame:
    """Mission, trajectory and phase of each descent (flighttest folders); what the live guard logged
    inside it: samples it measured inside its region (``margin_mps < 0``) and the actions it took.

    A descent is labelled with the phase at its middle, or at its start when the abort cut it short;
    the main descent with the phase it began in (``stream``: it may end in the ``settle`` after it).
    A descent that starts after the flight's abort began is phase ``"abort"`` unless the log names
    the ladder's phase (``abort_recover|abort_hold|abort_land``: folders written before the ladder
    logged its phases label PX4's Land after an abort ``stream``)."""
    traj = log.meta.get("trajectory_meta", {})
    kind = traj.get("kind") if isinstance(traj, dict) else None
    tpath = log.meta.get("trajectory")
    if isinstance(tpath, dict):
        kind = kind or tpath.get("kind")
        tpath = tpath.get("path")
    descents["mission"] = log.mission_name
    descents["trajectory"] = kind or (Path(tpath).stem if isinstance(tpath, str) else None)
    phases, inside_n, actions = [], [], []
    sp, gd = log.setpoints, log.guard
    phase_events = sorted(
        (e["t_s"], str(e["phase"]))
        for e in log.events
        if e.get("event") == "phase" and isinstance(e.get("t_s"), int | float) and "phase" in e
    )
    t_abort = abort_time_s(log.events)
    for row in descents.itertuples():
        phase = None
        mid = row.start_s if getattr(row, "main", False) else 0.5 * (row.start_s + row.end_s)
        before = [p for t, p in phase_events if t <= mid]
        if before:
            phase = before[-1]
        elif sp is not None and "phase" in sp and "t_s" in sp:
            inside = sp[(sp["t_s"] >= row.start_s) & (sp["t_s"] <= row.end_s)]
            if len(inside):
                phase = str(inside["phase"].mode().iloc[0])
        if t_abort is not None and row.start_s >= t_abort and not is_abort_phase(phase):
            phase = "abort"
        elif is_abort_phase(phase) and (t_abort is None or row.start_s < t_abort):
            # a descent the abort cut short (the probe's loud one) was flown in the phase it began in
            at_start = [p for t, p in phase_events if t <= row.start_s]
            phase = at_start[-1] if at_start else phase
        phases.append(phase)
        if gd is not None and "t_s" in gd and "margin_mps" in gd:
            inside = gd[(gd["t_s"] >= row.start_s) & (gd["t_s"] <= row.end_s)]
            inside_n.append(int((pd.to_numeric(inside["margin_mps"], errors="coerce") < 0).sum()))
            acts = inside["action"].dropna().astype(str) if "action" in inside else pd.Series([], dtype=str)
            acts = sorted(set(acts) - {"", "none", "observe"})
            actions.append(",".join(acts) or None)
        else:
            inside_n.append(None)
            actions.append(None)
    descents["phase"] = phases
    descents["guard_inside_samples"] = inside_n
    descents["guard_actions"] = actions
    return descents


@dataclass
class Prepared:
    """What :func:`prepare_state` found: the height arbitration, the descents timed on the trusted
    height (columns ``segment.DESCENT_COLUMNS``), every glitch span (``segment.GLITCH_COLUMNS``)."""

    heights: HeightArbitration
    descents: pd.DataFrame
    glitches: pd.DataFrame
    notes: list[str] = field(default_factory=list)
    timed: dtime.LogDescent | None = None  # the flight's own descent by the descent-time rule (None: not one)


def prepare_state(log: FlightLog, seg: SegmentConfig | None = None, h_cfg: HeightConfig | None = None) -> Prepared:
    """The height every analysis of a log works on, and the descents on it: the one place the rule
    lives (:func:`analyse` and :mod:`flighttest.analysis.identify` both come through here).

    Arbitrates the log's height sources, puts the trusted height into ``log.state`` (in place:
    ``d_m``/``vd_mps``, the originals kept as ``d_est_m``/``vd_est_mps``), sets ``state.glitch``,
    and finds the descents on it. A height change while the vehicle was disarmed throughout, in a
    log that shows it armed for its flight, is not a descent: PX4's estimator settles by half a
    metre in the first second after boot and drifts on the ground after landing (a ``.ulg`` starts
    at boot, our ``.tlog`` only when flighttest connects, so only one of the two would report it).
    Calling it again on the same log gives the same result (the originals are kept)."""
    seg = seg or SegmentConfig()
    heights = arbitrate(log.state, log.heights, h_cfg)
    apply(log.state, heights, h_cfg)
    timed = dtime.from_log(log)
    flown = timed.flown if timed is not None else None
    # one row for the flight's own descent, unless an abort cut it before it was a descent at all
    main = flown if flown is not None and (flown.reached is not None or flown.height_m >= seg.min_height_m) else None
    window = (main.start_s, main.end_s) if main is not None else None
    descents, jumps = find_descents(log.state, seg, bridged=heights.bridged, source=heights.source, exclude=window)
    descents["main"] = False
    if main is not None:
        descents = _with_main(descents, log.state, main)
    notes = list(heights.notes)
    on_ground = _disarmed_throughout(log.state, descents) & ~descents["main"].to_numpy(bool)
    if on_ground.any():
        descents = descents[~on_ground].reset_index(drop=True)
        descents["descent"] = np.arange(1, len(descents) + 1)
        notes.append(f"{int(on_ground.sum())} height change(s) while disarmed on the ground: not counted as descents")
    if len(jumps):
        notes.append(f"{len(jumps)} estimator glitch(es) flagged (altitude jumps), not counted as descents")
    log.events[:] = [e for e in log.events if e.get("event") != TIMED_EVENT]
    if timed is not None:  # the timing the analysis found, for compare.flown_descent (in memory only)
        log.events.append(dtime.event_of(timed))
    return Prepared(heights, descents, _merge_glitches(jumps, heights.glitches), notes, timed)


def _with_main(descents: pd.DataFrame, state: pd.DataFrame, flown: dtime.FlownDescent) -> pd.DataFrame:
    """``descents`` with the main descent as one more row (``main`` True), in time order, renumbered."""
    t = state["t_s"].to_numpy(float)
    inside = (t >= flown.start_s) & (t <= flown.end_s)
    n, e = state["n_m"].to_numpy(float)[inside], state["e_m"].to_numpy(float)[inside]
    horiz = float(np.nanmax(np.hypot(n - n[0], e - e[0]))) if len(n) else np.nan
    row = {"start_s": flown.start_s, "end_s": flown.end_s, "duration_s": flown.duration_s,
           "height_m": flown.height_m, "start_alt_m": -flown.start_d_m, "end_alt_m": -flown.end_d_m,
           "mean_rate_mps": flown.mean_rate_mps, "max_rate_mps": flown.max_rate_mps,
           "horizontal_excursion_m": horiz,
           "glitch": bool(state["glitch"].to_numpy(bool)[inside].any()) if "glitch" in state else False,
           "settled": flown.reached is not None, "main": True}  # fmt: skip
    out = pd.concat([descents, pd.DataFrame([row])], ignore_index=True) if len(descents) else pd.DataFrame([row])
    out = out.sort_values("start_s", kind="stable").reset_index(drop=True)
    out["descent"] = np.arange(1, len(out) + 1)
    out["main"] = out["main"].astype(bool)
    out["glitch"] = out["glitch"].astype(bool)
    out["settled"] = out["settled"].astype(bool)
    return out


def _disarmed_throughout(state: pd.DataFrame, descents: pd.DataFrame) -> np.ndarray:
    """Per descent: the armed flag reads 0 at every sample of it while the log shows the vehicle armed
    somewhere (a log never seen armed, or without the flag, keeps all its descents)."""
    out = np.zeros(len(descents), dtype=bool)
    armed = state["armed"].to_numpy(float) if "armed" in state else np.empty(0)
    if not len(descents) or not (armed == 1).any():
        return out
    t = state["t_s"].to_numpy(float)
    for k, row in enumerate(descents.itertuples()):
        inside = armed[(t >= row.start_s) & (t <= row.end_s)]
        out[k] = len(inside) > 0 and bool((inside == 0).all())
    return out


def analyse(
    log: FlightLog,
    vehicle: str | None = None,
    seg: SegmentConfig | None = None,
    fl_cfg: FluctuationConfig | None = None,
    h_cfg: HeightConfig | None = None,
    profile_now: bool = False,
) -> Analysis:
    profile, notes, judged = resolve_profile(log, vehicle, profile_now)
    prep = prepare_state(log, seg, h_cfg)
    descents, glitches, heights = prep.descents, prep.glitches, prep.heights
    # the wind after the heights (its estimator needs to know when the vehicle is off the ground); the drag
    # model a folder recorded goes first unless a profile was given explicitly
    wind = wind_mod.apply(log, wind_mod.resolve(log, profile, drag_from_meta=not vehicle))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN windows of absent streams
        fl, baselines = fluctuation(log.state, fl_cfg)
    track = velocity_track(log.state, profile, wind) if profile else None
    t_state = log.state["t_s"].to_numpy(float)
    airborne = None
    if track is not None:
        air = wind_mod.airborne_mask(log.state)
        airborne = {"airborne_s": float(np.sum(np.diff(t_state, append=t_state[-1])[air])),
                    **exposure_over(track, air)}  # fmt: skip
    exp_rows = []
    for row in descents.itertuples():
        exp = (
            descent_exposure(track, row.start_s, row.end_s)
            if track is not None
            else dict.fromkeys(EXPOSURE_COLUMNS, np.nan)
        )
        sel = (fl["t_s"] >= row.start_s) & (fl["t_s"] <= row.end_s)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            exp["fluct_index_max"] = float(np.nanmax(fl.loc[sel, "fluct_index"])) if sel.any() else np.nan
            exp["rate_rms_max_radps"] = float(np.nanmax(fl.loc[sel, "rate_rms_radps"])) if sel.any() else np.nan
        exp.update(descent_wind(wind, (t_state >= row.start_s) & (t_state <= row.end_s)))
        exp_rows.append(exp)
    extra = pd.DataFrame(exp_rows, columns=[*EXPOSURE_COLUMNS, "fluct_index_max", "rate_rms_max_radps", *DESCENT_WIND])
    descents = pd.concat([descents.reset_index(drop=True), extra], axis=1)
    descents = _context(log, descents)
    descents.insert(0, "source", log.source)
    descents.insert(0, "log", display_path(log.path))  # the table's text must be UTF-8 whatever the name
    notes.extend(prep.notes)
    notes.extend(wind.notes)
    main, main_note = _main_descent(log, descents, prep.timed)
    plan = plan_track.plan_on_log(log)
    win = dtime.window(log.events)  # the stream and the settle after it, until an abort or the landing
    tracking = plan_track.tracking_error(log.state, plan, win[1] if win else None) if plan is not None else None
    return Analysis(log, descents, glitches, track, fl, baselines, profile, notes + log.notes, heights, airborne,
                    main, main_note, judged, plan, tracking)  # fmt: skip


def _main_descent(
    log: FlightLog, descents: pd.DataFrame, timed: dtime.LogDescent | None
) -> tuple[dict | None, str | None]:
    """(the main descent's record, why there is none): a flighttest flight's own descent by the
    descent-time rule with its plan timed the same way, else the segmentation's main descent."""
    planned = plan_track.planned(log)
    why = no_main_descent_why(descents, log.events)
    if timed is not None and timed.flown is not None:
        start = next((e for e in log.events if e.get("event") == "stream_start"), {})
        ground = next((e.get("alt_m") for e in log.events if e.get("event") == "ground"), None)
        rec = dtime.main_descent_record(timed.flown, planned, start_unix_s=start.get("unix_s"),
                                        ground_alt_m=ground if isinstance(ground, int | float) else 0.0,
                                        note=timed.why)  # fmt: skip
        if not descents["main"].any():  # cut short by the abort before it was a descent
            rec["note"] = f"{timed.why}; {why}" if why else timed.why
        hover = dtime.from_log(log, dtime.HOVER_RULE)
        reached = hover.reached if hover is not None else None
        rec.update(efficiency(reached.descent_time_s if reached else None, logged_optimum_s(log.meta)))
        return rec, why
    main = primary_descent(descents, log.events)
    if main is None:
        return None, why
    descents.loc[descents["descent"] == main["descent"], "main"] = True
    note = "the trajectory returns to its start: no descent to time" if planned is not None else None
    return main_record(main, planned, note), None


def _merge_glitches(jumps: pd.DataFrame, disagreements: pd.DataFrame) -> pd.DataFrame:
    """One glitch table, in time order: altitude jumps and spans where the height sources disagree."""
    parts = [g for g in (jumps, disagreements) if len(g)]
    if not parts:
        return pd.DataFrame(columns=GLITCH_COLUMNS)
    merged = pd.concat(parts, ignore_index=True) if len(parts) > 1 else parts[0]
    return merged[GLITCH_COLUMNS].sort_values("start_s", kind="stable").reset_index(drop=True)


def analyse_path(
    path: Path | str, vehicle: str | None = None, seg: SegmentConfig | None = None, profile_now: bool = False
) -> Analysis:
    return analyse(load_log(path), vehicle, seg, profile_now=profile_now)
