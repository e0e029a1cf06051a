"""The airframe's drag across the thrust axis: what the wind does to a multicopter, and how it is sensed.

Per body axis x and y, with ``v`` the air-relative velocity in the body frame (CONVENTIONS §1):
``F = −(linear·v + quadratic·|v|·v)``. The linear term is the rotors' momentum drag (PX4's
``EKF2_MCOEF``, ArduPilot's ``EK3_DRAG_MCOEF``; PX4 SIH's whole drag, ``SIH_KDV``), the quadratic one the
body's bluff-body drag (``EKF2_BCOEF_X/Y``, ``EK3_DRAG_BCOEF_X/Y``; most of ArduCopter SITL's frame
model at speed). Thrust acts along −z_body only, so the specific force the IMU measures across it is
``F / m``: the air's drag, from which the wind is estimated (``flighttest.model.wind_estimate``).

``rel_sd`` is the model's 1 σ relative uncertainty in that force over the airspeeds flown: an assumed
model is ±50 %, one identified from a calibration flight says its own (``flighttest.analysis.drag``).

A rotor's momentum drag grows with the square root of its thrust (momentum theory: the air it turns grows
so), which a descent moves far from hover; ``linear_thrust_exponent`` 0.5 scales the linear term with
(thrust / hover thrust)^0.5, the thrust read off the IMU's own specific force along z. PX4 SIH's drag does
not depend on thrust (exponent 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

ASSUMED_REL_SD = 0.5  # a drag model nobody measured


@dataclass(frozen=True)
class DragModel:
    linear_n_per_mps: tuple[float, float]  # body x, y
    quadratic_n_per_mps2: tuple[float, float] = (0.0, 0.0)
    rel_sd: float = ASSUMED_REL_SD
    source: str = "assumed"
    details: dict[str, Any] = field(default_factory=dict, compare=False)  # an identification's own figures
    linear_thrust_exponent: float = 0.0

    def __post_init__(self) -> None:
        values = (*self.linear_n_per_mps, *self.quadratic_n_per_mps2, self.rel_sd)
        if not all(isinstance(v, int | float) and math.isfinite(v) and v >= 0 for v in values):
            raise ValueError("drag coefficients and their relative uncertainty must be finite and ≥ 0")
        if self.linear_n_per_mps[0] + self.quadratic_n_per_mps2[0] <= 0 or (
            self.linear_n_per_mps[1] + self.quadratic_n_per_mps2[1] <= 0
        ):
            raise ValueError("each body axis needs some drag (linear or quadratic > 0)")

    @classmethod
    def isotropic_linear(cls, n_per_mps: float, rel_sd: float = ASSUMED_REL_SD, source: str = "assumed") -> DragModel:
        return cls((n_per_mps, n_per_mps), (0.0, 0.0), rel_sd, source)

    def thrust_scale(self, thrust_ratio=1.0):
        """The linear term's factor at ``thrust_ratio`` = thrust / hover thrust (clipped to 0.1..3)."""
        if not self.linear_thrust_exponent:
            return 1.0
        return np.clip(thrust_ratio, 0.1, 3.0) ** self.linear_thrust_exponent

    def force_n(self, vx_mps, vy_mps, thrust_ratio=1.0):
        """Drag force along body x and y (N) for air-relative body velocity (m/s); numpy-vectorised."""
        k = self.thrust_scale(thrust_ratio)
        (lx, ly), (qx, qy) = self.linear_n_per_mps, self.quadratic_n_per_mps2
        return (-(k * lx * vx_mps + qx * np.abs(vx_mps) * vx_mps),
                -(k * ly * vy_mps + qy * np.abs(vy_mps) * vy_mps))  # fmt: skip

    def slope_n_per_mps(self, vx_mps, vy_mps, thrust_ratio=1.0):
        """How fast the drag grows with airspeed along x and y (N per m/s, > 0): −dF/dv."""
        k = self.thrust_scale(thrust_ratio)
        (lx, ly), (qx, qy) = self.linear_n_per_mps, self.quadratic_n_per_mps2
        return k * lx + 2.0 * qx * np.abs(vx_mps), k * ly + 2.0 * qy * np.abs(vy_mps)

    def mean_linear_n_per_mps(self, airspeed_mps: float = 2.0) -> float:
        """One linear coefficient for what needs one (the feed-forward): the secant at ``airspeed_mps``."""
        return 0.5 * sum(lin + quad * airspeed_mps for lin, quad in zip(self.linear_n_per_mps,
                                                                          self.quadratic_n_per_mps2))  # fmt: skip

    def to_table(self) -> dict[str, Any]:
        return {"linear_n_per_mps": list(self.linear_n_per_mps),
                "quadratic_n_per_mps2": list(self.quadratic_n_per_mps2), "rel_sd": self.rel_sd,
                "linear_thrust_exponent": self.linear_thrust_exponent, "source": self.source,
                **({"details": self.details} if self.details else {})}  # fmt: skip

    @classmethod
    def from_table(cls, t: dict[str, Any]) -> DragModel:
        """A profile's ``[drag]`` table (``ValueError`` naming what is wrong)."""
        def pair(key: str, default: tuple[float, float] | None) -> tuple[float, float]:
            v = t.get(key, default)
            if v is None:
                raise ValueError(f"[drag] needs {key}")
            if isinstance(v, int | float) and not isinstance(v, bool):
                v = (v, v)
            if not (isinstance(v, list | tuple) and len(v) == 2
                    and all(isinstance(x, int | float) and not isinstance(x, bool) for x in v)):  # fmt: skip
                raise ValueError(f"[drag] {key} must be a number or two (body x, y)")
            return float(v[0]), float(v[1])

        unknown = set(t) - {"linear_n_per_mps", "quadratic_n_per_mps2", "rel_sd", "source", "details",
                            "linear_thrust_exponent"}
        if unknown:
            raise ValueError(f"[drag] has unknown keys: {', '.join(sorted(unknown))}")
        rel = t.get("rel_sd", ASSUMED_REL_SD)
        if isinstance(rel, bool) or not isinstance(rel, int | float):
            raise ValueError("[drag] rel_sd must be a number")
        source = t.get("source", "assumed")
        details = t.get("details", {})
        exponent = t.get("linear_thrust_exponent", 0.0)
        if isinstance(exponent, bool) or not isinstance(exponent, int | float) or not 0 <= exponent <= 1:
            raise ValueError("[drag] linear_thrust_exponent must be a number from 0 to 1")
        return cls(pair("linear_n_per_mps", None), pair("quadratic_n_per_mps2", (0.0, 0.0)), float(rel),
                   str(source), details if isinstance(details, dict) else {}, float(exponent))  # fmt: skip
