"""Online estimation of hidden markers (docs/METHOD.md 5.4), without look-ahead.

A marker that no camera pair measures in a frame is *estimated* from the past and from this
frame's other markers, or reported *lost*. The estimators are pure functions on arrays; the
:class:`Estimator` keeps their state and calls them every frame (docs/HIDDEN_MARKERS.md has the
measured comparison and the recommended configuration):

- **Equation 5**, constant velocity (:func:`constant_velocity`)::

      P_m(n) = P_m(n-1) + dP_m(n-1)

- **Equation 6**, neighbour motion (:func:`neighbour_motion`)::

      P_m(n) = P_m(n-1) + dP_m(n-1) + (1 / sum_i S_mi) sum_i S_mi dP_i(n)

  with the weight ``S_mi`` of neighbour i for marker m and ``dP_i(n)`` neighbour i's
  displacement from frame n-1 to n (measured in both frames). ``own_velocity=False`` drops the
  ``dP_m(n-1)`` term: with the estimate fed back, the paper's formula adds the neighbours' motion
  to the marker's velocity every frame, so the estimate runs away (measured: metres).
- **Rigid segment** (:func:`rigid_estimate`): the rotation and translation (weighted Kabsch,
  reflection-guarded) that carry the segment's other markers from a reference frame to their
  positions now carry the hidden marker too. The reference is the most recent frame in which the
  hidden marker and (at least three of) the supports were measured, so the shape adapts to the
  person and to slow changes. Markers estimated earlier in the same frame support with a small
  weight. With two supports (or collinear ones) the rotation about their line is free: a weak
  pseudo-point at the marker's prediction (its neighbours' motion plus its own relative velocity,
  decaying) picks it.
- **Elbow hinge** (:func:`hinge_axis`, :class:`Hinge`): a hidden epicondyle marker lies on the
  flexion axis, at the learned distance from the other epicondyle marker. The axis is
  perpendicular to the humerus (shoulder pivot -> elbow centre) and to the forearm (elbow centre
  -> wrist centre); with the elbow centre on the axis both conditions are linear in the axis
  direction. The shoulder pivot is the acromion marker plus an offset in the trunk frame learned
  online from exactly this perpendicularity (the acromion is on the scapula, ~6 cm above the
  humeral head). Where the two conditions do not fix the axis (elbow nearly straight, wrists
  hidden) the rigid forearm-elbow fit (or the previous axis) fills in; where two mirror-image
  solutions remain, the one on the previous axis' side is kept.
- **Forearm** (:func:`wrist_centre`, :class:`Forearm`): a hidden styloid marker comes from the
  rigid forearm-elbow fit while that fits (RMS misfit of its supports <= ``max_rigid_residual_m``);
  when the forearm has turned (pronation-supination breaks the rigid shape), it is the mirror of
  the measured styloid through the wrist centre, which lies on a learned circle about the flexion
  axis with the measured styloid in its plane perpendicular to the forearm. (The circle alone is
  exact but amplifies noise: the styloids are only 5 cm off a 24 cm axis.) Where the arm's
  flexion and supination are tracked (:func:`fit_forearm`), a hidden styloid comes from their fit
  to the measured styloid; a styloid whose partner has not pinned both angles for longer than the
  extrapolation allows is LOST.
- **Single views** (:meth:`Estimator.observe_views`): a camera that alone sees a hidden marker
  gives a ray; it enters the forearm fit, and moves an elbow hinge's estimate across the ray.
Each estimator falls back to the next simpler one when ill-posed (hinge/forearm -> rigid ->
equation 6 -> the marker's own decaying velocity). The estimate is fed back as the base of the
next frame, as in the paper. An estimate is dropped to LOST when it leaves what the body allows:
a distance to a measured partner of a near-rigid pair (``length_pairs``) outside the range
learned while both were measured, widened by ``tolerance_m``; the marker hidden longer than
``max_hidden_s``; or no marker of its body segment measured for longer than
``max_unsupported_s``. A marker never measured is LOST, and a LOST marker stays LOST until it is
measured again.

The Estimator takes plain arrays and marker indices; :func:`estimator_config` builds them from
the marker set's ``hidden_markers:`` section (content/markersets/*.yaml), so every marker set
chooses its own estimators, weights, rigid groups and limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Mapping, Sequence

import numpy as np

from tracking.status import MarkerStatus


_DROP = np.full(3, np.nan)  # an estimator's verdict: the body cannot pin this marker now (LOST)


class Method(IntEnum):
    """How a hidden marker is estimated (each falls back to the one below it when ill-posed)."""

    CONSTANT_VELOCITY = 0  # equation 5
    NEIGHBOURS = 1         # equation 6
    RIGID = 2              # Kabsch on a segment, falls back to equation 6
    HINGE = 3              # elbow axis (epicondyle markers), falls back to RIGID
    FOREARM = 4            # styloid markers from the elbow and the other styloid, falls back to RIGID

    @classmethod
    def parse(cls, value: "Method | str | int") -> "Method":
        if isinstance(value, str):
            try:
                return cls[value.strip().upper()]
            except KeyError:
                allowed = ", ".join(m.name.lower() for m in cls)
                raise ValueError(f"estimator {value!r} is not one of {allowed}") from None
        return cls(value)


@dataclass(frozen=True, slots=True)
class Hinge:
    """An elbow hinge for estimating ``marker`` (indices into the marker set).

    Attributes:
        marker: the epicondyle marker to estimate.
        partner: the other epicondyle marker of that elbow (the axis runs partner -> marker).
        shoulder: the acromion marker of that arm (the shoulder pivot is learned relative to it).
        wrists: the two styloid markers of that forearm (their midpoint gives the forearm's axis).
    """

    marker: int
    partner: int
    shoulder: int
    wrists: tuple[int, int]


@dataclass(frozen=True, slots=True)
class Forearm:
    """A forearm for estimating the styloid marker ``marker`` when its rigid fit does not hold.

    Attributes:
        marker: the styloid marker to estimate.
        partner: the other styloid marker of that wrist.
        elbow: the two epicondyle markers of that arm (the flexion axis).
    """

    marker: int
    partner: int
    elbow: tuple[int, int]


# ---------------------------------------------------------------------------------------------
# Pure estimators


def constant_velocity(p_prev_m: np.ndarray, v_prev_m: np.ndarray) -> np.ndarray:
    """Equation 5: ``P(n) = P(n-1) + dP(n-1)``.

    Args:
        p_prev_m: (M, 3) positions in frame n-1, world metres.
        v_prev_m: (M, 3) displacements from frame n-2 to n-1 (NaN counts as 0).

    Returns:
        (M, 3) predicted positions in frame n.
    """
    return p_prev_m + np.nan_to_num(v_prev_m)


def neighbour_motion(
    p_prev_m: np.ndarray,
    v_prev_m: np.ndarray,
    d_now_m: np.ndarray,
    d_ok: np.ndarray,
    weights: np.ndarray,
    *,
    own_velocity: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """Equation 6 for every marker at once.

    Args:
        p_prev_m: (M, 3) positions in frame n-1, world metres.
        v_prev_m: (M, 3) each marker's own displacement n-2 -> n-1 (NaN counts as 0).
        d_now_m: (M, 3) each marker's displacement n-1 -> n (rows with ``d_ok`` False ignored).
        d_ok: (M,) bool, the displacement is known (measured in both frames).
        weights: (M, M) ``S[m, i]``, weight of neighbour i for marker m (0: not a neighbour).
        own_velocity: add the marker's own ``dP_m(n-1)`` (the paper's formula) or not.

    Returns:
        positions: (M, 3) estimates for frame n.
        ok: (M,) bool, at least one weighted neighbour moved known (else the row is NaN).
    """
    w = weights * d_ok[None, :]
    total = w.sum(axis=1)
    ok = total > 0
    d = np.where(d_ok[:, None], d_now_m, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_d = (w @ d) / total[:, None]
    out = p_prev_m + mean_d
    if own_velocity:
        out = out + np.nan_to_num(v_prev_m)
    out[~ok] = np.nan
    return out, ok


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
    if _det3(r) < 0:  # reflection guard: flip the least significant axis
        vt[2] *= -1.0
        r = vt.T @ u.T
    return r, cd - r @ cs


def _det3(m: np.ndarray) -> float:
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


def rigid_estimate(
    ref_m: np.ndarray,
    cur_m: np.ndarray,
    target_ref_m: np.ndarray,
    *,
    weights: np.ndarray | None = None,
    prior_m: np.ndarray | None = None,
    prior_weight: float = 0.1,
    min_spread_m: float = 0.015,
    residual: list[float] | None = None,
) -> np.ndarray | None:
    """Carry a segment's hidden marker with the rigid motion of its other markers.

    Args:
        ref_m: (K, 3) reference positions of the support markers (a frame in which the hidden
            marker was measured too).
        cur_m: (K, 3) their positions now.
        target_ref_m: (3,) the hidden marker's position in the reference frame.
        weights: (K,) support weights (default 1; estimated supports weigh less).
        prior_m: (3,) predicted position of the hidden marker, used as a weak extra point when
            the support alone leaves a rotation free (K = 2 or collinear points).
        prior_weight: that point's weight.
        min_spread_m: support points closer than this (RMS) to a line are collinear.
        residual: a one-element list that receives the supports' RMS misfit (m).

    Returns:
        (3,) the estimate, or None when the fit is ill-posed (K < 2, or free rotation and no prior).
    """
    k = len(ref_m)
    if k < 2:
        return None
    if k < 3 or spread_m(ref_m) < min_spread_m:
        if prior_m is None or not np.all(np.isfinite(prior_m)):
            return None
        # the prior lives in the current frame; its reference is the target's reference position
        ref_m = np.vstack([ref_m, target_ref_m])
        cur_m = np.vstack([cur_m, prior_m])
        w = np.ones(k + 1) if weights is None else np.r_[weights, 0.0]
        w[-1] = prior_weight
    else:
        w = weights
    r, t = kabsch(ref_m, cur_m, w)
    est = r @ target_ref_m + t
    if residual is not None:  # RMS misfit of the supports: how far the segment is from rigid
        d = ref_m @ r.T + t - cur_m
        residual[0] = math.sqrt(float((d * d).sum()) / len(d))
    return est


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.sqrt((v * v).sum(axis=-1, keepdims=True))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of (..., 3) arrays (np.cross costs ~20 us on tiny arrays)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _solve3(a: np.ndarray, b: np.ndarray) -> list[float]:
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


def _turn_z(v: Sequence[float], phi: float) -> list[float]:
    """The 3-vector v turned by phi (rad) about z, in plain floats."""
    c, s = math.cos(phi), math.sin(phi)
    return [c * v[0] - s * v[1], s * v[0] + c * v[1], v[2]]


def _ema(old: np.ndarray, new: np.ndarray, rate: float) -> np.ndarray:
    """Exponential moving average; NaN (nothing learned yet) takes the new value."""
    return np.where(np.isfinite(old), old + rate * (new - old), new)


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


def wrist_centre(
    partner_m: np.ndarray,
    elbow_a_m: np.ndarray,
    elbow_b_m: np.ndarray,
    along_m: float,
    radius_m: float,
    centre_pred_m: np.ndarray,
) -> np.ndarray:
    """Wrist centre (midpoint of the two styloid markers) from one styloid marker and the elbow.

    The forearm turns about the elbow's flexion axis (through the two epicondyle markers), so
    the wrist centre lies on a circle about that axis: ``along_m`` from the elbow centre along the
    axis, ``radius_m`` from it. Pronation-supination turns the styloid markers about the forearm's
    long axis (elbow centre -> wrist centre), so the measured one lies in the plane through the
    wrist centre perpendicular to that axis. Of the (up to) two points of the circle that satisfy
    this, the one nearer ``centre_pred_m`` is returned.

    Args:
        partner_m: (3,) the measured styloid marker.
        elbow_a_m, elbow_b_m: (3,) the epicondyle markers (measured or estimated).
        along_m, radius_m: the learned wrist-centre circle.
        centre_pred_m: (3,) a prediction of the wrist centre.
    """
    centre = 0.5 * (elbow_a_m + elbow_b_m)
    n = _unit(elbow_b_m - elbow_a_m)
    pred = centre_pred_m - centre
    a = pred - (pred @ n) * n
    norm_a = float(np.linalg.norm(a))
    if norm_a < 1e-9:
        return centre_pred_m
    a /= norm_a
    b = _cross(n, a)
    q = partner_m - centre - along_m * n
    qa, qb = float(q @ a), float(q @ b)
    rq = math.hypot(qa, qb)
    phi = math.atan2(qb, qa)
    delta = math.acos(min(1.0, radius_m / rq)) if rq > 0 else 0.0
    # angles measured from the prediction's direction (theta = 0): the solution nearer to 0
    theta = min((phi - delta, phi + delta), key=lambda t: abs(math.remainder(t, 2 * math.pi)))
    return centre + along_m * n + radius_m * (math.cos(theta) * a + math.sin(theta) * b)


@dataclass(frozen=True, slots=True)
class ElbowFrame:
    """The elbow's flexion axis with a reference direction fixed in the humerus.

    Attributes:
        centre: (3,) elbow centre (midpoint of the epicondyle markers), world metres.
        n: (3,) unit flexion axis (first epicondyle marker -> second).
        r1: (3,) unit humerus direction (shoulder pivot -> elbow) made perpendicular to n.
        r2: (3,) ``n x r1``; the forearm's flexion angle theta is measured from r1 towards r2.
    """

    centre: np.ndarray
    n: np.ndarray
    r1: np.ndarray
    r2: np.ndarray


def elbow_frame(elbow_a_m: np.ndarray, elbow_b_m: np.ndarray, pivot_m: np.ndarray, square: float = 0.0
                ) -> ElbowFrame | None:
    """The :class:`ElbowFrame` from the two epicondyle markers and the shoulder pivot (None if
    degenerate: coincident markers, or the humerus along the flexion axis).

    Args:
        square: how much of the axis' component along the humerus (pivot -> elbow centre) is
            taken out (1: the axis made perpendicular to the humerus, as the hinge is; 0: the
            markers' direction as it is). See :attr:`Estimator.axis_square`.
    """
    centre = 0.5 * (elbow_a_m + elbow_b_m)
    e = elbow_b_m - elbow_a_m
    le = math.sqrt(float(e @ e))
    if not le > 1e-6:
        return None
    n = e / le
    h = centre - pivot_m
    if square:
        lh = math.sqrt(float(h @ h))
        if lh > 1e-6:
            n = n - (square * float(n @ h) / (lh * lh)) * h
            n = n / math.sqrt(float(n @ n))
    h = h - float(h @ n) * n
    lh = math.sqrt(float(h @ h))
    if not lh > 1e-6:
        return None
    r1 = h / lh
    return ElbowFrame(centre, n, r1, _cross(n, r1))


@dataclass(frozen=True, slots=True)
class ForearmShape:
    """Constants of one forearm, learned while its four markers are measured.

    The wrist centre C (midpoint of the styloid markers) is ``along`` along the flexion axis from
    the elbow centre and ``radius`` from the axis; the styloid markers are ``half`` either side of
    C along u, whose component along the forearm axis (elbow centre -> C) is ``tilt``.
    """

    along: float
    radius: float
    half: float
    tilt: float


def forearm_markers(frame: ElbowFrame, shape: ForearmShape, theta: float, psi: float) -> tuple[np.ndarray, np.ndarray]:
    """The two styloid markers for flexion ``theta`` (about n, from r1) and supination ``psi``
    (u about the forearm axis, from the flexion axis), radians."""
    c = frame.centre + shape.along * frame.n + shape.radius * (math.cos(theta) * frame.r1 + math.sin(theta) * frame.r2)
    a = _unit(c - frame.centre)
    p1 = _unit(frame.n - float(frame.n @ a) * a)
    p2 = _cross(a, p1)
    side = math.sqrt(max(1.0 - shape.tilt * shape.tilt, 0.0))
    u = shape.tilt * a + side * (math.cos(psi) * p1 + math.sin(psi) * p2)
    return c - shape.half * u, c + shape.half * u


def forearm_angles(frame: ElbowFrame, wrist_a_m: np.ndarray, wrist_b_m: np.ndarray
                   ) -> tuple[float, float, ForearmShape] | None:
    """Inverse of :func:`forearm_markers`: (theta, psi, shape) of measured styloid markers (None
    for degenerate input: coincident styloids, or the wrist centre on the elbow centre)."""
    c = 0.5 * (wrist_a_m + wrist_b_m)
    v = c - frame.centre
    w = wrist_b_m - wrist_a_m
    half = 0.5 * math.sqrt(float(w @ w))
    lv = math.sqrt(float(v @ v))
    if not (half > 1e-6 and lv > 1e-6):
        return None
    along = float(v @ frame.n)
    radial = v - along * frame.n
    theta = math.atan2(float(radial @ frame.r2), float(radial @ frame.r1))
    a = v / lv
    u = w / (2.0 * half)
    p1 = _unit(frame.n - float(frame.n @ a) * a)
    p2 = _cross(a, p1)
    psi = math.atan2(float(u @ p2), float(u @ p1))
    return theta, psi, ForearmShape(along, math.sqrt(float(radial @ radial)), half, float(u @ a))


def _forearm_points_f(c0, n, r1, r2, along, radius, half, tilt, theta, psi):
    """:func:`forearm_markers` in plain floats (tuples): the inner loop of :func:`fit_forearm`."""
    ct, st = math.cos(theta), math.sin(theta)
    v = [along * n[i] + radius * (ct * r1[i] + st * r2[i]) for i in range(3)]
    lv = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    a = [x / lv for x in v]
    na = n[0] * a[0] + n[1] * a[1] + n[2] * a[2]
    p1 = [n[i] - na * a[i] for i in range(3)]
    lp = math.sqrt(p1[0] * p1[0] + p1[1] * p1[1] + p1[2] * p1[2])
    p1 = [x / lp for x in p1]
    p2 = [a[1] * p1[2] - a[2] * p1[1], a[2] * p1[0] - a[0] * p1[2], a[0] * p1[1] - a[1] * p1[0]]
    side = math.sqrt(max(1.0 - tilt * tilt, 0.0))
    cp, sp = math.cos(psi), math.sin(psi)
    u = [tilt * a[i] + side * (cp * p1[i] + sp * p2[i]) for i in range(3)]
    c = [c0[i] + v[i] for i in range(3)]
    return [c[i] - half * u[i] for i in range(3)], [c[i] + half * u[i] for i in range(3)]


def fit_forearm(frame: ElbowFrame, shape: ForearmShape, measured: Sequence[tuple[int, np.ndarray]],
                theta_pred: float, psi_pred: float, sigma_theta: float, sigma_psi: float,
                sigma_m: float = 0.002, iterations: int = 4, pinned: list[bool] | None = None,
                rays: Sequence[tuple[int, Sequence[float], Sequence[float], float]] = (),
                info: list[float] | None = None, pin_sigma: float | None = None) -> tuple[float, float]:
    """Flexion and supination (radians) that best place the measured styloid markers, near the
    prediction: Gauss-Newton on ``sum |marker - model|^2 / sigma_m^2 + (theta - theta_pred)^2 /
    sigma_theta^2 + (psi - psi_pred)^2 / sigma_psi^2``, plus for each single camera view of a
    hidden styloid marker (a ray) the model marker's distance from the ray over that view's
    uncertainty there (``sigma_rad`` times the distance along the ray).

    One styloid marker leaves flexion and supination confounded where its line is near the flexion
    axis (palm up or down: the marker's motion along the forearm's front is R dtheta + half dpsi);
    a view of the hidden one separates them unless it looks along that direction; the prediction
    settles what the markers cannot.

    Args:
        measured: (slot, position) pairs, slot 0 for the first styloid marker, 1 for the second.
        sigma_m: marker noise (m); sigma_theta, sigma_psi: prediction uncertainty (rad).
        pinned: a one-element list that receives whether the markers alone pin both angles more
            firmly than the prediction (the data's information in its weakest direction exceeds
            the prior's), i.e. whether the answer is evidence rather than the prediction echoed.
        pin_sigma: judge ``pinned`` against this uncertainty (rad) instead of the prior's (a prior
            loosened by a long extrapolation would make weak data look pinning).
        rays: (slot, camera centre, unit direction, sigma_rad) of single views of hidden styloid
            markers (world metres).
        info: a three-element list that receives the normal matrix (aa, ab, bb) of the last
            iteration, prior included (its inverse is the fit's covariance, rad^2).
    """
    geo = (frame.centre.tolist(), frame.n.tolist(), frame.r1.tolist(), frame.r2.tolist(),
           shape.along, shape.radius, shape.half, shape.tilt)
    obs = [(slot, pos.tolist()) for slot, pos in measured]
    wm, wt, wp = 1.0 / sigma_m, 1.0 / sigma_theta, 1.0 / sigma_psi
    # each ray's weight at the prediction's distance along it (it barely changes within the fit)
    pts0 = _forearm_points_f(*geo, theta_pred, psi_pred)
    lines = []
    for slot, o, d, sigma_rad in rays:
        along = sum((pts0[slot][i] - o[i]) * d[i] for i in range(3))
        lines.append((slot, o, d, 1.0 / (sigma_rad * max(along, 0.1))))

    def residual(th: float, ps: float) -> list[float]:
        pts = _forearm_points_f(*geo, th, ps)
        res = [(pts[slot][i] - pos[i]) * wm for slot, pos in obs for i in range(3)]
        for slot, o, d, w in lines:  # the part of (model - camera centre) across the ray
            q = [pts[slot][i] - o[i] for i in range(3)]
            s = q[0] * d[0] + q[1] * d[1] + q[2] * d[2]
            res += [(q[i] - s * d[i]) * w for i in range(3)]
        res += [(th - theta_pred) * wt, (ps - psi_pred) * wp]
        return res

    th, ps, h = theta_pred, psi_pred, 1e-6
    for _ in range(iterations):
        r0 = residual(th, ps)
        ja = [(x - y) / h for x, y in zip(residual(th + h, ps), r0)]
        jb = [(x - y) / h for x, y in zip(residual(th, ps + h), r0)]
        aa = sum(x * x for x in ja)
        ab = sum(x * y for x, y in zip(ja, jb))
        bb = sum(x * x for x in jb)
        if pinned is not None:  # the data's part of the normal matrix (without the two prior rows)
            da, db = aa - wt * wt, bb - wp * wp
            smallest = 0.5 * (da + db) - math.sqrt(max(0.25 * (da - db) ** 2 + ab * ab, 0.0))
            pinned[0] = smallest > (max(wt, wp) if pin_sigma is None else 1.0 / pin_sigma) ** 2
        if info is not None:
            info[:] = [aa, ab, bb]
        ga = sum(x * y for x, y in zip(ja, r0))
        gb = sum(x * y for x, y in zip(jb, r0))
        det = aa * bb - ab * ab
        if not det > 0:
            break
        dth = -(bb * ga - ab * gb) / det
        dps = -(aa * gb - ab * ga) / det
        th, ps = th + dth, ps + dps
        if dth * dth + dps * dps < 1e-12:
            break
    return th, ps


# ---------------------------------------------------------------------------------------------
# The stateful estimator


class Estimator:
    """Per-frame hidden-marker estimation with the state it needs (positions, velocities, learned
    segment shapes, lengths and shoulder pivots).

    Args:
        methods: (M,) the estimator of each marker (:class:`Method` or its name).
        weights: (M, M) equation 6 weights ``S[m, i]`` (row m: the neighbours of marker m), or a
            mapping ``{m: {i: S}}``.
        segments: groups of marker indices treated as rigid (RIGID and the hinge's fallback); a
            marker tries the groups that contain it in the order given.
        hinges: elbow hinges (elbow markers with method HINGE).
        forearms: forearms (styloid markers with method FOREARM): the rigid forearm fit, or where
            its misfit exceeds ``max_rigid_residual_m`` (the forearm turned), the wrist circle.
        length_pairs: (i, j) marker pairs of near-constant distance, checked for drift.
        trunk: (upper, lower, left, right) marker indices of the trunk frame in which the
            shoulder pivots are learned (None: the world frame).
        body_segments: (M,) the body segment of each marker (the marker set's ``segment``): an
            estimate whose segment has no measured marker for longer than ``max_unsupported_s``
            is dropped (a whole forearm hidden: its turning is guesswork, and rotations keep the
            distances the drift check sees). None: no such check.
        own_velocity: equation 6 adds the marker's own last displacement (the paper's formula).
        tolerance_m: drift tolerance on the learned distance ranges.
        max_hidden_s: an estimate older than this is dropped (a scalar or one per marker).
        max_unsupported_s: see ``body_segments``.
        fps: frame rate (for ``max_hidden_s`` and the learning memories).
        prior_weight: weight of the predicted position in under-determined rigid fits.
        min_spread_m: support markers nearer than this to one line leave a rotation free.
        pivot_prior_m: (3,) the shoulder pivot (glenohumeral centre) relative to the shoulder
            marker in the trunk frame before anything is learned (x right, y up, z backwards).
        pivot_memory_s: time constant of the pivot learning (older frames are forgotten).
        min_singular: hinge constraints weaker than this leave the axis to the prediction
            (:func:`hinge_axis`).
        weak_singular: a second hinge constraint weaker than ``min_singular`` but not than this
            (elbow nearly straight, wrists measured: about 0.28 for a straight arm whatever the
            body's size, as the angle between the two conditions is the epicondyle markers'
            half-distance over the humerus and forearm lengths) gives an axis that is averaged with
            the prediction's instead of leaving the turn to it (see ``_hinge``); its turn is still
            counted as guessed (``axis_guessed``).
        estimate_weight: weight of a marker estimated earlier in the same frame as support of a
            rigid fit (measured markers weigh 1).
        velocity_decay_s: where a fit leaves a direction free, the hidden marker moves with its
            neighbours (equation 6) plus its own velocity relative to them, which decays with
            this time constant (0: none; a scalar or one per marker).
        max_rigid_residual_m: see ``forearms``.
        forearm_sigma_rad: uncertainty of the predicted flexion and supination of a forearm with a
            hidden styloid marker (:func:`fit_forearm`).
        forearm_decay_s: with both styloid markers hidden, the forearm's angular velocities decay
            with this time constant.
        scapular_rhythm: upward rotation of the scapula (deg) per degree of humerus elevation
            within ``rhythm_deg`` (2:1 glenohumeral to scapulothoracic): the learned shoulder pivot
            offset turns with it (0: a fixed offset).
        rhythm_deg: the elevation range (deg) over which the scapula turns.
        forearm_accel_deg_s2, max_forearm_sigma_deg: with neither styloid marker measured, the
            forearm's angles are extrapolated; their uncertainty grows as an unknown angular
            acceleration (``forearm_accel_deg_s2``) plus 30 % of the angular speed, and past
            ``max_forearm_sigma_deg`` both styloid estimates are dropped to LOST.
        forearm_reversal: the prior of a forearm fit (the angles extrapolated ``age`` frames with
            their velocity v) is uncertain by ``forearm_sigma_rad`` plus the unknown acceleration's
            share plus this times ``|v| age``: the turn may reverse within those frames (2: a full
            reversal, a change of 2 v).
        max_hinge_sigma_deg: the same for an elbow marker whose axis the hinge's conditions do not
            pin (elbow nearly straight, or the styloids hidden): the axis' turn about the arm is
            extrapolated, and dropped past this uncertainty.
        max_forearm_stale_s: a LOST styloid marker is estimated again from the other, measured,
            while its forearm's angles are at most this old.
        view_gate_m: a single camera view of a hidden marker (:meth:`observe_views`) counts
            (in the forearm fit, or moving an elbow hinge's estimate across the ray) when its ray
            passes this near the predicted marker (farther: another ball of the colour).
        drop_unpinned: a styloid marker whose partner, measured, has not pinned both forearm
            angles for longer than the extrapolation allows (``max_forearm_sigma_deg``) is LOST.
        view_estimate_sigma_m: uncertainty of an elbow hinge's estimate across a view's ray
            (the estimate moves towards the ray by the views' relative weight).
        axis_square: the forearm model's flexion axis is the epicondyle markers' direction with
            this share of its component along the humerus (learned shoulder pivot -> elbow centre)
            taken out (1: perpendicular to the humerus, as the learned pivot makes the hinge on
            average; 0: as measured). The wrist centre lies in the plane through the elbow centre
            perpendicular to that axis, ~24 cm away: 1 degree of tilt towards the forearm moves it
            4 mm out of the plane and the hidden styloid's estimate 8 mm (~5 degrees of
            supination), and the epicondyle markers 11 cm apart give the axis to 1-2 degrees at
            320x240. The humerus, 30 cm from the learned pivot, pins that tilt where the elbow is
            not far bent (the forearm then runs along the humerus). None (default): per frame,
            the two estimates of that component weighed by their variances, ``s_m^2 / (s_m^2 +
            axis_model_sigma^2)`` with ``s_m`` the markers' (``marker_sigma_m`` of the two
            epicondyle markers over their distance): the humerus' where the markers are coarse
            (320x240, 2 m: ~0.85), the markers' where they are sharp (640x480: ~0.55).
        axis_model_sigma_deg: how far the hinge's axis strays from perpendicular to the humerus
            through the learned pivot (the pivot's error, the arm's own geometry).
        marker_sigma_m: position noise of a measured marker (m), until the caller sets
            :attr:`marker_sigma_m` (M,) per frame (the tracker does, from the cameras' pixel size
            at each marker).

    After each :meth:`update`, ``axis_guessed`` (M,) bool marks the estimates whose direction to
    their pair (the elbow axis ``E2 - E1``, the wrist axis ``W2 - W1``), which forearm supination
    reads, no measurement of this frame pins:

    - elbow (HINGE) markers whose axis' turn about the arm neither the hinge nor a view of the
      marker pins: the axis was carried from earlier frames or taken from a rigid fit (with the
      elbow straight the forearm may turn without any measured marker showing it);
    - styloid markers of an arm with neither styloid measured and no views that pin the forearm's
      angles: the angles are extrapolated.

    Their positions still serve the elbow and wrist centres (the angles that read those).
    """

    def __init__(
        self,
        methods: Sequence[Method | str | int],
        weights: np.ndarray | Mapping[int, Mapping[int, float]],
        segments: Sequence[Sequence[int]] = (),
        hinges: Sequence[Hinge] = (),
        forearms: Sequence[Forearm] = (),
        length_pairs: Sequence[tuple[int, int]] = (),
        trunk: tuple[int, int, int, int] | None = None,
        body_segments: Sequence[str] | None = None,
        *,
        own_velocity: bool = False,
        tolerance_m: float = 0.03,
        max_hidden_s: float | Sequence[float] = 5.0,
        max_unsupported_s: float = 0.5,
        fps: float = 30.0,
        prior_weight: float = 0.1,
        min_spread_m: float = 0.015,
        pivot_prior_m: Sequence[float] = (0.0, -0.06, 0.0),
        pivot_memory_s: float = 3.0,
        min_singular: float = 0.3,
        weak_singular: float = 0.25,
        estimate_weight: float = 0.3,
        velocity_decay_s: float | Sequence[float] = 0.15,
        max_rigid_residual_m: float = 0.004,
        forearm_sigma_rad: float = 0.06,
        forearm_decay_s: float = 0.3,
        scapular_rhythm: float = 0.5,
        rhythm_deg: tuple[float, float] = (30.0, 150.0),
        forearm_accel_deg_s2: float = 150.0,
        max_forearm_sigma_deg: float = 3.0,
        forearm_reversal: float = 2.0,
        max_hinge_sigma_deg: float = 10.0,
        max_forearm_stale_s: float = 0.5,
        view_gate_m: float = 0.025,
        drop_unpinned: bool = True,
        view_estimate_sigma_m: float = 0.01,
        axis_square: float | None = None,
        axis_model_sigma_deg: float = 0.5,
        marker_sigma_m: float = 0.0015,
        limb_accel_m_s2: float = 3.0,
        max_extrapolation_m: float = 0.015,
    ) -> None:
        m = len(methods)
        self.n_markers = m
        self.methods = np.array([Method.parse(x) for x in methods], dtype=np.int8)
        if isinstance(weights, Mapping):
            w = np.zeros((m, m))
            for i, row in weights.items():
                for j, v in row.items():
                    w[i, j] = v
        else:
            w = np.array(weights, dtype=np.float64)
        if w.shape != (m, m) or np.any(w < 0) or not np.all(np.isfinite(w)):
            raise ValueError(f"weights must be a non-negative ({m}, {m}) array, got shape {w.shape}")
        np.fill_diagonal(w, 0.0)
        self.weights = w
        self.segments = tuple(np.array(g, dtype=np.intp) for g in segments)
        for g in self.segments:
            if len(g) < 2 or g.min() < 0 or g.max() >= m or len(set(g.tolist())) != len(g):
                raise ValueError(f"segment {g.tolist()} must list at least 2 distinct marker indices 0..{m - 1}")
        self._segments_of = [[k for k, g in enumerate(self.segments) if i in g] for i in range(m)]
        self.hinges = {h.marker: h for h in hinges}
        self.forearms = {f.marker: f for f in forearms}
        for i in np.flatnonzero(self.methods == Method.HINGE):
            if int(i) not in self.hinges:
                raise ValueError(f"marker {int(i)} uses the hinge estimator but has no hinge")
        for i in np.flatnonzero(self.methods == Method.FOREARM):
            if int(i) not in self.forearms:
                raise ValueError(f"marker {int(i)} uses the forearm estimator but has no forearm")
        self._f_idx = np.array([[f.marker, f.partner, *f.elbow] for f in forearms], dtype=np.intp).reshape(-1, 4)
        self._f_row = {f.marker: r for r, f in enumerate(forearms)}
        # estimation order: elbows first (the wrists' fits may lean on them), then by method
        self._rank = np.where(np.isin(np.arange(m), list(self.hinges)), 10, 0) + self.methods
        # learning arrays over hinges: (H,) marker, partner, shoulder, wrist a, wrist b
        self._h_idx = np.array([[h.marker, h.partner, h.shoulder, *h.wrists] for h in hinges],
                               dtype=np.intp).reshape(-1, 5)
        self._h_row = {h.marker: r for r, h in enumerate(hinges)}
        self._shoulder_slot = {sh: i for i, sh in enumerate(sorted({h.shoulder for h in hinges}))}
        self._h_shoulder_slot = np.array([self._shoulder_slot[h.shoulder] for h in hinges], dtype=np.intp)
        # forearms as arms (styloid a, styloid b, epicondyle a, epicondyle b, shoulder): flexion and
        # supination are tracked per arm when the arm's shoulder is known from a hinge
        shoulder_of = {m_: h.shoulder for h in hinges for m_ in (h.marker, h.partner)}
        self._arms: list[tuple[int, int, int, int, int]] = []
        self._arm_of: dict[int, tuple[int, int]] = {}
        for f in forearms:
            wa, wb = sorted((f.marker, f.partner))
            ea, eb = f.elbow
            sh = shoulder_of.get(ea, -1)
            if sh < 0 or shoulder_of.get(eb) != sh:
                continue
            arm = (wa, wb, ea, eb, sh)
            if arm not in self._arms:
                self._arms.append(arm)
            self._arm_of[f.marker] = (self._arms.index(arm), 0 if f.marker == wa else 1)
        self._arm_of_elbow = {e: r for r, (_, _, ea, eb, _) in enumerate(self._arms) for e in (ea, eb)}
        # each arm's chain (epicondyle and styloid markers): too few of them measured, the hinge
        # and the forearm have nothing to turn about, and the chain's markers keep their velocity
        self._chain = np.array([[ea, eb, wa, wb] for wa, wb, ea, eb, _ in self._arms], dtype=np.intp).reshape(-1, 4)
        self.limb_accel_m_s2 = float(limb_accel_m_s2)
        self.max_extrapolation_m = float(max_extrapolation_m)
        self.forearm_sigma_rad = float(forearm_sigma_rad)
        self.scapular_rhythm = float(scapular_rhythm)
        self.fps = float(fps)
        self.forearm_accel_rad_s2 = math.radians(forearm_accel_deg_s2)
        self.max_forearm_sigma_rad = math.radians(max_forearm_sigma_deg)
        self.forearm_reversal = float(forearm_reversal)
        self.max_hinge_sigma_rad = math.radians(max_hinge_sigma_deg)
        self.max_forearm_stale_frames = max_forearm_stale_s * float(fps)
        self.view_gate_m = float(view_gate_m)
        self.drop_unpinned = bool(drop_unpinned)
        self.view_estimate_sigma_m = float(view_estimate_sigma_m)
        self.axis_square = None if axis_square is None else float(axis_square)
        self.axis_model_sigma_rad = math.radians(axis_model_sigma_deg)
        self.marker_sigma_m = np.full(m, float(marker_sigma_m))
        self.rhythm_deg = (float(rhythm_deg[0]), float(rhythm_deg[1]))
        self._arm_beta = 1.0 - math.exp(-1.0 / (float(fps) * 0.1))  # angular velocity: ~0.1 s memory
        self._arm_decay = math.exp(-1.0 / (float(fps) * forearm_decay_s)) if forearm_decay_s > 0 else 0.0
        pairs = np.array(length_pairs, dtype=np.intp).reshape(-1, 2)
        self._pair_mask = np.zeros((m, m), dtype=bool)
        self._pair_mask[pairs[:, 0], pairs[:, 1]] = True
        self._pair_mask[pairs[:, 1], pairs[:, 0]] = True
        self._pairs = np.argwhere(np.triu(self._pair_mask))
        self.trunk = None if trunk is None else np.array(trunk, dtype=np.intp)
        if body_segments is None:
            self._partners = np.zeros((m, m), dtype=bool)
        else:
            labels = np.asarray(body_segments)
            if labels.shape != (m,):
                raise ValueError(f"body_segments must name one segment per marker ({m}), got {labels.shape}")
            self._partners = (labels[:, None] == labels[None, :]) & ~np.eye(m, dtype=bool)
        self._has_partner = self._partners.any(axis=1)
        self.max_unsupported_frames = math.ceil(max_unsupported_s * float(fps)) if np.isfinite(max_unsupported_s) else np.inf
        self.own_velocity = bool(own_velocity)
        self.tolerance_m = float(tolerance_m)
        max_s = np.broadcast_to(np.asarray(max_hidden_s, dtype=np.float64), (m,))
        self.max_hidden_frames = np.ceil(max_s * float(fps))  # float: inf allowed
        self.prior_weight = float(prior_weight)
        self.min_spread_m = float(min_spread_m)
        self.min_singular = float(min_singular)
        self.weak_singular = float(weak_singular)
        self.estimate_weight = float(estimate_weight)
        self.max_rigid_residual_m = float(max_rigid_residual_m)
        self.pivot_prior_m = np.asarray(pivot_prior_m, dtype=np.float64)
        self._forget = math.exp(-1.0 / (float(fps) * pivot_memory_s))
        self._ema = 1.0 - math.exp(-1.0 / (float(fps) * 0.3))  # hinge lengths: ~0.3 s memory
        finite = self.max_hidden_frames[np.isfinite(self.max_hidden_frames)]
        self._hist_len = int(max(2, min(finite.max() if finite.size else 10.0 * fps, 20.0 * fps) + 1))
        # velocity carried into a free rotation decays to 1/e in ``velocity_decay_s``
        tau = np.broadcast_to(np.asarray(velocity_decay_s, dtype=np.float64), (m,))
        with np.errstate(divide="ignore"):
            self._decay = np.where(tau > 0, np.exp(-1.0 / (float(fps) * tau)), 0.0)[:, None]
        self.reset()

    def reset(self) -> None:
        """Forget everything (after re-identification)."""
        m = self.n_markers
        self.positions = np.full((m, 3), np.nan)     # last output, the base of the next frame
        self.velocity = np.full((m, 3), np.nan)      # last output step
        self.velocity_before = np.full((m, 3), np.nan)  # the step before it
        self.measured = np.zeros(m, dtype=bool)      # measured in the last frame
        self.status = np.full(m, MarkerStatus.LOST, dtype=np.uint8)
        self.hidden_frames = np.zeros(m, dtype=np.int64)
        self.unsupported_frames = np.zeros(m, dtype=np.int64)  # hidden with the whole segment
        self.used = np.full(m, -1, dtype=np.int8)    # Method used for each estimate (-1: none)
        # estimates whose direction to their pair no measurement pins (see axis_guessed)
        self.axis_guessed = np.zeros(m, dtype=bool)
        self.dist_lo = np.full(len(self._pairs), np.inf)
        self.dist_hi = np.full(len(self._pairs), -np.inf)
        # recent frames (a ring): rigid fits take their reference configuration from them
        self._hist_pos = np.full((self._hist_len, m, 3), np.nan)
        self._hist_ok = np.zeros((self._hist_len, m), dtype=bool)
        self._hist_frame = np.full(self._hist_len, -1, dtype=np.int64)
        self._ref_cache: dict[tuple[int, bytes], int] = {}  # (marker, supports) -> reference slot
        self.frame = -1
        # per hinge: axis length, and n . (wrist centre - partner)
        self.hinge_length = np.full(len(self._h_idx), np.nan)
        self.hinge_fore = np.full(len(self._h_idx), np.nan)
        self.hinge_free = np.zeros(len(self._h_idx), dtype=np.int64)  # frames in a row with the axis extrapolated
        self.hinge_sense = np.zeros(len(self._h_idx))  # sign of n . (humerus x forearm), learned (0: unknown)
        self._hinge_free_now: set[int] = set()
        self._hinge_weak_now: set[int] = set()  # rows whose axis' turn rests on a weak condition
        # per forearm: wrist centre along the flexion axis and distance from it
        self.fore_along = np.full(len(self._f_idx), np.nan)
        self.fore_radius = np.full(len(self._f_idx), np.nan)
        # per arm: learned shape, flexion and supination (rad) and their velocities (rad per frame)
        self.arm_shape: list[ForearmShape | None] = [None] * len(self._arms)
        self.arm_angles = np.full((len(self._arms), 2), np.nan)
        self.arm_velocity = np.full((len(self._arms), 2), np.nan)
        self.arm_age = np.zeros(len(self._arms), dtype=np.int64)         # frames since the angles were known
        self.arm_unmeasured = np.zeros(len(self._arms), dtype=np.int64)  # frames with neither styloid measured
        self.arm_unpinned = np.zeros(len(self._arms), dtype=np.int64)  # frames since the data last pinned both angles
        self._arm_seen: dict[int, tuple[float, float, bool]] = {}  # this frame: arm -> (theta, psi, measured)
        self._arm_var: dict[int, tuple[float, float]] = {}  # this frame: arm -> the fit's data variances (rad^2)
        self._arm_points: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._arm_pinned: set[int] = set()
        self.chain_coast = np.zeros(len(self._arms), dtype=np.int64)  # frames in a row the chain coasted
        self._views: dict[int, list[tuple[list[float], list[float], float]]] = {}
        # per shoulder: normal equations of the pivot offset (trunk frame)
        self._piv_a = np.zeros((len(self._shoulder_slot), 3, 3))
        self._piv_b = np.zeros((len(self._shoulder_slot), 3))
        self._rest_cache: dict[int, np.ndarray] = {}  # shoulder slot -> solved offset, until _piv_* change
        self._shoulder_side = np.ones(len(self._shoulder_slot))  # +1 right, -1 left (trunk x)
        self._trunk_rot: np.ndarray | None = None

    # ------------------------------------------------------------------ learning
    def _learn(self, p: np.ndarray, ok: np.ndarray) -> None:
        slot = self.frame % self._hist_len
        if self._ref_cache and (ok.any() or any(v == slot for v in self._ref_cache.values())):
            self._ref_cache = {key: v for key, v in self._ref_cache.items() if not ok[key[0]] and v != slot}
        self._hist_pos[slot] = p
        self._hist_ok[slot] = ok
        self._hist_frame[slot] = self.frame
        if len(self._pairs):
            both = ok[self._pairs].all(axis=1)
            if both.any():
                q = p[self._pairs]
                d = np.sqrt(((q[:, 0] - q[:, 1]) ** 2).sum(axis=1))
                self.dist_lo = np.where(both, np.fmin(self.dist_lo, d), self.dist_lo)
                self.dist_hi = np.where(both, np.fmax(self.dist_hi, d), self.dist_hi)
        if self.trunk is not None and ok[self.trunk].all():
            try:
                self._trunk_rot = trunk_rotation(*p[self.trunk])
            except ValueError:  # degenerate this frame: keep the last good frame
                pass
        self._arm_seen = {}
        self._arm_var: dict[int, tuple[float, float]] = {}
        self._arm_points = {}
        self._arm_pinned: set[int] = set()
        pl = okl = None
        for r, (wa, wb, ea, eb, sh) in enumerate(self._arms):
            if not (ok[wa] and ok[wb] and ok[ea] and ok[eb]):
                continue
            if pl is None:
                pl, okl = p.tolist(), ok.tolist()
            angles = self._forearm_angles_f(r, pl, okl)
            if angles is None:
                continue
            theta, psi, shape = angles
            old = self.arm_shape[r]
            if old is None:
                self.arm_shape[r] = shape
            else:
                self.arm_shape[r] = ForearmShape(*(o + self._ema * (s - o) for o, s in zip(
                    (old.along, old.radius, old.half, old.tilt), (shape.along, shape.radius, shape.half, shape.tilt))))
            self._arm_seen[r] = (theta, psi, True)
        if not (len(self._f_idx) or len(self._h_idx)):
            return
        # a few 3-vectors per arm: plain floats are several times faster than numpy here
        if pl is None:
            pl, okl = p.tolist(), ok.tolist()
        rate = self._ema
        for r, (w, wp, ea, eb) in enumerate(self._f_idx.tolist()):
            if not (okl[w] and okl[wp] and okl[ea] and okl[eb]):
                continue
            v = [0.5 * (pl[w][i] + pl[wp][i] - pl[ea][i] - pl[eb][i]) for i in range(3)]  # elbow -> wrist centre
            e = [pl[eb][i] - pl[ea][i] for i in range(3)]
            le = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
            if le < 1e-6:  # coincident elbow markers: nothing to learn from this frame
                continue
            along = (v[0] * e[0] + v[1] * e[1] + v[2] * e[2]) / le
            radius = math.sqrt(max(v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - along * along, 0.0))
            old_a, old_r = self.fore_along[r], self.fore_radius[r]
            first = not math.isfinite(old_r)
            self.fore_along[r] = along if first else old_a + rate * (along - old_a)
            self.fore_radius[r] = radius if first else old_r + rate * (radius - old_r)
        for r, (mk, pa, sh, wa, wb) in enumerate(self._h_idx.tolist()):
            if not (okl[mk] and okl[pa] and okl[sh] and okl[wa] and okl[wb]):
                continue
            e = [pl[mk][i] - pl[pa][i] for i in range(3)]
            length = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
            if length < 1e-6:
                continue
            n = [c / length for c in e]
            fore = sum(n[i] * (0.5 * (pl[wa][i] + pl[wb][i]) - pl[pa][i]) for i in range(3))  # n . (wrist centre - partner)
            old_l, old_f = self.hinge_length[r], self.hinge_fore[r]
            first = not math.isfinite(old_l)
            self.hinge_length[r] = length if first else old_l + rate * (length - old_l)
            self.hinge_fore[r] = fore if first else old_f + rate * (fore - old_f)
            # which way the axis runs relative to humerus x forearm (the elbow bends one way only):
            # learned where the elbow is clearly flexed (sine of the angle > 0.3)
            hum = [0.5 * (pl[mk][i] + pl[pa][i]) - pl[sh][i] for i in range(3)]
            fa = [0.5 * (pl[wa][i] + pl[wb][i] - pl[mk][i] - pl[pa][i]) for i in range(3)]
            hx = [hum[1] * fa[2] - hum[2] * fa[1], hum[2] * fa[0] - hum[0] * fa[2], hum[0] * fa[1] - hum[1] * fa[0]]
            sense = n[0] * hx[0] + n[1] * hx[1] + n[2] * hx[2]
            if abs(sense) > 0.3 * math.sqrt(sum(x * x for x in hum) * sum(x * x for x in fa)):
                self.hinge_sense[r] += rate * (math.copysign(1.0, sense) - self.hinge_sense[r])
            # shoulder pivot G = S + R g: the axis is perpendicular to the humerus,
            # n . (centre - G) = 0, i.e. (R^T n) . g = n . (centre - S): one equation per frame,
            # accumulated with forgetting (normal equations per shoulder, solved when needed)
            if mk < pa:  # the other marker's hinge gives the same equation (n reversed)
                continue
            centre = [0.5 * (pl[mk][i] + pl[pa][i]) for i in range(3)]
            rhs = sum(n[i] * (centre[i] - pl[sh][i]) for i in range(3))
            rt = self.trunk_rot.tolist()
            a_t = [n[0] * rt[0][j] + n[1] * rt[1][j] + n[2] * rt[2][j] for j in range(3)]
            k = self._h_shoulder_slot[r]
            if self.scapular_rhythm > 0:  # the equation for the offset at the scapula's rest
                if self.trunk is not None and okl[self.trunk[0]]:
                    lateral = sum((pl[sh][i] - pl[self.trunk[0]][i]) * rt[i][0] for i in range(3))
                    self._shoulder_side[k] = 1.0 if lateral >= 0 else -1.0
                a_t = _turn_z(a_t, -self._scapula_angle(k, pl[sh], centre))
            self._piv_a[k] = self._forget * self._piv_a[k] + np.array([[a_t[i] * a_t[j] for j in range(3)] for i in range(3)])
            self._piv_b[k] = self._forget * self._piv_b[k] + np.array([rhs * a_t[i] for i in range(3)])
            self._rest_cache.pop(k, None)

    @property
    def trunk_rot(self) -> np.ndarray:
        """(3, 3) trunk -> world rotation of the last frame with the trunk markers measured."""
        return np.eye(3) if self._trunk_rot is None else self._trunk_rot

    def _rest_offset(self, k: int) -> np.ndarray:
        # solved once per change of the normal equations (several callers per frame, ~20 us each)
        g = self._rest_cache.get(k)
        if g is None:
            g = np.array(_solve3(self._piv_a[k] + np.eye(3), self._piv_b[k] + self.pivot_prior_m))
            g.flags.writeable = False
            self._rest_cache[k] = g
        return g

    def _scapula_angle(self, k: int, shoulder: Sequence[float], elbow: Sequence[float]) -> float:
        """Angle (rad, about the trunk's z) of the scapula's upward rotation for the humerus
        elevation (shoulder slot k, the shoulder marker and the elbow centre now, world
        3-sequences): the scapulohumeral rhythm, ``scapular_rhythm`` degrees per degree of
        elevation between ``rhythm_deg`` (the acromion marker turns medially over the humeral head
        as the arm rises). In plain floats: it runs for every arm in every frame."""
        rt = self.trunk_rot.tolist()
        g = self._rest_offset(k).tolist()
        d = [elbow[i] - shoulder[i] for i in range(3)]
        u = [rt[0][j] * d[0] + rt[1][j] * d[1] + rt[2][j] * d[2] - g[j] for j in range(3)]
        lu = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
        if not lu > 1e-9:
            return 0.0
        elevation = math.degrees(math.acos(max(-1.0, min(1.0, -u[1] / lu))))
        lo, hi = self.rhythm_deg
        return math.radians(self.scapular_rhythm * (min(max(elevation, lo), hi) - lo)) * float(self._shoulder_side[k])

    def _offset_f(self, k: int, shoulder: Sequence[float], elbow: Sequence[float]) -> list[float]:
        """The pivot offset of shoulder slot k (trunk frame) turned with the scapula for the
        humerus elevation (:meth:`_scapula_angle`), in plain floats."""
        g = self._rest_offset(k).tolist()
        if self.scapular_rhythm <= 0:
            return g
        return _turn_z(g, self._scapula_angle(k, shoulder, elbow))

    def pivot_offset(self, shoulder: int, elbow_m: np.ndarray | None = None, shoulder_m: np.ndarray | None = None) -> np.ndarray:
        """(3,) learned shoulder pivot (glenohumeral centre) minus the shoulder marker, trunk frame;
        turned with the scapula for the humerus elevation when the elbow centre and the shoulder
        marker are given."""
        k = self._shoulder_slot[shoulder]
        if elbow_m is None or shoulder_m is None or self.scapular_rhythm <= 0:
            return self._rest_offset(k)
        return np.array(self._offset_f(k, shoulder_m.tolist(), elbow_m.tolist()))

    # ------------------------------------------------------------------ estimation
    def _hinge(self, k: int, p: np.ndarray, ok: np.ndarray, weight: np.ndarray, prior: np.ndarray,
               base: np.ndarray) -> np.ndarray | None:
        h = self.hinges[k]
        r = self._h_row[k]
        length = self.hinge_length[r]
        if not (ok[h.partner] and ok[h.shoulder]) or not np.isfinite(length):
            return None
        # prediction: the rigid forearm-elbow fit (exact while the forearm does not turn), else
        # the axis of the previous frame
        prev_axis = base[k] - base[h.partner]
        prev_axis = _unit(prev_axis) if np.all(np.isfinite(prev_axis)) else None
        rigid = self._rigid(k, p, weight, prior)
        if rigid is not None:
            axis_pred = _unit(rigid - p[h.partner])
        elif prev_axis is not None:
            axis_pred = prev_axis
        else:
            return None
        # the axis is perpendicular to the humerus (pivot -> elbow centre) and to the forearm
        # (elbow centre -> wrist centre); with the centre = partner + length/2 n both are linear in n
        pivot = p[h.shoulder] + self.trunk_rot @ self.pivot_offset(h.shoulder, p[h.partner], p[h.shoulder])
        rows = [p[h.partner] - pivot]
        values = [-0.5 * length]
        wa, wb = h.wrists
        if ok[wa] and ok[wb]:
            rows.append(0.5 * (p[wa] + p[wb]) - p[h.partner])
            values.append(self.hinge_fore[r])
        side = prev_axis
        if len(rows) == 2 and abs(self.hinge_sense[r]) > 0.5:
            # of the two mirror images the one on the side the elbow bends (anatomy), rather than
            # the previous axis' (which may itself be an extrapolation, or unknown after LOST)
            side = math.copysign(1.0, self.hinge_sense[r]) * _unit(_cross(rows[0], rows[1]))
        fixed, sv = [0], []
        rows_a, values_a = np.array(rows), np.array(values)
        n = hinge_axis(rows_a, values_a, axis_pred, min_singular=self.min_singular, axis_prev=side, fixed=fixed,
                       singular=sv)
        if fixed[0] < 2 and len(sv) == 2 and sv[1] >= self.weak_singular:
            # elbow nearly straight, wrists measured: the second condition pins the axis' turn
            # about the arm only weakly (its error follows the learned pivot's), the prediction
            # (the previous axis, or the rigid fit that turns with the forearm) drifts with the
            # forearm's turn: two estimates with independent errors of similar size, averaged.
            # Not extrapolated, so not dropped; supination still withheld (axis_guessed)
            n = _unit(n + hinge_axis(rows_a, values_a, axis_pred, min_singular=self.weak_singular, axis_prev=side))
            self._hinge_weak_now.add(r)
        elif fixed[0] < 2:  # the axis' turn about the arm is extrapolated (elbow straight, wrists hidden)
            free = self.hinge_free[r] + 1
            arm = self._arm_of_elbow.get(k)
            speed = abs(float(self.arm_velocity[arm][1])) * self.fps if arm is not None and np.isfinite(self.arm_velocity[arm][1]) else 0.0
            t = free / self.fps
            if 0.5 * self.forearm_accel_rad_s2 * t * t + 0.3 * speed * t > self.max_hinge_sigma_rad:
                return _DROP
            self._hinge_free_now.add(r)
        return p[h.partner] + length * n

    def _forearm_angles_f(self, r: int, pl: list, okl: list) -> tuple[float, float, ForearmShape] | None:
        """``forearm_angles(self._elbow_frame(r, p, ok, square=0), p[wa], p[wb])`` in plain floats
        (``pl``, ``okl``: p and ok as lists): run for every arm in every frame while its markers are
        measured. The learned angles and shape are about the markers' own axis, as the reported
        supination reads it (not squared to the humerus: that measured better on the simulated
        walk at 320x240, right and left supination 2.04-2.13 degrees against 2.11-2.20)."""
        wa, wb, ea, eb, sh = self._arms[r]
        shoulder = pl[sh] if okl[sh] else self.positions[sh].tolist()
        if not all(math.isfinite(x) for x in shoulder):
            return None
        a, b = pl[ea], pl[eb]
        centre = [0.5 * (a[i] + b[i]) for i in range(3)]
        # the shoulder pivot (as _elbow_frame's, in floats)
        rt = self.trunk_rot.tolist()
        g = self._offset_f(self._shoulder_slot[sh], shoulder, centre)
        pivot = [shoulder[i] + rt[i][0] * g[0] + rt[i][1] * g[1] + rt[i][2] * g[2] for i in range(3)]
        # the elbow frame (elbow_frame)
        e = [b[i] - a[i] for i in range(3)]
        le = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        if not le > 1e-6:
            return None
        n = [x / le for x in e]
        h = [centre[i] - pivot[i] for i in range(3)]
        hn = h[0] * n[0] + h[1] * n[1] + h[2] * n[2]
        h = [h[i] - hn * n[i] for i in range(3)]
        lh = math.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])
        if not lh > 1e-6:
            return None
        r1 = [x / lh for x in h]
        r2 = [n[1] * r1[2] - n[2] * r1[1], n[2] * r1[0] - n[0] * r1[2], n[0] * r1[1] - n[1] * r1[0]]
        # the forearm angles (forearm_angles)
        pa, pb = pl[wa], pl[wb]
        v = [0.5 * (pa[i] + pb[i]) - centre[i] for i in range(3)]
        w = [pb[i] - pa[i] for i in range(3)]
        half = 0.5 * math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
        lv = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        if not (half > 1e-6 and lv > 1e-6):
            return None
        along = v[0] * n[0] + v[1] * n[1] + v[2] * n[2]
        radial = [v[i] - along * n[i] for i in range(3)]
        theta = math.atan2(radial[0] * r2[0] + radial[1] * r2[1] + radial[2] * r2[2],
                           radial[0] * r1[0] + radial[1] * r1[1] + radial[2] * r1[2])
        av = [x / lv for x in v]
        uw = [x / (2.0 * half) for x in w]
        na = n[0] * av[0] + n[1] * av[1] + n[2] * av[2]
        p1 = [n[i] - na * av[i] for i in range(3)]
        lp = math.sqrt(p1[0] * p1[0] + p1[1] * p1[1] + p1[2] * p1[2])
        p1 = [x / lp for x in p1]
        p2 = [av[1] * p1[2] - av[2] * p1[1], av[2] * p1[0] - av[0] * p1[2], av[0] * p1[1] - av[1] * p1[0]]
        psi = math.atan2(uw[0] * p2[0] + uw[1] * p2[1] + uw[2] * p2[2], uw[0] * p1[0] + uw[1] * p1[1] + uw[2] * p1[2])
        radius = math.sqrt(radial[0] * radial[0] + radial[1] * radial[1] + radial[2] * radial[2])
        return theta, psi, ForearmShape(along, radius, half, uw[0] * av[0] + uw[1] * av[1] + uw[2] * av[2])

    def _elbow_frame(self, r: int, p: np.ndarray, ok: np.ndarray, square: float | None = None) -> ElbowFrame | None:
        """Arm r's elbow frame now (the shoulder marker measured, else its last output), its axis
        squared to the humerus by ``square`` (default: :attr:`axis_square`)."""
        _, _, ea, eb, sh = self._arms[r]
        shoulder = p[sh] if ok[sh] else self.positions[sh]
        if not np.all(np.isfinite(shoulder)):
            return None
        pivot = shoulder + self.trunk_rot @ self.pivot_offset(sh, 0.5 * (p[ea] + p[eb]), shoulder)
        if square is None:
            square = self.axis_square
        if square is None:
            e = p[eb] - p[ea]
            noise = (self.marker_sigma_m[ea] ** 2 + self.marker_sigma_m[eb] ** 2) / max(float(e @ e), 1e-6)
            square = noise / (noise + self.axis_model_sigma_rad ** 2) if noise > 0 else 0.0
        return elbow_frame(p[ea], p[eb], pivot, square)

    def _arm_sigma(self, r: int, frames: float, speed_share: float = 0.3) -> np.ndarray:
        """(2,) uncertainty (rad) of arm r's flexion and supination extrapolated ``frames`` ahead:
        an unknown angular acceleration up to ``forearm_accel`` plus ``speed_share`` of the
        speed."""
        t = frames / self.fps
        speed = np.abs(np.nan_to_num(self.arm_velocity[r])) * self.fps
        return 0.5 * self.forearm_accel_rad_s2 * t * t + speed_share * speed * t

    def _arm_estimate(self, k: int, p: np.ndarray, ok: np.ndarray, weight: np.ndarray):
        """Styloid marker k from its arm's flexion and supination: fitted to the arm's measured
        styloid marker near their prediction, or (both hidden) the prediction alone, its angular
        velocities decaying, until the extrapolation's uncertainty passes ``max_forearm_sigma_rad``
        (then :data:`_DROP`). None where the arm has no state (nothing learned, elbow unknown)."""
        r, slot = self._arm_of[k]
        if r in self._arm_points:
            return self._arm_points[r][slot]
        wa, wb, ea, eb, _ = self._arms[r]
        shape = self.arm_shape[r]
        angles, vel = self.arm_angles[r], self.arm_velocity[r]
        if shape is None or not np.all(np.isfinite(angles)) or not (weight[ea] > 0 and weight[eb] > 0):
            return None
        frame = self._elbow_frame(r, p, ok)
        if frame is None:
            return None
        measured = [(s, p[w]) for s, w in ((0, wa), (1, wb)) if ok[w]]
        age = int(self.arm_age[r]) + 1  # frames since the angles were last known
        pred = angles + np.nan_to_num(vel) * min(age, 2)
        rays = self._styloid_rays(r, frame, shape, pred, ok)
        evidence = bool(measured)
        theta = psi = math.nan
        if measured or rays:
            # the prediction carries the velocity over ``age`` frames, in which the turn may
            # reverse: a change of up to twice the velocity (the walking capture's supination
            # reverses at up to 4000 degrees/s^2, the median being 130)
            sigma = self.forearm_sigma_rad + self._arm_sigma(r, age, self.forearm_reversal)
            pinned = [False]
            info = [0.0, 0.0, 0.0]
            theta, psi = fit_forearm(frame, shape, measured, float(pred[0]), float(pred[1]),
                                     float(sigma[0]), float(sigma[1]), pinned=pinned, rays=rays,
                                     pin_sigma=self.forearm_sigma_rad, info=info)
            # the data's own variance of each angle (the other one free): how far this fit's step
            # is evidence of the angle's speed (_arm_update)
            da, ab, db = info[0] - float(sigma[0]) ** -2, info[1], info[2] - float(sigma[1]) ** -2
            self._arm_var[r] = (1.0 / (da - ab * ab / db) if da > 0 and db > 0 and da * db > ab * ab else math.inf,
                                1.0 / (db - ab * ab / da) if da > 0 and db > 0 and da * db > ab * ab else math.inf)
            if pinned[0]:
                self._arm_pinned.add(r)
                evidence = True
            elif measured and self.drop_unpinned and np.any(
                    self._arm_sigma(r, int(self.arm_unpinned[r]) + 1) > self.max_forearm_sigma_rad):
                # one styloid measured, but for a while it has not pinned both angles (palm up or
                # down: flexion and supination confounded): the hidden one is a guess, dropped;
                # the fit stays the arm's state, so the marker returns once the data pin it again
                self._arm_seen[r] = (theta, psi, False)
                self._arm_points[r] = (_DROP, _DROP)
                return _DROP
        if not evidence:  # neither styloid measured, and no view that pins the angles
            unmeasured = int(self.arm_unmeasured[r]) + 1
            if np.any(self._arm_sigma(r, unmeasured) > self.max_forearm_sigma_rad):
                self._arm_points[r] = (_DROP, _DROP)
                return _DROP
            theta, psi = (float(x) for x in angles + np.nan_to_num(vel) * self._arm_decay)
        self._arm_seen[r] = (theta, psi, evidence)
        pts = forearm_markers(frame, shape, theta, psi)
        self._arm_points[r] = pts
        return pts[slot]

    def _styloid_rays(self, r: int, frame: ElbowFrame, shape: ForearmShape, pred: np.ndarray,
                      ok: np.ndarray) -> list[tuple[int, list[float], list[float], float]]:
        """Single camera views (:meth:`observe_views`) of arm r's hidden styloid markers that pass
        within ``view_gate_m`` of the predicted marker, the nearest one per marker, as
        :func:`fit_forearm`'s rays."""
        if not self._views:
            return []
        wa, wb = self._arms[r][:2]
        out = []
        pts = None
        for slot, w in ((0, wa), (1, wb)):
            if ok[w] or w not in self._views:
                continue
            if pts is None:
                pts = forearm_markers(frame, shape, float(pred[0]), float(pred[1]))
            q = pts[slot].tolist()
            # of several views within the gate only the nearest: the tracker passes a marker's
            # full-sized single views when they made no consistent point, so two or more hold
            # at most one of the marker (the walk: a second ball 41 mm off moved MRW1 19 mm)
            nearest = None
            for o, d, sigma_rad in self._views[w]:
                v = [q[i] - o[i] for i in range(3)]
                s = v[0] * d[0] + v[1] * d[1] + v[2] * d[2]
                off2 = sum((v[i] - s * d[i]) ** 2 for i in range(3))
                if off2 <= self.view_gate_m ** 2 and (nearest is None or off2 < nearest[0]):
                    nearest = (off2, (slot, o, d, sigma_rad))
            if nearest is not None:
                out.append(nearest[1])
        return out

    def _refine_with_views(self, k: int, est: np.ndarray) -> tuple[np.ndarray, bool]:
        """An estimate of marker k moved across its single camera views (rays passing within
        ``view_gate_m``): per ray, the estimate's offset across the ray is shrunk by the weight of
        the view (``sigma_rad`` times the distance) against the estimate's (``view_estimate_sigma_m``);
        the depth along the ray stays the estimate's. Returns the estimate and whether a view was
        used."""
        q = est.tolist()
        used = False
        for o, d, sigma_rad in self._views[k]:
            v = [q[i] - o[i] for i in range(3)]
            s = v[0] * d[0] + v[1] * d[1] + v[2] * d[2]
            off = [v[i] - s * d[i] for i in range(3)]
            if s <= 0 or sum(x * x for x in off) > self.view_gate_m ** 2:
                continue
            sr2 = (sigma_rad * s) ** 2
            gain = self.view_estimate_sigma_m ** 2 / (self.view_estimate_sigma_m ** 2 + sr2)
            q = [q[i] - gain * off[i] for i in range(3)]
            used = True
        return np.array(q), used

    def _arm_update(self, p: np.ndarray, ok: np.ndarray) -> None:
        """Carry the arms' flexion and supination to the next frame."""
        for r, (wa, wb, ea, eb, _) in enumerate(self._arms):
            seen = self._arm_seen.get(r)
            if seen is None and ok[wa] and ok[wb] and np.all(np.isfinite(p[[ea, eb]])):
                # styloids measured, an epicondyle estimated (by the hinge)
                frame = self._elbow_frame(r, p, ok)
                angles = None if frame is None else forearm_angles(frame, p[wa], p[wb])
                if angles is not None:
                    seen = (angles[0], angles[1], True)
            measured_now = bool(ok[wa] or ok[wb]) or (seen is not None and seen[2])
            self.arm_unmeasured[r] = 0 if measured_now else self.arm_unmeasured[r] + 1
            pinned_now = bool(ok[wa] and ok[wb]) or r in self._arm_pinned
            self.arm_unpinned[r] = 0 if pinned_now else self.arm_unpinned[r] + 1
            if seen is None:  # the last angles stay, older by a frame
                self.arm_age[r] += 1
                continue
            theta, psi, measured = seen
            old = self.arm_angles[r]
            if not (ok[wa] and ok[wb]):
                # a fit to one styloid (with or without views) leans on the prediction where the
                # styloid does not pin an angle: that step is no evidence of speed (it would feed
                # itself), and a pinned step carries the styloid's and the elbow axis' noise (2-4
                # degrees per frame of supination at 320x240). So each angle's speed decays, and
                # takes the step in by the steady-state Kalman gain of a constant-speed model:
                # process noise the unknown angular acceleration (forearm_accel) over a frame,
                # measurement noise the step's variance from the fit's data (_arm_var). Flexion,
                # pinned by a styloid 24 cm from the elbow, keeps its speed through the fits;
                # supination, from a styloid 2-3 cm off the forearm's axis, mostly decays
                vel = np.nan_to_num(self.arm_velocity[r]) * self._arm_decay
                var = self._arm_var.get(r)
                if measured and var is not None and np.all(np.isfinite(old)):
                    steps = self.arm_age[r] + 1
                    d = np.array([math.remainder(theta - old[0], math.tau),
                                  math.remainder(psi - old[1], math.tau)]) / steps
                    q = (self.forearm_accel_rad_s2 / (self.fps * self.fps)) ** 2
                    for i in range(2):
                        noise = 2.0 * var[i] / (steps * steps)
                        if math.isfinite(noise):
                            pss = 0.5 * (q + math.sqrt(q * q + 4.0 * q * noise))
                            gain = min(pss / (pss + noise), self._arm_beta)
                            vel[i] += gain * (d[i] - vel[i])
                self.arm_velocity[r] = vel
            elif measured and np.all(np.isfinite(old)):
                steps = self.arm_age[r] + 1
                d = np.array([math.remainder(theta - old[0], math.tau), math.remainder(psi - old[1], math.tau)]) / steps
                vel = self.arm_velocity[r]
                self.arm_velocity[r] = np.where(np.isfinite(vel), vel + self._arm_beta * (d - vel), d)
            elif measured:
                self.arm_velocity[r] = 0.0
            self.arm_angles[r] = (theta, psi)
            self.arm_age[r] = 0

    def _forearm(self, k: int, p: np.ndarray, ok: np.ndarray, weight: np.ndarray, prior: np.ndarray) -> np.ndarray | None:
        if k in self._arm_of:
            est = self._arm_estimate(k, p, ok, weight)
            if est is not None:
                return est
        f = self.forearms[k]
        r = self._f_row[k]
        ea, eb = f.elbow
        resid = [0.0]
        rigid = self._rigid(k, p, weight, prior, resid)
        if rigid is not None and resid[0] <= self.max_rigid_residual_m:
            return rigid
        # the forearm turned (or no rigid fit): the other styloid, measured, on the wrist circle
        if not (ok[f.partner] and weight[ea] > 0 and weight[eb] > 0) or not np.isfinite(self.fore_radius[r]):
            return rigid
        pred = rigid if rigid is not None else prior
        centre = wrist_centre(p[f.partner], p[ea], p[eb], self.fore_along[r], self.fore_radius[r],
                              0.5 * (pred + p[f.partner]))
        return 2.0 * centre - p[f.partner]

    def _model(self, k: int, p: np.ndarray, ok: np.ndarray, weight: np.ndarray, prior: np.ndarray,
               base: np.ndarray) -> tuple[np.ndarray | None, int]:
        """Hinge or rigid estimate of marker k as its method allows, and the method used."""
        method = self.methods[k]
        if method in (Method.HINGE, Method.FOREARM):
            est = (self._hinge(k, p, ok, weight, prior, base) if method == Method.HINGE
                   else self._forearm(k, p, ok, weight, prior))
            if est is not None:
                return est, method
            method = Method.RIGID
        if method == Method.RIGID:
            est = self._rigid(k, p, weight, prior)
            if est is not None:
                return est, Method.RIGID
        return None, -1

    def _reference(self, k: int, cand: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The most recent stored frame in which marker k and at least three of the candidate
        supports ``cand`` (indices) were measured (else the one with most of them), as
        (positions (M, 3), measured (M,))."""
        key = (k, cand.tobytes())
        slot = self._ref_cache.get(key)
        if slot is not None:
            return self._hist_pos[slot], self._hist_ok[slot]
        has = self._hist_ok[:, k] & (self._hist_frame >= 0)
        if not has.any() or not len(cand):
            return None
        count = np.where(has, self._hist_ok[:, cand].sum(axis=1), -1)
        need = min(3, int(count.max()))
        if need < 1:
            return None
        slots = np.flatnonzero(count >= need)
        slot = int(slots[np.argmax(self._hist_frame[slots])])
        # valid while k stays hidden (a newer reference needs k measured) and the slot is kept
        self._ref_cache[key] = slot
        return self._hist_pos[slot], self._hist_ok[slot]

    def _rigid(self, k: int, p: np.ndarray, weight: np.ndarray, prior: np.ndarray,
               residual: list[float] | None = None) -> np.ndarray | None:
        """Rigid estimate of marker k from the first of its segments that gives one.

        ``weight[i]`` is marker i's weight as a support now (0: no position this frame).
        """
        for s in self._segments_of[k]:
            seg = self.segments[s]
            cand = seg[(weight[seg] > 0) & (seg != k)]
            ref = self._reference(k, cand)
            if ref is None:
                continue
            ref_pos, ref_ok = ref
            sup = cand[ref_ok[cand]]
            est = rigid_estimate(ref_pos[sup], p[sup], ref_pos[k], weights=weight[sup], prior_m=prior,
                                 prior_weight=self.prior_weight, min_spread_m=self.min_spread_m,
                                 residual=residual)
            if est is not None:
                return est
        return None

    def _coasting(self, ok: np.ndarray) -> dict[int, np.ndarray]:
        """Chain markers (epicondyles, styloids) that no model of the arm can place this frame
        keep their last velocity: while fewer than two of the chain's markers are measured, every
        hidden one but an epicondyle marker whose hinge partner is measured (the hinge places it).
        A moving arm behind the other one for a frame or two: the rigid and neighbour fallbacks
        would leave it where it was, and a forearm fit to one styloid about coasting epicondyles
        measured worse than the styloid's own velocity (population seeds 1-12, wrists at 15
        frames/s 20.4 against 15.8 mm mean at reappearance). Coasting lasts while the extrapolation's uncertainty ``0.5 a t^2`` (a:
        ``limb_accel_m_s2`` plus the marker's own acceleration over its last two steps; t from
        the last frame with two chain markers measured) stays within ``max_extrapolation_m``;
        beyond it the other estimators take over, with their own gates (dropping every coasted
        marker there lost the walking capture's right forearm in 31 % of its frames, against 2 %,
        and 3 % of its measurements, which the tracker's windows find from the estimates; without
        the marker's own acceleration the swinging arms of the walk coasted 45 mm off). Returns marker -> estimate."""
        out: dict[int, np.ndarray] = {}
        if not len(self._chain):
            return out
        counts = ok[self._chain].sum(axis=1)
        for r in np.flatnonzero(counts < 2).tolist():
            t = (int(self.chain_coast[r]) + 1) / self.fps
            for k in self._chain[r].tolist():
                if ok[k]:
                    continue
                hinge = self.hinges.get(k)
                if hinge is not None and ok[hinge.partner]:
                    continue
                v, base = self.velocity[k], self.positions[k]
                # the acceleration the marker just had counts with the unknown one: a swinging
                # arm (the walk: ~12 m/s^2 at the wrist) does not coast
                accel = float(np.linalg.norm(v - self.velocity_before[k])) * self.fps * self.fps
                if not (np.all(np.isfinite(base)) and math.isfinite(accel)):
                    continue
                if 0.5 * (self.limb_accel_m_s2 + accel) * t * t <= self.max_extrapolation_m:
                    out[k] = base + v
        return out

    def observe_views(self, markers: np.ndarray, origins_m: np.ndarray, directions: np.ndarray,
                      sigma_rad: np.ndarray) -> None:
        """Single camera views of markers that the next :meth:`update` will not have measured
        (seen by one camera, or by views that do not agree), used by that update only.

        A view is a ray: the marker lies on ``origin + s direction`` (s > 0) up to the view's
        angular uncertainty. Where the one-styloid forearm fit cannot tell flexion from
        supination (palm up or down), a view of the hidden styloid marker can.

        Args:
            markers: (K,) marker index of each view (a marker may have several).
            origins_m: (K, 3) camera centres, world metres.
            directions: (K, 3) unit ray directions, world frame.
            sigma_rad: (K,) angular uncertainty of each view (centroid error over focal length).
        """
        views: dict[int, list[tuple[list[float], list[float], float]]] = {}
        for k, o, d, sr in zip(np.asarray(markers).tolist(), np.asarray(origins_m).tolist(),
                               np.asarray(directions).tolist(), np.asarray(sigma_rad).tolist()):
            views.setdefault(int(k), []).append((o, d, float(sr)))
        self._views = views

    def update(self, positions_m: np.ndarray, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One frame: pass measured markers through, estimate the hidden ones.

        Args:
            positions_m: (M, 3) float64 world metres; rows of unmeasured markers are ignored (NaN).
            measured: (M,) bool, the marker was measured in this frame.

        Returns:
            positions: (M, 3) measured or estimated positions, NaN where LOST (a new array).
            status: (M,) uint8 :class:`~tracking.status.MarkerStatus` values.
        """
        ok = np.asarray(measured, dtype=bool) & np.isfinite(positions_m).all(axis=1)
        p = np.where(ok[:, None], positions_m, np.nan)
        self.frame += 1
        self._learn(p, ok)

        prev = self.positions
        has_base = np.isfinite(prev).all(axis=1)
        hidden_frames = np.where(ok, 0, self.hidden_frames + 1)
        alone = self._has_partner & ~(self._partners & ok[None, :]).any(axis=1)
        unsupported_frames = np.where(~ok & alone, self.unsupported_frames + 1, 0)
        if self._arms:  # a lost styloid comes back from the other, measured, while its forearm is known
            for r, (wa, wb, _, _, _) in enumerate(self._arms):
                if ok[wa] != ok[wb] and self.arm_age[r] <= self.max_forearm_stale_frames and self.arm_shape[r] is not None:
                    has_base[wb if ok[wa] else wa] = True
        for mk, pa, sh, wa, wb in self._h_idx.tolist():  # a lost epicondyle where the hinge pins it
            if not ok[mk] and ok[pa] and ok[sh] and ok[wa] and ok[wb] and self.methods[mk] == Method.HINGE:
                has_base[mk] = True
        hidden = (~ok & has_base & (hidden_frames <= self.max_hidden_frames)
                  & (unsupported_frames <= self.max_unsupported_frames))
        used = np.full(self.n_markers, -1, dtype=np.int8)
        guessed = np.zeros(self.n_markers, dtype=bool)

        if hidden.any():
            d_ok = ok & self.measured
            d_now = np.where(d_ok[:, None], p - prev, 0.0)
            eq6, eq6_ok = neighbour_motion(prev, self.velocity, d_now, d_ok, self.weights,
                                           own_velocity=self.own_velocity)
            # what a rigid fit's free rotation follows: the neighbours' motion plus the marker's own
            # velocity relative to them, decaying (equation 6 with a damped equation 5 term)
            step6 = np.where(eq6_ok[:, None], eq6 - prev, 0.0)
            prior = prev + step6 + self._decay * np.nan_to_num(self.velocity - step6)
            weight = ok.astype(np.float64)
            # hinges first, then rigid segments (which may lean on the elbows' estimates), ...
            order = np.flatnonzero(hidden)
            order = order[np.argsort(-self._rank[order], kind="stable")]
            coasting = self._coasting(ok)
            for k in order:
                if int(k) in coasting:
                    est, how = coasting[int(k)], Method.CONSTANT_VELOCITY
                    used[k] = how
                    p[k] = est
                    weight[k] = self.estimate_weight
                    guessed[k] = k in self._arm_of or k in self.hinges
                    continue
                with np.errstate(invalid="ignore", divide="ignore"):
                    try:
                        est, how = self._model(k, p, ok, weight, prior[k], prev)
                    except np.linalg.LinAlgError:  # degenerate geometry (coincident markers)
                        est = None
                if est is _DROP:
                    hidden[k] = False
                    continue
                if est is None or not np.all(np.isfinite(est)):
                    if self.methods[k] == Method.CONSTANT_VELOCITY:
                        est, how = constant_velocity(prev[k], self.velocity[k]), Method.CONSTANT_VELOCITY
                    elif eq6_ok[k]:
                        est, how = eq6[k], Method.NEIGHBOURS
                    else:  # nothing to follow: the own velocity, decaying (a seated body mostly rests)
                        est, how = prior[k], Method.CONSTANT_VELOCITY
                if not np.all(np.isfinite(est)):
                    hidden[k] = False
                    continue
                viewed = False
                if how == Method.HINGE and k in self._views:
                    est, viewed = self._refine_with_views(k, est)
                if self.methods[k] == Method.HINGE:
                    # the elbow axis' turn about the arm: pinned by the hinge (elbow bent, or the
                    # wrists measured) or by a view of the marker; else extrapolated, a rigid
                    # fit's guess or a weak condition's mean with it (a straight elbow while the
                    # forearm turns: supination unknown)
                    guessed[k] = not (viewed or (how == Method.HINGE and self._h_row[k] not in self._hinge_free_now
                                                 and self._h_row[k] not in self._hinge_weak_now))
                elif k in self._arm_of:
                    # the wrist's turn: a styloid marker of the arm measured, or views that pin
                    # the forearm's angles; else the angles extrapolated from earlier frames
                    r = self._arm_of[k][0]
                    wa, wb = self._arms[r][:2]
                    guessed[k] = not (ok[wa] or ok[wb] or r in self._arm_pinned)
                used[k] = how
                p[k] = est
                weight[k] = self.estimate_weight

            # drift: a distance to a measured partner outside the learned range (+ tolerance)
            if len(self._pairs):
                i, j = self._pairs[:, 0], self._pairs[:, 1]
                check = ((hidden[i] & ok[j]) | (hidden[j] & ok[i])) & (self.dist_hi >= self.dist_lo)
                if check.any():
                    d = np.linalg.norm(p[i[check]] - p[j[check]], axis=1)
                    out = (d < self.dist_lo[check] - self.tolerance_m) | (d > self.dist_hi[check] + self.tolerance_m)
                    if out.any():
                        bad = np.r_[i[check][out], j[check][out]]
                        hidden[bad] = False
            p[~ok & ~hidden] = np.nan
            used[~hidden] = -1
        else:
            p[~ok] = np.nan

        if len(self._h_idx):
            self.hinge_free = np.array([self.hinge_free[r] + 1 if r in self._hinge_free_now else 0
                                        for r in range(len(self._h_idx))], dtype=np.int64)
            self._hinge_free_now = set()
            self._hinge_weak_now = set()
        if self._arms:
            self._arm_update(p, ok)
            if len(self._chain):
                few = ok[self._chain].sum(axis=1) < 2
                self.chain_coast = np.where(few, self.chain_coast + 1, 0)
        known = ok | hidden
        # a reappearing marker keeps the velocity of its estimate (its measured jump is estimate error)
        keep_v = ok & ~self.measured & has_base
        self.velocity_before = self.velocity
        self.velocity = np.where(keep_v[:, None], self.velocity, np.where(known[:, None], p - prev, np.nan))
        self.positions = p
        self.measured = ok
        self.hidden_frames = hidden_frames
        self.unsupported_frames = unsupported_frames
        self.used = used
        self.axis_guessed = guessed & hidden & ~ok
        self.status = np.where(ok, MarkerStatus.MEASURED,
                               np.where(hidden, MarkerStatus.ESTIMATED, MarkerStatus.LOST)).astype(np.uint8)
        self._views = {}
        return p.copy(), self.status.copy()


# ---------------------------------------------------------------------------------------------
# Configuration from the marker set (content/markersets/*.yaml, ``hidden_markers:``)


def estimator_config(markerset, *, method: Method | str | None = None, own_velocity: bool = False) -> dict:
    """Keyword arguments of :class:`Estimator` from a marker set's ``hidden_markers:`` section.

    Args:
        markerset: a :class:`~tracking.markerset.MarkerSet` (its ``hidden`` configuration and
            body ``segments``).
        method: one estimator for every marker instead of the file's choice (comparisons).
        own_velocity: equation 6 as the paper writes it (with the marker's own last velocity).
    """
    from tracking.markerset import default_hidden

    names = list(markerset.names)
    index = {n: i for i, n in enumerate(names)}
    cfg = markerset.hidden if markerset.hidden is not None else default_hidden(names, markerset.segments)
    m = len(names)
    weights = np.zeros((m, m))
    for name, row in cfg.weights.items():
        for other, s in row.items():
            weights[index[name], index[other]] = s
    methods = [Method.parse(e) for e in cfg.estimators]
    if method is not None:
        methods = [Method.parse(method)] * m
    hinges = []
    for a, b, shoulder, wa, wb in cfg.elbows:
        a, b, s, wa, wb = (index[n] for n in (a, b, shoulder, wa, wb))
        hinges += [Hinge(a, b, s, (wa, wb)), Hinge(b, a, s, (wa, wb))]
    forearms = []
    for wa, wb, ea, eb in cfg.forearms:
        wa, wb, ea, eb = (index[n] for n in (wa, wb, ea, eb))
        forearms += [Forearm(wa, wb, (ea, eb)), Forearm(wb, wa, (ea, eb))]
    return {
        "methods": methods,
        "weights": weights,
        "segments": [tuple(index[n] for n in g) for g in cfg.rigid_groups],
        "hinges": hinges,
        "forearms": forearms,
        "length_pairs": [(index[a], index[b]) for a, b in cfg.length_pairs],
        "trunk": None if cfg.trunk is None else tuple(index[n] for n in cfg.trunk),
        "body_segments": list(markerset.segments),
        "own_velocity": own_velocity,
        "tolerance_m": cfg.drift_tolerance_m,
        "max_hidden_s": [cfg.max_hidden_s[x.name.lower()] for x in methods],
        "max_unsupported_s": cfg.max_unsupported_s,
        "velocity_decay_s": list(cfg.velocity_decay_s),
    }
