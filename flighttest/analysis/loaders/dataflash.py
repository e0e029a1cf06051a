"""ArduPilot DataFlash ``.bin`` → :class:`FlightLog` via pymavlink's DFReader.

DFReader applies the DataFlash format multipliers (``c``/``C``/``e``/``E`` ×0.01, ``L`` ×1e-7), so
centidegree attitudes arrive in degrees and ``Lat``/``Lng`` in degrees. What is left to convert:

- position/velocity: ``XKF1`` (EKF3; ``NKF1`` for EKF2): ``PN PE PD`` m and ``VN VE VD`` m/s, NED
  from the EKF origin. Without them: ``POS`` (``Lat Lng`` → flat-earth metres from the first fix,
  ``RelHomeAlt`` m **up-positive** → ``d_m = −RelHomeAlt``) and the climb rate ``CTUN.CRt``
  (**cm/s, up-positive** → ``vd_mps = −CRt/100``).
- attitude: ``ATT`` ``Roll Pitch Yaw`` in degrees (ZYX Euler) → quaternion.
- body rates and specific force: ``IMU`` (first instance) ``GyrX..Z`` rad/s, ``AccX..Z`` m/s², FRD.
- motors: ``RCOU`` ``C1..C8`` PWM µs → (µs − 1000)/1000; channels never non-zero dropped.
- mode: ``MODE.ModeNum`` → ArduCopter mode name; armed: ``ARM.ArmState``, else ``EV`` ids 10/11.
- wind: ``XKF2`` ``VWN VWE`` (m/s, velocity of the air) when present.

Times are ``TimeUS`` (µs since boot); the log has no wall clock here, so ``unix_s`` is NaN.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
from pymavlink import mavutil

from flighttest.analysis.schema import (
    FlightLog,
    build_state,
    continuous_quaternions,
    fill_derived,
    normalise_quaternions,
    resample,
)
from flighttest.errors import FlighttestError
from flighttest.frames import quat_from_euler

MAX_GAP_S = 1.0
EARTH_RADIUS_M = 6_378_137.0
DF_MAGIC = b"\xa3\x95"
EV_ARMED, EV_DISARMED = 10, 11

WANTED = {
    "XKF1": ["TimeUS", "C", "PN", "PE", "PD", "VN", "VE", "VD"],
    "NKF1": ["TimeUS", "PN", "PE", "PD", "VN", "VE", "VD"],
    "XKF2": ["TimeUS", "C", "VWN", "VWE"],
    "POS": ["TimeUS", "Lat", "Lng", "RelHomeAlt"],
    "CTUN": ["TimeUS", "CRt"],
    "ATT": ["TimeUS", "Roll", "Pitch", "Yaw"],
    "IMU": ["TimeUS", "I", "GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ"],
    "RCOU": ["TimeUS", "C1", "C2", "C3", "C4", "C5", "C6", "C7", "C8"],
    "MODE": ["TimeUS", "ModeNum"],
    "ARM": ["TimeUS", "ArmState"],
    "EV": ["TimeUS", "Id"],
}


@contextlib.contextmanager
def _quiet_fds():
    """Silence fd 1/2 too: pymavlink's compiled DataFlash indexer prints damage reports from C."""
    saved = [os.dup(1), os.dup(2)]
    with tempfile.TemporaryFile() as sink:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            yield
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)


def _read(path: Path) -> tuple[dict[str, dict[str, np.ndarray]], str]:
    rows: dict[str, dict[str, list]] = {k: {f: [] for f in v} for k, v in WANTED.items()}
    chatter = io.StringIO()
    try:
        with _quiet_fds(), contextlib.redirect_stderr(chatter), contextlib.redirect_stdout(chatter):
            df = mavutil.mavlink_connection(str(path))
            while (m := df.recv_match(type=list(WANTED))) is not None:
                name = m.get_type()
                fields = WANTED[name]
                d = m.to_dict()
                if fields[1] in ("I", "C") and d.get(fields[1], 0) != 0:
                    continue  # first IMU / first EKF core only
                for f in fields:
                    rows[name][f].append(d.get(f, np.nan))
    except Exception as exc:
        raise FlighttestError(f"{path}: cannot parse DataFlash log ({type(exc).__name__}: {exc})") from None
    out = {k: {f: np.asarray(v, dtype=float) for f, v in cols.items()} for k, cols in rows.items() if cols["TimeUS"]}
    return out, chatter.getvalue()


def load_dataflash(path: Path) -> FlightLog:
    with open(path, "rb") as fh:
        if fh.read(2) != DF_MAGIC:
            raise FlighttestError(f"{path}: not an ArduPilot DataFlash log (bad header)")
    msgs, chatter = _read(path)
    if not msgs:
        raise FlighttestError(f"{path}: DataFlash log has no readable records (truncated or corrupt)")
    notes = ["DataFlash reader: " + line for line in chatter.splitlines()[:3] if line.strip()]
    ekf = msgs.get("XKF1") or msgs.get("NKF1")
    cols: dict[str, np.ndarray] = {}
    if ekf is not None and len(ekf["TimeUS"]) >= 2:
        t = ekf["TimeUS"] / 1e6
        cols.update(n_m=ekf["PN"], e_m=ekf["PE"], d_m=ekf["PD"], vn_mps=ekf["VN"], ve_mps=ekf["VE"], vd_mps=ekf["VD"])
    elif (pos := msgs.get("POS")) is not None and len(pos["TimeUS"]) >= 2:
        t = pos["TimeUS"] / 1e6
        lat, lon = pos["Lat"], pos["Lng"]
        cols.update(
            n_m=np.radians(lat - lat[0]) * EARTH_RADIUS_M,
            e_m=np.radians(lon - lon[0]) * EARTH_RADIUS_M * np.cos(np.radians(lat[0])),
            d_m=-pos["RelHomeAlt"],
        )
        if (ct := msgs.get("CTUN")) is not None:
            cols["vd_mps"] = -resample(ct["TimeUS"] / 1e6, ct["CRt"] / 100.0, t, MAX_GAP_S)
            # horizontal velocity from the position fixes (POS carries none)
            cols["vn_mps"] = np.gradient(cols["n_m"], t)
            cols["ve_mps"] = np.gradient(cols["e_m"], t)
        notes.append("position from POS (no EKF XKF1/NKF1 records); north/east velocity differentiated")
    else:
        raise FlighttestError(f"{path}: log has no position (XKF1, NKF1 or POS records)")

    if (att := msgs.get("ATT")) is not None:
        q = quat_from_euler(*(np.radians(att[k]) for k in ("Roll", "Pitch", "Yaw")))
        qi = normalise_quaternions(resample(att["TimeUS"] / 1e6, continuous_quaternions(q), t, MAX_GAP_S))
        cols.update(qw=qi[:, 0], qx=qi[:, 1], qy=qi[:, 2], qz=qi[:, 3])
    if (imu := msgs.get("IMU")) is not None:
        ti = imu["TimeUS"] / 1e6
        v = resample(
            ti, np.column_stack([imu[k] for k in ("GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ")]), t, MAX_GAP_S
        )
        cols.update(
            p_radps=v[:, 0], q_radps=v[:, 1], r_radps=v[:, 2], ax_mps2=v[:, 3], ay_mps2=v[:, 4], az_mps2=v[:, 5]
        )
    if (rc := msgs.get("RCOU")) is not None:
        m = np.column_stack([rc[f"C{i}"] for i in range(1, 9)])
        used = np.flatnonzero(np.nan_to_num(m).any(axis=0))
        mi = resample(rc["TimeUS"] / 1e6, (m[:, used] - 1000.0) / 1000.0, t, MAX_GAP_S)
        for k in range(mi.shape[1]):
            cols[f"motor_{k}"] = mi[:, k]
    if (mode := msgs.get("MODE")) is not None:
        names = np.array([mavutil.mode_string_acm(int(n)) for n in mode["ModeNum"]], dtype=object)
        cols["mode"] = resample(mode["TimeUS"] / 1e6, names, t, 1e9, hold=True)
    if (arm := msgs.get("ARM")) is not None:
        cols["armed"] = resample(arm["TimeUS"] / 1e6, (arm["ArmState"] != 0).astype(float), t, 1e9, hold=True)
    elif (ev := msgs.get("EV")) is not None:
        sel = np.isin(ev["Id"], [EV_ARMED, EV_DISARMED])
        if sel.any():
            cols["armed"] = resample(
                ev["TimeUS"][sel] / 1e6, (ev["Id"][sel] == EV_ARMED).astype(float), t, 1e9, hold=True
            )
    if (k2 := msgs.get("XKF2")) is not None:
        w = np.column_stack([k2["VWN"], k2["VWE"], np.zeros(len(k2["VWN"]))])
        wi = resample(k2["TimeUS"] / 1e6, w, t, 5.0)
        cols.update(wn_mps=wi[:, 0], we_mps=wi[:, 1], wd_mps=wi[:, 2])
    missing: dict[str, str] = {}
    state = fill_derived(build_state(t, None, cols), missing)
    return FlightLog(path=Path(path), source="dataflash", state=state, missing=missing, notes=notes)
