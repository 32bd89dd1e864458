"""Small 3D geometry of the hidden-marker estimators: rigid fits, the trunk frame, the elbow axis.

Pure functions on arrays and plain floats (on single 3-vectors plain floats are several times
faster than numpy, and these run for every arm in every frame).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np


def kabsch(src: np.ndarray, dst: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares rotation and translation with ``dst ~ R @ src + t``.

    Args:
        src, dst: (N, 3) corresponding points.
        w: (N,) non-negative weights (default 1).

    Returns:
        R: (3, 3) proper rotation (det +1: a reflection is never returned).
        t: (3,) translation.
    """
    if w is None:
        cs, cd = src.mean(axis=0), dst.mean(axis=0)
        h = (src - cs).T @ (dst - cd)
    else:
        ws = w / w.sum()
        cs, cd = ws @ src, ws @ dst
        h = (src - cs).T @ ((dst - cd) * ws[:, None])
    u, _, vt = np.linalg.svd(h)
    r = vt.T @ u.T
    if det3(r) < 0:  # reflection guard: flip the least significant axis
        vt[2] *= -1.0
        r = vt.T @ u.T
    return r, cd - r @ cs


def det3(m: np.ndarray) -> float:
    (a, b, c), (d, e, f), (g, h, i) = m.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)


def spread_m(points_m: np.ndarray) -> float:
    """RMS distance (m) of (N, 3) points from their best-fitting line (0 for N < 3)."""
    if len(points_m) < 3:
        return 0.0
    if len(points_m) == 3:  # the common case, in plain floats: RMS distance from the best line
        (ax, ay, az), (bx, by, bz), (cx, cy, cz) = points_m.tolist()
        ux, uy, uz, vx, vy, vz = bx - ax, by - ay, bz - az, cx - ax, cy - ay, cz - az
        area2 = (uy * vz - uz * vy) ** 2 + (uz * vx - ux * vz) ** 2 + (ux * vy - uy * vx) ** 2
        sides = ux * ux + uy * uy + uz * uz + vx * vx + vy * vy + vz * vz + (cx - bx) ** 2 + (cy - by) ** 2 + (cz - bz) ** 2
        # for 3 points: lambda_2 + lambda_3 = (sum of squared sides - sqrt((...)^2 - 12 area2)) / 6
        disc = max(sides * sides - 12.0 * area2, 0.0)
        return math.sqrt(max((sides - math.sqrt(disc)) / 6.0, 0.0) / 3.0)
    c = points_m - points_m.mean(axis=0)
    ev = np.linalg.eigvalsh(c.T @ c)  # ascending; the two smallest are the spread off the line
    return math.sqrt(max(float(ev[0] + ev[1]), 0.0) / len(points_m))



def unit(v: np.ndarray) -> np.ndarray:
    return v / np.sqrt((v * v).sum(axis=-1, keepdims=True))


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of (..., 3) arrays (np.cross costs ~20 us on tiny arrays)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def solve3(a: np.ndarray, b: np.ndarray) -> list[float]:
    """x with a x = b for a (3, 3) matrix well away from singular (Cramer's rule in plain floats:
    ~10x faster than numpy's solve on one 3x3 system)."""
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = a.tolist()
    b0, b1, b2 = b.tolist()
    c00, c01, c02 = a11 * a22 - a12 * a21, a12 * a20 - a10 * a22, a10 * a21 - a11 * a20
    det = a00 * c00 + a01 * c01 + a02 * c02
    if det == 0.0:
        raise np.linalg.LinAlgError("singular 3x3 system")
    x0 = (b0 * c00 + a01 * (a12 * b2 - b1 * a22) + a02 * (b1 * a21 - a11 * b2)) / det
    x1 = (a00 * (b1 * a22 - a12 * b2) + b0 * c01 + a02 * (a10 * b2 - b1 * a20)) / det
    x2 = (a00 * (a11 * b2 - b1 * a21) + a01 * (b1 * a20 - a10 * b2) + b0 * c02) / det
    return [x0, x1, x2]


def turn_z(v: Sequence[float], phi: float) -> list[float]:
    """The 3-vector v turned by phi (rad) about z, in plain floats."""
    c, s = math.cos(phi), math.sin(phi)
    return [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]]



def trunk_rotation(upper_m: np.ndarray, lower_m: np.ndarray, left_m: np.ndarray, right_m: np.ndarray) -> np.ndarray:
    """(3, 3) trunk -> world rotation, columns x (to the right), y (up the trunk), z (backwards).

    The trunk frame of docs/JOINT_ANGLES.md: ``y = unit(upper - lower)``, ``x`` = ``right - left``
    made orthogonal to y. (Plain floats: on 3-vectors they are several times faster than numpy.)
    A ValueError says which markers make the frame degenerate.
    """
    (ax, ay, az), (bx, by, bz), (lx, ly, lz), (qx, qy, qz) = np.stack([upper_m, lower_m, left_m, right_m]).tolist()
    ux, uy, uz = ax - bx, ay - by, az - bz
    nu = math.sqrt(ux * ux + uy * uy + uz * uz)
    if nu < 1e-9:
        raise ValueError("trunk frame: the upper and lower trunk markers coincide")
    k = 1.0 / nu
    yx, yy, yz = ux * k, uy * k, uz * k
    rx, ry, rz = qx - lx, qy - ly, qz - lz
    d = rx * yx + ry * yy + rz * yz
    rx, ry, rz = rx - d * yx, ry - d * yy, rz - d * yz
    nr = math.sqrt(rx * rx + ry * ry + rz * rz)
    if nr < 1e-9:
        raise ValueError("trunk frame: the left and right markers lie on the trunk's axis")
    k = 1.0 / nr
    xx, xy, xz = rx * k, ry * k, rz * k
    zx, zy, zz = xy * yz - xz * yy, xz * yx - xx * yz, xx * yy - xy * yx
    return np.array([[xx, yx, zx], [xy, yy, zy], [xz, yz, zz]])


def hinge_axis(rows: np.ndarray, values: np.ndarray, axis_pred: np.ndarray, *, min_singular: float = 0.3,
               axis_prev: np.ndarray | None = None, fixed: list[int] | None = None,
               singular: list[float] | None = None) -> np.ndarray:
    """Unit vector n with ``rows @ n = values`` where they determine it, else nearest ``axis_pred``.

    Each row is a linear constraint ``a . n = b``, scaled to unit ``a`` (b becomes a cosine).
    Along the right-singular directions of the scaled rows whose singular value is at least
    ``min_singular`` the constraints fix n's components (least squares); the directions they
    leave free or fix only weakly (two nearly parallel constraints: their difference is mostly
    noise) keep the prediction's direction, scaled so that n has unit length. With two
    independent constraints this is the intersection of their planes with the unit sphere on
    the prediction's side.

    Args:
        rows: (K, 3) constraint vectors a.
        values: (K,) right-hand sides b (same units as a).
        axis_pred: (3,) unit prediction.
        min_singular: singular values below this count as free directions.
        axis_prev: (3,) the previous frame's axis: where two constraints leave two mirror-image
            solutions, the one on its side is taken (continuity), not the prediction's.
        fixed: a one-element list that receives how many directions the constraints fix (2: the
            axis is pinned up to the mirror image; fewer: the prediction fills in).
        singular: a list that receives the scaled constraints' singular values, largest first.
    """
    scale = np.sqrt((rows * rows).sum(axis=1))
    a = rows / scale[:, None]
    b = values / scale
    u, sv, vt = np.linalg.svd(a)  # full: vt (3, 3), rows past len(sv) span the null space
    k = int((sv >= min_singular).sum())  # singular values come sorted, largest first
    if fixed is not None:
        fixed[0] = k
    if singular is not None:
        singular[:] = sv.tolist()
    coef = (u[:, :k].T @ b) / sv[:k]
    fixed = coef @ vt[:k]
    norm2 = float(coef @ coef)
    if norm2 >= 1.0:  # inconsistent beyond the unit sphere: the nearest unit vector
        return fixed / math.sqrt(norm2)
    free = vt[k:]
    rest = free.T @ (free @ axis_pred)  # the prediction's part in the free directions
    if k == 2 and axis_prev is not None:
        # one free direction: two solutions, mirror images through the constraints' plane; the
        # one on the previous axis' side (continuity) unless the previous axis lies in the plane
        side = float(free[0] @ axis_prev)
        if abs(side) > 0.05:
            rest = free[0] * math.copysign(1.0, side)
    r = math.sqrt(float(rest @ rest))
    if r < 1e-9:
        rest, r = free[0], 1.0
    return fixed + math.sqrt(1.0 - norm2) * rest / r
