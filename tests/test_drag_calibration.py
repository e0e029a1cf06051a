"""The drag calibration (issue 21): its flight plan, and the drag identified from what the IMU feels along
it — linear and quadratic per body axis, the wind found with them, the uncertainty stated, implausible logs
refused — on synthetic samples of a vehicle whose drag and wind the test knows."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from flighttest.analysis.drag import NoDrag, identify_drag
from flighttest.analysis.schema import FlightLog
from flighttest.model.drag import DragModel
from flighttest.model.frames import ned_to_body, quat_from_euler
from flighttest.model.profiles import load_profile, write_drag
from flighttest.planner.calibration import CalibrationPlan, calibration_trajectory

X500 = load_profile("x500")


def calibration_log(drag: DragModel, wind=(0.6, -1.2, 0.0), noise=0.15, speeds=(1.0, 2.0, 3.0), seed=1) -> FlightLog:
    """The calibration flown perfectly, the vehicle tilted as its thrust needs, the IMU feeling ``drag``."""
    traj = calibration_trajectory(CalibrationPlan(speeds), "x500", 10.0)
    df = traj.df
    rng = np.random.default_rng(seed)
    m = X500.mass_kg
    v = df[["vn_mps", "ve_mps", "vd_mps"]].to_numpy()
    a = df[["an_mps2", "ae_mps2", "ad_mps2"]].to_numpy()
    w = np.asarray(wind)
    # the tilt the thrust needs against the acceleration and the drag (small-angle, for realism only)
    roll = np.radians(np.clip(a[:, 1] * 4.0, -20, 20))
    pitch = np.radians(np.clip(-a[:, 0] * 4.0, -20, 20))
    q = np.array([quat_from_euler(r, p, 0.0) for r, p in zip(roll, pitch)])
    bx, by, _ = ned_to_body(*(v - w).T, *q.T)
    fx, fy = drag.force_n(bx, by)
    t = df["t_s"].to_numpy()
    state = pd.DataFrame({"t_s": t, "vn_mps": v[:, 0], "ve_mps": v[:, 1], "vd_mps": v[:, 2], "qw": q[:, 0],
                          "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3], "ax_mps2": fx / m + rng.normal(0, noise, len(t)),
                          "ay_mps2": fy / m + rng.normal(0, noise, len(t)), "az_mps2": -9.80665 + 0 * t})  # fmt: skip
    events = [{"event": "stream_start", "t_s": 0.0}, {"event": "stream_end", "t_s": float(t[-1])}]
    return FlightLog(Path("calibration"), "flighttest-folder", state, events=events)


def test_the_plan_flies_each_speed_both_ways_along_both_axes_within_the_geofence():
    traj = calibration_trajectory(CalibrationPlan((1.0, 2.0, 3.0)), "x500", 10.0)
    df = traj.df
    assert df[["n_m", "e_m"]].abs().max().max() == pytest.approx(6.0, abs=0.01)  # (9/1.5 + 6)/2
    for col in ("vn_mps", "ve_mps"):
        for v in (1.0, 2.0, 3.0):
            assert (np.isclose(df[col], v).sum() > 50) and (np.isclose(df[col], -v).sum() > 50)
    assert df.iloc[-1][["n_m", "e_m", "vn_mps", "ve_mps"]].abs().max() < 1e-9  # home, at rest
    with pytest.raises(Exception, match="geofence"):
        calibration_trajectory(CalibrationPlan((1.0, 5.0)), "x500", 10.0)


@pytest.mark.parametrize("truth", [DragModel((0.9, 1.1), (0.0, 0.0)), DragModel((0.6, 0.6), (0.12, 0.08))])
def test_the_drag_and_the_wind_are_identified_within_the_stated_uncertainty(truth):
    r = identify_drag(calibration_log(truth), X500)
    m = r.model
    for v in (1.0, 2.0, 3.0):
        for axis in (0, 1):
            f_true = truth.linear_n_per_mps[axis] * v + truth.quadratic_n_per_mps2[axis] * v * v
            f_est = m.linear_n_per_mps[axis] * v + m.quadratic_n_per_mps2[axis] * v * v
            assert abs(f_est - f_true) <= 2.5 * m.rel_sd * f_true + 1e-3
    assert 0.03 <= m.rel_sd < 0.15
    assert math.hypot(r.wind_ned_mps[0] - 0.6, r.wind_ned_mps[1] + 1.2) < 0.15
    assert m.source.startswith("identified from calibration")


def test_a_single_speed_or_noise_alone_is_refused():
    with pytest.raises(NoDrag, match="more than one speed"):  # a creep at 0.4 m/s spans too little air
        identify_drag(calibration_log(DragModel((0.9, 0.9)), speeds=(0.4,), wind=(0, 0, 0)), X500)
    with pytest.raises(NoDrag, match="known only to"):
        identify_drag(calibration_log(DragModel((0.1, 0.1)), noise=2.0), X500)  # ±49 %
    with pytest.raises(NoDrag, match="below what the IMU can tell"):
        identify_drag(calibration_log(DragModel((0.001, 0.001)), noise=0.001), X500)


def test_an_identified_drag_is_stored_in_the_users_copy_and_read_back(tmp_path):
    r = identify_drag(calibration_log(DragModel((0.9, 1.1))), X500)
    path = write_drag(X500, r.model, tmp_path / "x500.toml")
    back = load_profile(path)
    assert back.drag == r.model and back.drag.rel_sd == r.model.rel_sd
    assert back.drag_n_per_mps == pytest.approx(r.model.mean_linear_n_per_mps(), abs=1e-4)
