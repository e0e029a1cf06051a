"""The fake in wind against the autopilots' simulators: hover lean, IMU specific force, and the drag law the IMU shows.

    python bench/bench_fake_wind.py [--shared ../shared/wind_sitl] [--json]

References (``../shared/wind_sitl``, 3 m/s of wind blowing east): PX4 SITL with SIH (``px4.ulg.xz``: truth
``vehicle_attitude_groundtruth``, ``vehicle_local_position_groundtruth``; IMU ``sensor_combined``) and ArduCopter
SITL (``arducopter.bin.xz``: truth ``SIM`` attitude, ``SIM2`` velocity; ``IMU``). ArduCopter SITL's wind is
``SIM_WIND_SPD`` scaled by √(h/60) below 60 m when ``SIM_WIND_T`` is 0 (read from the PARM records): at 7 m,
1.02 m/s. For each flight:

- **hover**: the longest span ≥ 1 s above 5 m with the truth speed below 0.2 m/s (the settle before the
  descent, less its first 0.3 s): mean truth tilt, the IMU's body-y specific force, the truth's vertical
  acceleration over it;
- **drag law**: the IMU's body x/y specific force against the truth air-relative body velocity over the whole
  flight above 1 m, least squares ``f·m = −(k1·v + k2·|v|·v)``.

The fake (``sitl_fakes.fast``, fast time, perfect estimate): the same airframe and personality (sih_quadx on
PX4, arducopter_sitl on ArduPilot) hovering 7 m up in the reference's wind at the vehicle for 30 s (the last
5 s averaged), then flying legs at 3 m/s north and south across the wind; the same fit on its HIGHRES_IMU
(with its noise).
"""

from __future__ import annotations

import argparse
import json
import lzma
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from sitl_fakes.ardupilot import CopterMode
from sitl_fakes.fast import advance, hover_at, vehicle
from sitl_fakes.link import mavlink
from sitl_fakes.px4 import Mode

WIND_E_MPS = 3.0
VELOCITY_MASK = 0b111 | (0b111 << 6) | (1 << 10) | (1 << 11)  # velocity only, yaw and yaw rate ignored


def body_velocity(q: np.ndarray, v_ned: np.ndarray) -> np.ndarray:
    """Rᵀ(q) v for rows of quaternions (w, x, y, z) and NED vectors."""
    w, x, y, z = q.T
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])  # fmt: skip
    return np.einsum("jin,nj->ni", r, v_ned)


def tilt_deg(q: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2), -1, 1)))


def fit(v_body: np.ndarray, f_body: np.ndarray, mass: float) -> dict:
    """Least squares of the drag law on body x and y together (N per m/s, N per (m/s)²)."""
    v = np.concatenate([v_body[:, 0], v_body[:, 1]])
    f = np.concatenate([f_body[:, 0], f_body[:, 1]]) * mass
    lin = float(np.linalg.lstsq(-v[:, None], f, rcond=None)[0][0])
    both = np.linalg.lstsq(np.column_stack([-v, -np.abs(v) * v]), f, rcond=None)[0]
    return {"linear_only_n_per_mps": round(lin, 3), "k1_n_per_mps": round(float(both[0]), 3),
            "k2_n_per_mps2": round(float(both[1]), 4), "airspeed_range_mps": [round(float(v.min()), 2),
                                                                              round(float(v.max()), 2)]}  # fmt: skip


def hover_window(t: np.ndarray, speed: np.ndarray, height: np.ndarray) -> tuple[float, float]:
    ok = (speed < 0.2) & (height > 5.0)
    runs, start = [], None
    for i, o in enumerate(ok):
        if o and start is None:
            start = i
        if (not o or i == len(ok) - 1) and start is not None:
            runs.append((t[start], t[i - 1]))
            start = None
    a, b = max((r for r in runs if r[1] - r[0] > 1.0), key=lambda r: r[1] - r[0])
    return a + 0.3, b


def px4_reference(path: Path, tmp: Path) -> dict:
    from pyulog import ULog

    ulg = tmp / (path.parent.name + ".ulg")
    ulg.write_bytes(lzma.decompress(path.read_bytes()))
    u = ULog(str(ulg), ["vehicle_attitude_groundtruth", "vehicle_local_position_groundtruth", "sensor_combined"])
    data = {d.name: d.data for d in u.data_list}
    att, lp, sc = (data[k] for k in ("vehicle_attitude_groundtruth", "vehicle_local_position_groundtruth",
                                     "sensor_combined"))  # fmt: skip
    mass = float(u.initial_parameters["SIH_MASS"])
    wind_set = [t / 1e6 for t, k, v in u.changed_parameters if k == "SIH_WIND_E"]
    tl, ta, ts = lp["timestamp"] / 1e6, att["timestamp"] / 1e6, sc["timestamp"] / 1e6
    v = np.column_stack([lp["vx"], lp["vy"], lp["vz"]])
    a, b = hover_window(tl, np.linalg.norm(v, axis=1), -lp["z"])
    q = np.column_stack([att[f"q[{i}]"] for i in range(4)])
    acc = np.column_stack([sc[f"accelerometer_m_s2[{i}]"] for i in range(3)])
    m_att, m_imu, m_lp = (ta >= a) & (ta <= b), (ts >= a) & (ts <= b), (tl >= a) & (tl <= b)
    hover = {"window_s": [round(a, 2), round(b, 2)], "tilt_deg": round(float(tilt_deg(q[m_att]).mean()), 2),
             "fy_mps2": round(float(acc[m_imu, 1].mean()), 3),
             "vertical_accel_mps2": round(float(np.polyfit(tl[m_lp], v[m_lp, 2], 1)[0]), 2)}  # fmt: skip
    # the drag law over the flight, once the wind blows (SIH's air-relative velocity is v − wind)
    vi = np.column_stack([np.interp(ts, tl, v[:, k]) for k in range(3)])
    qi = np.column_stack([np.interp(ts, ta, q[:, k]) for k in range(4)])
    qi /= np.linalg.norm(qi, axis=1)[:, None]
    air = (ts > wind_set[0] + 2.0) & (-np.interp(ts, tl, lp["z"]) > 1.0)
    vb = body_velocity(qi[air], vi[air] - np.array([0.0, WIND_E_MPS, 0.0]))
    return {"hover": hover, "wind_at_vehicle_mps": WIND_E_MPS, "drag": fit(vb, acc[air], mass), "mass_kg": mass}


def ardupilot_reference(path: Path) -> dict:
    from pymavlink import mavutil

    log = mavutil.mavlink_connection(str(path), dialect="ardupilotmega")
    sim, sim2, imu, parm = [], [], [], {}
    while (msg := log.recv_match(type=["SIM", "SIM2", "IMU", "PARM"])) is not None:
        d = msg.to_dict()
        kind = msg.get_type()
        if kind == "SIM":
            sim.append((d["TimeUS"] / 1e6, d["Q1"], d["Q2"], d["Q3"], d["Q4"]))
        elif kind == "SIM2":
            sim2.append((d["TimeUS"] / 1e6, d["PD"], d["VN"], d["VE"], d["VD"]))
        elif kind == "IMU" and d["I"] == 0:
            imu.append((d["TimeUS"] / 1e6, d["AccX"], d["AccY"], d["AccZ"]))
        elif kind == "PARM":
            parm[d["Name"]] = d["Value"]
    sim_a, sim2_a, imu_a = np.array(sim), np.array(sim2), np.array(imu)
    ground = float(np.median(sim2_a[:50, 1]))
    height = ground - sim2_a[:, 1]
    speed_cfg, t_alt = float(parm["SIM_WIND_SPD"]), float(parm["SIM_WIND_T_ALT"])

    def wind_at(h):  # SIM_WIND_T 0 (WIND_TYPE_SQRT): √(h / SIM_WIND_T_ALT) below it
        if int(parm["SIM_WIND_T"]) != 0:
            return np.full_like(h, speed_cfg)
        return speed_cfg * np.sqrt(np.clip(h / t_alt, 0.0, 1.0))

    a, b = hover_window(sim2_a[:, 0], np.linalg.norm(sim2_a[:, 2:5], axis=1), height)
    m2, ms, mi = ((x[:, 0] >= a) & (x[:, 0] <= b) for x in (sim2_a, sim_a, imu_a))
    h_hover = float(height[m2].mean())
    hover = {"window_s": [round(a, 2), round(b, 2)], "height_m": round(h_hover, 2),
             "tilt_deg": round(float(tilt_deg(sim_a[ms, 1:]).mean()), 2),
             "fy_mps2": round(float(imu_a[mi, 2].mean()), 3),
             "vertical_accel_mps2": round(float(np.polyfit(sim2_a[m2, 0], sim2_a[m2, 4], 1)[0]), 2)}  # fmt: skip
    ti = imu_a[:, 0]
    hi = ground - np.interp(ti, sim2_a[:, 0], sim2_a[:, 1])
    v = np.column_stack([np.interp(ti, sim2_a[:, 0], sim2_a[:, k]) for k in (2, 3, 4)])
    q = np.column_stack([np.interp(ti, sim_a[:, 0], sim_a[:, k]) for k in (1, 2, 3, 4)])
    q /= np.linalg.norm(q, axis=1)[:, None]
    air = hi > 1.0
    v_air = v[air] - np.column_stack([0 * hi[air], wind_at(hi[air]), 0 * hi[air]])
    vb = body_velocity(q[air], v_air)
    return {"hover": hover, "sim_wind_t": int(parm["SIM_WIND_T"]), "sim_wind_spd": speed_cfg,
            "wind_at_vehicle_mps": round(float(wind_at(np.array([h_hover]))[0]), 3),
            "drag": fit(vb, imu_a[air, 1:], 3.0), "mass_kg": 3.0}  # fmt: skip


def fly_velocity(v, vel_ned, seconds: float, samples: list) -> None:
    msg = mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, VELOCITY_MASK, 0, 0, 0, *vel_ned, 0, 0, 0, 0, 0)
    for _ in range(round(seconds / 0.02)):
        v.handle(msg, ("bench", 0))
        if v.autopilot_name == "px4" and v.mode is not Mode.OFFBOARD:
            v.set_mode(Mode.OFFBOARD, "bench")
        advance(v, 0.02)
        s = v.body.state
        f = v.telemetry.highres_imu()
        samples.append((s.vn_mps, s.ve_mps, s.vd_mps, s.qw, s.qx, s.qy, s.qz, f.xacc, f.yacc, f.zacc))


def fake(profile: str, autopilot: str, wind_e_mps: float) -> dict:
    v = hover_at(vehicle(profile, autopilot, wind_ned=(0.0, wind_e_mps, 0.0), seed=1), (0.0, 0.0, -7.0))
    v.autopilot_name = autopilot
    if autopilot == "ardupilot":
        v.set_mode(CopterMode.GUIDED, "bench")
    rows = []
    advance(v, 30.0, each=lambda v: rows.append((v.now, math.degrees(v.body.state.tilt_rad()), v.body.state.fy_mps2)))
    r = np.array(rows)
    tail = r[r[:, 0] > r[-1, 0] - 5.0]
    imu = np.array([v.telemetry.highres_imu().yacc for _ in range(500)])
    hover = {"tilt_deg": round(float(tail[:, 1].mean()), 2), "fy_mps2": round(float(tail[:, 2].mean()), 3),
             "highres_imu_fy_mps2": round(float(imu.mean()), 3), "highres_imu_sd_mps2": round(float(imu.std()), 4)}
    samples: list = []
    for vel in ((3.0, 0.0, 0.0), (0.0, 0.0, 0.0), (-3.0, 0.0, 0.0), (0.0, 0.0, 0.0)):
        fly_velocity(v, vel, 6.0, samples)
    s = np.array(samples)
    vb = body_velocity(s[:, 3:7], s[:, 0:3] - np.array([0.0, wind_e_mps, 0.0]))
    return {"hover": hover, "wind_at_vehicle_mps": wind_e_mps, "drag": fit(vb, s[:, 7:10], v.profile.mass_kg),
            "truth_drag": v.body.drag.describe()}  # fmt: skip


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--shared", type=Path, default=Path(__file__).resolve().parents[2] / "shared" / "wind_sitl")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out: dict = {"reference": {}, "fake": {}}
    with tempfile.TemporaryDirectory(prefix="bench_fake_wind_") as tmp:
        for name in ("px4-vertical-wind3e", "px4-helix-wind3e"):
            out["reference"][name] = px4_reference(args.shared / name / "px4.ulg.xz", Path(tmp))
        for name in ("ardupilot-vertical-wind3e", "ardupilot-helix-wind3e"):
            binf = Path(tmp) / (name + ".bin")
            binf.write_bytes(lzma.decompress((args.shared / name / "arducopter.bin.xz").read_bytes()))
            out["reference"][name] = ardupilot_reference(binf)
    sitl_wind = out["reference"]["ardupilot-vertical-wind3e"]["wind_at_vehicle_mps"]
    out["fake"]["sih_quadx px4"] = fake("sih_quadx", "px4", WIND_E_MPS)
    out["fake"]["arducopter_sitl ardupilot"] = fake("arducopter_sitl", "ardupilot", sitl_wind)
    out["fake"]["arducopter_sitl ardupilot, 3 m/s"] = fake("arducopter_sitl", "ardupilot", WIND_E_MPS)
    out["fake"]["x500 px4"] = fake("x500", "px4", WIND_E_MPS)
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print("| flight | wind at vehicle m/s | hover tilt ° | IMU f_y m/s² | (vertical accel m/s²) | drag fit k1 N/(m/s) "
          "| k2 N/(m/s)² | linear only |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for group, rows in out.items():
        for name, r in rows.items():
            h, d = r["hover"], r["drag"]
            print(f"| {group}: {name} | {r['wind_at_vehicle_mps']:g} | {h['tilt_deg']:.2f} | {h['fy_mps2']:.3f} | "
                  f"{h.get('vertical_accel_mps2', 0.0):+.2f} | {d['k1_n_per_mps']:.3f} | {d['k2_n_per_mps2']:.4f} | "
                  f"{d['linear_only_n_per_mps']:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
