"""The wind the live guard judges with: every estimate flighttest has, each with its uncertainty, fused.

- the operator's (``--wind-ned``, a measurement on the ground): a prior, with its standard deviation;
- the autopilot's report (``WIND_COV``), used while fresh and only when it is an estimate: a report of
  exactly zero is what an estimator that does not estimate the wind sends, not a calm;
- nothing known: calm, with ``unknown_sd_mps``.

The fused wind is the inverse-variance mean, and its uncertainty carries the estimates' disagreement too
(the variance of the mixture), so two sources that contradict each other widen the guard's margin rather
than narrow it. The guard judges the worst air within ``WIND_COVERAGE_SIGMAS`` of it
(``flighttest.model.frames.worst_blade_velocity_mps``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

# a horizontal wind within this many σ of the estimate covers 95 % of a 2-D normal distribution
WIND_COVERAGE_SIGMAS = 2.45
WIND_REPORT_MAX_AGE_S = 2.0  # PX4 and the fake send WIND_COV at 2 Hz or more: older is not the wind now
REPORT_SD_UNKNOWN_MPS = 1.0  # a report that gives no accuracy
PRIOR_SD_MPS = 1.0  # a wind measured on the ground, at the vehicle's height: shear and gusts
MIN_SD_MPS = 0.05  # no estimate of the wind is better than this


@dataclass(frozen=True)
class WindEstimate:
    ned_mps: tuple[float, float, float]
    sd_mps: float  # horizontal, 1 σ per axis
    source: str

    @property
    def radius_mps(self) -> float:
        """How far from ``ned_mps`` the guard looks for the worst air."""
        return WIND_COVERAGE_SIGMAS * self.sd_mps

    def describe(self) -> dict[str, object]:
        return {"wind_ned_mps": [round(x, 3) for x in self.ned_mps], "wind_sd_mps": round(self.sd_mps, 3),
                "wind_source": self.source}  # fmt: skip


def fuse(estimates: Sequence[WindEstimate]) -> WindEstimate:
    """Inverse-variance mean; its variance (1 / the summed precision) widened by the weighted spread of the
    estimates about it, the larger horizontal axis's."""
    if len(estimates) == 1:
        return estimates[0]
    weights = [1.0 / max(e.sd_mps, MIN_SD_MPS) ** 2 for e in estimates]
    total = sum(weights)
    mean = tuple(sum(w * e.ned_mps[i] for w, e in zip(weights, estimates)) / total for i in range(3))
    spread = max(sum(w * (e.ned_mps[i] - mean[i]) ** 2 for w, e in zip(weights, estimates)) / total for i in (0, 1))
    return WindEstimate(mean, math.sqrt(1.0 / total + spread), "+".join(e.source for e in estimates))


class WindReport(Protocol):
    wind_ned_mps: tuple[float, float, float] | None
    wind_accuracy_mps: float
    t_wind: float | None


def autopilot_report(st: WindReport, now_s: float) -> WindEstimate | None:
    """The autopilot's wind while it is a fresh estimate, else None."""
    w = st.wind_ned_mps
    if w is None or st.t_wind is None or now_s - st.t_wind > WIND_REPORT_MAX_AGE_S:
        return None
    if not all(math.isfinite(x) for x in w) or all(x == 0.0 for x in w):
        return None
    acc = st.wind_accuracy_mps
    sd = acc if math.isfinite(acc) and acc > 0 else REPORT_SD_UNKNOWN_MPS
    return WindEstimate(tuple(float(x) for x in w), sd, "autopilot")


@dataclass
class WindSources:
    """The estimates available to one flight; ``current`` fuses those valid now."""

    prior: WindEstimate | None = None  # the operator's
    unknown_sd_mps: float = 0.0  # nothing known: calm, this uncertain

    def current(self, st: WindReport, now_s: float) -> WindEstimate:
        found = [e for e in (autopilot_report(st, now_s), self.prior) if e is not None]
        if not found:
            return WindEstimate((0.0, 0.0, 0.0), self.unknown_sd_mps, "assumed calm")
        return fuse(found)
