"""The forearm's model: wrist centre on a circle about the elbow axis, flexion and supination.

The forearm turns about the elbow's flexion axis (flexion) and about its own axis (supination);
the styloid markers follow from the two angles and a few lengths learned while all four markers
of the arm are measured (:class:`ForearmShape`). docs/HIDDEN_MARKERS.md ("Forearm") derives it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from tracking.hidden.geometry import cross3, unit


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
    n = unit(elbow_b_m - elbow_a_m)
    pred = centre_pred_m - centre
    a = pred - (pred @ n) * n
    norm_a = float(np.linalg.norm(a))
    if norm_a < 1e-9:
        return centre_pred_m
    a /= norm_a
    b = cross3(n, a)
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
    return ElbowFrame(centre, n, r1, cross3(n, r1))


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
    a = unit(c - frame.centre)
    p1 = unit(frame.n - float(frame.n @ a) * a)
    p2 = cross3(a, p1)
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
    p1 = unit(frame.n - float(frame.n @ a) * a)
    p2 = cross3(a, p1)
    psi = math.atan2(float(u @ p2), float(u @ p1))
    return theta, psi, ForearmShape(along, math.sqrt(float(radial @ radial)), half, float(u @ a))


def forearm_points_f(c0, n, r1, r2, along, radius, half, tilt, theta, psi):
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
    pts0 = forearm_points_f(*geo, theta_pred, psi_pred)
    lines = []
    for slot, o, d, sigma_rad in rays:
        along = sum((pts0[slot][i] - o[i]) * d[i] for i in range(3))
        lines.append((slot, o, d, 1.0 / (sigma_rad * max(along, 0.1))))

    def residual(th: float, ps: float) -> list[float]:
        pts = forearm_points_f(*geo, th, ps)
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


def forearm_angles_floats(a: list[float], b: list[float], centre: list[float], pivot: list[float],
                          pa: list[float], pb: list[float]) -> tuple[float, float, ForearmShape] | None:
    """``forearm_angles(elbow_frame(a, b, pivot, square=0), pa, pb)`` in plain floats (a, b: the
    epicondyle markers, ``centre`` their midpoint; pa, pb: the styloid markers): it runs for every
    arm in every frame while its markers are measured."""
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
