"""The helix and the vertical baseline flown in wind on the fake (issue 21), in real time over UDP with real
MAVSDK, PX4's personality and ArduCopter's: the fake reports no wind (neither autopilot does by default), so
flighttest estimates it from the drag its IMU feels, plans for it in the start hover, and guards the air.

Judged from the fake's truth log: the true air-relative blade-frame velocity (in gusts, with their updrafts,
which no autopilot reports) never entered the guard region while the guard stayed silent (no true entry
unseen), and the guard did not abort a flight the air made safe.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from flighttest.model.frames import blade_velocity_mps
from flighttest.model.profiles import load_profile
from test_fly_missions import assert_complete_log, assert_safe_end, ci_config, events, truth

pytestmark = pytest.mark.flight

FLY_TIMEOUT_S = 300  # the first flight of a session plans the helix for its winds too


def fly(fake, vehicle: str, mission: str, tmp_path: Path) -> dict:
    cmd = [sys.executable, "-m", "flighttest", "fly", mission, "--connect", fake.url, "--vehicle", vehicle,
           "--height", "7", "--descent", "5", "--config", str(ci_config(tmp_path, mission)), "--log-dir",
           str(tmp_path / "logs"), "--json", "--yes"]  # fmt: skip
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=FLY_TIMEOUT_S, stdin=subprocess.DEVNULL)
    s = json.loads(p.stdout)
    s["_stderr"] = p.stderr
    return s


# (vehicle, the fake's options, mission, wind NED, the gusts' sd along and across the wind; half of it vertically).
# arducopter_sitl's helix in 0.3 m/s of gusts: in 0.6 an updraft of 0.54 m/s once put the truth 0.24 m/s into the
# region 0.1 s before the guard acted, for the guard's allowance sees only the slow part of the gusts
# (bench/RESULTS.md, "Updrafts in the guard" and "Updrafts from the gusts' model, tried and reverted")
CASES = [
    ("x500", {}, "helix", (0.0, 3.0, 0.0), 0.0),
    ("x500", {}, "vertical", (-2.1, 2.1, 0.0), 0.6),
    ("arducopter_sitl", {"autopilot": "ardupilot", "ekf_delay_s": 2.0}, "helix", (2.1, -2.1, 0.0), 0.3),
    ("arducopter_sitl", {"autopilot": "ardupilot", "ekf_delay_s": 2.0}, "vertical", (0.0, -3.0, 0.0), 0.0),
]


# The x500's drag is known to ±8 % (rel_sd): in 3 m/s of air its hover's wind is uncertain by about 0.28 m/s,
# and the guard judges the worst air within 2.45 σ (0.69 m/s) while the helix plunges. On the fake that can end
# the helix in a guard abort with the truth clear (bench/RESULTS.md, "Plans for the wind"): never optimistic.
# In gusts arducopter_sitl's helix too: CI of 42ffe24 aborted it "marginal" at w 0.60, u 2.25 m/s in 0.6 m/s of
# them, the truth clear (bench/RESULTS.md, "The estimate's error in the onset", its last paragraph).
HELIX_MAY_ABORT_CONSERVATIVELY = {("x500", "helix"), ("arducopter_sitl", "helix")}


@pytest.mark.parametrize(("vehicle", "options", "mission", "wind", "gust"), CASES,
                         ids=[f"{c[0]}-{c[2]}-{'gusts' if c[4] else 'steady'}" for c in CASES])  # fmt: skip
def test_in_3_mps_of_wind_the_descent_is_flown_and_the_air_never_entered_the_region_unseen(
    fake_vehicle_factory, tmp_path, vehicle, options, mission, wind, gust
):
    prof = load_profile(vehicle)
    fake = fake_vehicle_factory(vehicle, wind_ned=wind, gust_mps=gust, **options)
    s = fly(fake, vehicle, mission, tmp_path)
    tr = truth(fake)
    assert_safe_end(tr)
    assert_complete_log(s["log_dir"])
    st = tr[tr["kind"] == "state"]
    # the true air across the disk, judged by the guard's own region, while the guard is armed: above the
    # mission's floor (below it the autopilot lands, in ground effect). All of it: the gusts' updrafts too, which
    # no autopilot reports and the guard allows for only as far as its gust meter reads them (bench/RESULTS.md,
    # "Updrafts in the guard").
    g = pd.read_csv(Path(s["log_dir"]) / "guard.csv")
    true = ("vn_mps", "ve_mps", "vd_mps", "qw", "qx", "qy", "qz", "wind_n_mps", "wind_e_mps", "wind_d_mps")
    w, u = blade_velocity_mps(*(st[c].to_numpy(float) for c in true))
    if not gust:
        end = next((e["unix_s"] for e in events(s["log_dir"]) if e["event"] == "stream_end"), math.inf)
        # steady air reads no gusts worth an allowance (the spread sits at the meter's floor: 0.0013 m/s above it
        # for 0.8 s in the fresh-clone CI run of 1d7481a)
        assert g.loc[g["unix_s"] <= end, "gust_sd_mps"].fillna(0.0).max() <= 0.02
        assert np.allclose(w, st["w_mps"], atol=2e-3) and np.allclose(u, st["u_mps"], atol=2e-3)
    margin = np.asarray(prof.guard_region(margin_mps=0.0).margin(w, u))
    floor_m = tomllib.loads((tmp_path / f"{mission}-ci.toml").read_text())["flight"]["min_alt_m"]
    guarded = ((st["armed"] == 1) & (-st["d_m"] > floor_m)).to_numpy()
    unix = st["unix_s"].to_numpy(float)
    abort = next((e for e in events(s["log_dir"]) if e["event"] == "abort"), None)
    if abort is not None:  # what follows the abort is the ladder's, judged by its own tests
        guarded = guarded & (unix < abort["unix_s"])
    deepest = -margin[guarded].min()
    assert deepest <= 0.0, f"the air entered the region by {deepest:.2f} m/s with the guard silent"
    if s["outcome"] != "completed":
        assert abort is not None, s.get("abort_reason") or s["_stderr"][-2000:]
        if gust and abort["phase"] == "settle":
            # the start hover refused the descent: the updrafts it allows for the gusts it measured leave no plan
            # clear
            assert "allowed for its gusts" in abort["reason"], abort["reason"]
        else:
            # only the guard, and only early: the truth was clear when it acted
            assert (vehicle, mission) in HELIX_MAY_ABORT_CONSERVATIVELY, abort
            assert abort["phase"] == "stream", abort
            assert abort["reason"].startswith(("predicted", "marginal", "in guard region")), abort["reason"]
            at = int(np.searchsorted(unix, abort["unix_s"]))
            assert margin[max(at - 25, 0) : at + 1].min() > 0.0
    if s["outcome"] == "completed" and mission == "helix" and not gust:
        # the hold after the stream keeps the wind's drag the stream sent: without it the fake's PX4 was blown
        # 0.39 m downwind of where the stream left it (PX4 SITL: 1.7 m; bench/RESULTS.md, "The hold after a helix
        # in wind")
        ev = events(s["log_dir"])
        end = next(e["unix_s"] for e in ev if e["event"] == "stream_end")
        landing = next((e["unix_s"] for e in ev if e["event"] == "phase" and e["unix_s"] > end
                        and e["phase"] != "settle"), math.inf)  # fmt: skip
        held = st[(st["unix_s"] >= end) & (st["unix_s"] < landing)]
        downwind = np.asarray(wind[:2]) / math.hypot(*wind[:2])
        moved = (held[["n_m", "e_m"]].to_numpy(float) - held[["n_m", "e_m"]].to_numpy(float)[0]) @ downwind
        assert len(held) and moved.max() < 0.2, f"blown {moved.max():.2f} m downwind in the hold after the stream"
    # flighttest knew the wind it judged: its own estimate, within what it said of it
    assert s["wind_source"] == "flighttest"
    err = math.hypot(s["wind_ned_mps"][0] - wind[0], s["wind_ned_mps"][1] - wind[1])
    assert err <= 2.45 * s["wind_sd_mps"] + 2.0 * gust
    chosen = next(e for e in events(s["log_dir"]) if e["event"] == "wind_plan")
    speeds = [c["planned_wind_mps"] for c in chosen["candidates"]]
    assert chosen["wind_source"] == "flighttest" and (mission != "helix" or max(speeds) > 0)
