"""Analysis judges the air too (issue 21 item 6): ``../shared/wind_sitl``, four flights on real autopilot
firmware in a steady wind blowing east, analysed from flighttest's folders and from the autopilots' own logs,
against the simulators' truth.

Neither autopilot estimated the wind (no WIND_COV in the tlogs; ArduCopter's XKF2 wind is exact zeros) and the
folders' guard.csv assumed calm (wind 0, no wind_source column), so every log must name flighttest's own
estimate from the IMU's drag. The truth:

- PX4 SITL (SIH): ``vehicle_local_position_groundtruth`` and ``vehicle_attitude_groundtruth`` in the ``.ulg``;
  the wind is ``−SIH_WIND_E`` east from when the parameter was set (its air-relative velocity is
  ``v_ned + (SIH_WIND_N, SIH_WIND_E, 0)``).
- ArduCopter SITL: ``SIM2`` (VN, VE, VD) and ``SIM`` (Q1–Q4, Alt) in the ``.bin``; with ``SIM_WIND_T`` 0
  SITL scales the wind by ``sqrt(alt / SIM_WIND_T_ALT)`` below ``SIM_WIND_T_ALT`` (its barometric altitude
  above home; ``libraries/SITL/SITL_State``), so at 7 m its 3 m/s are 1.0 m/s; ``SIM_WIND_DIR`` is where
  it comes from.

Each log's exposure (per descent and over all its time airborne) is held to the truth's, judged with the
same guard region (the profile's, margin included) on the truth's own air-relative velocity over the same
span of the autopilot's boot clock:

- time inside within ``INSIDE_TOL_S`` (0.1 s): the logs sample at 10-125 Hz and the truth at 50 Hz, so one
  boundary crossing at each end of a span can fall a sample (≤ 0.02 s at 50 Hz, 0.1 s at DataFlash's
  10 Hz XKF1) apart;
- minimum margin within ``MARGIN_TOL_MPS`` (0.05 m/s): what the wind's error (≤ 0.15 m/s here) moves
  ``w`` by through a tilt of up to 20° and ``u`` by through the cone's tan 20°, plus the estimator's
  velocity against the simulator's;
- the worst air within the wind's uncertainty covers the truth: the minimum margin there is never above
  the truth's (by more than that tolerance).

The wind itself: within ``WIND_COVERAGE_SIGMAS`` (2.45) of its stated 1 σ at ≥ 95 % of the airborne samples
(the live guard's coverage), and within ``WIND_TOL_MPS`` (0.2 m/s) everywhere airborne.
"""

from __future__ import annotations

import json
import lzma
import math
import shutil
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from flighttest.analysis import wind as wind_mod
from flighttest.analysis.exposure import sample_durations
from flighttest.analysis.loaders import load_log
from flighttest.analysis.pipeline import Analysis, analyse
from flighttest.analysis.schema import continuous_quaternions
from flighttest.cli import main
from flighttest.flying.wind import WIND_COVERAGE_SIGMAS
from flighttest.model.profiles import load_profile

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
WIND_DIR = SHARED / "wind_sitl"
FLIGHTS = {  # folder: (vehicle, the autopilot's log inside it)
    "px4-helix-wind3e": ("sih_quadx", "px4.ulg.xz"),
    "px4-vertical-wind3e": ("sih_quadx", "px4.ulg.xz"),
    "ardupilot-helix-wind3e": ("arducopter_sitl", "arducopter.bin.xz"),
    "ardupilot-vertical-wind3e": ("arducopter_sitl", "arducopter.bin.xz"),
}
INSIDE_TOL_S = 0.1
MARGIN_TOL_MPS = 0.05
WIND_TOL_MPS = 0.2
COVERAGE = 0.95


def _need(path: Path) -> None:
    if not path.is_file():
        pytest.skip(f"reference flight not available: {path} (needs ../shared next to the checkout)")


def px4_truth(path: Path) -> pd.DataFrame:
    from pyulog import ULog

    u = ULog(str(path), ["vehicle_local_position_groundtruth", "vehicle_attitude_groundtruth"])
    d = {x.name: x.data for x in u.data_list}
    lp, at = d["vehicle_local_position_groundtruth"], d["vehicle_attitude_groundtruth"]
    t = lp["timestamp"] / 1e6
    q = continuous_quaternions(np.column_stack([at[f"q[{i}]"] for i in range(4)]).astype(float))
    q = np.column_stack([np.interp(t, at["timestamp"] / 1e6, q[:, i]) for i in range(4)])
    set_at = [(ts / 1e6, v) for ts, name, v in u.changed_parameters if name == "SIH_WIND_E"]
    east0 = -float(u.initial_parameters.get("SIH_WIND_E", 0.0))
    we = np.full(len(t), east0)
    for ts, v in set_at:
        we[t >= ts] = -float(v)
    north = -float(u.initial_parameters.get("SIH_WIND_N", 0.0))
    return _truth(t, lp["vx"], lp["vy"], lp["vz"], q, np.full(len(t), north), we)


def ardupilot_truth(path: Path) -> pd.DataFrame:
    from pymavlink import DFReader

    df = DFReader.DFReader_binary(str(path))
    sim, sim2, parm = [], [], {}
    try:
        while (m := df.recv_match(type=["SIM", "SIM2", "PARM"])) is not None:
            k = m.get_type()
            if k == "PARM":
                parm[m.Name] = m.Value
            elif k == "SIM":
                sim.append((m.TimeUS / 1e6, m.Q1, m.Q2, m.Q3, m.Q4, m.Alt))
            else:
                sim2.append((m.TimeUS / 1e6, m.VN, m.VE, m.VD))
    finally:
        df.data_map.close()
        df.filehandle.close()
    sim, sim2 = np.array(sim), np.array(sim2)
    t = sim2[:, 0]
    q_sim = continuous_quaternions(sim[:, 1:5])
    q = np.column_stack([np.interp(t, sim[:, 0], q_sim[:, i]) for i in range(4)])
    alt = np.interp(t, sim[:, 0], sim[:, 5]) - sim[0, 5]  # above home: the first SIM altitude, on the ground
    speed = np.full(len(t), parm["SIM_WIND_SPD"])
    if parm.get("SIM_WIND_T", 0) == 0:  # WIND_TYPE_SQRT
        below = alt < parm["SIM_WIND_T_ALT"]
        speed[below] *= np.sqrt(np.clip(alt[below], 0.0, None) / parm["SIM_WIND_T_ALT"])
    came_from = math.radians(parm["SIM_WIND_DIR"])
    return _truth(t, sim2[:, 1], sim2[:, 2], sim2[:, 3], q, -speed * math.cos(came_from), -speed * math.sin(came_from))


def _truth(t, vn, ve, vd, q, wn, we) -> pd.DataFrame:
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    return pd.DataFrame({"boot_s": t, "vn": vn, "ve": ve, "vd": vd, "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2],
                         "qz": q[:, 3], "wn": wn, "we": we, "wd": 0.0})  # fmt: skip


class _Flights:
    """Each flight's truth and its two analyses (folder, autopilot log), once per module."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.cache: dict[str, tuple[pd.DataFrame, dict[str, Analysis]]] = {}

    def __call__(self, name: str) -> tuple[pd.DataFrame, dict[str, Analysis]]:
        if name not in self.cache:
            vehicle, packed = FLIGHTS[name]
            folder = WIND_DIR / name
            _need(folder / packed)
            own = self.tmp / f"{name}{'.ulg' if packed.startswith('px4') else '.bin'}"
            with lzma.open(folder / packed) as src, open(own, "wb") as dst:
                shutil.copyfileobj(src, dst, 1 << 20)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                truth = px4_truth(own) if own.suffix == ".ulg" else ardupilot_truth(own)
                # the folder names its vehicle (meta.json); the autopilot's log is given it
                analyses = {"folder": analyse(load_log(folder)), "autopilot log": analyse(load_log(own), vehicle)}
            self.cache[name] = (truth, analyses)
        return self.cache[name]


@pytest.fixture(scope="module")
def flights(tmp_path_factory) -> _Flights:
    return _Flights(tmp_path_factory.mktemp("wind_sitl"))


def truth_exposure(truth: pd.DataFrame, vehicle: str, sel: np.ndarray) -> tuple[float, float]:
    """(time inside, min margin) of the truth's air-relative blade-frame velocity over the samples ``sel``."""
    region = load_profile(vehicle).guard_region()
    cols = ["vn", "ve", "vd", "qw", "qx", "qy", "qz", "wn", "we", "wd"]
    _, _, _, m = region.check(*(truth[c].to_numpy(float) for c in cols))
    dt = sample_durations(truth["boot_s"].to_numpy(float))
    return float(dt[sel & (m < 0)].sum()), float(m[sel].min())


def _spans(a: Analysis, truth: pd.DataFrame) -> list[tuple[str, dict, np.ndarray]]:
    """(what, our exposure, the truth's samples over the same span of the boot clock): every descent, and
    all the time airborne."""
    s = a.log.state
    t, boot = s["t_s"].to_numpy(float), s["boot_s"].to_numpy(float)
    tb = truth["boot_s"].to_numpy(float)
    out = []
    for d in a.descents.to_dict("records"):
        b0, b1 = np.interp([d["start_s"], d["end_s"]], t, boot)
        out.append((f"descent {d['descent']} ({d['phase']})", d, (tb >= b0) & (tb <= b1)))
    air = wind_mod.airborne_mask(s)
    out.append(("airborne", a.airborne, np.interp(tb, boot, air.astype(float)) > 0.5))
    return out


@pytest.mark.parametrize("name", list(FLIGHTS))
@pytest.mark.parametrize("kind", ["folder", "autopilot log"])
def test_the_wind_is_named_and_the_exposure_is_the_truths(flights, name, kind):
    truth, analyses = flights(name)
    a = analyses[kind]
    vehicle = FLIGHTS[name][0]
    s = a.summary()
    assert s["wind_source"] == "flighttest estimate", s["wind_detail"]
    assert "wind" not in s["missing"]
    problems = []
    for what, ours, sel in _spans(a, truth):
        inside, margin = truth_exposure(truth, vehicle, sel)
        if abs(ours["time_inside_s"] - inside) > INSIDE_TOL_S:
            problems.append(f"{what}: inside {ours['time_inside_s']:.2f} s, the truth {inside:.2f} s")
        # the margin moves with the wind's error at most one for one: within its stated 1 σ
        if abs(ours["min_margin_mps"] - margin) > max(MARGIN_TOL_MPS, ours.get("wind_sd_mps", 0.0)):
            problems.append(f"{what}: min margin {ours['min_margin_mps']:.3f} m/s, the truth {margin:.3f}")
        if ours["min_margin_worst_mps"] > margin + MARGIN_TOL_MPS:
            problems.append(f"{what}: the worst air's margin {ours['min_margin_worst_mps']:.3f} m/s does not cover "
                            f"the truth's {margin:.3f}")  # fmt: skip
    assert not problems, f"{name} ({kind}): " + "; ".join(problems)


@pytest.mark.parametrize("name", list(FLIGHTS))
def test_the_wind_estimate_is_the_truths_within_its_uncertainty(flights, name):
    truth, analyses = flights(name)
    for kind, a in analyses.items():
        s = a.log.state
        air = wind_mod.airborne_mask(s)
        tb = truth["boot_s"].to_numpy(float)
        boot = s["boot_s"].to_numpy(float)[air]
        true = np.column_stack([np.interp(boot, tb, truth[c].to_numpy(float)) for c in ("wn", "we")])
        err = np.hypot(*(a.log.wind.ned_mps[air, :2] - true).T)
        covered = float(np.mean(err <= WIND_COVERAGE_SIGMAS * a.log.wind.sd_mps[air]))
        assert err.max() < WIND_TOL_MPS and covered >= COVERAGE, (kind, err.max(), covered)


def test_the_px4_helix_was_inside_only_in_the_air_before_its_abort(flights):
    """The guard's ground-relative view put PX4's Land after the abort inside the region; in the air it was
    far outside, and the 0.5 s inside came 0.3 s into the helix's descent, before any descent the segmenter
    counts (README of ../shared/wind_sitl)."""
    truth, analyses = flights("px4-helix-wind3e")
    a = analyses["folder"]
    land = a.descents.iloc[0]
    assert land["phase"] == "abort_land" and land["time_inside_s"] == 0.0 and land["min_margin_mps"] > 0.8
    assert 0.4 < a.airborne["time_inside_s"] < 0.6 and a.airborne["deepest_s"] < land["start_s"]


def test_analyse_of_the_folders_names_the_wind_source(tmp_path, capsys):
    _need(WIND_DIR / "px4-helix-wind3e" / "flight.tlog")
    capsys.readouterr()
    rc = main(["analyse", str(WIND_DIR), "--json", "--parquet", str(tmp_path / "d.parquet")])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and len(out) == len(FLIGHTS)
    for s in out:
        assert s["wind_source"] == "flighttest estimate" and s["wind_sd_mps"] is not None, s["log"]
        assert "wind" not in s["missing"] and all(d["wind_source"] for d in s["descents"])
    speeds = {Path(s["log"]).name: math.hypot(*s["wind_ned_mps"][:2]) for s in out}
    assert speeds["px4-vertical-wind3e"] == pytest.approx(3.0, abs=0.1)
    assert speeds["ardupilot-vertical-wind3e"] == pytest.approx(0.75, abs=0.15)  # sqrt(alt / 60) × 3 m/s
