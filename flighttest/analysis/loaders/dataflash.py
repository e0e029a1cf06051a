"""ArduPilot DataFlash ``.bin`` → :class:`FlightLog` via pymavlink's DFReader.

DFReader applies the DataFlash format multipliers (``c``/``C``/``e``/``E`` ×0.01, ``L`` ×1e-7), so
centidegree attitudes arrive in degrees and ``Lat``/``Lng`` in degrees. What is left to convert:

- position/velocity: ``XKF1`` (EKF3; ``NKF1`` for EKF2): ``PN PE PD`` m and ``VN VE VD`` m/s, NED
  from the EKF origin. Without them: ``POS`` (``Lat Lng`` → flat-earth metres from the first fix,
  ``RelHomeAlt`` m **up-positive** → ``d_m = −RelHomeAlt``) and the climb rate ``CTUN.CRt``
  (**cm/s, up-positive** → ``vd_mps = −CRt/100``).
- attitude, the first of: ``ATT`` ``Roll Pitch Yaw`` (degrees, ZYX Euler); ``AHR2`` (the backup
  DCM attitude: ``Q1..Q4`` where logged, else its Euler angles); ``XKQ`` (EKF3 core 0 ``Q1..Q4``);
  ``NKQ`` / ``NKQ1`` (EKF2). Logs that leave ATT out (a log-bitmask choice) still have attitude.
- body rates and specific force: ``IMU`` (first instance) ``GyrX..Z`` rad/s, ``AccX..Z`` m/s², FRD.
- motors: ``RCOU`` ``C1..C8`` PWM µs → (µs − 1000)/1000; channels never non-zero dropped.
- mode: ``MODE.ModeNum`` → ArduCopter mode name; armed: ``ARM.ArmState``, else ``EV`` ids 10/11;
  landed: ``EV`` ids 18 (``LAND_COMPLETE``) → 1 and 28 (``NOT_LANDED``) → 0, the land detector's changes.
- wind: ``XKF2`` ``VWN VWE`` (m/s, velocity of the air; no accuracy) as ``FlightLog.wind_reported``; the
  state's wind columns only where it is an estimate: EKF3 logs exact zeros when it does not estimate
  the wind (``EK3_DRAG_BCOEF_X/Y`` and ``EK3_DRAG_MCOEF`` 0, the default on a multicopter).
- heights (up-positive m; the position's own first): ``XKF1.PD`` / ``NKF1.PD`` (negated, EKF origin,
  home-relative), ``POS.RelHomeAlt`` (home-relative) and ``POS.Alt`` (AMSL), ``CTUN.Alt`` (the
  altitude controller's, home-relative), ``BARO.Alt`` (first barometer, m above its ground
  calibration; ``CTUN.BAlt`` instead when no BARO records), ``GPS.Alt`` (first receiver, m AMSL, 3D
  fixes only: ``Status`` ≥ 3), ``RFND.Dist`` (m; ``Dist1`` in older logs; good readings only where
  ``Stat`` is logged, downward sensors where ``Orient`` is).
- parameters: ``PARM`` ``Name Value``, the last value of each name.

Times are ``TimeUS`` (µs since boot, also the state's ``boot_s``); the log has no wall clock here,
so ``unix_s`` is NaN. Multi-instance records (``I``, ``C``, ``Instance``) keep instance 0 only.
"""

from __future__ import annotations

import contextlib
import gc
import io
import os
import sys
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from pymavlink import DFReader, mavutil

from flighttest.analysis.schema import (
    FlightLog,
    HeightSource,
    build_state,
    continuous_quaternions,
    fill_derived,
    height_source,
    normalise_quaternions,
    param_value,
    resample,
    state_wind,
    wind_report,
)
from flighttest.errors import FlighttestError
from flighttest.model.frames import EARTH_RADIUS_M, quat_from_euler

MAX_GAP_S = 1.0
DF_MAGIC = b"\xa3\x95"
EV_ARMED, EV_DISARMED = 10, 11
EV_LAND_COMPLETE, EV_NOT_LANDED = 18, 28

WANTED = {
    "XKF1": ["TimeUS", "C", "PN", "PE", "PD", "VN", "VE", "VD"],
    "NKF1": ["TimeUS", "PN", "PE", "PD", "VN", "VE", "VD"],
    "XKF2": ["TimeUS", "C", "VWN", "VWE"],
    "POS": ["TimeUS", "Lat", "Lng", "Alt", "RelHomeAlt"],
    "CTUN": ["TimeUS", "CRt", "Alt", "BAlt"],
    "ATT": ["TimeUS", "Roll", "Pitch", "Yaw"],
    "AHR2": ["TimeUS", "Roll", "Pitch", "Yaw", "Q1", "Q2", "Q3", "Q4"],
    "XKQ": ["TimeUS", "C", "Q1", "Q2", "Q3", "Q4"],
    "NKQ": ["TimeUS", "C", "Q1", "Q2", "Q3", "Q4"],
    "NKQ1": ["TimeUS", "Q1", "Q2", "Q3", "Q4"],
    "IMU": ["TimeUS", "I", "GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ"],
    "RCOU": ["TimeUS", "C1", "C2", "C3", "C4", "C5", "C6", "C7", "C8"],
    "MODE": ["TimeUS", "ModeNum"],
    "ARM": ["TimeUS", "ArmState"],
    "EV": ["TimeUS", "Id"],
    "BARO": ["TimeUS", "I", "Alt"],
    "GPS": ["TimeUS", "I", "Status", "Alt"],
    "RFND": ["TimeUS", "Instance", "Dist", "Dist1", "Stat", "Orient"],
}
INSTANCE_FIELDS = ("I", "C", "Instance")
ATTITUDE_RECORDS = ("ATT", "AHR2", "XKQ", "NKQ", "NKQ1")  # in order of preference
PARM = "PARM"
GPS_OK_FIX_3D = 3
RANGEFINDER_GOOD = 4  # RangeFinder::Status::Good
ROTATION_PITCH_270 = 25  # downward


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


def _record_counts(df) -> dict[str, int] | None:
    """Records per type from the binary reader's index (None for a text log: no index)."""
    counts, names = getattr(df, "counts", None), getattr(df, "id_to_name", None)
    if not isinstance(counts, list) or not isinstance(names, dict):
        return None
    return {names[i]: c for i, c in enumerate(counts) if c and i in names}


def _types_to_read(counts: dict[str, int] | None) -> list[str]:
    """The record types worth decoding: of the fallbacks (EKF2 after EKF3, the attitude records)
    only the one that will be used, since decoding is most of the time spent."""
    types = [*WANTED, PARM]
    if counts is None:
        return types
    att = next((k for k in ATTITUDE_RECORDS if counts.get(k, 0) >= 2), None)
    return [
        k
        for k in types
        if k in counts and (k not in ATTITUDE_RECORDS or k == att) and not (k == "NKF1" and counts.get("XKF1", 0) >= 2)
    ]


def _number(v) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _close(df) -> None:
    """DFReader keeps its file and memory map open until garbage collection (ResourceWarning)."""
    for name in ("data_map", "filehandle"):
        with contextlib.suppress(Exception):
            getattr(df, name).close()


def _read(path: Path) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, float], str]:
    rows: dict[str, dict[str, list]] = {k: {f: [] for f in v} for k, v in WANTED.items()}
    instance = {k: next((f for f in v if f in INSTANCE_FIELDS), None) for k, v in WANTED.items()}
    params: dict[str, float] = {}
    chatter = io.StringIO()
    df = None
    failure = None
    try:
        with (
            _quiet_fds(),
            contextlib.redirect_stderr(chatter),
            contextlib.redirect_stdout(chatter),
            warnings.catch_warnings(),
        ):
            # a DFReader that fails in its constructor leaves its file open for the garbage collector
            warnings.simplefilter("ignore", ResourceWarning)
            # the binary reader itself, not mavutil.mavlink_connection: that picks the reader by the file
            # name, so a DataFlash log not named .bin was read as MAVLink byte by byte (a minute, then
            # "no readable records"), and a name with a ':' would even be taken for a UDP address
            df = DFReader.DFReader_binary(str(path))
            types = _types_to_read(_record_counts(df))
            while (m := df.recv_match(type=types)) is not None:
                name = m.get_type()
                d = m.to_dict()
                if name == PARM:
                    value = d.get("Value")
                    if isinstance(d.get("Name"), str) and _number(value) and np.isfinite(value):
                        params[d["Name"]] = param_value(value)
                    continue
                inst = instance[name]
                if inst is not None and d.get(inst, 0) != 0:
                    continue  # first IMU / EKF core / barometer / GPS / rangefinder only
                for f, col in rows[name].items():
                    v = d.get(f, np.nan)
                    col.append(v if _number(v) else np.nan)  # a damaged FMT can make a field text
    except Exception as exc:
        failure = f"{type(exc).__name__}: {exc}"
    finally:
        _close(df)
    if failure is not None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ResourceWarning)
            gc.collect()  # the failed reader's file is closed here, quietly, not in some later finalizer
        raise FlighttestError(f"{path}: cannot parse DataFlash log ({' '.join(failure.split())[:200]})")
    out = {k: {f: np.asarray(v, dtype=float) for f, v in cols.items()} for k, cols in rows.items() if cols["TimeUS"]}
    return out, dict(sorted(params.items())), chatter.getvalue()


def _attitude(msgs: dict[str, dict[str, np.ndarray]]) -> tuple[str, np.ndarray, np.ndarray] | None:
    """(record name, time s, quaternions w x y z) of the first attitude record the log has."""

    def quats(r: dict[str, np.ndarray]) -> np.ndarray | None:
        if "Q1" not in r:
            return None
        q = np.column_stack([r[f"Q{i}"] for i in range(1, 5)])
        n = np.linalg.norm(q, axis=1)
        return q if np.all(np.isfinite(q)) and np.all(np.abs(n - 1) < 0.1) else None

    for name in ATTITUDE_RECORDS:
        if (r := msgs.get(name)) is None or len(r["TimeUS"]) < 2:
            continue
        q = quats(r)
        if q is None and "Roll" in r:
            q = quat_from_euler(*(np.radians(r[k]) for k in ("Roll", "Pitch", "Yaw")))
        if q is not None:
            return name, r["TimeUS"] / 1e6, q
    return None


def _heights(msgs: dict[str, dict[str, np.ndarray]], first: str, origin_s: float) -> list[HeightSource]:
    """Every height record of the log, the position's own (``first``) leading; see module docstring."""
    out: list[HeightSource | None] = []

    def add(rec: str, field: str, kind: str, alt_m: np.ndarray | None = None, keep=None, home: bool = False):
        r = msgs.get(rec)
        if r is None or field not in r:
            return
        alt = r[field] if alt_m is None else alt_m
        sel = np.ones(len(alt), bool) if keep is None else keep
        out.append(height_source(f"{rec}.{field}", kind, r["TimeUS"][sel] / 1e6, alt[sel], origin_s, home))

    if first != "POS":
        add(first, "PD", "estimator", -msgs[first]["PD"], home=True)
    add("POS", "RelHomeAlt", "estimator", home=True)
    add("POS", "Alt", "estimator")
    add("CTUN", "Alt", "estimator", home=True)
    if "BARO" in msgs:
        add("BARO", "Alt", "baro")
    else:
        add("CTUN", "BAlt", "baro")
    if (g := msgs.get("GPS")) is not None:
        add("GPS", "Alt", "gps", keep=(g["Status"] >= GPS_OK_FIX_3D) | np.isnan(g["Status"]))
    if (rf := msgs.get("RFND")) is not None:
        field = "Dist" if np.isfinite(rf["Dist"]).any() else "Dist1"
        keep = (rf["Stat"] == RANGEFINDER_GOOD) | np.isnan(rf["Stat"])  # NaN: not logged
        keep &= (rf["Orient"] == ROTATION_PITCH_270) | np.isnan(rf["Orient"])
        add("RFND", field, "rangefinder", keep=keep & (rf[field] > 0))
    return [h for h in out if h is not None]


def load_dataflash(path: Path) -> FlightLog:
    with open(path, "rb") as fh:
        if fh.read(2) != DF_MAGIC:
            raise FlighttestError(f"{path}: not an ArduPilot DataFlash log (bad header)")
    msgs, params, chatter = _read(path)
    if not msgs:
        raise FlighttestError(f"{path}: DataFlash log has no readable records (truncated or corrupt)")
    notes = ["DataFlash reader: " + line for line in chatter.splitlines()[:3] if line.strip()]
    ekf_name = next((k for k in ("XKF1", "NKF1") if k in msgs and len(msgs[k]["TimeUS"]) >= 2), None)
    cols: dict[str, np.ndarray] = {}
    if ekf_name is not None:
        ekf = msgs[ekf_name]
        t = ekf["TimeUS"] / 1e6
        cols.update(n_m=ekf["PN"], e_m=ekf["PE"], d_m=ekf["PD"], vn_mps=ekf["VN"], ve_mps=ekf["VE"], vd_mps=ekf["VD"])
    elif (pos := msgs.get("POS")) is not None and len(pos["TimeUS"]) >= 2:
        ekf_name = "POS"
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
    cols["boot_s"] = t

    attitude = _attitude(msgs)
    if attitude is not None:
        _, att_t, q = attitude
        qi = normalise_quaternions(resample(att_t, continuous_quaternions(q), t, MAX_GAP_S))
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
        ok = np.isfinite(mode["ModeNum"]) & (np.abs(mode["ModeNum"]) < 2**31)  # damaged records: NaN, 1e30
        names = np.array([mavutil.mode_string_acm(int(n)) for n in mode["ModeNum"][ok]], dtype=object)
        cols["mode"] = resample(mode["TimeUS"][ok] / 1e6, names, t, 1e9, hold=True)
    if (arm := msgs.get("ARM")) is not None:
        cols["armed"] = resample(arm["TimeUS"] / 1e6, (arm["ArmState"] != 0).astype(float), t, 1e9, hold=True)
    elif (ev := msgs.get("EV")) is not None:
        sel = np.isin(ev["Id"], [EV_ARMED, EV_DISARMED])
        if sel.any():
            cols["armed"] = resample(
                ev["TimeUS"][sel] / 1e6, (ev["Id"][sel] == EV_ARMED).astype(float), t, 1e9, hold=True
            )
    if (ev := msgs.get("EV")) is not None:
        sel = np.isin(ev["Id"], [EV_LAND_COMPLETE, EV_NOT_LANDED])
        if sel.any():
            landed = (ev["Id"][sel] == EV_LAND_COMPLETE).astype(float)
            cols["landed"] = resample(ev["TimeUS"][sel] / 1e6, landed, t, 1e9, hold=True)
    reported = None
    if (k2 := msgs.get("XKF2")) is not None:
        w = np.column_stack([k2["VWN"], k2["VWE"], np.zeros(len(k2["VWN"]))])
        reported = wind_report("XKF2", k2["TimeUS"] / 1e6, w, None, 0.0)
        cols.update(state_wind(reported, t, 5.0))
    missing: dict[str, str] = {}
    state = fill_derived(build_state(t, None, cols), missing)
    if reported is not None:
        reported = replace(reported, t_s=reported.t_s - state.attrs["t_origin_s"])
    return FlightLog(
        path=Path(path),
        source="dataflash",
        state=state,
        missing=missing,
        notes=notes,
        heights=_heights(msgs, ekf_name, state.attrs["t_origin_s"]),
        attitude_source=None if attitude is None else attitude[0],
        params=params,
        params_source="dataflash PARM" if params else None,
        wind_reported=reported,
        accel_source="IMU" if "IMU" in msgs else None,
    )
