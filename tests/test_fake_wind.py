"""The fake in wind, as the autopilots are: its own drag per airframe (linear as SIH, quadratic as ArduCopter SITL),
steady wind plus Dryden-like turbulence, no wind report unless drag fusion is switched on (then a lagging, noisy
estimate), an IMU that feels the drag, and a truth log with the true air-relative blade-frame velocity.
In fast time (``sitl_fakes.fast``); the MAVLink side is in ``tests/test_fake_wind_flight.py``."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from flighttest.model.aero import G_MPS2
from flighttest.model.frames import blade_velocity_mps
from flighttest.model.profiles import load_profile
from sitl_fakes.drag import TRUTH_DRAG, TruthDrag, estimate_for, parse_truth_drag, truth_drag_for
from sitl_fakes.drag_fusion import DragFusionModel
from sitl_fakes.fast import advance, hover_at, vehicle
from sitl_fakes.physics import QuadBody, rotate_body_to_ned
from sitl_fakes.wind import Wind, dryden_length_scales_m

# ../shared/wind_sitl, holding position ~7 m up before the descent (sitl_fakes/README.md, bench/RESULTS.md):
# PX4 SIH in 3 m/s, ArduCopter SITL in the 1.02 m/s its SIM_WIND_T 0 leaves of 3 m/s at 7 m (3·√(7/60))
SIH_LEAN_DEG, SIH_FY_MPS2 = 17.08, 2.87  # helix flight's hover (the vertical's, accelerating down: 17.60, 2.92)
SITL_WIND_MPS = 3.0 * math.sqrt(7.0 / 60.0)
SITL_LEAN_DEG, SITL_FY_MPS2 = 1.75, 0.28


def tilt_deg(s) -> float:
    return math.degrees(s.tilt_rad())


class Recorder:
    sysid = 1

    def __init__(self):
        self.msgs = []

    def send(self, msg) -> None:
        self.msgs.append(msg)

    def types(self) -> set[str]:
        return {m.get_type() for m in self.msgs}


def hover_stats(v, seconds: float, tail_s: float = 5.0):
    rows = []
    advance(v, seconds, each=lambda v: rows.append((v.now, tilt_deg(v.body.state), v.body.state.fx_mps2,
                                                    v.body.state.fy_mps2, v.body.state.fz_mps2)))  # fmt: skip
    r = np.array(rows)
    return r[r[:, 0] > r[-1, 0] - tail_s]


# -- each airframe's own drag ----------------------------------------------------------------------------


def test_each_profile_has_its_own_truth_drag_not_the_products():
    sih, sitl, x500 = TRUTH_DRAG["sih_quadx"], TRUTH_DRAG["arducopter_sitl"], TRUTH_DRAG["x500"]
    # SIH: SIH_KDV, linear, isotropic, constant
    assert sih.linear_n_per_mps == (1.0, 1.0, 1.0) and sih.quadratic_n_per_mps2 == (0.0, 0.0, 0.0)
    assert not sih.momentum
    # ArduCopter SITL's frame model at CMAC's air density: areaCd 0.174 m², momentum drag 0.724 N/(m/s) at hover
    assert sitl.quadratic_n_per_mps2[0] == pytest.approx(0.101, abs=1e-3) and sitl.momentum
    assert sitl.linear_n_per_mps[0] == pytest.approx(0.724, abs=1e-3)
    # x500: momentum 0.6 N/(m/s) and CdA 0.05 m²
    assert x500.linear_n_per_mps[0] == 0.6 and x500.quadratic_n_per_mps2[0] == pytest.approx(0.5 * 1.225 * 0.05)
    for name in ("mambo", "tunnel_rig"):  # the tabled figures are the geometric estimate's, to 3 digits
        est = estimate_for(load_profile(name))
        assert TRUTH_DRAG[name].linear_n_per_mps[0] == pytest.approx(est.linear_n_per_mps[0], rel=0.01)
        assert TRUTH_DRAG[name].quadratic_n_per_mps2[0] == pytest.approx(est.quadratic_n_per_mps2[0], rel=0.02)
    # the product's numbers are not the fake's: x500's profile has what flighttest identified on the fake
    assert load_profile("x500").drag.linear_n_per_mps[0] != x500.linear_n_per_mps[0]
    # a profile the table does not know gets the estimate, never the profile's drag_n_per_mps
    other = replace(load_profile("x500"), name="someones_quad")
    assert truth_drag_for(other) == estimate_for(other)


def test_truth_drag_option_parses_two_or_six_numbers():
    assert parse_truth_drag("0.5,0.02") == TruthDrag((0.5,) * 3, (0.02,) * 3, False, "--truth-drag 0.5,0.02")
    d = parse_truth_drag("1,2,3,0.1,0.2,0.3")
    assert d.linear_n_per_mps == (1, 2, 3) and d.quadratic_n_per_mps2 == (0.1, 0.2, 0.3) and not d.momentum
    for bad in ("1", "1,2,3", "a,b", "-1,0", "nan,0"):
        with pytest.raises(ValueError):
            parse_truth_drag(bad)


def test_drag_force_per_body_axis_and_its_momentum_scaling():
    prof = load_profile("x500")
    body = QuadBody(prof)
    s = body.state
    s.on_ground, s.d_m = False, -10.0
    hover = prof.mass_kg * G_MPS2 / 4
    s.thrust_n = [hover] * 4
    # level, still, in 3 m/s of wind from the west (blowing east): drag pushes east with 0.6·3 + 0.0306·9
    body.step(1e-6, [hover] * 4, (1.0,) * 4, (0.0, 3.0, 0.0))
    assert s.drag_body_n[1] == pytest.approx(0.6 * 3 + 0.030625 * 9, rel=1e-6)
    assert s.drag_body_n[0] == pytest.approx(0.0, abs=1e-9) and s.drag_body_n[2] == pytest.approx(0.0, abs=1e-9)
    # the IMU feels it: specific force across the thrust axis is the drag over the mass
    assert s.fy_mps2 == pytest.approx(s.drag_body_n[1] / prof.mass_kg)
    # half the thrust on every rotor: the momentum term by √½, the bluff body unchanged
    s.thrust_n = [hover / 2] * 4
    body.step(1e-6, [hover / 2] * 4, (1.0,) * 4, (0.0, 3.0, 0.0))
    assert s.drag_body_n[1] == pytest.approx(0.6 * math.sqrt(0.5) * 3 + 0.030625 * 9, rel=1e-4)
    # SIH's drag is a constant whatever the thrust
    sih = QuadBody(load_profile("sih_quadx"))
    sih.state.on_ground, sih.state.d_m = False, -10.0
    sih.state.thrust_n = [0.5] * 4
    sih.step(1e-6, [0.5] * 4, (1.0,) * 4, (-2.0, 0.0, 0.0))  # the air moves south: it drags the vehicle south
    assert sih.state.drag_body_n[0] == pytest.approx(-2.0, rel=1e-6)


# -- hover in wind, each personality against its reference -----------------------------------------------


def test_sih_quadx_on_px4_leans_into_3_mps_as_sih_does():
    v = hover_at(vehicle("sih_quadx", wind_ned=(0.0, 3.0, 0.0)), (0.0, 0.0, -7.0))
    r = hover_stats(v, 25.0)
    lean, fy = r[:, 1].mean(), r[:, 3].mean()
    # SIH: 3 N of linear drag on 1 kg, atan(3/9.81) = 17.0° in a steady hover (reference 17.08° / 17.60°)
    assert lean == pytest.approx(math.degrees(math.atan(3.0 / G_MPS2)), abs=0.2)
    assert lean == pytest.approx(SIH_LEAN_DEG, abs=0.7)
    assert fy == pytest.approx(SIH_FY_MPS2, abs=0.1)  # leaning west, the air pushes along body +y
    assert abs(r[:, 2].mean()) < 0.02
    # the HIGHRES_IMU it sends carries that specific force, with SIH's noise and the IMU's bias
    imu = np.array([[m.xacc, m.yacc, m.zacc] for m in (v.telemetry.highres_imu() for _ in range(2000))])
    assert imu[:, 1].mean() == pytest.approx(v.body.state.fy_mps2 + v.cfg.imu_bias_mps2[1], abs=0.01)
    assert imu[:, 1].std() == pytest.approx(0.07, abs=0.01)


def test_arducopter_sitl_on_ardupilot_leans_as_sitl_does_in_its_wind():
    v = hover_at(vehicle("arducopter_sitl", "ardupilot", wind_ned=(0.0, SITL_WIND_MPS, 0.0)), (0.0, 0.0, -7.0))
    r = hover_stats(v, 25.0)
    lean, fy = r[:, 1].mean(), r[:, 3].mean()
    # SITL's quad: 0.724·1.02 + 0.101·1.02² = 0.84 N on 3 kg: 1.64° (reference 1.74-1.80°, IMU 0.278-0.280 m/s²)
    assert lean == pytest.approx(SITL_LEAN_DEG, abs=0.2)
    assert fy == pytest.approx(SITL_FY_MPS2, abs=0.02)
    imu = v.telemetry.highres_imu()
    # SITL's accelerometer is clean; the fake's carries a real IMU's bias (sitl_fakes.vehicle.IMU_BIAS_MPS2)
    assert imu.yacc == pytest.approx(fy + v.cfg.imu_bias_mps2[1], abs=0.01)
    # RAW_IMU in milli-g carries it too (ArduPilot's units)
    raw = v.telemetry.raw_imu()
    bias_mg = v.cfg.imu_bias_mps2[1] / G_MPS2 * 1000
    assert raw.yacc == pytest.approx(fy / G_MPS2 * 1000 + bias_mg, abs=2) and raw.zacc == pytest.approx(-1000, abs=5)


def test_in_a_steady_hover_thrust_and_drag_balance_the_weight():
    # whatever the airframe, the specific force in NED is −g straight up: the IMU and the lean agree (not the
    # mambo: the fake's PX4 cascade, SIH's gains, does not hold a 63 g airframe once anything disturbs it)
    for name in ("x500", "tunnel_rig", "sih_quadx"):
        v = hover_at(vehicle(name, wind_ned=(2.0, -1.0, 0.0)), (0.0, 0.0, -5.0))
        advance(v, 20.0)
        s = v.body.state
        fn, fe, fd = rotate_body_to_ned(s.fx_mps2, s.fy_mps2, s.fz_mps2, s.qw, s.qx, s.qy, s.qz)
        assert (fn, fe, fd) == pytest.approx((0.0, 0.0, -G_MPS2), abs=0.02), name
        assert math.hypot(s.n_m, s.e_m) < 0.05, name


# -- no wind report unless drag fusion is on ---------------------------------------------------------------


def streamed(v, seconds: float) -> Recorder:
    rec = Recorder()
    v.link = rec
    t_end = v.now + seconds
    while v.now < t_end:
        advance(v, 0.02)
        v.telemetry.tick(v.now)
    return rec


def test_no_wind_report_by_default_on_either_autopilot():
    px4 = hover_at(vehicle("x500", wind_ned=(0.0, 3.0, 0.0), gust_mps=0.5), (0.0, 0.0, -5.0))
    rec = streamed(px4, 10.0)
    assert "HIGHRES_IMU" in rec.types() and "WIND_COV" not in rec.types()
    assert px4.wind_report() is None and px4.telemetry.wind_cov() is None
    # ArduCopter streams nothing it is not asked for; asked for WIND, its EKF3's inhibited wind states say 0
    ap = hover_at(vehicle("x500", "ardupilot", wind_ned=(0.0, 3.0, 0.0)), (0.0, 0.0, -5.0))
    rec = streamed(ap, 5.0)
    assert "WIND" not in rec.types()
    assert ap.telemetry.set_interval(168, 200_000)[0] == 0
    rec = streamed(ap, 2.0)
    winds = [m for m in rec.msgs if m.get_type() == "WIND"]
    assert len(winds) >= 8 and all(m.speed == 0.0 and m.speed_z == 0.0 for m in winds)


@pytest.mark.parametrize(("name", "autopilot", "params"), [
    ("sih_quadx", "px4", {"EKF2_DRAG_CTRL": 1, "EKF2_MCOEF": 1.0, "EKF2_BCOEF_X": 0.0, "EKF2_BCOEF_Y": 0.0}),
    ("arducopter_sitl", "ardupilot", {"EK3_DRAG_MCOEF": 0.724 / 3.0, "EK3_DRAG_BCOEF_X": 3.0 / 0.174,
                                      "EK3_DRAG_BCOEF_Y": 3.0 / 0.174}),
])  # fmt: skip
def test_with_drag_fusion_on_the_estimate_lags_and_errs(name, autopilot, params):
    # coefficients that fit the airframe: the estimate converges over tens of seconds to a few tenths off
    v = hover_at(vehicle(name, autopilot, wind_ned=(0.0, 3.0, 0.0), params=params, seed=5), (0.0, 0.0, -7.0))
    seen = {}
    for t in (2.0, 5.0, 10.0, 30.0, 60.0, 90.0):
        advance(v, t - v.now)
        msg = v.telemetry.wind_cov() if autopilot == "px4" else v.telemetry.wind()
        assert msg is not None
        seen[t] = (v.wind_report(), msg)
    east = {t: w[0][1] for t, w in seen.items()}
    assert east[2.0] < 1.0 and east[5.0] < 2.2 and east[10.0] < 2.7  # a 10 s lag: far behind at first
    late = [seen[t][0] for t in (30.0, 60.0, 90.0)]
    assert all(math.hypot(w[0], w[1] - 3.0) < 0.8 for w in late)  # then within a few tenths
    assert any(math.hypot(w[0], w[1] - 3.0) > 0.02 for w in late)  # never the truth
    if autopilot == "px4":
        var = {t: m.var_horiz for t, (_, m) in seen.items()}
        # honest: large while converging, the wandering error's 2·0.3² once converged
        assert var[2.0] > 2.0 > var[10.0] > var[90.0] and var[90.0] == pytest.approx(0.18, abs=0.05)
        assert all(m.horiz_accuracy == 0.0 and m.wind_z == 0.0 for _, m in seen.values())  # as PX4 fills it
        assert math.sqrt(var[2.0] / 2) > 0.5 * abs(3.0 - east[2.0])  # it says it does not know yet
    else:
        m = seen[90.0][1]
        assert m.direction == pytest.approx(-90.0, abs=15.0) and m.speed == pytest.approx(3.0, abs=0.8)


def test_px4_defaults_with_drag_fusion_on_a_sih_airframe_overestimate_as_ekf2_would():
    # EKF2_MCOEF 0.15 and EKF2_BCOEF 100 describe a drag far weaker than SIH's 1 N/(m/s) on 1 kg: the drag it
    # measures means a much faster airspeed to that model, and so a much stronger wind
    v = hover_at(vehicle("sih_quadx", wind_ned=(0.0, 3.0, 0.0), params={"EKF2_DRAG_CTRL": 1}), (0.0, 0.0, -7.0))
    advance(v, 90.0)
    assert v.wind_report()[1] > 8.0
    model = DragFusionModel(0.15, 100.0, 100.0)
    assert model.airspeed_mps(-3.0, 100.0) == pytest.approx(13.05, abs=0.05)


def test_drag_fusion_off_or_on_the_ground_learns_nothing():
    v = vehicle("sih_quadx", wind_ned=(0.0, 3.0, 0.0), params={"EKF2_DRAG_CTRL": 1, "EKF2_MCOEF": 1.0})
    advance(v, 5.0)  # on the ground, disarmed: EKF2 estimates no wind there
    assert v.wind_report() is None and not v.wind_estimate.started
    assert not DragFusionModel(0.001, 1.0, 1.0).used and DragFusionModel(0.0, 1.5, 0.0).used


# -- the truth log ------------------------------------------------------------------------------------------


def test_truth_log_carries_true_air_relative_blade_velocity_and_wind(tmp_path):
    path = tmp_path / "truth.csv"
    v = vehicle("x500", wind_ned=(1.0, 3.0, 0.0), gust_mps=0.8, gust_tau_s=1.0, truth_log=path, seed=2,
                params={"EKF2_DRAG_CTRL": 1, "EKF2_MCOEF": 0.3})  # fmt: skip
    hover_at(v, (0.0, 0.0, -5.0))
    advance(v, 6.0)
    v.log.close()
    df = pd.read_csv(path)
    st = df[df.kind == "state"]
    assert len(st) >= 1400
    # the wind is the steady wind plus the turbulence, and the turbulence moves
    for axis, steady in zip("ned", (1.0, 3.0, 0.0)):
        assert np.allclose(st[f"wind_{axis}_mps"], steady + st[f"gust_{axis}_mps"], atol=2e-4)
    assert st.gust_e_mps.std() > 0.1 and st.gust_d_mps.std() > 0.05
    # w, u: the row's own true velocity less its own true wind, in its own true attitude
    w, u = blade_velocity_mps(st.vn_mps, st.ve_mps, st.vd_mps, st.qw, st.qx, st.qy, st.qz,
                              st.wind_n_mps, st.wind_e_mps, st.wind_d_mps)  # fmt: skip
    assert np.allclose(st.w_mps, w, atol=2e-3) and np.allclose(st.u_mps, u, atol=2e-3)
    # the body-frame air velocity says the same (blade frame = body frame), with 3 m/s of air across the disk
    assert np.allclose(st.w_mps, st.vaz_mps, atol=2e-4)
    assert np.allclose(st.u_mps, np.hypot(st.vax_mps, st.vay_mps), atol=2e-3)
    assert st.u_mps.iloc[-500:].mean() == pytest.approx(math.hypot(1.0, 3.0), abs=0.5)
    # the specific force the IMU measures, and the autopilot's estimate once drag fusion runs
    assert st.fz_mps2.iloc[-500:].mean() == pytest.approx(-G_MPS2, abs=0.3)
    assert st.est_wind_e_mps.notna().iloc[-100:].all() and st.est_wind_e_mps.iloc[-1] < 3.0
    # the region's depth is judged on that same w, u: hovering with the air across the disk, far outside
    assert (st.depth_n < 0).all()


def test_truth_log_has_no_estimate_without_drag_fusion(tmp_path):
    path = tmp_path / "truth.csv"
    v = vehicle("x500", wind_ned=(0.0, 3.0, 0.0), truth_log=path)
    hover_at(v, (0.0, 0.0, -5.0))
    advance(v, 2.0)
    v.log.close()
    st = pd.read_csv(path).query("kind == 'state'")
    assert st.est_wind_n_mps.isna().all() and (st.gust_n_mps == 0).all()


# -- turbulence ---------------------------------------------------------------------------------------------


def autocorrelation(x: np.ndarray, lag: int) -> float:
    x = x - x.mean()
    return float(np.dot(x[:-lag], x[lag:]) / np.dot(x, x))


def test_turbulence_has_its_standard_deviation_and_correlation_time():
    dt, tau = 0.05, 2.0
    wind = Wind((0.0, 3.0, 0.0), gust_mps=1.0, seed=4, gust_tau_s=tau)
    n = 80_000  # 4000 s: 2000 correlation times
    g = np.empty((n, 3))
    for i in range(n):
        wind.step(dt, 7.0, (0.0, 0.0, 0.0))
        g[i] = wind.gust
    sd = g.std(axis=0)
    assert sd[0] == pytest.approx(1.0, rel=0.08) and sd[1] == pytest.approx(1.0, rel=0.08)
    assert sd[2] == pytest.approx(0.5, rel=0.08)
    assert np.abs(g.mean(axis=0)).max() < 0.1
    lag = round(tau / dt)
    for i in range(3):
        assert autocorrelation(g[:, i], lag) == pytest.approx(math.exp(-1.0), abs=0.06)


def test_turbulence_follows_dryden_by_default():
    l_u, l_w = dryden_length_scales_m(7.0)
    assert l_u == pytest.approx(49.6, abs=0.5) and l_w == pytest.approx(7.0)
    wind = Wind((0.0, 3.0, 0.0), gust_mps=1.0)
    # hovering: the turbulence passes at the wind's speed; flying against it, faster
    assert wind.correlation_times_s(7.0, 3.0) == pytest.approx((l_u / 3, l_u / 3, 7.0 / 3))
    assert wind.correlation_times_s(7.0, 6.0)[2] == pytest.approx(7.0 / 6)
    # near the ground the eddies are smaller; below 2 m, the 2 m ones
    assert wind.correlation_times_s(0.5, 3.0) == wind.correlation_times_s(2.0, 3.0)
    assert wind.correlation_times_s(2.0, 3.0)[0] < wind.correlation_times_s(7.0, 3.0)[0]
    # along the mean wind and across it: the east wind's along-axis is east
    calm = Wind((0.0, 0.0, 0.0), gust_mps=1.0, seed=1)
    assert calm._along == (1.0, 0.0) and Wind((0.0, 3.0, 0.0), gust_mps=1.0)._along == (0.0, 1.0)
    # the turbulence is there from the first step (drawn from its stationary distribution)
    starts = np.array([Wind((0, 3, 0), gust_mps=1.0, seed=s).gust for s in range(400)])
    assert starts[:, 1].std() == pytest.approx(1.0, rel=0.15)


def test_turbulence_in_flight_moves_the_vehicle_as_gusts_do():
    v = hover_at(vehicle("x500", wind_ned=(0.0, 3.0, 0.0), gust_mps=1.0, seed=3), (0.0, 0.0, -7.0))
    pos = []
    advance(v, 60.0, each=lambda v: pos.append((v.body.state.e_m, v.wind.gust[1])))
    p = np.array(pos)
    # the controller holds the position, but not perfectly: gusts of 1 m/s move it by decimetres
    assert 0.01 < np.abs(p[:, 0]).max() < 1.5
    assert p[:, 1].std() > 0.3
