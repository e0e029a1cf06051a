"""Trajectory files: round trip, resampling, and rejection of malformed or limit-breaking files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from flighttest.errors import FlighttestError
from flighttest.model.profiles import load_profile
from flighttest.model.trajectory import FORMAT, Trajectory


def _traj(rate_hz: float = 50.0, t_f: float = 2.0, accel: float = 2.0) -> Trajectory:
    t = np.arange(0.0, t_f + 1e-9, 1.0 / rate_hz)
    z = np.zeros_like(t)
    phi = 0.2 * np.sin(t)
    return Trajectory.from_arrays(
        {"kind": "vertical", "vehicle": "x500", "problem": {"height_m": 4.0}, "status": "closed_form"},
        t_s=t, n_m=z, e_m=0.5 * t**2, d_m=0.5 * accel * t**2, vn_mps=z, ve_mps=t, vd_mps=accel * t,
        an_mps2=z, ae_mps2=z + 1.0, ad_mps2=z + accel, yaw_deg=z + 10.0,
        qw=np.cos(phi / 2), qx=np.sin(phi / 2), qy=z, qz=z, thrust_n=z + 15.0,
    )  # fmt: skip


def test_round_trip_keeps_values_and_metadata(tmp_path):
    tr = _traj()
    csv_path, json_path = tr.save(tmp_path / "sub" / "descent")
    assert csv_path.name == "descent.csv" and json_path.name == "descent.json"
    for name in ("descent", "descent.csv", "descent.json"):
        back = Trajectory.load(tmp_path / "sub" / name)
        assert list(back.df.columns) == list(tr.df.columns)
        np.testing.assert_allclose(back.df.to_numpy(), tr.df.to_numpy(), rtol=1e-8, atol=1e-9)
        assert back.meta["format"] == FORMAT
        assert back.meta["kind"] == "vertical"
        assert back.meta["t_f_s"] == pytest.approx(2.0)
        assert back.meta["problem"] == {"height_m": 4.0}


def test_resample_hits_rate_and_end_and_interpolates_consistently():
    tr = _traj(rate_hz=10.0)
    rs = tr.resample(50.0)
    t = rs.t_s
    assert t[0] == 0.0 and t[-1] == pytest.approx(2.0)
    np.testing.assert_allclose(np.diff(t), 0.02, atol=1e-9)
    # Quadratic positions are reproduced exactly by the Hermite interpolant with the velocities.
    np.testing.assert_allclose(rs.column("d_m"), t**2, atol=1e-9)
    np.testing.assert_allclose(rs.column("vd_mps"), 2 * t, atol=1e-9)
    q = rs.attitude_quat()
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    assert rs.meta["resampled_hz"] == 50.0
    rs.validate()


def test_resample_rejects_bad_rate():
    with pytest.raises(FlighttestError, match="positive"):
        _traj().resample(0.0)


def _write(tmp_path, tr: Trajectory, edit_csv=None, edit_meta=None):
    csv_path, json_path = tr.save(tmp_path / "t")
    if edit_csv:
        csv_path.write_text(edit_csv(csv_path.read_text()))
    if edit_meta:
        meta = json.loads(json_path.read_text())
        edit_meta(meta)
        json_path.write_text(json.dumps(meta))
    return csv_path


def _replace_cell(text: str, col: str, row: int, value: str) -> str:
    lines = text.splitlines()
    header = lines[0].split(",")
    cells = lines[row + 1].split(",")
    cells[header.index(col)] = value
    lines[row + 1] = ",".join(cells)
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("edit_csv", "edit_meta", "message"),
    [
        (lambda s: _replace_cell(s, "vd_mps", 3, "nan"), None, "non-finite value in column 'vd_mps'"),
        (lambda s: _replace_cell(s, "d_m", 2, "inf"), None, "non-finite"),
        (lambda s: _replace_cell(s, "e_m", 2, "abc"), None, "non-numeric"),
        (lambda s: _replace_cell(s, "t_s", 5, "0.01"), None, "not strictly increasing"),
        (lambda s: s.replace("yaw_deg", "heading"), None, "missing column"),
        (lambda s: _replace_cell(s, "n_m", 0, "3.0"), None, "relative to the start"),
        (lambda s: _replace_cell(s, "qw", 4, "0.5"), None, "not unit length"),
        (lambda s: s.splitlines()[0] + "\n", None, "at least 2 rows"),
        (lambda s: "", None, "malformed"),
        (None, lambda m: m.update(format="other/9"), "unknown format"),
        (None, lambda m: m.pop("kind"), "metadata lacks kind"),
        (None, lambda m: m.update(kind="loop"), "unknown kind"),
    ],
)
def test_malformed_files_are_rejected(tmp_path, edit_csv, edit_meta, message):
    path = _write(tmp_path, _traj(), edit_csv, edit_meta)
    with pytest.raises(FlighttestError, match=message):
        Trajectory.load(path)


def test_broken_json_and_missing_files(tmp_path):
    path = _write(tmp_path, _traj())
    path.with_suffix(".json").write_text("{not json")
    with pytest.raises(FlighttestError, match="malformed trajectory metadata"):
        Trajectory.load(path)
    with pytest.raises(FlighttestError, match="not found"):
        Trajectory.load(tmp_path / "nothing.csv")


def test_limit_breaking_trajectories_are_rejected_with_profile(tmp_path):
    x500 = load_profile("x500")
    ok = _write(tmp_path, _traj())
    Trajectory.load(ok, profile=x500)  # within limits
    cases = [
        (lambda s: _replace_cell(s, "thrust_n", 3, "-2.0"), "below the vehicle minimum"),
        (lambda s: _replace_cell(s, "thrust_n", 3, "80"), "collective thrust 80 N"),
        (lambda s: _replace_cell(_replace_cell(s, "qw", 3, "0.8660254"), "qx", 3, "0.5"), "tilt 60"),
    ]
    for edit, message in cases:
        path = _write(tmp_path, _traj(), edit)
        Trajectory.load(path)  # well formed…
        with pytest.raises(FlighttestError, match=message):  # …but not for this vehicle
            Trajectory.load(path, profile=x500)


def test_tilt_from_acceleration_when_no_attitude(tmp_path):
    t = np.linspace(0, 0.5, 11)
    z = np.zeros_like(t)
    # 20 m/s² sideways at 1 g vertical needs a tilt of atan(20/9.8) ≈ 64°, beyond the x500's 45°.
    tr = Trajectory.from_arrays(
        {"kind": "probe", "vehicle": "x500", "problem": {}, "status": "closed_form"},
        t_s=t, n_m=10.0 * t**2, e_m=z, d_m=z, vn_mps=20.0 * t, ve_mps=z, vd_mps=z, an_mps2=z + 20.0, ae_mps2=z,
        ad_mps2=z,
        yaw_deg=z,
    )  # fmt: skip
    with pytest.raises(FlighttestError, match=r"tilt|thrust"):
        tr.validate(load_profile("x500"))


def test_sample_times_never_print_two_rows_at_one_time(tmp_path):
    # the campaign's vertical on the ArduCopter fake (w_allow 0.55 identified, cruise 0.1 m/s): its cruise
    # ended at 50.000000001 s beside the grid's 50.0, and the saved file could not be loaded again
    from flighttest.model.profiles import load_profile
    from flighttest.model.trajectory import SAMPLE_MIN_GAP_FRACTION, sample_times
    from flighttest.planner.export import vertical_trajectory
    from flighttest.planner.vertical import plan_vertical

    t = sample_times(50.000000001, 100.0, (1.0 / 9.0, 50.000000001))
    assert t[0] == 0.0 and 50.000000001 in t and np.diff(t).min() >= SAMPLE_MIN_GAP_FRACTION / 100.0
    # two boundaries 1e-13 s apart (a jerk-limited ramp that never reaches its acceleration) are one
    t = sample_times(1.0, 100.0, (0.3152260000001, 0.315226, 0.5))
    assert np.diff(t).min() >= SAMPLE_MIN_GAP_FRACTION / 100.0 and np.sum(np.abs(t - 0.315226) < 1e-9) == 1
    ac = load_profile("arducopter_sitl")
    vp = plan_vertical(ac, height_m=5.0, w_allow_mps=0.5499999999999998, margin_mps=0.44999999999999996,
                       accel_fraction=0.15)  # fmt: skip
    traj = vertical_trajectory(vp, ac.name, ac.mass_kg)
    traj.save(tmp_path / "vertical.csv")
    again = Trajectory.load(tmp_path / "vertical.csv")
    assert again.duration_s == pytest.approx(vp.t_f_s)
    # the x500's at the mission's jerk, whose ramps never reach their acceleration (the fast lane's first catch)
    x500 = load_profile("x500")
    vp = plan_vertical(x500, height_m=120.0, margin_mps=0.45, accel_fraction=0.15, jerk_mps3=4.0)
    vertical_trajectory(vp, x500.name, x500.mass_kg).save(tmp_path / "v120.csv")
    assert Trajectory.load(tmp_path / "v120.csv").duration_s == pytest.approx(vp.t_f_s)
