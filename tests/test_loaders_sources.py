"""Every loader reports every height source, the attitude source, the parameters and the boot clock.

Synthetic logs with the faults of issue 14 (an estimator height that sits metres below home, an
estimator excursion below the ground at the landing, a DataFlash log without ATT) are checked
against the known truth of :class:`SyntheticFlight`; the reference logs of real PX4 and ArduPilot
SITL flights in ``../shared`` are checked for the sources they carry and for a shared boot clock.
"""

from __future__ import annotations

import json
import lzma
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from flighttest.analysis.loaders import dataflash, load_log
from flighttest.analysis.schema import FlightLog, pressure_altitude_m
from synthetic import (
    ARDUPILOT_PARAMS,
    DF_RECORDS,
    HOME_AMSL_M,
    PX4_PARAMS,
    TLOG_ALL_STREAMS,
    ULOG_TOPICS,
    SyntheticFlight,
    isa_pressure_pa,
    write_dataflash,
    write_tlog,
    write_ulog,
)

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
PX4_FLIGHT = SHARED / "px4_sih" / "vertical-3m-completed"
AP_FLIGHT = SHARED / "ardupilot_sitl" / "vertical-guard-abort"

# take off from home to 10 m, land at 15..20 s; the estimator sits 4 m below the truth at the start,
# 12 m at the end, and dips 7.5 m further below (and back) at the landing
FAULTY = SyntheticFlight(
    duration_s=30.0,
    start_alt_m=0.0,
    descents=[(3.0, -10.0, 4.0), (15.0, 10.0, 5.0)],
    ekf_offset_m=(4.0, 12.0),
    ekf_excursion=(19.0, 3.0, 7.5),
)
NO_ATT = tuple(r for r in DF_RECORDS if r != "ATT")


def _tlog(p: Path) -> Path:
    return write_tlog(FAULTY, p / "f.tlog", streams=TLOG_ALL_STREAMS)


def _tlog_ardupilot_global(p: Path) -> Path:
    """ArduCopter 3.x style: position only as GLOBAL_POSITION_INT, Euler ATTITUDE, float params."""
    streams = ("global", "att_euler", "heartbeat", "baro", "gps", "params")
    return write_tlog(FAULTY, p / "g.tlog", streams=streams, autopilot="ardupilot")


def _ulog(p: Path) -> Path:
    return write_ulog(FAULTY, p / "f.ulg", topics=(*ULOG_TOPICS, "distance_sensor"))


def _ulog_old(p: Path) -> Path:
    """sensor_baro instead of vehicle_air_data, the pre-1.14 GPS topic (alt in mm)."""
    topics = (*(t for t in ULOG_TOPICS if t != "vehicle_air_data"), "sensor_baro")
    return write_ulog(FAULTY, p / "o.ulg", topics=topics, old_gps=True)


def _bin(p: Path) -> Path:
    return write_dataflash(FAULTY, p / "f.bin", records=(*DF_RECORDS, "XKF1", "RFND"))


def _bin_no_att(p: Path) -> Path:
    """The issue's .BIN: no ATT, but AHR2 and the EKF quaternion XKQ; position from POS."""
    return write_dataflash(FAULTY, p / "n.bin", records=(*NO_ATT, "AHR2", "XKQ"))


# case: (writer, boot clock at flight t = 0, height sources in order, attitude source, params source, params)
CASES = {
    "tlog": (
        _tlog,
        5.0,
        [
            "LOCAL_POSITION_NED.z",
            "GLOBAL_POSITION_INT.relative_alt",
            "ALTITUDE.altitude_monotonic",
            "SCALED_PRESSURE.press_abs",
            "GPS_RAW_INT.alt",
            "DISTANCE_SENSOR.current_distance",
        ],
        "ATTITUDE_QUATERNION",
        "tlog PARAM_VALUE",
        PX4_PARAMS,
    ),
    "tlog-ardupilot-global": (
        _tlog_ardupilot_global,
        5.0,
        ["GLOBAL_POSITION_INT.relative_alt", "SCALED_PRESSURE.press_abs", "GPS_RAW_INT.alt"],
        "ATTITUDE",
        "tlog PARAM_VALUE",
        ARDUPILOT_PARAMS,
    ),
    "ulog": (
        _ulog,
        5.0,
        [
            "vehicle_local_position.z",
            "vehicle_global_position.alt",
            "vehicle_air_data.baro_alt_meter",
            "vehicle_gps_position.altitude_msl_m",
            "distance_sensor.current_distance",
        ],
        "vehicle_attitude",
        "ulog",
        PX4_PARAMS,
    ),
    "ulog-old": (
        _ulog_old,
        5.0,
        ["vehicle_local_position.z", "vehicle_global_position.alt", "sensor_baro.pressure", "vehicle_gps_position.alt"],
        "vehicle_attitude",
        "ulog",
        PX4_PARAMS,
    ),
    "dataflash": (
        _bin,
        20.0,
        ["XKF1.PD", "POS.RelHomeAlt", "POS.Alt", "CTUN.Alt", "BARO.Alt", "GPS.Alt", "RFND.Dist"],
        "ATT",
        "dataflash PARM",
        ARDUPILOT_PARAMS,
    ),
    "dataflash-no-att": (
        _bin_no_att,
        20.0,
        ["POS.RelHomeAlt", "POS.Alt", "CTUN.Alt", "BARO.Alt", "GPS.Alt"],
        "AHR2",
        "dataflash PARM",
        ARDUPILOT_PARAMS,
    ),
}

# what each source reads minus the true height above home: (datum, carries the estimator's fault, tolerance)
DATUM = {
    "estimator_home": (0.0, True, 0.02),
    "estimator_amsl": (HOME_AMSL_M, True, 0.02),
    "baro_amsl": (HOME_AMSL_M, False, FAULTY.baro_noise_m + 0.01),  # ISA pressure altitude
    "baro_home": (0.0, False, FAULTY.baro_noise_m + 0.01),  # ArduPilot: m above its ground calibration
    "gps": (HOME_AMSL_M, False, FAULTY.gps_noise_m + 0.01),
    "rangefinder": (0.0, False, 0.02),
}


def _datum(name: str, kind: str, home_relative: bool) -> str:
    if kind == "estimator":
        return "estimator_home" if home_relative else "estimator_amsl"
    if kind == "baro":
        return "baro_home" if name == "BARO.Alt" else "baro_amsl"
    return kind


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    """Each case written and loaded once per module, on first use."""
    cache: dict[str, FlightLog] = {}
    root = tmp_path_factory.mktemp("sources")

    def get(case: str) -> FlightLog:
        if case not in cache:
            cache[case] = load_log(CASES[case][0](root))
        return cache[case]

    return get


@pytest.mark.parametrize("case", list(CASES))
def test_height_sources_names_signs_units_clock(logs, case):
    _, boot0, names, *_ = CASES[case]
    log = logs(case)
    assert [h.name for h in log.heights] == names
    first = log.heights[0]
    assert first.kind == "estimator" and first.home_relative
    s = log.state
    # the first source is the one the state's d_m came from, on the state's clock
    assert np.interp(s["t_s"], first.t_s, first.alt_m) == pytest.approx(-s["d_m"].to_numpy(), abs=0.02)
    # state t_s = 0 is boot_s[0]; the flight's own time is boot_s − boot0
    offset_s = s["boot_s"].iloc[0] - boot0
    for h in log.heights:
        t = h.t_s + offset_s
        datum, faulty, tol = DATUM[_datum(h.name, h.kind, h.home_relative)]
        expect = FAULTY.true_alt_m(t) + datum - (FAULTY.estimator_error(t)[0] if faulty else 0.0)
        assert np.all(np.isfinite(h.alt_m)) and np.all(np.diff(h.t_s) > 0), h.name
        assert np.abs(h.alt_m - expect).max() < tol, h.name
        assert h.t_s[0] < 1.0 or h.kind == "rangefinder", h.name  # every stream from the start


@pytest.mark.parametrize("case", list(CASES))
def test_faults_show_in_the_estimator_not_in_the_barometer(logs, case):
    """The estimator sits 4 m below home at take-off, 12 m after landing, and dips ~7.5 m further at
    the landing; the barometer and GPS read home height on the ground (relative to their datum)."""
    log = logs(case)
    est = log.heights[0]
    baro = next(h for h in log.heights if h.kind == "baro")
    gps = next(h for h in log.heights if h.kind == "gps")
    assert est.alt_m[0] == pytest.approx(-4.0, abs=0.05)
    assert est.alt_m[-1] == pytest.approx(-12.0, abs=0.05)
    mid = np.argmin(np.abs(est.t_s + log.state["boot_s"].iloc[0] - CASES[case][1] - 20.5))  # the dip's middle
    assert est.alt_m[mid] == pytest.approx(-(4.0 + 8.0 * 20.5 / 30.0) - 7.5, abs=0.05)
    for h in (baro, gps):
        rise = h.alt_m - np.median(h.alt_m[h.t_s < 2.5])
        assert rise[-20:] == pytest.approx(0.0, abs=0.5), h.name  # back at home height
        assert rise.min() > -0.5 and rise.max() == pytest.approx(10.0, abs=0.5), h.name
    assert gps.alt_m.min() > 400  # the no-fix first GPS sample is dropped


@pytest.mark.parametrize("case", list(CASES))
def test_attitude_source_params_and_boot_clock(logs, case):
    _, boot0, _, attitude, params_source, params = CASES[case]
    log = logs(case)
    assert log.attitude_source == attitude
    assert "attitude" not in log.missing
    s = log.state
    # level, yaw 30°: q = (cos 15°, 0, 0, sin 15°), whatever the source
    assert s["qw"].median() == pytest.approx(math.cos(math.radians(15)), abs=2e-3)
    assert s["qz"].median() == pytest.approx(math.sin(math.radians(15)), abs=2e-3)
    assert log.params_source == params_source
    assert log.params == {k: float(v) for k, v in params.items()}  # ints exact, 0.95 not 0.949999988
    boot = s["boot_s"].to_numpy()
    assert np.all(np.isfinite(boot)) and np.all(np.diff(boot) > 0)
    assert boot - boot[0] == pytest.approx(s["t_s"].to_numpy(), abs=1e-6)
    assert boot[0] == pytest.approx(boot0, abs=0.01)


def test_tlog_boot_clock_and_wall_clock_both_kept(logs):
    s = logs("tlog").state
    assert s["boot_s"].iloc[0] == pytest.approx(5.0)
    assert s["unix_s"].iloc[0] - s["boot_s"].iloc[0] == pytest.approx(1_767_225_600.0 - 5.0, abs=0.005)


@pytest.mark.parametrize(("extra", "source"), [(("AHR2",), "AHR2"), (("XKQ",), "XKQ"), ((), None)])
def test_dataflash_attitude_fallbacks_ahr2_and_xkq(tmp_path, extra, source):
    flight = SyntheticFlight(duration_s=8.0, descents=[(2.0, 5.0, 2.5)])
    log = load_log(write_dataflash(flight, tmp_path / "a.bin", records=(*NO_ATT, *extra)))
    assert log.attitude_source == source
    if source is None:
        assert "attitude" in log.missing  # only when no source exists
    else:
        assert "attitude" not in log.missing
        assert log.state["qz"].median() == pytest.approx(math.sin(math.radians(15)), abs=2e-3)  # core 0, not 1


def test_instance_zero_only_and_filters(logs):
    """The writers add a wrong second barometer / EKF core and a forward-looking rangefinder."""
    log = logs("dataflash")
    baro = next(h for h in log.heights if h.name == "BARO.Alt")
    assert baro.alt_m.max() < 11.0  # the I = 1 barometer reads 30 m more
    assert log.state["d_m"].max() < 20  # XKF1 core 1 sits 50 m lower
    rng = next(h for h in logs("tlog").heights if h.kind == "rangefinder")
    assert rng.alt_m.max() < 10.1 and rng.alt_m.min() > 0.2  # not the forward sensor (5 m), no min/max readings


def test_pressure_altitude_inverts_the_standard_atmosphere():
    h = np.array([0.0, 488.0, 2000.0])
    assert pressure_altitude_m(isa_pressure_pa(h)) == pytest.approx(h, abs=1e-6)
    assert pressure_altitude_m(np.array([101_325.0]))[0] == pytest.approx(0.0)


def test_folder_params_priority(tmp_path):
    folder = tmp_path / "flight"
    folder.mkdir()
    write_tlog(FAULTY, folder / "flight.tlog", streams=("pos", "heartbeat", "params"))
    log = load_log(folder)
    assert log.params_source == "tlog PARAM_VALUE" and log.params["NAV_RCL_ACT"] == 2
    (folder / "preflight.json").write_text(json.dumps({"ok": True, "params": {"COM_OF_LOSS_T": 1.0, "X": None}}))
    log = load_log(folder)
    assert (log.params_source, log.params) == ("preflight.json", {"COM_OF_LOSS_T": 1.0})
    (folder / "params.json").write_text(json.dumps({"params": {"MPC_XY_P": 0.95, "COM_OBL_RC_ACT": 0}}))
    log = load_log(folder)
    assert (log.params_source, log.params) == ("params.json", {"COM_OBL_RC_ACT": 0.0, "MPC_XY_P": 0.95})
    assert [h.name for h in log.heights] == ["LOCAL_POSITION_NED.z"] and log.attitude_source is None


# -- the reference logs of real firmware --------------------------------------------------------------

needs_px4 = pytest.mark.skipif(not (PX4_FLIGHT / "px4.ulg.xz").is_file(), reason=f"no reference logs in {PX4_FLIGHT}")
needs_ap = pytest.mark.skipif(
    not (AP_FLIGHT / "arducopter.bin.xz").is_file(), reason=f"no reference logs in {AP_FLIGHT}"
)


def _unxz(src: Path, dst: Path) -> Path:
    with lzma.open(src) as fin, open(dst, "wb") as fout:
        shutil.copyfileobj(fin, fout, 1 << 20)
    return dst


@pytest.fixture(scope="module")
def px4_ulog(tmp_path_factory) -> FlightLog:
    return load_log(_unxz(PX4_FLIGHT / "px4.ulg.xz", tmp_path_factory.mktemp("px4") / "px4.ulg"))


@pytest.fixture(scope="module")
def ap_bin(tmp_path_factory) -> Path:
    return _unxz(AP_FLIGHT / "arducopter.bin.xz", tmp_path_factory.mktemp("ap") / "arducopter.bin")


@pytest.fixture(scope="module")
def ap_log(ap_bin) -> FlightLog:
    return load_log(ap_bin)


def _same_boot_clock(a: FlightLog, b: FlightLog, tol_m: float) -> None:
    """Two logs of one flight: at the same autopilot boot time the estimator gives the same height."""
    sa, sb = a.state, b.state
    inside = (sa["boot_s"] > sb["boot_s"].min()) & (sa["boot_s"] < sb["boot_s"].max())
    assert inside.mean() > 0.5
    d_b = np.interp(sa["boot_s"][inside], sb["boot_s"], sb["d_m"])
    assert np.abs(d_b - sa["d_m"][inside]).max() < tol_m


def _climb_m(h) -> float:
    return float(np.max(h.alt_m) - np.median(h.alt_m[:5]))


@needs_px4
def test_px4_reference_folder_and_ulog(px4_ulog):
    folder = load_log(PX4_FLIGHT)
    assert [h.name for h in folder.heights] == [
        "LOCAL_POSITION_NED.z",
        "GLOBAL_POSITION_INT.relative_alt",
        "ALTITUDE.altitude_monotonic",
        "SCALED_PRESSURE.press_abs",
        "GPS_RAW_INT.alt",
        "DISTANCE_SENSOR.current_distance",
    ]
    assert [h.name for h in px4_ulog.heights] == [
        "vehicle_local_position.z",
        "vehicle_global_position.alt",
        "vehicle_air_data.baro_alt_meter",
        "vehicle_gps_position.altitude_msl_m",
        "distance_sensor.current_distance",
    ]
    assert (folder.attitude_source, px4_ulog.attitude_source) == ("ATTITUDE_QUATERNION", "vehicle_attitude")
    assert folder.params_source == "preflight.json" and folder.params["MPC_Z_VEL_MAX_DN"] == 1.5
    assert px4_ulog.params_source == "ulog" and len(px4_ulog.params) > 500
    p = px4_ulog.params
    assert (p["MPC_Z_VEL_MAX_DN"], p["MPC_XY_P"], p["MC_ROLL_P"], p["COM_OBL_RC_ACT"]) == (1.5, 0.95, 4.0, 0.0)
    _same_boot_clock(folder, px4_ulog, tol_m=0.01)
    for log in (folder, px4_ulog):  # the ~5 m climb shows in every source (SIH: no real faults)
        for h in log.heights:
            if h.kind != "rangefinder":
                assert _climb_m(h) == pytest.approx(_climb_m(log.heights[0]), abs=1.0), h.name


@needs_ap
def test_ardupilot_reference_bin_and_folder(ap_log):
    log = ap_log
    assert [h.name for h in log.heights] == ["XKF1.PD", "POS.RelHomeAlt", "POS.Alt", "CTUN.Alt", "BARO.Alt", "GPS.Alt"]
    assert log.attitude_source == "ATT"
    assert log.params_source == "dataflash PARM" and len(log.params) > 1000
    assert log.params["ATC_ANG_RLL_P"] == 4.5 and log.params["GUID_TIMEOUT"] == 3.0
    for h in log.heights:
        assert _climb_m(h) == pytest.approx(5.0, abs=0.3), h.name
    folder = load_log(AP_FLIGHT)
    assert [h.name for h in folder.heights] == ["LOCAL_POSITION_NED.z", "GPS_RAW_INT.alt"]
    assert folder.params_source == "tlog PARAM_VALUE" and folder.params["STAT_FLTCNT"] == 1.0  # ArduPilot: cast
    _same_boot_clock(folder, log, tol_m=0.02)


@needs_ap
@pytest.mark.parametrize("source", ["AHR2", "XKQ"])
def test_ardupilot_reference_bin_without_att(ap_bin, ap_log, monkeypatch, source):
    """The real .bin read as if ATT were not logged: AHR2, or XKQ, give the same attitude."""
    monkeypatch.setattr(dataflash, "ATTITUDE_RECORDS", (source,))
    log = load_log(ap_bin)
    assert log.attitude_source == source and "attitude" not in log.missing
    q, q0 = log.state[["qw", "qx", "qy", "qz"]].to_numpy(), ap_log.state[["qw", "qx", "qy", "qz"]].to_numpy()
    ok = np.isfinite(q).all(axis=1) & np.isfinite(q0).all(axis=1)
    angle_deg = np.degrees(2 * np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", q[ok], q0[ok])), 0, 1)))
    assert ok.mean() > 0.9 and np.median(angle_deg) < 3.0


# -- the land detector (state column "landed"), a ground witness for the height arbitration ----------


def test_tlog_landed_state_from_extended_sys_state(tmp_path):
    """1 on the ground before take-off (3 s) and after the landing (20 s), 0 in the air; absent: NaN."""
    state = load_log(_tlog(tmp_path)).state
    t, landed = state["t_s"].to_numpy(), state["landed"].to_numpy()
    assert (landed[(t > 0.1) & (t < 2.5)] == 1).all() and (landed[(t > 4.0) & (t < 19.5)] == 0).all()
    assert (landed[t > 21.5] == 1).all()
    assert load_log(_tlog_ardupilot_global(tmp_path)).state["landed"].isna().all()


def _landed_changes(log: FlightLog) -> list[tuple[float, float]]:
    """(t_s, value) of the land detector's first known value and of every change after it."""
    t, landed = log.state["t_s"].to_numpy(), log.state["landed"].to_numpy()
    known = np.flatnonzero(np.isfinite(landed))
    k = known[np.concatenate([[True], landed[known][1:] != landed[known][:-1]])]
    return [(float(t[i]), float(landed[i])) for i in k]


@needs_px4
def test_px4_land_detector_in_ulog_and_tlog(px4_ulog):
    """vehicle_land_detected.landed and EXTENDED_SYS_STATE: in the air between arming and disarming."""
    for log in (px4_ulog, load_log(PX4_FLIGHT)):
        changes = _landed_changes(log)
        assert [v for _, v in changes] == [1.0, 0.0, 1.0], changes
        armed = log.state["armed"].to_numpy() == 1
        t = log.state["t_s"].to_numpy()
        assert t[armed].min() < changes[1][0] and changes[2][0] < t[armed].max()


@needs_ap
def test_ardupilot_land_detector_from_ev_records(ap_log):
    """DataFlash EV 28 (NOT_LANDED) then 18 (LAND_COMPLETE): the take-off and the touch-down (the log
    starts at arming, before the detector's first change)."""
    assert [v for _, v in _landed_changes(ap_log)] == [0.0, 1.0]
