"""Rotations between NED and body FRD, and the blade-frame velocity the VRS guard looks at.

Quaternions are ``(w, x, y, z)`` and rotate body → NED, as PX4 and MAVSDK report them. Functions
take either scalars or numpy arrays (one element per state) and use plain arithmetic, so a single
guard sample costs microseconds and a million states run vectorised through the *same* code.

**One argument order** for every helper that rotates a vector, here and elsewhere (the guard's
``predicted_blade_velocity_mps``, the fake's own ``sitl_fakes.physics.rotate_*`` and
``sitl_fakes.disturbance.blade_velocity_mps``): the vector's three components first, then the
quaternion's ``w, x, y, z``, then (where there is one) the wind's three components, defaulting to
still air. A quaternion alone (``quat_to_rotmat``, ``quat_to_euler``, ``quat_multiply``) is one
``(..., 4)`` array. Both sides of a swap are seven floats, so nothing but a test catches one:
``tests/test_frames.py`` checks every helper's signature and a rotation with a known answer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from flighttest.model.aero import CONE_DEG, guard_margin_mps

# a float for one state, an array (one element per state) for many: the same arithmetic serves both
FloatOrArray = float | np.ndarray

UNIT_QUAT_TOL = 1e-3
# WGS-84 equatorial radius: local north/east metres from latitude/longitude (flat Earth over a flight)
EARTH_RADIUS_M = 6_378_137.0


def quat_to_rotmat(q_wxyz) -> np.ndarray:
    """Rotation matrix body → NED, shape (..., 3, 3), from quaternions shaped (..., 4)."""
    q = np.asarray(q_wxyz, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )
    return r


def quat_from_euler(roll_rad, pitch_rad, yaw_rad) -> np.ndarray:
    """Quaternion (w, x, y, z) from ZYX (yaw-pitch-roll) Euler angles, shape (..., 4)."""
    cr, sr = np.cos(np.asarray(roll_rad) / 2), np.sin(np.asarray(roll_rad) / 2)
    cp, sp = np.cos(np.asarray(pitch_rad) / 2), np.sin(np.asarray(pitch_rad) / 2)
    cy, sy = np.cos(np.asarray(yaw_rad) / 2), np.sin(np.asarray(yaw_rad) / 2)
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        -1,
    )


def quat_to_euler(q_wxyz) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZYX Euler angles (roll, pitch, yaw) in rad from quaternions (..., 4)."""
    q = np.asarray(q_wxyz, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product ``a ⊗ b`` of (..., 4) quaternions."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    aw, ax, ay, az = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bw, bx, by, bz = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        -1,
    )


def ned_to_body(
    vn: FloatOrArray, ve: FloatOrArray, vd: FloatOrArray,
    qw: FloatOrArray, qx: FloatOrArray, qy: FloatOrArray, qz: FloatOrArray,
) -> tuple[FloatOrArray, FloatOrArray, FloatOrArray]:  # fmt: skip
    """Rotate a NED vector into body FRD: ``v_b = R(q)ᵀ v_ned``. Returns (vx, vy, vz) body.

    Uses ``v' = v + 2 r × (r × v + s v)`` with the conjugate quaternion (s, r) = (w, −x, −y, −z),
    which needs no matrix and no normalisation beyond the unit quaternion the caller provides.
    """
    rx, ry, rz = -qx, -qy, -qz
    # t = 2 r × v
    tx = 2.0 * (ry * vd - rz * ve)
    ty = 2.0 * (rz * vn - rx * vd)
    tz = 2.0 * (rx * ve - ry * vn)
    # v' = v + s t + r × t
    bx = vn + qw * tx + (ry * tz - rz * ty)
    by = ve + qw * ty + (rz * tx - rx * tz)
    bz = vd + qw * tz + (rx * ty - ry * tx)
    return bx, by, bz


def body_to_ned(
    bx: FloatOrArray, by: FloatOrArray, bz: FloatOrArray,
    qw: FloatOrArray, qx: FloatOrArray, qy: FloatOrArray, qz: FloatOrArray,
) -> tuple[FloatOrArray, FloatOrArray, FloatOrArray]:  # fmt: skip
    """Rotate a body FRD vector into NED: ``v_ned = R(q) v_b``."""
    return ned_to_body(bx, by, bz, qw, -qx, -qy, -qz)


def blade_velocity_mps(
    vn: FloatOrArray, ve: FloatOrArray, vd: FloatOrArray,
    qw: FloatOrArray, qx: FloatOrArray, qy: FloatOrArray, qz: FloatOrArray,
    wn: FloatOrArray = 0.0, we: FloatOrArray = 0.0, wd: FloatOrArray = 0.0,
) -> tuple[FloatOrArray, FloatOrArray]:  # fmt: skip
    """Air-relative blade-frame velocity: ``w`` (m/s, > 0 = air flows up through the disk) and ``u``.

    ``v_air_ned = v_ned − wind_ned``; ``v_b = R(q)ᵀ v_air``; ``w = v_b,z``; ``u = hypot(v_b,x, v_b,y)``.
    """
    bx, by, bz = ned_to_body(vn - wn, ve - we, vd - wd, qw, qx, qy, qz)
    return bz, (bx * bx + by * by) ** 0.5


def disk_tilt_sin(qw: FloatOrArray, qx: FloatOrArray, qy: FloatOrArray, qz: FloatOrArray) -> FloatOrArray:
    """``sin`` of the disk's tilt: the horizontal length of body +z in NED (0 level, 1 on edge)."""
    zn = 2.0 * (qx * qz + qw * qy)
    ze = 2.0 * (qy * qz - qw * qx)
    return (zn * zn + ze * ze) ** 0.5


def worst_blade_velocity_mps(
    w_mps: FloatOrArray, u_mps: FloatOrArray, tilt_sin: FloatOrArray, wind_radius_mps: FloatOrArray,
    updraft_mps: FloatOrArray = 0.0,
) -> tuple[FloatOrArray, FloatOrArray]:  # fmt: skip
    """``(w, u)`` as bad as a horizontal wind anywhere within ``wind_radius_mps`` of the one assumed, and an
    updraft up to ``updraft_mps`` (which no autopilot reports), can make them: a horizontal wind error δ moves
    ``w`` by at most ``sin(tilt)·|δ|`` and ``u`` by at most ``|δ|``; an updraft ``a`` moves ``w`` by at most
    ``a`` and ``u`` by at most ``sin(tilt)·a``. All the bounds at once may be more than one air can do:
    pessimistic by design, never optimistic."""
    return (w_mps + tilt_sin * wind_radius_mps + updraft_mps,
            np.maximum(u_mps - wind_radius_mps - tilt_sin * updraft_mps, 0.0))  # fmt: skip


@dataclass(frozen=True, slots=True)
class GuardRegion:
    """The forbidden region in blade-frame velocity: forbidden iff ``w > max(w_allow, tan(cone)·u) − margin``.

    ``v_h_mps`` only serves the normalised outputs; the test itself is in m/s.
    """

    w_allow_mps: float
    v_h_mps: float
    cone_deg: float = CONE_DEG
    margin_mps: float = 0.0

    def margin(self, w_mps, u_mps):
        """Signed margin (m/s): ≥ 0 allowed, < 0 forbidden."""
        return guard_margin_mps(w_mps, u_mps, self.w_allow_mps, self.cone_deg, self.margin_mps)

    def check(self, vn, ve, vd, qw, qx, qy, qz, wn=0.0, we=0.0, wd=0.0):
        """``(allowed, w_mps, u_mps, margin_mps)`` for one state (floats) or many (arrays).

        The guard's per-sample test and ``flighttest region check`` both call this.
        """
        w, u = blade_velocity_mps(vn, ve, vd, qw, qx, qy, qz, wn, we, wd)
        m = self.margin(w, u)
        return m >= 0.0, w, u, m

    def normalised(self, w_mps, u_mps):
        """Paper's normalised climb-positive ``(v_H, v_z) = (u, −w) / v_h``."""
        return u_mps / self.v_h_mps, -w_mps / self.v_h_mps


def validate_quaternion(qw, qx, qy, qz, tol: float = UNIT_QUAT_TOL) -> np.ndarray:
    """Boolean mask of quaternions that are finite and of unit norm within ``tol``."""
    n2 = np.asarray(qw, float) ** 2 + np.asarray(qx, float) ** 2 + np.asarray(qy, float) ** 2
    n2 = n2 + np.asarray(qz, float) ** 2
    return np.isfinite(n2) & (np.abs(np.sqrt(np.where(np.isfinite(n2), n2, 0.0)) - 1.0) <= tol)
