"""Windows: each marker's centroid in each camera, from the colour table inside a search window
around its predicted image position (docs/METHOD.md 5.3).

Q (equation 4) is a product of one factor per camera, 1 / (1 + |G_j C_j|), so the candidate of
largest Q takes in every camera the centroid nearest to the predicted image position. The window's
pixels of the marker's colour usually form that one ball: its centroid comes from the mask's
moments. Every marker is projected into every camera at once, and the windows of all markers in
all cameras are gathered for one table look-up (compiled: :mod:`tracking.window_kernel`; numpy:
:mod:`tracking.pipeline.moments`). A window whose mask is too large or not round holds several
balls (or clutter): then its regions are separated and the one nearest to the prediction is taken.
Partly hidden balls have their centres fitted to their visible arcs (:mod:`tracking.pipeline.arcs`).
With ``TrackerParams.window_luma`` a window's whole ball has its centre checked against a fit in the
luma, which webcams send at full resolution while their colour is halved (:func:`luma_windows`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from tracking import window_kernel
from tracking.blobs import ARC_EDGE_SHRINK_PX, PIXEL_MOMENT, axis_ratio, find_blobs, luma_centre
from tracking.colour.table import ColourTable
from tracking.pipeline.arcs import ArcRegions
from tracking.pipeline.moments import window_moments_numpy
from tracking.pipeline.params import TrackerParams
from tracking.pipeline.state import FrameState, MarkerMemory, Setup
from tracking.pipeline.timing import at_image_instants


class ImageSizes:
    """(C, 2) width and height of the frame set's images, worked out again only when they change."""

    def __init__(self) -> None:
        self._shapes: list[tuple[int, ...]] = []
        self._size = np.zeros((0, 2), dtype=np.int64)

    def of(self, images: Sequence[np.ndarray]) -> np.ndarray:
        shapes = [img.shape for img in images]
        if shapes != self._shapes:
            self._shapes = shapes
            self._size = np.array([s[1::-1] for s in shapes], dtype=np.int64)  # (C, 2) width, height
        return self._size


class LumaLabels:
    """One (H, W) uint8 colour-label image per camera for the luma fits of the windows
    (:func:`luma_windows`), kept from frame set to frame set. Each fit's box is labelled from the
    colour table just before the fit: a label is a function of its pixel alone, so boxes that
    overlap write the same labels, and a fit never reads a cell outside its own box."""

    def __init__(self) -> None:
        self._labels: list[np.ndarray] = []

    def of(self, images: Sequence[np.ndarray]) -> list[np.ndarray]:
        if [lab.shape for lab in self._labels] != [img.shape[:2] for img in images]:
            self._labels = [np.zeros(img.shape[:2], np.uint8) for img in images]
        return self._labels


@dataclass(frozen=True, slots=True)
class SearchWindows:
    """The frame set's search windows: (M, C) ``valid`` (in front of the camera, overlapping the
    image, the marker known), (M, C, 2) predicted ``uv`` and (M, C) ``half`` size, ball radius
    ``r_px`` and prediction uncertainty ``sigma_px`` (pixels), (C, 2) image ``size``."""

    valid: np.ndarray
    uv: np.ndarray
    half: np.ndarray
    r_px: np.ndarray
    sigma_px: np.ndarray
    size: np.ndarray


@dataclass(frozen=True, slots=True)
class WindowMoments:
    """The moments of the K valid windows: flat index ``at``, marker ``mi``, camera ``ci``,
    ``centre`` pixel, corners ``lo``/``hi`` (exclusive), pixel count ``count``, the own-colour pixels'
    ``col``/``row`` in their window, ``first`` (2, K) offset of each window's first pixel from its
    centre, ``mxy`` (K, 2) centroid about the centre, ``round_px`` roundness as
    :mod:`tracking.blobs` measures it, ``r_k`` the ball's radius, ``ok`` (a view), ``simple`` (one
    ball), ``radius`` the mask's equivalent radius."""

    at: np.ndarray
    mi: np.ndarray
    ci: np.ndarray
    centre: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    count: np.ndarray
    col: np.ndarray
    row: np.ndarray
    first: np.ndarray
    mxy: np.ndarray
    round_px: np.ndarray
    r_k: np.ndarray
    ok: np.ndarray
    simple: np.ndarray
    radius: np.ndarray


def search_windows(setup: Setup, p: TrackerParams, frame: FrameState, memory: MarkerMemory, fps: float,
                   size: np.ndarray) -> SearchWindows:
    """Project the predictions into every camera and size each window from the ball and the
    prediction's uncertainty; fills ``frame.pred_uv``, ``frame.pred_depth`` and ``frame.windows_px``."""
    stack = setup.stack
    m_count, n_cams = len(frame.pred), len(setup.cameras)
    if frame.skew_s is None:
        uv, depth = stack.project(frame.pred)  # predictions in each image (also for Q); NaN if unknown
    else:  # where each camera sees the marker: at its image's instant (and its row's)
        uv, depth = stack.project_camera_points(at_image_instants(setup, frame, memory.seen_velocity, fps))
    frame.pred_uv, frame.pred_depth = uv, depth
    focal = stack.focal_px
    safe_depth = np.maximum(depth, p.min_depth_m)
    r_px = focal * setup.radius_m / safe_depth
    sigma_px = focal * frame.sigma[:, None] / safe_depth
    half = np.minimum(r_px * p.window_ball_factor + p.window_margin_px + p.window_sigmas * sigma_px, p.max_window_px)
    # in front of the camera (project() gives NaN behind it) and the window overlaps the image
    # (comparisons with NaN are False, without a warning)
    windows = np.empty((m_count, n_cams, 3))
    windows[..., :2] = uv
    windows[..., 2] = half
    valid = ((uv > -windows[..., 2:]) & (uv < size + windows[..., 2:])).all(axis=2) & frame.known[:, None]
    windows[~valid] = np.nan
    frame.windows_px = windows
    return SearchWindows(valid, uv, half, r_px, sigma_px, size)


def window_observations(setup: Setup, p: TrackerParams, table: ColourTable, frame: FrameState, memory: MarkerMemory,
                        fps: float, sizes: ImageSizes, images: Sequence[np.ndarray],
                        luma: LumaLabels | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each marker's centroid in each camera, from the colour table inside its search window
    (the whole balls' centres checked in the luma where ``p.window_luma``; ``luma`` keeps the
    label images of those fits between frame sets).

    Returns:
        uv (M, C, 2) float64 centroids (NaN where none), radius (M, C) equivalent radius in px.
    """
    m_count, n_cams = len(frame.pred), len(setup.cameras)
    uv_out = np.empty((m_count, n_cams, 2))
    uv_out.fill(np.nan)
    rad_out = np.empty((m_count, n_cams))
    rad_out.fill(np.nan)
    win = search_windows(setup, p, frame, memory, fps, sizes.of(images))
    if win.valid.any():
        compiled = setup.compiled and window_kernel.usable(images)
        wm = window_moments(setup, p, table, images, win, compiled)
        uv_out.reshape(-1, 2)[wm.at[wm.simple]] = wm.centre[wm.simple] + wm.mxy[wm.simple]
        rad_out.reshape(-1)[wm.at[wm.simple]] = wm.radius[wm.simple]
        arcs = ArcRegions()
        part = queue_partial_balls(arcs, p, win, wm)
        if p.window_luma:
            luma_windows(setup, table, images, wm, wm.simple & ~part, luma or LumaLabels(), compiled, uv_out,
                         p.window_luma_confirm_px)
        # several regions in the window: separate them, in a window of the size that the markers
        # measured last frame share in this camera (the largest of theirs), or of the marker's own
        recent = frame.known & (memory.frames_unmeasured == 0)
        crowded_windows(setup, p, table, images, win, wm, recent, compiled, arcs, uv_out, rad_out)
        if arcs.count:
            m_idx, c_idx, uv_fit = arcs.fit(setup.compiled, images if p.arc_subpixel else None)
            uv_out[m_idx, c_idx] = uv_fit
        one_ball_one_marker(setup, p, win.uv, win.sigma_px, win.r_px, uv_out, rad_out)
    return uv_out, rad_out


def window_moments(setup: Setup, p: TrackerParams, table: ColourTable, images: Sequence[np.ndarray],
                   win: SearchWindows, compiled: bool) -> WindowMoments:
    """The moments of the ``valid`` windows' pixels of their marker's colour.

    A window holds the pixels within ``half`` (rounded down) of the rounded prediction, cut at
    the image border; the moments are taken about that pixel centre.
    """
    valid, uv, half, size = win.valid, win.uv, win.half, win.size
    at = np.flatnonzero(valid)  # (K,) flat (marker, camera) index of each window
    mi, ci = np.divmod(at, valid.shape[1])
    centre = np.round(uv.reshape(-1, 2)[at]).astype(np.int64)  # (K, 2) window centre pixel x, y
    ext = half.reshape(-1)[at].astype(np.int64)[:, None]  # half size rounded down (it is positive)
    size_k = size[ci]
    lo = np.minimum(np.maximum(centre - ext, 0), size_k)  # (K, 2) x0, y0
    hi = np.maximum(np.minimum(centre + ext + 1, size_k), lo)  # (K, 2) x1, y1 (exclusive)
    if compiled:
        # one compiled pass over the windows' pixels (tracking.window_kernel): the same
        # counts, sums and pixel coordinates as the numpy path, to the bit
        count, sums, col, row = window_kernel.window_moments(
            images, table.lut, ci, np.concatenate([lo, hi], axis=1), setup.label[mi], table.bits)
    else:
        count, sums, col, row = window_moments_numpy(table, images, setup.label[mi], ci, lo, hi)
    sc, sr, scc, srr, scr = sums
    first = (lo - centre).astype(np.float64).T  # (2, K) offsets of each window's first pixel
    fx, fy = first
    m00 = count.astype(np.float64)
    sxy = sums[:2] + m00 * first
    sx, sy = sxy
    with np.errstate(divide="ignore", invalid="ignore"):
        mxy = sxy / m00  # (2, K) centroid about the centre pixel
        mx, my = mxy
        mu20 = (scc + fx * (sc + sx)) / m00 - mx**2
        mu02 = (srr + fy * (sr + sy)) / m00 - my**2
        mu11 = (scr + fy * sc + fx * sy) / m00 - mx * my
        roundness = axis_ratio(mu20, mu02, mu11)
        round_px = axis_ratio(mu20, mu02, mu11, PIXEL_MOMENT)  # roundness as tracking.blobs measures it
    r_k = win.r_px.reshape(-1)[at]
    ball_area = np.pi * r_k**2
    # a sliver (under 40 % of the ball's area) is a ball mostly hidden in this camera: no view
    ok = (m00 >= setup.min_area_px[ci]) & (m00 >= p.sliver_area_ratio * ball_area)
    simple = ok & (m00 <= p.simple_max_area_ratio * ball_area) & (roundness >= p.simple_min_roundness)
    radius = np.sqrt(m00 / np.pi)
    return WindowMoments(at, mi, ci, centre, lo, hi, count, col, row, first, mxy.T, round_px, r_k, ok, simple,
                         radius)


def queue_partial_balls(arcs: ArcRegions, p: TrackerParams, win: SearchWindows, wm: WindowMoments) -> np.ndarray:
    """A partly hidden ball: its region's centroid lies towards the visible part; its centre comes
    from the visible arc instead (only these few windows pay for it), all in one call with those of
    the crowded windows. Returns (K,) which windows were queued."""
    m00 = wm.count.astype(np.float64)
    simple = wm.simple
    edge_r = wm.r_k - ARC_EDGE_SHRINK_PX
    # (a region larger than the whole ball is no partly hidden ball: two balls of the colour
    # touching, whose outline fits neither)
    part = simple & (m00 <= np.pi * edge_r**2) & ((m00 < np.pi * (p.arc_fit_ratio * edge_r) ** 2)
                                                 | (wm.round_px < p.arc_fit_roundness)
                                                 | (edge_r < p.arc_fit_all_below_px))
    # a view well below the ball's size is left out anyway while two full views remain (views stage)
    ratio = wm.radius / wm.r_k
    full = simple & p.full_view(ratio)
    part &= ~((ratio < p.partial_ratio) & (np.bincount(wm.mi[full], minlength=win.valid.shape[0])[wm.mi] >= 2))
    if part.any():
        fx, fy = wm.first
        win_k = np.repeat(np.arange(wm.mi.size), wm.count)
        sel = part[win_k]
        ws = win_k[sel]
        at, centre = wm.at, wm.centre
        arcs.add_many((np.cumsum(part) - 1)[ws], wm.col[sel] + fx[ws], wm.row[sel] + fy[ws], wm.mxy[part],
                      win.uv.reshape(-1, 2)[at[part]] - centre[part], edge_r[part], wm.first.T[part],
                      (wm.hi - 1 - centre)[part], centre[part], wm.mi[part], wm.ci[part],
                      win.sigma_px.reshape(-1)[at[part]])
    return part


def luma_windows(setup: Setup, table: ColourTable, images: Sequence[np.ndarray], wm: WindowMoments,
                 whole: np.ndarray, luma: LumaLabels, compiled: bool, uv_out: np.ndarray,
                 confirm_px: float = 0.2) -> None:
    """The centres of the windows' whole balls (``whole``: one ball, not fitted to its arc) from
    the luma, with the full-frame detection's fit and gates (:func:`tracking.blobs.find_blobs`
    with ``luma=True``): of the balls within the camera's blob gates, each centroid is checked
    against :func:`~tracking.blobs.luma_centre`, and the fit's centre taken where the fit is sure
    and differs by more than ``confirm_px`` (``TrackerParams.window_luma_confirm_px``). The
    labels of all the fits' boxes are written in one compiled pass; the fits are one call each
    (``luma_centre`` is the blobs module's one entry to the fit)."""
    m00 = wm.count.astype(np.float64)
    min_area = np.array([g.min_area_px for g in setup.gates])[wm.ci]
    max_area = np.array([g.max_area_px for g in setup.gates])[wm.ci]
    min_round = np.array([g.min_roundness for g in setup.gates])[wm.ci]
    fit = np.flatnonzero(whole & (m00 >= min_area) & (m00 <= max_area) & (wm.round_px >= min_round))
    if not fit.size:
        return
    uv = wm.centre[fit] + wm.mxy[fit]  # (F, 2) the colour centroids
    radius = wm.radius[fit]
    ci = wm.ci[fit]
    # each fit reads the pixels within radius + 3 of its start (luma_centre): a box around that
    reach = np.ceil(radius)[:, None] + 5.0
    size = np.array([img.shape[1::-1] for img in images], dtype=np.int64)[ci]
    lo = np.clip(np.floor(uv - reach), 0, size).astype(np.int64)
    hi = np.clip(np.ceil(uv + reach) + 1, 0, size).astype(np.int64)
    hi = np.maximum(hi, lo)
    labels = luma.of(images)
    if compiled:
        window_kernel.fill_labels(images, table.lut, ci, np.concatenate([lo, hi], axis=1), table.bits, labels)
    else:
        for c, (x0, y0), (x1, y1) in zip(ci.tolist(), lo.tolist(), hi.tolist()):
            labels[c][y0:y1, x0:x1] = table.classify_window(images[c], x0, y0, x1, y1)
    colour = setup.colour[wm.mi[fit]]
    for j, k in enumerate(fit.tolist()):
        c = int(ci[j])
        u, v = float(uv[j, 0]), float(uv[j, 1])
        centre = luma_centre(images[c], labels[c], int(colour[j]), u, v, float(radius[j]), compiled=compiled)
        if centre is not None and math.hypot(centre[0] - u, centre[1] - v) > confirm_px:
            uv_out[wm.mi[k], c] = centre


def crowded_windows(setup: Setup, p: TrackerParams, table: ColourTable, images: Sequence[np.ndarray],
                    win: SearchWindows, wm: WindowMoments, recent: np.ndarray, compiled: bool, arcs: ArcRegions,
                    uv_out: np.ndarray, rad_out: np.ndarray) -> None:
    """The windows holding several regions (``ok`` but not ``simple``): the region of the marker's
    colour nearest its prediction, in a window of the size that the markers measured last frame
    (``recent``) share in this camera; a partly hidden one goes to ``arcs``."""
    uv, half, valid, sigma_px = win.uv, win.half, win.valid, win.sigma_px
    edge_r = wm.r_k - ARC_EDGE_SHRINK_PX
    size_k = win.size[wm.ci]
    for k in np.flatnonzero(wm.ok & ~wm.simple).tolist():
        m, c = int(wm.mi[k]), int(wm.ci[k])
        hw = int(np.ceil(half[recent & valid[:, c], c].max() if recent[m] else half[m, c]))
        img, gate = images[c], setup.gates[c]
        (cx, cy), (w_img, h_img) = wm.centre[k].tolist(), size_k[k].tolist()
        x0k, y0k = max(0, cx - hw), max(0, cy - hw)
        x1k, y1k = min(w_img, cx + hw + 1), min(h_img, cy + hw + 1)
        if compiled:  # the same regions, gates and choice in one compiled pass
            found, uv_j, area, round_j, xs, ys = window_kernel.crowded_window(
                img, table.lut, table.bits, (x0k, y0k, x1k, y1k), int(setup.label[m]), uv[m, c], gate)
            if found:
                radius_j = math.sqrt(area / math.pi)
                uv_out[m, c] = uv_j
                rad_out[m, c] = radius_j
                if radius_j <= edge_r[k] and (radius_j < p.arc_fit_ratio * edge_r[k]
                                              or round_j < p.arc_fit_roundness):
                    arcs.add_pixels(xs, ys, np.array(uv_j), uv[m, c], (x0k, y0k), (x1k - x0k, y1k - y0k), edge_r[k],
                                    m, c, float(sigma_px[m, c]))
            continue
        win_labels = table.classify_window(img, x0k, y0k, x1k, y1k)
        blobs = find_blobs(win_labels, table.n_colours, min_area_px=gate.min_area_px,
                           max_area_px=gate.max_area_px, min_roundness=gate.min_roundness,
                           offset_px=(x0k, y0k), colours=(int(setup.colour[m]),))
        if len(blobs):
            j = np.argmin(np.linalg.norm(blobs.uv_px - uv[m, c], axis=1))
            uv_out[m, c] = blobs.uv_px[j]
            rad_out[m, c] = blobs.radius_px[j]
            if blobs.radius_px[j] <= edge_r[k] and (blobs.radius_px[j] < p.arc_fit_ratio * edge_r[k]
                                                    or blobs.roundness[j] < p.arc_fit_roundness):
                # e.g. half a ball (roundness ~0.5), or a ball beside another of its colour
                arcs.add_region(win_labels == setup.label[m], blobs.uv_px[j], uv[m, c], (x0k, y0k), edge_r[k], m, c,
                                float(sigma_px[m, c]))


def one_ball_one_marker(setup: Setup, p: TrackerParams, uv: np.ndarray, sigma_px: np.ndarray, r_px: np.ndarray,
                        uv_out: np.ndarray, rad_out: np.ndarray) -> None:
    """A ball that the windows of two markers of its colour both found (the same blob in one
    camera, e.g. a hidden wrist marker behind the elbow marker of its colour on one line of
    sight) is a view of the marker whose prediction makes it likelier only; the other loses
    that view. Likelier: the smaller ``d^2 / sigma^2 + 4 ln sigma`` (minus twice the log of a
    2D normal density; d the distance from the prediction, sigma its uncertainty, pixels), so
    a marker estimated for a while, whose wide uncertainty puts any ball near its prediction,
    does not take the ball of a marker measured last frame that is a little farther from its
    sharp prediction."""
    i, j = setup.colour_pairs_ij
    d = uv_out[i] - uv_out[j]  # (P, C, 2), NaN where either has none (no warning: no inf)
    shared = (d * d).sum(axis=2) < (p.shared_view_ratio * np.minimum(r_px[i], r_px[j])) ** 2
    if not shared.any():
        return
    pair, cam = np.nonzero(shared)
    ab = np.stack((i[pair], j[pair]))  # (2, S) the two markers of each shared view
    s = sigma_px[ab, cam]
    # (4 ln sigma: minus twice the log of the 2D normal's normalization, not a tuned number)
    score = ((uv_out[ab, cam] - uv[ab, cam]) ** 2).sum(axis=2) / (s * s) + 4.0 * np.log(s)
    a, b = ab
    loser = np.where(score[0] <= score[1], b, a)
    uv_out[loser, cam] = np.nan
    rad_out[loser, cam] = np.nan
