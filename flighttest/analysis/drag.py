"""The airframe's drag identified from a calibration flight (``flighttest fly drag``), with its uncertainty.

Thrust acts along −z_body, so the specific force the IMU measures along body x and y is the air's drag
over the mass (``flighttest.model.drag``). Over the calibration's legs — the same speeds both ways along
two axes — a least-squares fit finds the linear and quadratic coefficient of each body axis together
with the steady wind that blew (it cancels between opposite legs, so it is found, not assumed). The
uncertainty is a block bootstrap over the flight (blocks of ``BLOCK_S``: the residuals of neighbouring
samples are not independent); ``rel_sd`` is the largest relative spread of the force over the airspeeds
flown, never below ``REL_SD_FLOOR`` (a two-term model of a real airframe is not exact).

``identify_drag`` refuses — ``NoDrag`` with the reason — a log that cannot say: too few samples at
speed, a single speed, a fit no more certain than ``REL_SD_MAX``, or a drag no airframe has.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from flighttest.analysis.schema import FlightLog
from flighttest.errors import FlighttestError
from flighttest.model.aero import G_MPS2
from flighttest.model.drag import DragModel
from flighttest.model.frames import ned_to_body
from flighttest.model.profiles import VehicleProfile

BLOCK_S = 2.0
BOOTSTRAP = 40
REL_SD_FLOOR = 0.03
REL_SD_MAX = 0.3  # a model less certain than this is not worth storing: the assumed one says as much
MIN_SPEED_SPREAD_MPS = 1.0  # the legs must span at least this much airspeed: a line needs two points
MIN_SAMPLES = 200
MAX_TILT_DEG = 60.0  # no airframe needs more to hold against its drag at the speeds flown
MIN_FORCE_OF_WEIGHT = 0.005  # ... nor feels less than this of its weight at the fastest leg
MAX_WIND_MPS = 15.0


class NoDrag(FlighttestError):
    """This log does not identify the drag (the reason is the message)."""


@dataclass
class DragIdentification:
    model: DragModel
    wind_ned_mps: tuple[float, float, float]
    samples: int
    airspeed_max_mps: float
    residual_sd_mps2: float
    bootstrap: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        return {"drag": self.model.to_table(), "calibration_wind_ned_mps": [round(x, 3) for x in self.wind_ned_mps],
                "samples": self.samples, "airspeed_max_mps": round(self.airspeed_max_mps, 3),
                "residual_sd_mps2": round(self.residual_sd_mps2, 4), "bootstrap": self.bootstrap}  # fmt: skip


def calibration_samples(log: FlightLog) -> dict[str, np.ndarray]:
    """The samples of the calibration's stream: velocity NED, attitude, body specific force x, y, time."""
    st = log.state
    start = next((e for e in log.events if e.get("event") == "stream_start"), None)
    end = next((e for e in log.events if e.get("event") == "stream_end"), None)
    t = st["t_s"].to_numpy(float)
    sel = np.ones(len(t), dtype=bool)
    if start is not None and isinstance(start.get("t_s"), int | float):
        sel &= t >= float(start["t_s"])
    if end is not None and isinstance(end.get("t_s"), int | float):
        sel &= t <= float(end["t_s"])
    cols = ["vn_mps", "ve_mps", "vd_mps", "qw", "qx", "qy", "qz", "ax_mps2", "ay_mps2", "az_mps2"]
    data = {c: st[c].to_numpy(float)[sel] for c in cols if c in st}
    if len(data) < len(cols):
        raise NoDrag(f"{log.path}: the log has no body specific force (IMU) or attitude: nothing to identify")
    ok = np.all([np.isfinite(v) for v in data.values()], axis=0)
    out = {k: v[ok] for k, v in data.items()}
    out["t_s"] = t[sel][ok]
    return out


def _coefficients(b: np.ndarray, f: np.ndarray, scale: np.ndarray | float = 1.0
                  ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(linear, quadratic) ≥ 0 minimising |f − (−(l·scale·b + q·|b|·b))|² along one axis, and the residuals."""
    cols = np.column_stack([-scale * b, -np.abs(b) * b])
    best = None
    for use in ((0, 1), (0,), (1,)):  # the unconstrained fit first; a negative term is dropped
        coef = np.zeros(2)
        sol, *_ = np.linalg.lstsq(cols[:, use], f, rcond=None)
        if np.any(sol < 0):
            continue
        coef[list(use)] = sol
        r = f - cols @ coef
        if best is None or r @ r < best[1] @ best[1] - 1e-12:
            best = (coef, r)
        if use == (0, 1):
            break
    if best is None:
        return np.zeros(2), f.copy()
    return best


def _fit(s: dict[str, np.ndarray], idx: np.ndarray, mass_kg: float, x0: np.ndarray | None = None,
         exponent: float = 0.0) -> np.ndarray:  # fmt: skip
    """(lx, ly, qx, qy, wn, we) minimising the specific-force residuals of the samples ``idx``: for a given
    wind the coefficients are a linear least-squares fit, so Gauss-Newton searches the wind alone. The linear
    term grows with (thrust / hover thrust)^``exponent`` (``flighttest.model.drag``)."""
    vn, ve, vd = (s[k][idx] for k in ("vn_mps", "ve_mps", "vd_mps"))
    q = tuple(s[k][idx] for k in ("qw", "qx", "qy", "qz"))
    fx, fy = s["ax_mps2"][idx] * mass_kg, s["ay_mps2"][idx] * mass_kg
    scale = np.clip(np.abs(s["az_mps2"][idx]) / G_MPS2, 0.1, 3.0) ** exponent

    def solve(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        bx, by, _ = ned_to_body(vn - w[0], ve - w[1], vd, *q)
        (cx, rx), (cy, ry) = _coefficients(bx, fx, scale), _coefficients(by, fy, scale)
        return np.array([cx[0], cy[0], cx[1], cy[1]]), np.concatenate([rx, ry])

    w = np.zeros(2) if x0 is None else np.asarray(x0[4:6], float).copy()
    coef, r = solve(w)
    for _ in range(30):
        jac = np.empty((len(r), 2))
        for k in range(2):
            dw = np.zeros(2)
            dw[k] = 1e-3
            jac[:, k] = (solve(w + dw)[1] - r) / 1e-3
        step, *_ = np.linalg.lstsq(jac, -r, rcond=None)
        lam = 1.0
        while lam > 1e-3:
            w_new = np.clip(w + lam * step, -MAX_WIND_MPS, MAX_WIND_MPS)
            c_new, r_new = solve(w_new)
            if r_new @ r_new < r @ r:
                break
            lam *= 0.5
        else:
            break
        converged = np.hypot(*(w_new - w)) < 1e-4
        w, coef, r = w_new, c_new, r_new
        if converged:
            break
    return np.concatenate([coef, w])


def identify_drag(log: FlightLog, profile: VehicleProfile, source: str = "") -> DragIdentification:
    s = calibration_samples(log)
    n = len(s["t_s"])
    if n < MIN_SAMPLES:
        raise NoDrag(f"{log.path}: {n} samples in the calibration's stream (at least {MIN_SAMPLES}): "
                     "fly `flighttest fly drag`")
    m = profile.mass_kg
    # the thrust dependence is physics, not what level legs at hover thrust can tell: the profile's
    exponent = profile.drag.linear_thrust_exponent if profile.drag is not None else 0.0
    all_idx = np.arange(n)
    th = _fit(s, all_idx, m, exponent=exponent)
    thrust = np.abs(s["az_mps2"]) / G_MPS2
    model = DragModel((th[0], th[1]), (th[2], th[3]), 0.0, "fit", linear_thrust_exponent=exponent)
    bx, by, _ = ned_to_body(s["vn_mps"] - th[4], s["ve_mps"] - th[5], s["vd_mps"], s["qw"], s["qx"], s["qy"], s["qz"])
    air = np.hypot(bx, by)
    if np.percentile(air, 95) - np.percentile(air, 5) < MIN_SPEED_SPREAD_MPS:
        raise NoDrag(f"{log.path}: the airspeed spans {np.percentile(air, 95) - np.percentile(air, 5):.2f} m/s "
                     f"(at least {MIN_SPEED_SPREAD_MPS:g}): fly legs at more than one speed")  # fmt: skip
    fx, fy = model.force_n(bx, by, thrust)
    resid = np.concatenate([fx / m - s["ax_mps2"], fy / m - s["ay_mps2"]])
    # block bootstrap: resample BLOCK_S blocks of the flight with replacement
    rng = np.random.default_rng(0)
    blocks = np.floor((s["t_s"] - s["t_s"][0]) / BLOCK_S).astype(int)
    ids = np.unique(blocks)
    by_block = [np.flatnonzero(blocks == b) for b in ids]
    reps = []
    for _ in range(BOOTSTRAP):
        pick = rng.integers(0, len(by_block), len(by_block))
        reps.append(_fit(s, np.concatenate([by_block[k] for k in pick]), m, th, exponent))
    reps = np.array(reps)
    v_top = float(np.percentile(air, 95))
    speeds = np.linspace(0.5, max(v_top, 0.6), 12)
    rel = 0.0
    for axis in (0, 1):
        f_est = th[axis] * speeds + th[2 + axis] * speeds**2
        f_rep = reps[:, axis, None] * speeds + reps[:, 2 + axis, None] * speeds**2
        spread = 0.5 * (np.percentile(f_rep, 84, axis=0) - np.percentile(f_rep, 16, axis=0))
        rel = max(rel, float(np.max(spread / np.maximum(f_est, 1e-9))))
    rel_sd = max(REL_SD_FLOOR, rel)
    f_top = max(th[0] * v_top + th[2] * v_top**2, th[1] * v_top + th[3] * v_top**2)
    weight = m * G_MPS2
    if f_top > math.tan(math.radians(MAX_TILT_DEG)) * weight:
        raise NoDrag(f"{log.path}: a drag of {f_top:.2f} N at {v_top:.1f} m/s would tilt the vehicle past "
                     f"{MAX_TILT_DEG:g}° to hold: not a plausible drag for {profile.name}")  # fmt: skip
    if f_top < MIN_FORCE_OF_WEIGHT * weight:
        raise NoDrag(f"{log.path}: a drag of {f_top:.3f} N at {v_top:.1f} m/s is below what the IMU can tell from "
                     "noise: the log does not identify it")  # fmt: skip
    if rel_sd > REL_SD_MAX:
        raise NoDrag(f"{log.path}: the drag is known only to ±{rel_sd:.0%} (at most ±{REL_SD_MAX:.0%} to be worth "
                     "storing): fly the calibration in steadier air or with longer legs")  # fmt: skip
    where = source or str(log.path)
    model = DragModel((float(th[0]), float(th[1])), (float(th[2]), float(th[3])), round(rel_sd, 4),
                      f"identified from {where} (flighttest identify --drag)",
                      {"calibration_wind_ned_mps": [round(float(th[4]), 3), round(float(th[5]), 3), 0.0],
                       "airspeed_max_mps": round(v_top, 3), "samples": n}, exponent)  # fmt: skip
    boot = {"replicates": BOOTSTRAP, "block_s": BLOCK_S,
            "linear_sd_n_per_mps": [float(np.std(reps[:, 0])), float(np.std(reps[:, 1]))],
            "quadratic_sd_n_per_mps2": [float(np.std(reps[:, 2])), float(np.std(reps[:, 3]))]}  # fmt: skip
    return DragIdentification(model, (float(th[4]), float(th[5]), 0.0), n, v_top, float(np.std(resid)), boot)
