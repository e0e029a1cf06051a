"""The fake's ground truth as CSV: one row per physics step (or decimated), plus event rows.

Columns and row kinds are documented in ``sitl_fakes/README.md``; keep the two in step.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

from sitl_fakes.physics import rotate_ned_to_body

COLUMNS = (
    "t_s", "unix_s", "kind", "mode", "armed", "landed",
    "n_m", "e_m", "d_m", "vn_mps", "ve_mps", "vd_mps",
    "qw", "qx", "qy", "qz", "p_radps", "q_radps", "r_radps",
    "wind_n_mps", "wind_e_mps", "wind_d_mps",
    "w_mps", "u_mps", "depth_n", "region", "thrust_loss", "dT_T",
    "t1_n", "t2_n", "t3_n", "t4_n",
    "gust_n_mps", "gust_e_mps", "gust_d_mps", "vax_mps", "vay_mps", "vaz_mps", "fx_mps2", "fy_mps2", "fz_mps2",
    "est_wind_n_mps", "est_wind_e_mps",
    "sp_source", "sp_type_mask", "sp_n_m", "sp_e_m", "sp_d_m", "sp_vn_mps", "sp_ve_mps", "sp_vd_mps",
    "sp_an_mps2", "sp_ae_mps2", "sp_ad_mps2", "sp_yaw_deg",
    "detail",
)  # fmt: skip
FLUSH_PERIOD_S = 1.0


def _f(x: float) -> str:
    if x != x or x in (math.inf, -math.inf):
        return ""
    return f"{x:.5g}" if abs(x) < 1e-3 else f"{x:.4f}"


def _quote(text: str) -> str:
    if any(c in text for c in ',"\n'):
        return '"' + text.replace('"', '""').replace("\n", " ") + '"'
    return text


class TruthLog:
    def __init__(self, path: Path | None, t0_monotonic: float):
        self.path = path
        self.t0 = t0_monotonic
        self.fh = None
        self.last_flush = t0_monotonic
        self.rows = 0
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            self.fh = open(path, "w", encoding="utf-8", newline="")  # noqa: SIM115 - lives with the fake
            self.fh.write(",".join(COLUMNS) + "\n")
            self.fh.flush()
        self.n_cols = len(COLUMNS)

    def row(self, now: float, kind: str, mode: str, armed: bool, landed: bool, state=None, dist=None,
            wind=(0.0, 0.0, 0.0), sp=None, detail: str = "", gust=None, est_wind=None) -> None:  # fmt: skip
        """``state``: RigidBodyState; ``dist``: Disturbance; ``wind``: the true wind (NED), ``gust``: its
        turbulence part; ``est_wind``: the autopilot's wind estimate (None: it has none);
        ``sp``: (source, type_mask, Target)."""
        if self.fh is None:
            return
        flags = ["1" if armed else "0", "1" if landed else "0"]
        parts = [f"{now - self.t0:.4f}", f"{time.time():.6f}", kind, mode, *flags]
        if state is not None:
            s = state
            parts += [_f(v) for v in (s.n_m, s.e_m, s.d_m, s.vn_mps, s.ve_mps, s.vd_mps, s.qw, s.qx, s.qy, s.qz,
                                      s.p_radps, s.q_radps, s.r_radps, wind[0], wind[1], wind[2])]  # fmt: skip
        else:
            parts += [""] * 16
        if dist is not None:
            parts += [_f(dist.w_mps), _f(dist.u_mps), _f(dist.depth_n), str(dist.region), _f(dist.loss), _f(dist.dT_T)]
        else:
            parts += [""] * 6
        if state is not None:
            s = state
            parts += [_f(t) for t in s.thrust_n]
            parts += [_f(g) for g in gust] if gust is not None else [""] * 3
            air = rotate_ned_to_body(s.vn_mps - wind[0], s.ve_mps - wind[1], s.vd_mps - wind[2], s.qw, s.qx, s.qy, s.qz)
            parts += [_f(v) for v in (*air, s.fx_mps2, s.fy_mps2, s.fz_mps2)]
        else:
            parts += [""] * 13
        parts += [_f(est_wind[0]), _f(est_wind[1])] if est_wind is not None else ["", ""]
        if sp is not None:
            source, mask, t = sp
            yaw = math.degrees(t.yaw_rad) if t.yaw_rad == t.yaw_rad else math.nan
            parts += [source, str(mask)] + [_f(v) for v in (*t.pos, *t.vel, *t.acc, yaw)]
        else:
            parts += [""] * 12
        parts.append(_quote(detail))
        self.fh.write(",".join(parts) + "\n")
        self.rows += 1
        if now - self.last_flush >= FLUSH_PERIOD_S:
            self.flush(now)

    def flush(self, now: float | None = None) -> None:
        if self.fh is not None:
            self.fh.flush()
        self.last_flush = time.monotonic() if now is None else now

    def close(self) -> None:
        if self.fh is not None:
            self.fh.flush()
            self.fh.close()
            self.fh = None
