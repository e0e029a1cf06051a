"""Height-source arbitration on flights built here: the two real ArduCopter faults of issue 14, PX4's
honest drift, a single source, and the invariance of the verdict to a barometer's datum."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from flighttest.analysis.heights import HeightConfig, apply, arbitrate
from flighttest.analysis.pipeline import analyse
from flighttest.analysis.schema import FlightLog, HeightSource, build_state
from flighttest.analysis.segment import GLITCH_COLUMNS, find_descents
from flighttest.errors import FlighttestError

RATE_HZ = 50.0


def profile(t: np.ndarray, moves: list[tuple[float, float, float]]) -> np.ndarray:
    """Up-positive height above home: raised-cosine moves (t0, change in m, duration) from 0 m."""
    h = np.zeros_like(t)
    for t0, dh, dur in moves:
        tau = np.clip(t - t0, 0.0, dur)
        h += dh * (1 - np.cos(np.pi * tau / dur)) / 2
    return h


def state_for(t: np.ndarray, up_m: np.ndarray, armed: np.ndarray) -> pd.DataFrame:
    """A state whose d_m/vd_mps come from the height ``up_m`` (as a loader would build it)."""
    vd = -np.gradient(up_m, t)
    cols = {"n_m": np.zeros_like(t), "e_m": np.zeros_like(t), "d_m": -up_m, "vn_mps": 0 * t, "ve_mps": 0 * t}
    return build_state(t, None, {**cols, "vd_mps": vd, "armed": armed})


def src(name, kind, t, alt, home_relative=False, rate_hz=None):
    """A height stream at its own rate (every ``RATE_HZ / rate_hz``-th sample of the state clock)."""
    step = max(1, round(RATE_HZ / rate_hz)) if rate_hz else 1
    return HeightSource(name, kind, t[::step].copy(), np.asarray(alt, float)[::step].copy(), home_relative)


def truth_descents(t, up_m, armed):
    descents, _ = find_descents(state_for(t, up_m, armed))
    return descents


# the flights: take-off at 10 s, a 6 m step down at 30 s, landing at 45 s (disarmed before 8 s, after 53 s)
T = np.arange(0.0, 60.0, 1 / RATE_HZ)
MOVES = [(10.0, 10.0, 5.0), (30.0, -6.0, 3.0), (45.0, -4.0, 4.0)]
TRUTH = profile(T, MOVES)
ARMED = ((T >= 8.0) & (T <= 53.0)).astype(float)


def assert_same_descents(got, want, height_m=0.1, time_s=0.1):
    assert len(got) == len(want)
    for (_, g), (_, w) in zip(got.iterrows(), want.iterrows()):
        assert g["start_s"] == pytest.approx(w["start_s"], abs=time_s)
        assert g["duration_s"] == pytest.approx(w["duration_s"], abs=time_s)
        assert g["height_m"] == pytest.approx(w["height_m"], abs=height_m)


def bin_case(armed=ARMED):
    """ArduCopter 4.5 .BIN: every EKF height 4 → 12 m below home all flight, on the ground too."""
    offset = 4.0 + 8.0 * T / T[-1]
    ekf = TRUTH - offset
    state = state_for(T, ekf, armed)
    sources = [
        src("CTUN.Alt", "estimator", T, ekf, home_relative=True, rate_hz=10),
        src("POS.RelHomeAlt", "estimator", T, ekf + 0.05, home_relative=True, rate_hz=10),
        src("BARO.Alt", "baro", T, TRUTH + 0.3, rate_hz=10),
    ]
    return state, sources


def tlog_case():
    """ArduCopter 3.4 .tlog: at the hard landing GLOBAL_POSITION_INT runs 7.5 m below home and back."""
    exc = profile(T, [(49.0, -7.5, 1.0), (52.0, 7.5, 2.0)])  # 49–54 s, after touch-down at 49 s
    est = TRUTH + exc
    state = state_for(T, est, ARMED)
    sources = [
        src("GLOBAL_POSITION_INT.relative_alt", "estimator", T, est, home_relative=True, rate_hz=10),
        src("SCALED_PRESSURE", "baro", T, TRUTH + 121.0, rate_hz=10),
    ]
    return state, sources


def px4_case():
    """PX4 as SIH flies it: 0.5 m off in flight, drifting to 1.6 m on the ground after landing; GPS ±2 m."""
    rng = np.random.default_rng(7)
    off = 0.5 * np.sin(np.pi * np.clip(T - 10, 0, 39) / 39) + 1.6 * np.clip((T - 49) / 11, 0, 1)
    est = TRUTH + off
    state = state_for(T, est, ARMED)
    sources = [
        src("vehicle_local_position.z", "estimator", T, est, home_relative=True),
        src("vehicle_air_data.baro_alt_meter", "baro", T, TRUTH + 490.2 + rng.normal(0, 0.1, len(T)), rate_hz=10),
        src("vehicle_gps_position.alt", "gps", T, TRUTH + 489.4 + rng.normal(0, 2.0, len(T)), rate_hz=5),
    ]
    return state, sources


def test_bin_offset_estimator_gives_way_to_the_barometer():
    state, sources = bin_case()
    a = analyse(FlightLog(Path("ekf-offset.bin"), "dataflash", state, heights=sources))
    h = a.heights
    assert h.source == "BARO.Alt" and h.kind == "baro" and not h.is_estimator
    rows = h.sources.set_index("name")
    assert not rows.loc["CTUN.Alt", "consistent"] and not rows.loc["POS.RelHomeAlt", "consistent"]
    # −4.5 m at home before take-off (median over 0–8 s), and a further 7.0 m off after landing
    assert rows.loc["CTUN.Alt", "ground_error_m"] == pytest.approx(7.0, abs=0.1)
    assert "before take-off" in rows.loc["CTUN.Alt", "reason"] and "after landing" in rows.loc["CTUN.Alt", "reason"]
    assert rows.loc["BARO.Alt", "consistent"] and rows.loc["BARO.Alt", "ground_error_m"] < 0.05
    assert_same_descents(a.descents, truth_descents(T, TRUTH, ARMED))
    assert a.descents["start_alt_m"].iloc[0] == pytest.approx(10.0, abs=0.05)  # above home now
    assert "d_est_m" in state and np.allclose(state["d_est_m"], -(TRUTH - 4.0 - 8.0 * T / T[-1]))
    s = a.summary()
    assert s["height_source"] == "BARO.Alt" and len(s["height_sources"]) == 3
    assert set(s["height_sources"][0]) == {
        "name",
        "kind",
        "consistent",
        "ground_error_m",
        "below_ground_m",
        "max_disagreement_m",
        "reason",
    }
    assert any("BARO.Alt" in n for n in a.notes)


def test_bin_case_without_armed_flag_finds_the_ground_from_stillness():
    state, sources = bin_case(armed=np.full(len(T), np.nan))
    h = arbitrate(state, sources)
    assert h.source == "BARO.Alt"
    assert h.ground[T < 9.5].all() and h.ground[T > 50].all() and not h.ground[(T > 10.5) & (T < 48)].any()


def test_tlog_excursion_below_ground_is_a_glitch_not_a_descent():
    state, sources = tlog_case()
    a = analyse(FlightLog(Path("hard-landing.tlog"), "tlog", state, heights=sources))
    h = a.heights
    assert h.source == "GLOBAL_POSITION_INT.relative_alt" and h.is_estimator
    assert h.sources["consistent"].all()
    assert list(a.glitches.columns) == GLITCH_COLUMNS
    dis = a.glitches[a.glitches["kind"] == "disagreement"]
    assert len(dis) == 1
    g = dis.iloc[0]
    assert g["start_s"] == pytest.approx(49.0, abs=0.2) and g["end_s"] == pytest.approx(54.0, abs=0.2)
    assert g["source"] == "GLOBAL_POSITION_INT.relative_alt" and g["max_jump_m"] == pytest.approx(7.5, abs=0.1)
    assert g["sources"]["GLOBAL_POSITION_INT.relative_alt"] == pytest.approx(-7.5, abs=0.1)
    assert g["sources"]["SCALED_PRESSURE"] == pytest.approx(0.0, abs=0.1)
    # the descents are the truth's: nothing starts inside the excursion, the landing is 4 m
    assert_same_descents(a.descents, truth_descents(T, TRUTH, ARMED))
    assert not ((a.descents["start_s"] > 48.5) & (a.descents["start_s"] < 54.5)).any()
    assert a.descents["max_rate_mps"].max() < math.pi * 6 / (2 * 3) + 0.1  # the fake 7.5 m plunge is gone
    assert state["glitch"].to_numpy()[(T > 49.5) & (T < 53.5)].all()
    assert a.summary()["glitches"][0]["kind"] == "disagreement"


def test_px4_drift_is_tolerated_and_changes_nothing():
    state, sources = px4_case()
    before = state.copy()
    h = arbitrate(state, sources)
    assert h.source == "vehicle_local_position.z" and h.is_estimator and not h.changes_state
    assert h.sources["consistent"].all(), h.sources
    assert h.glitches.empty and not h.bridged.any()
    apply(state, h)
    assert state.equals(before)


@pytest.mark.parametrize("referee", [True, False])
def test_a_barometer_dip_is_not_blamed_on_the_estimator_when_gps_or_the_ground_sides_with_it(referee):
    """Mid-flight at 10 m (GPS sides with the estimator) or in ground effect at landing (only the
    barometer goes through the ground): the estimator is kept as it is."""
    rng = np.random.default_rng(3)
    at = 20.0 if referee else 49.5
    baro = TRUTH + profile(T, [(at, -4.0, 0.5), (at + 2.0, 4.0, 0.5)])
    state = state_for(T, TRUTH, ARMED)
    sources = [src("LOCAL_POSITION_NED.z", "estimator", T, TRUTH, home_relative=True), src("baro", "baro", T, baro)]
    if referee:
        sources.append(src("gps", "gps", T, TRUTH + 30 + rng.normal(0, 1.5, len(T)), rate_hz=5))
    h = arbitrate(state, sources)
    assert h.is_estimator and not h.changes_state and h.glitches.empty
    assert any("sided with it" in n for n in h.notes)


def test_nothing_consistent_keeps_the_estimator_and_says_so():
    state, sources = bin_case()
    drifting = TRUTH - 6.0 * np.clip((T - 10) / 40, 0, 1)  # a barometer 6 m off by the landing
    sources = [*sources[:2], src("BARO.Alt", "baro", T, drifting, rate_hz=10)]
    h = arbitrate(state, sources)
    assert h.source == "CTUN.Alt" and h.is_estimator and not h.sources["consistent"].any()
    assert any("no height source is consistent" in n for n in h.notes)


def test_single_source_is_a_no_op_that_names_it():
    state, sources = bin_case()
    before = state.copy()
    h = arbitrate(state, sources[:1])
    assert h.source == "CTUN.Alt" and h.is_estimator and not h.changes_state and h.glitches.empty
    assert not h.sources["consistent"].iloc[0] and any("only height source" in n for n in h.notes)
    a = analyse(FlightLog(Path("x.bin"), "dataflash", state))  # no heights list at all
    assert a.heights.source == "state.d_m" and a.summary()["height_source"] == "state.d_m"
    assert state.drop(columns="glitch").equals(before.drop(columns="glitch", errors="ignore"))


def test_vertical_rate_comes_from_the_trusted_height_when_the_estimators_is_unusable():
    state, sources = bin_case()
    state["vd_mps"] = 0.0  # an estimator that never saw the vehicle move
    h = arbitrate(state, sources)
    assert not h.vd_usable
    apply(state, h)
    mid = np.argmin(np.abs(T - 31.5))
    assert state["vd_mps"].iloc[mid] == pytest.approx(math.pi * 6 / (2 * 3), rel=0.03)
    assert (state["vd_est_mps"] == 0).all()


def test_config_is_validated():
    with pytest.raises(FlighttestError):
        HeightConfig(ground_tol_m=0)
    with pytest.raises(FlighttestError):
        HeightConfig(max_bad_fraction=1.5)


CASES = {"bin": bin_case, "tlog": tlog_case, "px4": px4_case}
_BASE: dict = {}  # case → (state, sources, verdict): built once, the property only shifts the barometer


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(offset_m=st.floats(-2000.0, 2000.0, allow_nan=False), case=st.sampled_from(sorted(CASES)))
def test_baro_datum_never_changes_the_verdict(offset_m, case):
    if case not in _BASE:
        state, sources = CASES[case]()
        _BASE[case] = (state, sources, arbitrate(state, sources))
    state, sources, base = _BASE[case]
    shifted = [
        HeightSource(s.name, s.kind, s.t_s, s.alt_m + offset_m, s.home_relative) if s.kind == "baro" else s
        for s in sources
    ]
    got = arbitrate(state, shifted)
    assert got.source == base.source
    assert list(got.sources["consistent"]) == list(base.sources["consistent"])
    assert len(got.glitches) == len(base.glitches)
    assert np.allclose(got.height_m, base.height_m, atol=1e-6 * max(1.0, abs(offset_m)))


# -- issue 23: independent witnesses only, and the ground outranks an estimator -----------------------

T34 = np.arange(0.0, 150.0, 1 / RATE_HZ)
ARMED34 = (T34 >= 8.0).astype(float)  # armed on the ground after the landing, to the end of the log


def knots(t: np.ndarray, pts: list[tuple[float, float]]) -> np.ndarray:
    """Piecewise-linear through ``pts``, 0 outside them."""
    kt, kv = np.array(pts).T
    return np.where((t >= kt[0]) & (t <= kt[-1]), np.interp(t, kt, kv), 0.0)


def ac34_case(ground_m: float = 0.0, baro_wobble_m: float = 0.0, landed: bool = False):
    """The ArduCopter 3.4 .tlog's hard landing (issue 23) in small: up to 6 m, then down in 2 s at 120 s
    onto ground ``ground_m`` above home (a slope: below it). Both position messages of its one estimator
    run on down to 7.6 m below that ground after the touch-down and come back, the vehicle armed on the
    ground; the GPS altitude sags with them (an estimator fusing GPS vertical velocity drifts with it),
    so a GPS referee sides with the estimator. The barometer wobbles by ``baro_wobble_m`` on the ground
    (prop wash); ``landed``: the state has the land detector's flag."""
    truth = profile(T34, [(10.0, 6.0, 4.0), (120.0, ground_m - 6.0, 2.0)])
    sink = knots(T34, [(120.0, 0.0), (122.0, 0.4), (136.0, 7.6), (139.0, 0.3), (142.0, 0.0)])
    est = truth - sink
    baro = truth + 250.0 + baro_wobble_m * np.sin(2 * np.pi * T34) * (T34 > 122.0)
    rng = np.random.default_rng(34)
    gps = truth - 0.8 * sink + 480.0 + rng.normal(0, 1.0, len(T34))
    state = state_for(T34, est, ARMED34)
    if landed:
        state["landed"] = ((T34 < 10.0) | (T34 > 122.0)).astype(float)
    sources = [
        src("LOCAL_POSITION_NED.z", "estimator", T34, est, home_relative=True, rate_hz=10),
        src("GLOBAL_POSITION_INT.relative_alt", "estimator", T34, est + 0.02, home_relative=True, rate_hz=10),
        src("SCALED_PRESSURE.press_abs", "baro", T34, baro, rate_hz=10),
        src("GPS_RAW_INT.alt", "gps", T34, gps, rate_hz=5),
    ]
    return state, sources


@pytest.mark.parametrize("ground_m", [0.0, -3.0])
def test_estimator_below_the_resting_barometer_is_a_glitch_whatever_the_gps_says(ground_m):
    """The barometer at rest on the ground (at home, or 3 m below it: the lowest level it rests at)
    outranks the estimator and the GPS that sides with it: the excursion is one glitch, bridged, and the
    landing is the barometer's."""
    state, sources = ac34_case(ground_m)
    a = analyse(FlightLog(Path("ac34.tlog"), "tlog", state, heights=sources))
    h = a.heights
    assert h.source == "LOCAL_POSITION_NED.z" and h.is_estimator
    (g,) = a.glitches.itertuples()
    assert g.kind == "disagreement" and g.source == "LOCAL_POSITION_NED.z"
    assert 119.5 < g.start_s < 122.5 and 138.5 < g.end_s < 142.5
    assert g.sources["GLOBAL_POSITION_INT.relative_alt"] == pytest.approx(ground_m - 7.6, abs=0.2)
    assert g.sources["SCALED_PRESSURE.press_abs"] == pytest.approx(ground_m, abs=0.2)
    assert g.sources["GPS_RAW_INT.alt"] < ground_m - 3.0  # the referee went down with the estimator
    assert any("the ground outranks" in n for n in h.notes) and not any("sided with it" in n for n in h.notes)
    landing = a.descents[a.descents["start_s"] > 110.0]
    assert len(landing) == 1 and landing["height_m"].iloc[0] == pytest.approx(6.0 - ground_m, abs=0.3)
    assert landing["duration_s"].iloc[0] < 3.0 and a.descents["height_m"].max() < 6.0 - ground_m + 0.5


@pytest.mark.parametrize("landed", [True, False])
def test_the_land_detector_is_a_ground_witness(landed):
    """On ground 3 m below home with the barometer wobbling in the prop wash, neither the barometer
    (not at rest, and below the 2 m tolerance itself) nor home says where the ground is: only the land
    detector does. Without it the GPS referee, sagging with the estimator, still sides with it."""
    state, sources = ac34_case(ground_m=-3.0, baro_wobble_m=0.6, landed=landed)
    h = arbitrate(state, sources)
    assert h.is_estimator
    if landed:
        assert len(h.glitches) == 1 and h.bridged[(T34 > 125) & (T34 < 137)].all()
        assert any("the ground outranks" in n for n in h.notes)
    else:
        assert h.glitches.empty and any("sided with it" in n for n in h.notes)


def test_one_estimators_two_streams_are_one_vote():
    """Judging the GPS, the estimator's local and global heights count once beside the barometer: its
    7.5 m excursion moves that consensus by half of it, not all of it (a median of three streams, two
    of them the estimator's, would follow the estimator)."""
    state, sources = tlog_case()
    est = sources[0]
    rng = np.random.default_rng(5)
    sources = [
        HeightSource("LOCAL_POSITION_NED.z", "estimator", est.t_s, est.alt_m + 0.01, True),
        est,
        sources[1],
        src("GPS_RAW_INT.alt", "gps", T, TRUTH + 480.0 + rng.normal(0, 0.3, len(T)), rate_hz=5),
    ]
    h = arbitrate(state, sources)
    rows = h.sources.set_index("name")
    assert rows.loc["GPS_RAW_INT.alt", "max_disagreement_m"] == pytest.approx(7.5 / 2, abs=0.8)
    assert rows.loc["GPS_RAW_INT.alt", "consistent"]
