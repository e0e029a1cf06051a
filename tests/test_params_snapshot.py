"""The per-flight parameter snapshot: which parameters count, how flights differ, params.json at preflight,
the report's parameter sections and compare's outcome/parameter keys (no flying: the fake is only connected to)."""

from __future__ import annotations

import asyncio
import json
from types import SimpleNamespace

import pandas as pd
import pytest

from flighttest.analysis.compare import add_param_differences, compare_row, flight_outcome
from flighttest.analysis.params import (
    FALLBACK_SOURCE,
    PARAMS_FORMAT,
    PREFLIGHT_SOURCE,
    differences,
    format_value,
    guess_autopilot,
    relevant,
    snapshot,
)
from flighttest.analysis.report import param_differences_section, params_section

PX4 = {
    "MPC_Z_VEL_MAX_DN": 1.5,
    "MPC_XY_VEL_P_ACC": 1.8,
    "MPC_Z_VEL_P_ACC": 4.0,
    "MC_ROLL_P": 6.5,
    "MC_ROLLRATE_P": 0.15,
    "MC_PITCHRATE_MAX": 220.0,
    "COM_OBL_RC_ACT": 5,
    "SYS_AUTOSTART": 4001,
    "BAT1_V_CHARGED": 4.05,
}
ARDUPILOT = {"ATC_RAT_RLL_P": 0.135, "WPNAV_SPEED_DN": 150.0, "WP_SPD_DN": 1.5, "LAND_SPEED": 50, "ARMING_CHECK": 1}


def test_relevant_keeps_the_test_shaping_parameters_sorted():
    rel = relevant(PX4)
    assert list(rel) == sorted(rel)
    assert set(rel) == set(PX4) - {"SYS_AUTOSTART", "BAT1_V_CHARGED"}
    assert set(relevant(ARDUPILOT)) == {"ATC_RAT_RLL_P", "WPNAV_SPEED_DN", "WP_SPD_DN", "LAND_SPEED"}
    assert relevant({**PX4, **ARDUPILOT}, "PX4") == rel  # restricted to one autopilot's patterns
    assert relevant({}) == {} and relevant(None) == {}
    assert guess_autopilot(PX4) == "PX4" and guess_autopilot(ARDUPILOT) == "ArduPilot" and guess_autopilot({}) is None


def test_differences_values_and_missing_names():
    a = {"MPC_Z_VEL_MAX_DN": 1.5, "MC_YAW_P": 2.8, "COM_OBL_RC_ACT": 5}
    b = {"MPC_Z_VEL_MAX_DN": 2.0, "MC_YAW_P": 2.799999952316284, "COM_OBL_RC_ACT": 5, "MPC_LAND_SPEED": 0.7}
    diff = differences([a, b])
    # float32 read back over MAVLink is the same value; a name only one flight has is a difference
    assert diff == {"MPC_LAND_SPEED": [None, 0.7], "MPC_Z_VEL_MAX_DN": [1.5, 2.0]}
    assert list(diff) == sorted(diff)
    # a log without any parameters takes no part (else every parameter would "differ")
    assert differences([a, {}, b]) == {"MPC_LAND_SPEED": [None, None, 0.7], "MPC_Z_VEL_MAX_DN": [1.5, None, 2.0]}
    assert differences([a]) == {} and differences([a, {}]) == {} and differences([]) == {}
    assert differences([a, dict(a)]) == {}


def test_format_value_drops_float32_noise():
    assert [format_value(v) for v in (5, 1.5, 2.799999952316284, 220.0, None, 0.000123)] == [
        "5", "1.5", "2.8", "220", "–", "0.000123",
    ]  # fmt: skip


def test_snapshot_document_full_read_and_fallback():
    all_params = {**PX4, "COM_OF_LOSS_T": 1.0, "MC_YAW_P": 2.799999952316284}
    pre = {"COM_OF_LOSS_T": 1.0, "COM_OBL_RC_ACT": 5, "COM_RC_OVERRIDE": 1, "MPC_Z_VEL_MAX_DN": None}
    doc = snapshot(all_params, pre, "PX4", 1_767_225_600.1234)
    assert doc["format"] == PARAMS_FORMAT and doc["source"] == PREFLIGHT_SOURCE and doc["autopilot"] == "PX4"
    assert doc["unix_s"] == 1_767_225_600.123 and doc["note"] is None and doc["params_read"] == len(all_params)
    p = doc["params"]
    assert "SYS_AUTOSTART" not in p and p["COM_RC_OVERRIDE"] == 1  # relevant ones plus what preflight read
    assert p["MC_YAW_P"] == 2.8 and isinstance(p["COM_OBL_RC_ACT"], int) and list(p) == sorted(p)
    fb = snapshot(None, pre, None, 0.0, note="reading all parameters failed (timeout)")
    assert fb["source"] == FALLBACK_SOURCE and fb["autopilot"] == "PX4" and "timeout" in fb["note"]
    assert fb["params"] == {"COM_OBL_RC_ACT": 5, "COM_OF_LOSS_T": 1.0, "COM_RC_OVERRIDE": 1}


def test_flightlog_writes_params_json(tmp_path):
    from flighttest.flying.log_writer import FlightLogWriter

    log = FlightLogWriter(tmp_path, "probe")
    try:
        path = log.write_params(snapshot(PX4, {}, "PX4", log.unix0))
    finally:
        log.close()
    assert path == log.dir / "params.json" and not list(log.dir.glob("*.tmp"))
    doc = json.loads(path.read_text())
    assert doc["format"] == PARAMS_FORMAT and doc["params"]["MPC_Z_VEL_MAX_DN"] == 1.5


def test_link_reads_all_params_from_the_fake(fake_vehicle_factory):
    """What the preflight does, against the fake's PARAM_REQUEST_LIST answer (connects, does not fly)."""
    from flighttest.flying.link import VehicleLink

    fake = fake_vehicle_factory("x500")

    async def read():
        async with VehicleLink(fake.url, discover_s=0.2, connect_timeout_s=10.0) as link:
            return await link.get_all_params(5.0), await link.autopilot_name()

    params, autopilot = asyncio.run(asyncio.wait_for(read(), 14.0))
    assert autopilot == "PX4"
    assert params["MPC_Z_VEL_MAX_DN"] == pytest.approx(1.5) and params["COM_OBL_RC_ACT"] == 0
    assert isinstance(params["COM_OBL_RC_ACT"], int)
    doc = snapshot(params, {"COM_OF_LOSS_T": 1.0}, autopilot, 0.0)
    assert {"MPC_Z_VEL_MAX_DN", "MPC_TILTMAX_AIR", "COM_OF_LOSS_T", "MC_ROLL_P"} <= set(doc["params"])
    assert "SYS_AUTOSTART" not in doc["params"]


def _analysis(name, params, source="params.json"):
    return SimpleNamespace(log=SimpleNamespace(name=name, params=params, params_source=source))


def test_report_parameter_sections():
    md = "\n".join(params_section([_analysis("a", PX4)]))
    assert "- 1: 7 that shape these tests from params.json" in md and "`MPC_Z_VEL_MAX_DN` | 1.5" in md
    assert "SYS_AUTOSTART" not in md
    rows = [line for line in md.splitlines() if line.startswith("| `")]
    assert len(rows) == 4  # 7 parameters, two pairs per line (80 columns)
    assert "- 1: none in the log" in params_section([_analysis("b", {}, None)])
    other = {**PX4, "MPC_Z_VEL_MAX_DN": 2.0}
    # the report lists the parameters once: those the flights share, then those that differ side by side
    md = "\n".join(params_section([_analysis("a", PX4), _analysis("b", other)]))
    shared, differ = md.split("### Parameters that differ")
    assert "### The same in every flight that carries parameters (6)" in shared and "MPC_Z_VEL_MAX_DN" not in shared
    assert "| `MPC_Z_VEL_MAX_DN` | 1.5 | 2 |" in differ and "MC_ROLL_P" not in differ
    assert all(len(line) <= 80 for line in md.splitlines() if line.startswith("|"))
    md = "\n".join(param_differences_section([_analysis("a", PX4), _analysis("b", other)], ["a", "b"]))
    assert "| `MPC_Z_VEL_MAX_DN` | 1.5 | 2 |" in md and "MC_ROLL_P" not in md
    md = "\n".join(param_differences_section([_analysis("a", PX4), _analysis("b", {})], ["a", "b"]))
    assert "Only 1 of 2 flights carry parameters" in md
    assert "alike" in "\n".join(param_differences_section([_analysis("a", PX4), _analysis("b", PX4)], ["a", "b"]))


def test_compare_rows_outcome_and_param_differences():
    empty = pd.DataFrame()
    meta = {"summary": {"outcome": "aborted"}}
    rows = [
        compare_row("a", empty, [], meta, PX4),
        compare_row("b", empty, [], {}, {**PX4, "MPC_Z_VEL_MAX_DN": 2.0, "MC_YAW_P": 2.8}),
        compare_row("c.tlog", empty, None, {}, {}),
    ]
    add_param_differences(rows)
    assert [r["outcome"] for r in rows] == ["aborted", None, None]
    assert rows[0]["params"] == relevant(PX4)
    assert rows[0]["param_differences"] == {"MC_YAW_P": None, "MPC_Z_VEL_MAX_DN": 1.5}
    assert rows[1]["param_differences"] == {"MC_YAW_P": 2.8, "MPC_Z_VEL_MAX_DN": 2.0}
    assert rows[2]["param_differences"] == {"MC_YAW_P": None, "MPC_Z_VEL_MAX_DN": None}
    assert "outcome" not in compare_row("d", empty) and "params" not in compare_row("d", empty)  # campaign rows
    assert flight_outcome(None) is None and flight_outcome({"summary": {"outcome": ""}}) is None
