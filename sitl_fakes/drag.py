"""The fake's own drag: what the air does to each airframe, independent of what flighttest believes.

Per body axis (FRD x, y, z), with ``v`` the air-relative velocity in the body frame (true velocity minus the
true wind, rotated by the true attitude): ``F = −(linear·s·v + quadratic·|v|·v)``.

- ``linear``: the rotors' momentum drag (N per m/s) at hover thrust. Where ``momentum`` is true it scales,
  as ArduCopter SITL's ``SIM_Motor`` computes it, with the rotors' mass flow: ``s = Σ√T_i / (n·√T_hover)``
  (1 at hover, 0 with the motors stopped). PX4 SIH's ``SIH_KDV`` is a constant (``momentum`` false, s = 1).
- ``quadratic``: the body's bluff-body drag ½·ρ·CdA (N per (m/s)²), ArduCopter SITL's ``areaCd``.

The vertical axis gets the same coefficients: SIH's drag is isotropic, and ArduCopter SITL applies its
``areaCd`` and its momentum drag on body z too (``SIM_Frame::calculate_forces``, ``SIM_Motor::calculate_forces``).

The table is keyed by the profile's name; the product's ``drag_n_per_mps`` and ``[drag]`` table are never
read (flighttest must find the drag, not be told it). A profile not in the table gets a physical estimate
from its geometry (``estimate_for``); ``--truth-drag`` overrides both (``parse_truth_drag``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from flighttest.model.aero import G_MPS2
from flighttest.model.profiles import VehicleProfile

AIR_DENSITY_KGPM3 = 1.225
# ArduCopter SITL's momentum-drag coefficient (SIM_Frame default_model.mdrag_coef): per motor,
# F = mdrag_coef·√(ρ·A_rotor)·√T·v
SITL_MDRAG_COEF = 0.2
# bluff-body CdA per square metre of arm length (centre to rotor): 0.8 gives the x500's 0.05 m² (2 kg X frame,
# 0.25 m arms: central plates, arms, battery and landing gear broadside at Cd ≈ 1); used for frames not tabled
CDA_PER_ARM2 = 0.8


@dataclass(frozen=True)
class TruthDrag:
    linear_n_per_mps: tuple[float, float, float]  # body x, y, z, at hover thrust
    quadratic_n_per_mps2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    momentum: bool = False  # the linear term scales with Σ√T_i (rotor momentum drag), else constant
    source: str = ""

    def __post_init__(self) -> None:
        values = (*self.linear_n_per_mps, *self.quadratic_n_per_mps2)
        if len(self.linear_n_per_mps) != 3 or len(self.quadratic_n_per_mps2) != 3:
            raise ValueError("drag: three linear and three quadratic coefficients (body x, y, z)")
        if not all(math.isfinite(v) and v >= 0.0 for v in values):
            raise ValueError("drag coefficients must be finite and ≥ 0")

    def force_body_n(self, vx: float, vy: float, vz: float, scale: float = 1.0) -> tuple[float, float, float]:
        """Drag force (N) along body x, y, z for the air-relative body velocity (m/s); ``scale`` multiplies the
        linear term (the rotors' Σ√T_i against hover's)."""
        (lx, ly, lz), (qx, qy, qz) = self.linear_n_per_mps, self.quadratic_n_per_mps2
        return (-(lx * scale * vx + qx * abs(vx) * vx), -(ly * scale * vy + qy * abs(vy) * vy),
                -(lz * scale * vz + qz * abs(vz) * vz))  # fmt: skip

    def describe(self) -> str:
        lin = ",".join(f"{x:g}" for x in self.linear_n_per_mps)
        quad = ",".join(f"{x:g}" for x in self.quadratic_n_per_mps2)
        return f"linear {lin} N/(m/s){' (momentum)' if self.momentum else ''}, quadratic {quad} N/(m/s)^2"


def momentum_drag_n_per_mps(profile: VehicleProfile, coef: float = SITL_MDRAG_COEF) -> float:
    """Total rotor momentum drag at hover (N per m/s) by ArduCopter SITL's formula:
    n·coef·√(ρ·A_rotor·T_hover)."""
    area = math.pi * (0.5 * profile.rotor_diameter_m) ** 2
    t_hover = profile.mass_kg * G_MPS2 / profile.n_rotors
    return profile.n_rotors * coef * math.sqrt(AIR_DENSITY_KGPM3 * area * t_hover)


def estimate_for(profile: VehicleProfile) -> TruthDrag:
    """A physical estimate for an airframe the table does not know: ArduCopter SITL's momentum drag for its
    rotors, and a bluff body of CdA = 0.8·arm² (the x500's proportions)."""
    lin = momentum_drag_n_per_mps(profile)
    quad = 0.5 * AIR_DENSITY_KGPM3 * CDA_PER_ARM2 * profile.arm_length_m**2
    source = f"estimate: SITL momentum drag (mdrag_coef {SITL_MDRAG_COEF}) + CdA {CDA_PER_ARM2}·arm²"
    return TruthDrag((lin, lin, lin), (quad, quad, quad), True, source)


def _iso(lin: float, quad: float, momentum: bool, source: str) -> TruthDrag:
    return TruthDrag((lin, lin, lin), (quad, quad, quad), momentum, source)


# Each shipped airframe's truth. Figures against the reference flights: sitl_fakes/README.md, and bench/RESULTS.md,
# "The fake in wind: its own drag, turbulence, and no wind report by default (issue 21)".
TRUTH_DRAG: dict[str, TruthDrag] = {
    # PX4 SIH (simulator_sih/sih.cpp): −SIH_KDV·v_air, SIH_KDV 1 N per m/s, linear and isotropic; the IMU of
    # ../shared/wind_sitl's PX4 flights fits 1.000 /s on 1 kg with no quadratic term
    "sih_quadx": _iso(1.0, 0.0, False, "PX4 SIH: SIH_KDV 1 N/(m/s), linear, isotropic"),
    # ArduCopter SITL's default quad (SIM_Frame.cpp default_model: 3 kg, refSpd 15.08 m/s at refAngle 45° and
    # refAlt 593 m, disc_area 0.385 m², mdrag_coef 0.2), with the air density of the ISA at its altitude (SITL
    # computes both terms with it): areaCd = (m g tan 45° − momentum drag at 15.08·cos 45°) / (½ρ(593 m)·15.08²)
    # = 0.174 m²; flown at CMAC (584 m, ρ 1.158 kg/m³): ½ρ·areaCd = 0.101 N/(m/s)², momentum drag
    # 0.2·√(ρ·0.0963 m²)·√7.35 N per motor = 0.724 N/(m/s) at hover (0.745 and 0.0999 at sea level);
    # ../shared/wind_sitl's ArduCopter IMU fits 0.728-0.729 + 0.089-0.104
    "arducopter_sitl": _iso(0.724, 0.101, True, "ArduCopter SITL SIM_Frame default_model at CMAC: momentum "
                                               "0.724 N/(m/s) at hover + areaCd 0.174 m²"),
    # Holybro X500 (2 kg X frame, 10-inch rotors): rotor momentum drag 0.6 N/(m/s) at hover (0.3 /s, inside the
    # 0.15-0.5 /s that PX4's EKF2_MCOEF and published rotor-drag identifications of 1-2 kg quads span; SITL's
    # formula with its 0.2 coefficient gives 0.44) + a bluff body of CdA 0.05 m² (½ρ·CdA = 0.0306)
    "x500": _iso(0.6, 0.5 * AIR_DENSITY_KGPM3 * 0.05, True, "x500: momentum 0.6 N/(m/s) + CdA 0.05 m²"),
    # Parrot Mambo (63 g, 6.5 cm rotors, 0.062 m arms): SITL's momentum formula 0.020 N/(m/s) (0.32 /s), a
    # body of CdA 0.0031 m² (½ρ·CdA = 0.0019): the geometric estimate
    "mambo": _iso(0.0200, 0.0019, True, "Mambo: SITL momentum formula + CdA 0.0031 m²"),
    # the paper's tunnel rig (1.2 kg, 9.5-inch rotors, 0.225 m arms): SITL's momentum formula 0.325 N/(m/s)
    # (0.27 /s), CdA 0.04 m² (½ρ·CdA = 0.0248): the geometric estimate
    "tunnel_rig": _iso(0.325, 0.0248, True, "tunnel rig: SITL momentum formula + CdA 0.04 m²"),
}


def truth_drag_for(profile: VehicleProfile) -> TruthDrag:
    """The fake's drag for this airframe: the table's, else the geometric estimate."""
    return TRUTH_DRAG.get(profile.name) or estimate_for(profile)


def parse_truth_drag(text: str) -> TruthDrag:
    """``--truth-drag``: ``LIN,QUAD`` (every body axis) or ``LX,LY,LZ,QX,QY,QZ``; N per m/s and N per (m/s)²,
    a constant linear term (no thrust scaling): tests know the force exactly. ``ValueError`` naming the problem."""
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        raise ValueError(f"expected LIN,QUAD or LX,LY,LZ,QX,QY,QZ numbers (got {text!r})") from None
    if len(vals) == 2:
        lin, quad = vals
        return TruthDrag((lin, lin, lin), (quad, quad, quad), False, f"--truth-drag {text}")
    if len(vals) == 6:
        return TruthDrag(tuple(vals[:3]), tuple(vals[3:]), False, f"--truth-drag {text}")  # type: ignore[arg-type]
    raise ValueError(f"expected 2 (LIN,QUAD) or 6 (LX,LY,LZ,QX,QY,QZ) numbers (got {len(vals)})")
