"""The wind every analysis judges the air with (issue 21 item 6, ``flighttest.analysis.wind``), on synthetic
logs of every format: the loaders read the autopilot's wind where it estimated one (``WIND_COV`` with its
accuracy, ArduPilot's ``WIND`` — the direction the wind comes *from* —, the ulog's ``wind`` topic with its
variances, DataFlash ``XKF2``) and not where it sent exact zeros; a folder's ``guard.csv`` wind comes first
with its own source; otherwise flighttest's estimator over the log's own IMU, attitude and velocity; the
exposure is air-relative with it, beside the worst air within its uncertainty; ``identify`` says the wind
its probe was flown in, and refuses one flown in more wind than it can correct for.

The synthetic vehicle's IMU feels a linear drag of 0.5 /s (1 N per m/s on x500's 2 kg), level; these tests
fly it as an x500 whose drag is that, measured to ±5 %, from a user profile folder, so the estimator finds the
wind it flew in and says it knows it to about 5 % of the airspeed."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from flighttest.analysis import wind as wind_mod
from flighttest.analysis.exposure import velocity_track
from flighttest.analysis.identify import (
    IdentifyConfig,
    ProbeWind,
    WindyProbe,
    identify_onset,
    onera_entry_n,
    windy,
)
from flighttest.analysis.loaders import load_log
from flighttest.analysis.pipeline import analyse
from flighttest.cli import main
from flighttest.errors import FlighttestError
from flighttest.flying.wind import REPORT_SD_UNKNOWN_MPS, WIND_COVERAGE_SIGMAS
from flighttest.model.drag import DragModel
from flighttest.model.frames import quat_from_euler
from flighttest.model.profiles import SHIPPED_DIR, load_profile
from flighttest.model.wind_estimate import WindFilter
from synthetic import (
    TLOG_STREAMS,
    ULOG_TOPICS,
    UNIX0,
    SyntheticFlight,
    write_dataflash,
    write_tlog,
    write_ulog,
)


@pytest.fixture(autouse=True)
def x500_with_the_synthetic_drag(tmp_path_factory, monkeypatch):
    """The shipped x500 with its [drag] replaced by the synthetic IMU's, measured to ±5 % (user folders shadow
    shipped profiles, as an operator's would)."""
    d = tmp_path_factory.mktemp("vehicles")
    text = (SHIPPED_DIR / "x500.toml").read_text()
    head, rest = text.split("\n[drag]", 1)
    tail = rest[rest.index("[vrs]"):]
    head = "\n".join(ln for ln in head.splitlines() if not ln.startswith("drag_n_per_mps"))
    drag = 'linear_n_per_mps = 1.0\nrel_sd = 0.05\nsource = "the synthetic IMU\'s"\n'
    (d / "x500.toml").write_text(f"{head}\ndrag_n_per_mps = 1.0\n\n[drag]\n{drag}\n{tail}")
    monkeypatch.setenv("FLIGHTTEST_VEHICLES", str(d))
    assert load_profile("x500").drag.rel_sd == 0.05


EAST3 = (0.0, 3.0, 0.0)  # the air moves east at 3 m/s, as in ../shared/wind_sitl
FAST = IdentifyConfig(n_boot=3)


def hover_flight(wind=EAST3, **kw) -> SyntheticFlight:
    """Take off from the ground, hover at 10 m, a 5 m descent, land: the shape of a real flight."""
    return SyntheticFlight(duration_s=40.0, start_alt_m=0.0, wind_ned_mps=wind,
                           descents=[(3.0, -10.0, 5.0), (18.0, 5.0, 3.0), (30.0, 5.0, 4.0)], **kw)  # fmt: skip


def _wind_error(a, truth) -> float:
    """The largest horizontal error of the analysis' wind over the samples airborne."""
    air = wind_mod.airborne_mask(a.log.state)
    err = a.log.wind.ned_mps[air, :2] - np.asarray(truth[:2])
    return float(np.hypot(err[:, 0], err[:, 1]).max())


# -- the autopilot's own estimate, where it made one ----------------------------------------------
def test_wind_cov_is_the_autopilots_estimate_with_its_accuracy(tmp_path):
    log = load_log(write_tlog(hover_flight(wind_report_sd_mps=0.4), tmp_path / "w.tlog"))
    assert log.wind_reported.name == "WIND_COV" and log.wind_reported.estimating
    assert "wind" not in log.missing
    a = analyse(log, "x500")
    s = a.summary()
    assert s["wind_source"] == "autopilot: WIND_COV"
    assert s["wind_ned_mps"] == pytest.approx(list(EAST3), abs=1e-3)
    assert s["wind_sd_mps"] == pytest.approx(0.4, abs=1e-3)
    d = s["descents"][0]
    assert d["wind_ned_mps"] == pytest.approx(list(EAST3), abs=1e-3) and d["wind_source"] == "autopilot: WIND_COV"


def test_a_wind_cov_of_exact_zeros_is_no_estimate_and_flighttest_estimates_the_wind(tmp_path):
    log = load_log(write_tlog(hover_flight(wind_reported=False), tmp_path / "z.tlog"))
    assert log.wind_reported.name == "WIND_COV" and not log.wind_reported.estimating
    assert log.state["wn_mps"].isna().all()  # the state never takes zeros for a calm
    assert "wind" in log.missing
    a = analyse(log, "x500")
    s = a.summary()
    assert s["wind_source"] == "flighttest estimate" and "HIGHRES_IMU" in s["wind_detail"]
    assert _wind_error(a, EAST3) < 0.1
    # the drag is known to ±5 %: 3 m/s of air known to about 5 % of it, and the summary says so
    assert 0.1 < s["wind_sd_mps"] < 0.4
    assert "wind" not in a.log.missing and any("exact zeros" in n for n in a.notes)


def test_ardupilots_wind_gives_the_direction_it_comes_from(tmp_path):
    f = hover_flight(wind=(-2.0, 1.0, 0.0))
    streams = (*[s for s in TLOG_STREAMS if s != "wind"], "wind_ardupilot")
    log = load_log(write_tlog(f, tmp_path / "apm.tlog", autopilot="ardupilot", streams=streams))
    assert log.wind_reported.name == "WIND"
    a = analyse(log, "x500")
    assert a.summary()["wind_source"] == "autopilot: WIND"
    assert a.log.wind.ned_mps[100] == pytest.approx([-2.0, 1.0, 0.0], abs=0.01)
    assert a.log.wind.sd_mps[100] == REPORT_SD_UNKNOWN_MPS  # WIND gives no accuracy


@pytest.mark.parametrize("reported", [True, False])
def test_the_ulog_wind_topic(tmp_path, reported):
    f = hover_flight(wind_reported=reported, wind_report_sd_mps=0.3)
    log = load_log(write_ulog(f, tmp_path / "w.ulg", topics=(*ULOG_TOPICS, "wind")))
    assert log.wind_reported.name == "wind" and log.wind_reported.estimating == reported
    assert log.accel_source == "sensor_combined"
    a = analyse(log, "x500")
    s = a.summary()
    if reported:
        assert s["wind_source"] == "autopilot: wind" and s["wind_sd_mps"] == pytest.approx(0.3, abs=1e-3)
    else:
        assert s["wind_source"] == "flighttest estimate"
    assert _wind_error(a, EAST3) < 0.1


@pytest.mark.parametrize("reported", [True, False])
def test_dataflash_xkf2(tmp_path, reported):
    f = hover_flight(wind_reported=reported)
    log = load_log(write_dataflash(f, tmp_path / "w.bin", records=("ATT", "XKF1", "XKF2", "IMU", "BARO", "PARM")))
    assert log.wind_reported.name == "XKF2" and log.wind_reported.estimating == reported
    a = analyse(log, "x500")
    assert a.summary()["wind_source"] == ("autopilot: XKF2" if reported else "flighttest estimate")
    assert _wind_error(a, EAST3) < 0.15  # instance 0, not the wrong core 1


def test_nothing_to_estimate_from_is_still_air_and_said(tmp_path):
    log = load_log(write_tlog(hover_flight(wind_reported=False), tmp_path / "n.tlog",
                              streams=("pos", "att", "heartbeat", "wind")))  # fmt: skip
    a = analyse(log, "x500")
    s = a.summary()
    assert s["wind_source"] == "assumed calm" and s["wind_sd_mps"] is None
    assert "specific force" in a.log.missing["wind"] and "still air" in a.log.missing["wind"]
    assert math.isnan(a.descents.iloc[0]["time_inside_worst_s"])  # no worst case without an uncertainty


# -- what flighttest flew with ----------------------------------------------------------------------
def _folder(d: Path, flight: SyntheticFlight, guard: pd.DataFrame | None, vehicle: dict | None = None) -> Path:
    d.mkdir(parents=True)
    write_tlog(flight, d / "flight.tlog")
    (d / "meta.json").write_text(json.dumps({"mission": "vertical", "start_unix_s": UNIX0,
                                             "vehicle": vehicle or {"name": "x500"}}))  # fmt: skip
    if guard is not None:
        guard.to_csv(d / "guard.csv", index=False)
    return d


def _guard(wind, sd=None, source=None, n=2000) -> pd.DataFrame:
    t = np.arange(n) * 0.02
    g = {"t_s": t, "unix_s": UNIX0 + t, "verdict": "ok", "margin_mps": 1.0,
         "wn_mps": wind[0], "we_mps": wind[1], "wd_mps": wind[2]}  # fmt: skip
    if source is not None:
        g.update(wind_sd_mps=sd, wind_source=source)
    return pd.DataFrame(g)


def test_the_wind_flighttest_flew_with_comes_first(tmp_path):
    # the guard judged with the operator's 2 m/s north (1 σ 0.5); the autopilot's WIND_COV is in the tlog too
    d = _folder(tmp_path / "f", hover_flight(), _guard((2.0, 0.0, 0.0), 0.5, "operator"))
    a = analyse(load_log(d))
    s = a.summary()
    assert s["wind_source"] == "logged: operator"
    assert s["wind_ned_mps"] == pytest.approx([2.0, 0.0, 0.0], abs=1e-3) and s["wind_sd_mps"] == pytest.approx(0.5)


def test_rows_the_guard_judged_in_assumed_calm_take_the_nearest_measured_wind(tmp_path):
    g = _guard((0.0, 3.0, 0.0), 0.3, "autopilot")
    calm = g["t_s"] > 30.0
    g.loc[calm, ["wn_mps", "we_mps", "wd_mps"]] = 0.0
    g.loc[calm, "wind_source"] = "assumed calm"
    a = analyse(load_log(_folder(tmp_path / "f", hover_flight(), g)))
    assert a.log.wind.source == "logged: autopilot"
    late = a.log.state["t_s"].to_numpy() > 35.0
    assert a.log.wind.ned_mps[late, 1] == pytest.approx(3.0)
    assert (a.log.wind.sd_mps[late] >= REPORT_SD_UNKNOWN_MPS).all()


@pytest.mark.parametrize("source", ["assumed calm", None])
def test_a_folder_that_assumed_calm_is_no_measurement(tmp_path, source):
    # the guard's wind all 0: "assumed calm", or an older folder without wind_source (the 20 columns)
    g = _guard((0.0, 0.0, 0.0), 0.0 if source else None, source)
    a = analyse(load_log(_folder(tmp_path / "f", hover_flight(wind_reported=False), g)))
    assert a.summary()["wind_source"] == "flighttest estimate"
    assert _wind_error(a, EAST3) < 0.1


def test_an_older_folder_that_logged_a_wind_has_it_of_unknown_source(tmp_path):
    a = analyse(load_log(_folder(tmp_path / "f", hover_flight(wind_reported=False), _guard((0.0, 3.0, 0.0)))))
    assert a.log.wind.source == "logged (source not recorded)"
    assert a.log.wind.sd_mps[50] == REPORT_SD_UNKNOWN_MPS


def test_the_drag_model_a_folder_recorded_goes_first_unless_a_vehicle_is_given(tmp_path):
    # meta.json's vehicle summary says the drag was known to ±1 % when it flew; the x500 now says ±5 %
    measured = {"name": "x500", "mass_kg": 2.0, "drag": DragModel.isotropic_linear(1.0, 0.01, "measured").to_table()}
    d = _folder(tmp_path / "f", hover_flight(wind_reported=False), None, measured)
    own = analyse(load_log(d)).summary()
    given = analyse(load_log(d), "x500").summary()
    assert "meta.json" in own["wind_detail"] and "profile x500" in given["wind_detail"]
    assert own["wind_sd_mps"] < given["wind_sd_mps"]


# -- exposure in the air ---------------------------------------------------------------------------
def test_a_tailwind_descent_is_judged_in_the_air_not_over_the_ground(tmp_path):
    """Straight down with the air moving at the vehicle's own drift: over the ground it drifts 3 m/s east
    (the cone allows 1.1 m/s down), in the air it hangs still and descends straight through its wake."""
    f = SyntheticFlight(duration_s=25.0, descents=[(10.0, 5.0, 5.0)], east_speed_mps=3.0, wind_ned_mps=EAST3)
    calm_report = analyse(load_log(write_tlog(SyntheticFlight(**{**f.__dict__, "wind_reported": False}),
                                              tmp_path / "e.tlog")), "x500")  # fmt: skip
    d = calm_report.descents.iloc[0]
    assert d["wind_source"] == "flighttest estimate"
    bound = load_profile("x500").w_allow_mps - load_profile("x500").vrs.margin_mps
    peak = math.pi * 5.0 / (2 * 5.0)
    assert d["min_margin_mps"] == pytest.approx(bound - peak, abs=0.05)  # as if still air around it: u ≈ 0
    assert d["time_inside_s"] > 1.0
    # the worst air within the wind's uncertainty is never better than the estimate's
    assert d["time_inside_worst_s"] >= d["time_inside_s"] and d["min_margin_worst_mps"] <= d["min_margin_mps"]


def test_the_worst_air_is_the_guards(tmp_path):
    """A tilted disk: the worst horizontal wind within 2.45 σ raises w by sin(tilt)·radius, lowers u by radius."""
    prof = load_profile("x500")
    n = 5
    q = quat_from_euler(np.full(n, math.radians(20.0)), np.zeros(n), np.zeros(n))
    state = pd.DataFrame({"t_s": np.arange(n) * 0.1, "vn_mps": 0.0, "ve_mps": 1.0, "vd_mps": 0.4,
                          "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3],
                          "wn_mps": np.nan, "we_mps": np.nan, "wd_mps": np.nan})  # fmt: skip
    w = wind_mod.LogWind("test", "", np.zeros((n, 3)), np.full(n, 0.2))
    tr = velocity_track(state, prof, w)
    radius = WIND_COVERAGE_SIGMAS * 0.2
    w_worst = tr["w_mps"] + math.sin(math.radians(20.0)) * radius
    u_worst = np.maximum(tr["u_mps"] - radius, 0.0)
    assert tr["margin_worst_mps"].to_numpy() == pytest.approx(prof.guard_region().margin(w_worst, u_worst).to_numpy())
    assert (tr["margin_worst_mps"] < tr["margin_mps"]).all()


def test_the_smoothed_estimate_states_the_filters_own_uncertainty():
    """The vectorised model term is the filter's ``model_sd_mps`` (one definition, not two; with a linear drag
    the filter's slope, taken before its update, is the same at any wind)."""
    drag = DragModel((0.745, 0.6), (0.0, 0.0), 0.15, "linear")
    f = WindFilter(drag, 3.0)
    q = tuple(quat_from_euler(0.1, -0.05, 0.7))
    f.update(0.0, (1.0, -2.0, 0.3), q, (0.2, -0.4))
    v, qq, w = np.array([[1.0, -2.0, 0.3]]), np.array([q]), np.array([[f.wn_mps, f.we_mps, 0.0]])
    got = wind_mod._model_sd(drag, 3.0, v, qq, w, 0.0)[0]  # the live filter's bias is a state
    assert got == pytest.approx(f.model_sd_mps, rel=1e-9)
    held = WindFilter(drag, 3.0, bias_states=False)  # the log's: the bias held, in the model term
    held.update(0.0, (1.0, -2.0, 0.3), q, (0.2, -0.4))
    w = np.array([[held.wn_mps, held.we_mps, 0.0]])
    got = wind_mod._model_sd(drag, 3.0, v, qq, w, held.accel_bias_mps2)[0]
    assert got == pytest.approx(held.model_sd_mps, rel=1e-9)


def _level_samples(f: WindFilter, t0: float, t1: float, v_ned, wind, rate_hz: float = 50.0) -> None:
    """Level flight at ``v_ned`` in ``wind``: the IMU feels the filter's own drag model of the true airspeed,
    times 1.1 (a drag 10 % above the model)."""
    q = (1.0, 0.0, 0.0, 0.0)
    for t in np.arange(t0, t1, 1.0 / rate_hz):
        fx, fy = f.drag.force_n(v_ned[0] - wind[0], v_ned[1] - wind[1])
        f.update(float(t), (*v_ned, 0.0), q, (1.1 * fx / f.mass_kg, 1.1 * fy / f.mass_kg, -G))


G = 9.80665


def test_the_drags_scale_error_is_a_state_of_the_filter():
    """A drag 10 % stronger than the model: in a 3 m/s hover the wind and the scale cannot be told apart, the
    estimate is off by about 10 % of the airspeed and within what the filter says; a fast leg then (4.5 m/s
    north, as a helix's) tells them apart: the estimate comes closer to the truth instead of taking the leg's
    10 % of 5.4 m/s of air, the scale error is found, and the sd does not grow by rel_sd × the leg's air."""
    drag = DragModel((0.56, 0.58), (0.06, 0.04), 0.08, "identified")
    f = WindFilter(drag, 2.0)
    wind = (0.0, 3.0)
    _level_samples(f, 0.0, 10.0, (0.0, 0.0), wind)
    err_hover = math.hypot(f.wn_mps - wind[0], f.we_mps - wind[1])
    assert 0.1 < err_hover < 0.45  # the scale error the hover cannot see
    assert 2.45 * f.sd_mps >= err_hover  # within what it says
    sd_hover = f.sd_mps
    _level_samples(f, 10.0, 16.0, (4.5, 0.0), wind)  # 4.5 m/s north: 5.4 m/s of air
    err_leg = math.hypot(f.wn_mps - wind[0], f.we_mps - wind[1])
    assert err_leg < err_hover and 2.45 * f.sd_mps >= err_leg
    assert f.scale_error == pytest.approx(0.1, abs=0.03) and f.scale_sd < 0.04
    assert f.sd_mps <= sd_hover


# -- the report, compare and the campaign say it -----------------------------------------------------
def test_compare_and_report_carry_the_wind(tmp_path, capsys):
    a_path = write_tlog(hover_flight(wind_report_sd_mps=0.4), tmp_path / "a.tlog")
    assert main(["compare", str(a_path), str(a_path), "--vehicle", "x500", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert rows[0]["wind_ned_mps"] == pytest.approx(list(EAST3), abs=1e-3)
    assert rows[0]["wind_source"] == "autopilot: WIND_COV" and rows[0]["wind_sd_mps"] == pytest.approx(0.4)
    assert "time_inside_worst_s" in rows[0]
    assert main(["report", str(a_path), "--vehicle", "x500", "-o", str(tmp_path / "rep")]) == 0
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "- wind: **3.00 m/s**" in md and "autopilot: WIND_COV" in md and "inside, worst air s" in md
    assert main(["analyse", str(a_path), "--vehicle", "x500"]) == 0
    out = capsys.readouterr().out
    assert "wind: 3.00 m/s ± 0.40" in out and "from autopilot: WIND_COV" in out


# -- identify says the air its probe was flown in -----------------------------------------------------
STREAM = (8.0, 33.0)


def _probe(d: Path, wind, onset=0.7, amplitude_m=2.0, climb_m=0.0) -> Path:
    """A flighttest probe folder around a synthetic sweep flown in ``wind`` (reported by the autopilot),
    after a climb of ``climb_m`` (identify leaves out the samples within 0.5 m of the lowest)."""
    d.mkdir(parents=True)
    climb = [(1.0, -climb_m, 3.0)] if climb_m else []
    f = SyntheticFlight(duration_s=40.0, descents=climb, probe=(STREAM[0], amplitude_m, 0.02, STREAM[1] - STREAM[0]),
                        onset_mps=onset, wind_ned_mps=wind, wind_report_sd_mps=0.2)  # fmt: skip
    write_tlog(f, d / "flight.tlog", rate_hz=25.0)
    t = np.arange(2.0, 36.0, 0.02)
    phase = np.where(t < 5.0, "climb", np.where(t < STREAM[0], "settle", np.where(t <= STREAM[1], "stream", "settle")))
    pd.DataFrame({"t_s": t, "unix_s": UNIX0 + t, "phase": phase}).to_csv(d / "setpoints.csv", index=False)
    events = [{"t_s": STREAM[0], "unix_s": UNIX0 + STREAM[0], "event": "stream_start"},
              {"t_s": STREAM[1], "unix_s": UNIX0 + STREAM[1], "event": "stream_end", "result": "done"}]  # fmt: skip
    (d / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events))
    (d / "meta.json").write_text(json.dumps({"mission": "probe", "start_unix_s": UNIX0, "vehicle": {"name": "x500"}}))
    return d


def test_identify_says_the_probe_was_flown_in_wind(tmp_path):
    o = identify_onset(load_log(_probe(tmp_path / "p", (1.0, 0.0, 0.0))), load_profile("x500"), FAST)
    s = o.summary()
    assert s["onset_found"] and abs(o.w_onset_mps - 0.7) < 0.05
    assert s["wind_ned_mps"] == pytest.approx([1.0, 0.0, 0.0], abs=1e-3) and s["wind_source"] == "autopilot: WIND_COV"
    assert s["wind_note"].startswith("flown in 1.00 ± 0.20 m/s of wind (autopilot: WIND_COV): the onset found is for "
                                     "that air")  # fmt: skip
    assert s["in_plane_air_mps"] == pytest.approx(1.0, abs=0.05)


def test_a_probe_in_wind_that_never_descended_through_its_disk_is_refused_for_the_wind(tmp_path):
    # PX4 SITL's probe in 3 m/s: stopped before its air-relative descent reached 0.05 m/s; identify says the
    # wind, not "too few descending samples", and the refusal carries no onset (the campaign keeps the prior)
    folder = _probe(tmp_path / "p", (0.0, 3.5, 0.0), amplitude_m=0.005, climb_m=2.0)
    with pytest.raises(WindyProbe, match=r"no onset to find; refused: .*air across the disk") as caught:
        identify_onset(load_log(folder), load_profile("x500"), FAST)
    assert math.isnan(caught.value.w_onset_mps) and not caught.value.agrees_with(0.0)
    assert caught.value.wind["wind_ned_mps"] == pytest.approx([0.0, 3.5, 0.0], abs=1e-3)
    calm = _probe(tmp_path / "c", (0.0, 0.0, 0.0), amplitude_m=0.005, climb_m=2.0)
    with pytest.raises(FlighttestError, match="too few descending samples") as caught:
        identify_onset(load_log(calm), load_profile("x500"), FAST)
    assert not isinstance(caught.value, WindyProbe)


def test_identify_refuses_a_probe_flown_in_more_wind_than_it_can_correct_for(tmp_path, monkeypatch, capsys):
    folder = _probe(tmp_path / "p", (0.0, 3.5, 0.0))
    with pytest.raises(WindyProbe, match="air across the disk moves Onera's VRS entry"):
        identify_onset(load_log(folder), load_profile("x500"), FAST)
    user = tmp_path / "vehicles"
    user.mkdir()
    shutil.copy(SHIPPED_DIR / "x500.toml", user / "x500.toml")
    monkeypatch.setenv("FLIGHTTEST_VEHICLES", str(user))
    before = (user / "x500.toml").read_bytes()
    capsys.readouterr()
    rc = main(["identify", str(folder), "--vehicle", "x500", "--write-profile"])
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and "flown in 3.50" in lines[0] and "nothing stored" in lines[0], err
    assert (user / "x500.toml").read_bytes() == before


def test_the_wind_limits_are_the_identifications_tolerance():
    prof = load_profile("x500")
    # Onera's straight-down entry moves with the in-plane air: 3 % at 1 m/s, 28 % at 3 m/s on a 5.6 m/s v_h
    shift_1 = (onera_entry_n(0.0, prof) - onera_entry_n(1.0 / 5.6, prof)) / onera_entry_n(0.0, prof)
    shift_3 = (onera_entry_n(0.0, prof) - onera_entry_n(3.0 / 5.6, prof)) / onera_entry_n(0.0, prof)
    assert 0.02 < shift_1 < 0.04 and 0.25 < shift_3 < 0.32
    calm_enough = ProbeWind((1.0, 0.0, 0.0), 0.2, "x", 1.0, 0.1, 0.02, 0.02)
    uncertain = ProbeWind((1.0, 0.0, 0.0), 2.0, "x", 1.0, 0.1, 0.2, 0.02)  # sin(tilt)·σ = 0.2 > 25 % of 0.7
    assert windy(calm_enough, 0.7) == []
    assert len(windy(uncertain, 0.7)) == 1 and "uncertain by ±0.200" in windy(uncertain, 0.7)[0]
