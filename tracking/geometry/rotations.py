"""Rotation helpers and the humerus orientation in clinical terms (pure numpy, radians in, 3x3 out).

Shared by the simulated patient (:mod:`tracking.sim.body`), the BVH writer and the avatar: the
arm conventions are those of docs/JOINT_ANGLES.md, written for the right arm (the left arm uses
the same numbers mirrored across the sagittal plane).
"""

from __future__ import annotations

import math

import numpy as np

from tracking.errors import MotionError


# ---------------------------------------------------------------------------------------------
# Small rotation helpers (radians in, 3x3 out)


def rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def axis_angle_matrix(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """Rotation matrix of ``angle_rad`` about the unit vector ``axis`` (3,), right-hand rule."""
    x, y, z = axis
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    C = 1.0 - c
    return np.array([
        [c + x * x * C, x * y * C - z * s, x * z * C + y * s],
        [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
        [z * x * C - y * s, z * y * C + x * s, c + z * z * C],
    ])


def rotation_log(rot: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> (3,) rotation vector (axis * angle in radians)."""
    cos_a = min(1.0, max(-1.0, (np.trace(rot) - 1.0) / 2.0))
    angle = math.acos(cos_a)
    if angle < 1e-9:
        return np.zeros(3)
    if angle > math.pi - 1e-6:
        # Near 180 degrees the antisymmetric part vanishes: take the axis from R + I.
        m = (rot + np.eye(3)) / 2.0
        k = int(np.argmax(np.diag(m)))
        axis = m[:, k] / math.sqrt(max(m[k, k], 1e-12))
        return axis / np.linalg.norm(axis) * angle
    w = np.array([rot[2, 1] - rot[1, 2], rot[0, 2] - rot[2, 0], rot[1, 0] - rot[0, 1]])
    return w / (2.0 * math.sin(angle)) * angle


def rotation_exp(rotvec: np.ndarray) -> np.ndarray:
    """(3,) rotation vector -> (3, 3) rotation matrix."""
    angle = float(np.linalg.norm(rotvec))
    if angle < 1e-12:
        return np.eye(3)
    return axis_angle_matrix(rotvec / angle, angle)


def slerp_rotation(r0: np.ndarray, r1: np.ndarray, w: float) -> np.ndarray:
    """Geodesic interpolation between rotations (3, 3): w = 0 gives r0, w = 1 gives r1."""
    return r0 @ rotation_exp(w * rotation_log(r0.T @ r1))


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


# ---------------------------------------------------------------------------------------------
# Humerus orientation in clinical terms


def direction_from_plane(plane_deg: float, elevation_deg: float) -> np.ndarray:
    """Humerus direction (shoulder -> elbow), trunk frame, right-side convention.

    Args:
        plane_deg: plane of elevation: 0 = sideways (abduction), 90 = forward (flexion),
            -90 = backward (extension), 180 = across the body.
        elevation_deg: angle from hanging straight down, 0..180.

    Returns:
        (3,) unit vector.
    """
    p, e = math.radians(plane_deg), math.radians(elevation_deg)
    return np.array([math.sin(e) * math.cos(p), -math.cos(e), -math.sin(e) * math.sin(p)])


def direction_from_clinical(flexion_deg: float = 0.0, abduction_deg: float = 0.0) -> np.ndarray:
    """Humerus direction whose sagittal and frontal projection angles are the clinical angles.

    Matches the marker-based definitions of docs/JOINT_ANGLES.md: flexion =
    ``atan2(u . forward, u . down)``, abduction = ``atan2(u . out, u . down)``. One of the two may
    take any value; when both are non-zero both must lie in (-90, 90) (beyond that the two
    projections no longer define a direction: use :func:`direction_from_plane`).

    Returns:
        (3,) unit vector, trunk frame, right-side convention.
    """
    if abduction_deg == 0.0:
        return direction_from_plane(90.0 if flexion_deg >= 0 else -90.0, abs(flexion_deg))
    if flexion_deg == 0.0:
        return direction_from_plane(0.0 if abduction_deg >= 0 else 180.0, abs(abduction_deg))
    if not (abs(flexion_deg) < 90.0 and abs(abduction_deg) < 90.0):
        raise MotionError(
            f"flexion {flexion_deg:g} with abduction {abduction_deg:g}: combine flexion and abduction "
            "only below 90 degrees each; give plane_deg and elevation_deg for higher elevations"
        )
    v = np.array([math.tan(math.radians(abduction_deg)), -1.0, -math.tan(math.radians(flexion_deg))])
    return unit(v)


def swing_matrix(direction: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation taking straight down (0, -1, 0) to ``direction`` (3,) -> (3, 3).

    It defines external rotation 0 at every humerus direction: the frame a hanging arm reaches
    when it is raised along a great circle without axial rotation (so ER 0 = forearm forward at
    the side and in 90 degrees abduction, as in the clinical tests). Straight up is singular; a
    flexion-plane swing is used there.
    """
    d = unit(np.asarray(direction, dtype=np.float64))
    axis = np.array([-d[2], 0.0, d[0]])  # (0, -1, 0) x d
    s = float(np.linalg.norm(axis))
    c = -d[1]
    if s < 1e-9:
        return np.eye(3) if c > 0 else rot_x(math.pi)
    return axis_angle_matrix(axis / s, math.atan2(s, c))


def humerus_rotation(direction: np.ndarray, external_rotation_deg: float) -> np.ndarray:
    """(3, 3) humerus frame in the trunk frame from its direction (3,) and axial rotation.

    External rotation is a twist about the humerus long axis (right-hand rule about the
    shoulder->elbow direction, right-side convention) after the swing of :func:`swing_matrix`.
    """
    return swing_matrix(direction) @ rot_y(-math.radians(external_rotation_deg))


def swing_twist(humerus_rot: np.ndarray) -> tuple[np.ndarray, float]:
    """Inverse of :func:`humerus_rotation`: (3, 3) -> (direction (3,), external_rotation_deg)."""
    d = -humerus_rot[:, 1]
    t = swing_matrix(d).T @ humerus_rot
    return d, -math.degrees(math.atan2(t[0, 2], t[0, 0]))
