"""Connected marker-coloured regions -> sub-pixel centroids, areas and roundness.

A blob is an 8-connected region of one label of a :class:`tracking.colour.table.ColourTable`
label image. Nothing is merged or split: two touching markers of one colour form one blob, whose
poor roundness rejects it (or flags it when ``min_roundness=0``).

Centroids
---------
The centroid of the binary region is off by up to 0.43 px (RMS 0.12-0.18 px) on rendered balls of
radius 2.5-12 px: which edge pixels pass the saturation test depends on how bright the ball is there
(its dark side mixes with the background much sooner than its lit side) and on noise. When the
image is given, the centroid is instead the coverage-weighted mean position: interior pixels weigh
1; each edge pixel and each pixel of the one-pixel ring around the region weighs its estimated
coverage ``alpha``, from unmixing its colour ``p`` as ``p = a * m + c * b`` in least squares, where
``m`` is the unit direction of the region's interior colour (the free scale ``a`` absorbs the
shading, so a dark side needs no more coverage than a lit one), ``b`` the local background colour
(mean of the non-marker pixels 2-3 px outside the region within a 5x5 window) and
``alpha = 1 - c``. Two guards: where the background has almost no colour across ``m`` (black, or
the marker's own hue) the binary weight is kept, since there a half-covered pixel looks like a
darker covered one; and ``alpha`` may not exceed twice ``a`` over the darkest interior pixel
nearby, so that background darker than its surroundings (an arm shaded towards its outline) is
not taken for marker.

Measured on balls drawn like ``draw_ball`` in tests/tracking/test_blobs.py (8x8 supersampled
Lambert spheres, 0.3 ambient, palette colours, noise sigma 1 count), 900 per radius: 60 random
sub-pixel positions x 5 uniform backgrounds (grey 90, dark blue-grey, light grey, skin, navy) x 3
lights (frontal, 45 deg oblique, grazing); error in px, max / RMS over all 900:

=========  ==================  ==================
radius px  binary max / RMS    refined max / RMS
=========  ==================  ==================
2.5        0.43 / 0.18         0.079 / 0.018
3.5        0.43 / 0.16         0.041 / 0.011
5          0.39 / 0.14         0.030 / 0.009
8          0.29 / 0.13         0.020 / 0.007
12         0.28 / 0.12         0.019 / 0.005
=========  ==================  ==================

The refined radius is unbiased (mean error < 0.01 px), the binary one 0.25 px too small; the
refined roundness of these balls is >= 0.95 (binary >= 0.79 at radius 2.5). Harder scenes:

* a ball at the shaded outline of an arm over a dark shirt (test_ball_over_a_shaded_background_edge):
  refined 0.078 px RMS, binary 0.157; when the outline runs right along the ball's edge with
  steep shading, both ~0.155 (three colours in one pixel do not unmix into two);
* the simulated studio (tracking.sim, 4 cameras 640x480, radius 4.5-6.6 px, noise 1.5, markers
  >= 99 % visible, error against the projected ball centre, 220 observations): refined 0.063 px
  RMS (max 0.22), binary 0.137 (max 0.32); the worst are the cyan medial markers against arm and
  shirt (refined 0.10 RMS, binary 0.11);
* on a black background (< ~8 counts) the refined centroid falls back to the binary one.

A first try, weighting the ring pixels by their saturation, reached 0.03-0.06 px RMS with frontal
light but kept a 0.12 px bias towards the lit side with oblique light, hence the unmixing.
Refinement costs ~0.1-0.3 ms per blob (pure numpy/OpenCV on a patch around the blob). Holes
inside a region (a white specular highlight fails the saturation test) are filled before anything
is measured, and left out of the interior colour.

Colour at half resolution
-------------------------
Webcams send colour at half resolution (MJPEG 4:2:0 or 4:2:2, YUYV), which moves the colour edge,
and with it the centroid above, by a third to half a pixel; their luma is at full resolution.
With ``luma=True`` each refined centre is checked against a fit of the ball in the luma
(:func:`luma_centre`: a shaded disc over a background plane) and the fit's is taken where the two
disagree by more than ``LUMA_CONFIRM_PX`` and the fit pins the centre; the colour only names the
ball then. Measurements and what else was tried: docs/TRACKING.md, "Marker centres from the luma".

Partly hidden balls
-------------------
A ball partly hidden by something in front of it leaves a region whose centroid lies towards the
visible part, by up to 0.4 radii. :func:`arc_centres` fits the circle of the ball's known radius
to the visible arc of the region's outline instead (the tracker's windows use it, with the
radius from the predicted depth): on rendered balls 10-35 % hidden, 0.22 px RMS against the
centroid's 1.25 (docs/TRACKING.md, "Partly hidden balls"). Given the images (``colours``), it
fits each arc again on edge points placed by the pixels' coverage, unmixed from the ball's colour
inside and the background beyond (:func:`_subpixel_edges`), with the ball's full radius: a binary
region reaches into a dark background (a pixel a fifth covered still shows the ball's hue) and
stops short of a bright one. On rendered balls 10-35 % hidden the median error falls from 0.245 to
0.122 px (radius 2.5-3.8 px) and from 0.172 to 0.05 px (4-8 px).
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np
from scipy.special import erf as _erf

from tracking.jit import compile_loop, plain_images

DEFAULT_MIN_AREA_PX = 12
"""Fewer pixels than a disc of radius 2 px: noise (e.g. deep-shadow dark skin), not a marker."""
DEFAULT_MAX_AREA_PX = 5000
"""More than a disc of radius 40 px: a coloured garment or object, not a 40 mm ball."""
DEFAULT_MIN_ROUNDNESS = 0.7
"""Minor/major axis ratio: single balls measure >= 0.95 (>= 0.79 binary), two touching ones ~0.45."""

DEFAULT_MAX_PER_COLOUR = 32
"""Regions of one colour measured in one image at most. A marker set has a few markers of a colour
(the upper-limb set at most 4); sensor noise, JPEG blocks or a patterned garment of a marker
colour can make thousands, which would cost seconds per image here and gigabytes in the
matching across cameras. Beyond it the largest, roundest regions are measured (a warning says so)."""

log = logging.getLogger(__name__)
_capped_images = 0  # images whose regions were capped, for the warning's count

_MARGIN_PX = 3  # patch margin: 1 px coverage ring + 2 px background annulus
_BG_WINDOW_PX = 5  # window of the local background mean
# Background colour (counts) across the marker's colour direction below which coverage is not
# unmixed: on black, a half-covered pixel looks like a darker fully covered one.
_MIN_BACKGROUND_CHROMA = 8.0
# A marker's edge pixel can be this much darker than the darkest interior pixel near it (the
# limb of a ball lit from the camera falls to the ambient level within a pixel or two).
_MARKER_SHADING_RATIO = 2.0
_FAR = 1e9
_K3 = np.ones((3, 3), dtype=np.uint8)
_K5 = np.ones((5, 5), dtype=np.uint8)
_K7 = np.ones((7, 7), dtype=np.uint8)


@dataclass(frozen=True, slots=True, eq=False)
class Blobs:
    """Blobs of one image, ordered by colour, then by position of their first pixel in raster order.

    Attributes:
        uv_px: (N, 2) float64 centroids in full-image pixel coordinates (OpenCV: the centre of the
            top-left pixel is (0, 0), x right, y down).
        area_px: (N,) float64 area in pixels (coverage-weighted when refined from the image).
        colour: (N,) int64 palette index (label - 1).
        roundness: (N,) float64 minor/major axis ratio of the second moments, 0..1 (1 = disc).
        radius_px: (N,) float64 radius of the disc with that area, sqrt(area / pi).
    """

    uv_px: np.ndarray
    area_px: np.ndarray
    colour: np.ndarray
    roundness: np.ndarray
    radius_px: np.ndarray

    def __post_init__(self) -> None:
        n = self.uv_px.shape[0]
        if self.uv_px.shape != (n, 2) or any(
            a.shape != (n,) for a in (self.area_px, self.colour, self.roundness, self.radius_px)
        ):
            raise ValueError("Blobs arrays must be (N, 2) uv_px and (N,) area_px, colour, roundness, radius_px")

    def __len__(self) -> int:
        return int(self.uv_px.shape[0])

    @classmethod
    def empty(cls) -> "Blobs":
        """No blobs: arrays of length 0 with the documented shapes and dtypes."""
        z = np.zeros(0, dtype=np.float64)
        return cls(np.zeros((0, 2), dtype=np.float64), z, np.zeros(0, dtype=np.int64), z.copy(), z.copy())

    def of_colour(self, colour: int) -> "Blobs":
        """The blobs of one palette colour."""
        keep = self.colour == colour
        return Blobs(
            self.uv_px[keep], self.area_px[keep], self.colour[keep], self.roundness[keep], self.radius_px[keep]
        )


def find_blobs(
    labels: np.ndarray,
    n_colours: int,
    *,
    image_bgr: np.ndarray | None = None,
    min_area_px: float = DEFAULT_MIN_AREA_PX,
    max_area_px: float = DEFAULT_MAX_AREA_PX,
    min_roundness: float = DEFAULT_MIN_ROUNDNESS,
    offset_px: tuple[float, float] = (0.0, 0.0),
    colours: Sequence[int] | None = None,
    max_per_colour: int | Sequence[int] | None = DEFAULT_MAX_PER_COLOUR,
    luma: bool = False,
) -> Blobs:
    """Find the 8-connected regions of each colour label and measure them.

    Args:
        labels: (H, W) uint8 labels from :meth:`ColourTable.classify` (0 background, k + 1 colour k),
            or from ``classify_window`` for a window.
        n_colours: number of palette colours K; labels above K are ignored.
        image_bgr: (H, W, 3) uint8 BGR pixels the labels came from (for a window: the same window,
            ``image[y0:y1, x0:x1]``, a view). Given, centroids are refined by coverage unmixing
            (module doc); omitted, they are binary-region centroids (less accurate).
        min_area_px, max_area_px: accepted range of the region's pixel count (holes filled).
        min_roundness: minimum minor/major axis ratio, 0..1; 0 keeps every region.
        offset_px: (x, y) added to every centroid: the window's top-left corner (x0, y0) for labels
            of a window, so that centroids land in full-image coordinates.
        colours: palette indices to look for (default: all ``n_colours``); the blobs of a colour do
            not depend on the others, so this only saves time.
        max_per_colour: measure at most this many regions of each colour (None: all; a sequence:
            one bound per palette colour), the largest and roundest by their outline
            (:func:`_cap_regions`), so that time and memory stay bounded whatever the image; a
            warning says when regions were left out.
        luma: with ``image_bgr``, check each refined centre against a fit of the ball in the
            image's luma (:func:`luma_centre`) and take the fit's where they disagree by more than
            ``LUMA_CONFIRM_PX`` (colour subsampled by MJPEG or YUYV moves the colour edge; the luma
            is at full resolution). False: the colour centres alone.

    Returns:
        The accepted :class:`Blobs`.
    """
    _check_labels(labels, image_bgr)
    if labels.size == 0:
        return Blobs.empty()
    ox, oy = float(offset_px[0]), float(offset_px[1])
    rows: list[tuple[int, int, int, float, float, float, float]] = []
    for k in range(n_colours) if colours is None else sorted(c for c in colours if 0 <= c < n_colours):
        cap = max_per_colour if max_per_colour is None or isinstance(max_per_colour, int) else int(max_per_colour[k])
        for contour, measured in _colour_regions(labels, image_bgr, k, cap, min_area_px, max_area_px, min_roundness,
                                                 luma):
            first_x, first_y = (int(c) for c in contour[0, 0])
            rows.append((k, first_y, first_x, measured[0] + ox, measured[1] + oy, measured[2], measured[3]))
    if not rows:
        return Blobs.empty()
    rows.sort(key=lambda row: row[:3])
    arr = np.array([row[3:] for row in rows], dtype=np.float64)
    area = arr[:, 2].copy()
    return Blobs(
        uv_px=arr[:, 0:2].copy(),
        area_px=area,
        colour=np.array([row[0] for row in rows], dtype=np.int64),
        roundness=arr[:, 3].copy(),
        radius_px=np.sqrt(area / np.pi),
    )


def _check_labels(labels: np.ndarray, image_bgr: np.ndarray | None) -> None:
    """:func:`find_blobs`' arguments: (H, W) uint8 labels and, given, the image window they came from."""
    if labels.ndim != 2 or labels.dtype != np.uint8:
        raise ValueError(f"labels must be a (H, W) uint8 array, got {labels.dtype} {labels.shape}")
    if image_bgr is not None and (image_bgr.shape[:2] != labels.shape or image_bgr.dtype != np.uint8):
        raise ValueError(
            f"image_bgr {image_bgr.dtype} {image_bgr.shape} does not match labels {labels.shape}: "
            "pass the same window of the image as the labels"
        )


def _colour_regions(labels: np.ndarray, image_bgr: np.ndarray | None, k: int, cap: int | None, min_area_px: float,
                    max_area_px: float, min_roundness: float, luma: bool):
    """Yield (contour, (u, v, area, roundness)) of each accepted region of colour ``k`` (as
    :func:`find_blobs`; centres in label-image pixels)."""
    mask = np.equal(labels, k + 1).view(np.uint8)
    # the outer contours of the 8-connected regions: ~50x faster than connectedComponentsWithStats
    # on sparse masks, and filling one gives its region with the holes filled
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if cap is not None and len(contours) > cap:
        contours = _cap_regions(contours, k, cap, min_area_px, max_area_px)
    for contour in contours:
        x, y, w, h = cv2.boundingRect(contour)
        if w * h < min_area_px:
            continue
        measured = _measure(labels, image_bgr, contour, k, x, y, w, h, min_area_px, max_area_px)
        if measured is None or measured[3] < min_roundness:
            continue
        if luma and image_bgr is not None:  # (only the regions that passed the gates pay for the fit)
            fit = luma_centre(image_bgr, labels, k, measured[0], measured[1], math.sqrt(measured[2] / math.pi))
            if fit is not None and math.hypot(fit[0] - measured[0], fit[1] - measured[1]) > LUMA_CONFIRM_PX:
                measured = (fit[0], fit[1], measured[2], measured[3])
        yield contour, measured


def _cap_regions(contours, colour: int, cap: int, min_area_px: float, max_area_px: float) -> list:
    """The ``cap`` regions most like a marker among ``contours`` (more than ``cap``): in the area
    range by their outline, the largest and roundest first (outline area times roundness)."""
    global _capped_images
    scores = np.full(len(contours), -1.0)
    # A contour of one or two points (a lone pixel, a straight one-pixel run) encloses no area:
    # below any positive area range without its moments. Noise makes these ~96 % of the regions
    # (sigma 10 at 640x480), so skipping them is most of the cost of choosing.
    for i in (range(len(contours)) if min_area_px <= 0 else [i for i, c in enumerate(contours) if len(c) > 2]):
        contour = contours[i]
        mom = cv2.moments(contour)
        area = mom["m00"]   # the outline's area: a little under the pixel count
        if 0.5 * min_area_px <= area <= max_area_px:
            scores[i] = area * binary_roundness(area, mom["m10"], mom["m01"], mom["m20"], mom["m02"], mom["m11"])
    keep = np.argsort(-scores, kind="stable")[:cap]
    keep = np.sort(keep[scores[keep] >= 0])
    _capped_images += 1
    if _capped_images == 1 or _capped_images % 1000 == 0:
        log.warning("an image has %d regions of marker colour %d (noise, compression blocks or a garment of "
                    "that colour?): only the %d most marker-like are measured (%d such images so far)",
                    len(contours), colour, cap, _capped_images)
    return [contours[i] for i in keep]


def _measure(
    labels: np.ndarray,
    image_bgr: np.ndarray | None,
    contour: np.ndarray,
    colour: int,
    x: int,
    y: int,
    w: int,
    h: int,
    min_area_px: float,
    max_area_px: float,
) -> tuple[float, float, float, float] | None:
    """Centroid (u, v) in label-image pixels, area and roundness of the region inside ``contour``.

    Works on the region's bounding box (x, y, w, h) grown by ``_MARGIN_PX``; returns None when the
    region with its holes filled is outside the area range.
    """
    hh, ww = labels.shape
    x0, y0 = max(x - _MARGIN_PX, 0), max(y - _MARGIN_PX, 0)
    x1, y1 = min(x + w + _MARGIN_PX, ww), min(y + h + _MARGIN_PX, hh)
    filled = np.zeros((y1 - y0, x1 - x0), dtype=np.uint8)
    cv2.drawContours(filled, [contour], -1, 1, thickness=cv2.FILLED, offset=(-x0, -y0))
    count = cv2.countNonZero(filled)
    if count < min_area_px or count > max_area_px:
        return None
    if image_bgr is None:
        weights = filled
    else:
        weights = _coverage(image_bgr[y0:y1, x0:x1], labels[y0:y1, x0:x1], filled, colour)
    mom = cv2.moments(weights)
    total = mom["m00"]
    if total <= 0.0:
        return None
    if image_bgr is None:
        roundness = binary_roundness(total, mom["m10"], mom["m01"], mom["m20"], mom["m02"], mom["m11"])
        return x0 + mom["m10"] / total, y0 + mom["m01"] / total, float(total), roundness
    roundness = float(axis_ratio(mom["mu20"] / total, mom["mu02"] / total, mom["mu11"] / total, PIXEL_MOMENT))
    return x0 + mom["m10"] / total, y0 + mom["m01"] / total, float(total), roundness


LUMA_CONFIRM_PX = 0.2
"""The colour centre stands where the luma fit (:func:`luma_centre`) lands within this of it: with
colour at full resolution the unmixing is the more exact (it tells shading from coverage, which
brightness alone cannot); a larger disagreement is a colour edge moved by subsampled chroma."""
LUMA_MAX_SE_PX = 0.1
"""The luma fit is used only when it pins the centre to this standard error (px, from the fit's
residuals and Jacobian): a ball whose brightness barely differs from its background's (a green
ball on a mid-grey shirt) has a weak luma edge, and there the fit can wander to the background's
own edges."""
_LUMA_GROW_PX = 3.0  # pixels fitted: within the colour radius + this of the colour centre
_LUMA_ITERATIONS = 6
_LUMA_STEP_DONE_PX = 0.005  # a step of centre and radius below this ends the iterations
_LUMA_BGR = np.array([0.114, 0.587, 0.299])  # BT.601 luma, what JPEG keeps at full resolution
_SQRT2 = math.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


def luma_centre(image_bgr: np.ndarray, labels: np.ndarray, colour: int, u: float, v: float,
                radius_px: float, *, compiled: bool = True) -> tuple[float, float] | None:
    """The centre of a ball from its image's luma, by fitting a shaded disc over a background.

    Model of each pixel's luma within ``radius_px + 3`` of the start (u, v), pixels of other marker
    colours left out: ``Y = c S + (1 - c) B`` with ``c = Phi((r - d) / s)`` the disc's coverage (d
    the distance to the centre, r the radius, s the edge's blur: pixel area, lens, anti-aliasing),
    ``S`` the ball's shading as a quadratic in x, y (a matt ball under smooth light) and ``B`` the
    background as a plane. Centre, radius, blur and the 9 linear coefficients are fitted together
    by Gauss-Newton (the Jacobian exact: the polynomials are taken about the fixed start).

    Why it is unbiased under MJPEG: JPEG keeps luma at full resolution and only the colour at half
    (4:2:2, 4:2:0), so the luma edge is where the ball's edge is; the fit finds it for a ball
    brighter or darker than its background alike (the step's height and sign are coefficients,
    not assumptions), and the coverage model puts it at sub-pixel positions. What it cannot model:
    a shadow boundary across the ball (a hard light from one side, where the quadratic shading
    does not fit) and a background with edges of its own inside the fitted ring.

    ``compiled``: one compiled loop (numba, where installed; :func:`_luma_fit_loop`) instead of
    numpy: the same arithmetic, sums in another order (the centres agree to ~1e-9 px).

    Returns:
        (u, v) full-image pixels, or None where the fit is not sure (standard error above
        ``LUMA_MAX_SE_PX``), fails, or wanders (radius or centre beyond half the radius).
    """
    h_img, w_img = labels.shape
    reach = radius_px + _LUMA_GROW_PX
    x0, y0 = max(int(u - reach), 0), max(int(v - reach), 0)
    x1, y1 = min(int(u + reach) + 2, w_img), min(int(v + reach) + 2, h_img)
    if x1 - x0 < 3 or y1 - y0 < 3:
        return None
    loop = _luma_loop() if compiled and plain_images([image_bgr]) and labels.flags.c_contiguous else None
    if loop is not None:
        out = np.zeros(2)
        ok = loop(image_bgr, labels, colour + 1, x0, y0, x1, y1, float(u), float(v), float(radius_px), reach,
                  _LUMA_ITERATIONS, LUMA_MAX_SE_PX, out)
        return (u + out[0], v + out[1]) if ok else None
    gx, gy, lum = _luma_pixels(image_bgr, labels, colour, u, v, reach, (x0, y0, x1, y1))
    if gx.size < 16:
        return None
    fit = _luma_fit(gx, gy, lum, radius_px)
    return None if fit is None else (u + fit[0], v + fit[1])


def _luma_pixels(image_bgr: np.ndarray, labels: np.ndarray, colour: int, u: float, v: float, reach: float,
                 box: tuple[int, int, int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pixels :func:`luma_centre` fits: within ``reach`` of (u, v) in ``box`` (x0, y0, x1, y1),
    background or ``colour``; (x, y) about the start and their luma."""
    x0, y0, x1, y1 = box
    lab = labels[y0:y1, x0:x1]
    yy, xx = np.mgrid[y0:y1, x0:x1]
    near = ((xx - u) ** 2 + (yy - v) ** 2 <= reach * reach) & ((lab == 0) | (lab == colour + 1))
    py, px = np.nonzero(near)
    lum = image_bgr[y0:y1, x0:x1][py, px] @ _LUMA_BGR
    gx = px + (x0 - u)  # pixel positions about the start
    gy = py + (y0 - v)
    return gx, gy, lum


def _luma_fit(gx: np.ndarray, gy: np.ndarray, lum: np.ndarray, radius_px: float) -> tuple[float, float] | None:
    """:func:`luma_centre`'s Gauss-Newton fit in numpy on the pixels ``gx``, ``gy`` (about the
    start) of luma ``lum``: the centre's offset from the start, or None (as :func:`luma_centre`)."""
    n = gx.size
    scale = 1.0 / max(radius_px, 1.0)
    bx, by = gx * scale, gy * scale
    one = np.ones(n)
    shading = np.stack((one, bx, by, bx * bx, bx * by, by * by), axis=1)  # (n, 6)
    plane = shading[:, :3]
    cx = cy = 0.0
    r, s = float(radius_px), 0.5
    jac = np.empty((n, 13))
    for _ in range(_LUMA_ITERATIONS):
        dx, dy = gx - cx, gy - cy
        d = np.sqrt(dx * dx + dy * dy) + 1e-9
        z = (r - d) / s
        cov = 0.5 * (1.0 + _erf(z / _SQRT2))
        np.multiply(cov[:, None], shading, out=jac[:, 4:10])
        np.multiply((1.0 - cov)[:, None], plane, out=jac[:, 10:13])
        lin = jac[:, 4:]
        try:
            coef = np.linalg.solve(lin.T @ lin + 1e-9 * np.eye(9), lin.T @ lum)
        except np.linalg.LinAlgError:
            return None
        res = lum - lin @ coef
        contrast = shading @ coef[:6] - plane @ coef[6:]
        dens = contrast * np.exp(-0.5 * z * z) * (_INV_SQRT_2PI / s)  # dY / d(r - d)
        jac[:, 0] = dens * dx / d
        jac[:, 1] = dens * dy / d
        jac[:, 2] = dens
        jac[:, 3] = -dens * z
        normal = jac.T @ jac + 1e-9 * np.eye(13)
        try:
            step = np.linalg.solve(normal, jac.T @ res)
        except np.linalg.LinAlgError:
            return None
        cx, cy, r = cx + step[0], cy + step[1], r + step[2]
        s = min(max(s + step[3], 0.2), 1.5)
        if not (abs(r - radius_px) < 0.5 * radius_px and math.hypot(cx, cy) < 0.5 * radius_px):
            return None
        if max(abs(step[0]), abs(step[1]), abs(step[2])) < _LUMA_STEP_DONE_PX:
            break
    try:
        var = np.linalg.inv(normal)[:2, :2] * (float(res @ res) / max(n - 13, 1))
    except np.linalg.LinAlgError:
        return None
    if not var[0, 0] + var[1, 1] <= LUMA_MAX_SE_PX ** 2:
        return None
    return cx, cy


def _luma_rows(gx, gy, lum, n, scale, cx, cy, r, s, coef, jac, res):
    """The Jacobian rows (``jac``, (n, 13)) and residuals (``res``) of :func:`_luma_fit_loop`'s
    model at the current parameters; returns the residuals' sum of squares."""
    sse = 0.0
    inv_s = 1.0 / s
    inv_sqrt2 = 1.0 / math.sqrt(2.0)
    dens_scale = inv_s / math.sqrt(2.0 * math.pi)
    for i in range(n):
        dx, dy = gx[i] - cx, gy[i] - cy
        d = math.sqrt(dx * dx + dy * dy) + 1e-9
        z = (r - d) * inv_s
        gauss = math.exp(-0.5 * z * z)
        # erf(z / sqrt 2) by Abramowitz & Stegun 7.1.26 (|error| < 1.5e-7) on the exp the
        # derivative needs anyway: a luma error of ~1e-5 levels, a third of the pixel's cost
        t = 1.0 / (1.0 + 0.3275911 * abs(z) * inv_sqrt2)
        half = 0.5 * t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429)))) * gauss
        cov = 1.0 - half if z >= 0.0 else half
        bx, by = gx[i] * scale, gy[i] * scale
        sh = coef[0] + coef[1] * bx + coef[2] * by + coef[3] * bx * bx + coef[4] * bx * by + coef[5] * by * by
        bg = coef[6] + coef[7] * bx + coef[8] * by
        e = lum[i] - (cov * sh + (1.0 - cov) * bg)
        res[i] = e
        sse += e * e
        dens = (sh - bg) * gauss * dens_scale
        row = jac[i]
        row[0], row[1], row[2], row[3] = dens * dx / d, dens * dy / d, dens, -dens * z
        row[4], row[5], row[6], row[7], row[8], row[9] = cov, cov * bx, cov * by, cov * bx * bx, cov * bx * by, cov * by * by
        row[10], row[11], row[12] = 1.0 - cov, (1.0 - cov) * bx, (1.0 - cov) * by
    return sse


def _luma_fit_loop(img, labels, own, x0, y0, x1, y1, u, v, radius, reach, iterations, max_se, out):
    """:func:`luma_centre`'s fit as loops over the pixels (compiled by numba; plain Python runs it
    too): the same model, tests and start; all 13 parameters stepped together by Gauss-Newton
    from a first linear solve (the numpy path solves the 9 linear ones anew each iteration: both
    converge to the same least-squares fit). The normal equations are one matrix product of the
    Jacobian (BLAS), not sums per pixel. ``out`` receives the centre's offset from (u, v).
    Returns whether the fit is sure."""
    cap = (y1 - y0) * (x1 - x0)
    gx = np.empty(cap)
    gy = np.empty(cap)
    lum = np.empty(cap)
    n = 0
    for y in range(y0, y1):
        for x in range(x0, x1):
            lab = labels[y, x]
            if (x - u) ** 2 + (y - v) ** 2 <= reach * reach and (lab == 0 or lab == own):
                gx[n] = x - u
                gy[n] = y - v
                lum[n] = 0.114 * img[y, x, 0] + 0.587 * img[y, x, 1] + 0.299 * img[y, x, 2]
                n += 1
    if n < 16:
        return False
    scale = 1.0 / max(radius, 1.0)
    coef = np.zeros(9)
    jac = np.empty((n, 13))
    res = np.empty(n)
    ridge = 1e-9 * np.eye(13)
    cx = 0.0
    cy = 0.0
    r = radius
    s = 0.5
    # the linear coefficients at the start (with coef 0 the residual is the luma itself)
    _luma_rows(gx, gy, lum, n, scale, cx, cy, r, s, coef, jac, res)
    lin = np.ascontiguousarray(jac[:, 4:])
    coef[:] = np.linalg.solve(lin.T @ lin + ridge[4:, 4:], lin.T @ res)
    normal = ridge
    sse = 0.0
    for _ in range(iterations):
        sse = _luma_rows(gx, gy, lum, n, scale, cx, cy, r, s, coef, jac, res)
        normal = jac.T @ jac + ridge
        step = np.linalg.solve(normal, jac.T @ res)
        cx += step[0]
        cy += step[1]
        r += step[2]
        s = min(max(s + step[3], 0.2), 1.5)
        coef += step[4:]
        if not (abs(r - radius) < 0.5 * radius and math.sqrt(cx * cx + cy * cy) < 0.5 * radius):
            return False
        if max(abs(step[0]), abs(step[1]), abs(step[2])) < _LUMA_STEP_DONE_PX:
            break
    inv = np.linalg.inv(normal)
    if not (inv[0, 0] + inv[1, 1]) * sse / max(n - 13, 1) <= max_se * max_se:
        return False
    out[0] = cx
    out[1] = cy
    return True


def _luma_loop():
    return compile_loop(_luma_fit_loop, helpers=(_luma_rows,))



def binary_roundness(m00: float, m10: float, m01: float, m20: float, m02: float, m11: float) -> float:
    """:func:`axis_ratio` (with :data:`PIXEL_MOMENT`) of a binary region from its raw moments
    (integer sums about a corner near it): the central moments as exact integer differences
    (``m00 m20 - m10^2`` ...), divided once. OpenCV's own central moments round differently from
    build to build (fused multiply-adds), which decides on which side of the roundness gate a small
    region of exactly 0.5 falls (a 10-pixel region 3 x 5 pixels wide); these do not, and the
    compiled crowded-window pass (:mod:`tracking.window_kernel`) takes them the same way."""
    nn = m00 * m00
    a = (m00 * m20 - m10 * m10) / nn
    b = (m00 * m02 - m01 * m01) / nn
    c = (m00 * m11 - m10 * m01) / nn
    mean_var = 0.5 * (a + b) + PIXEL_MOMENT
    spread = math.sqrt(0.25 * (a - b) * (a - b) + c * c)
    return math.sqrt(max(mean_var - spread, 0.0) / (mean_var + spread))


PIXEL_MOMENT = 1.0 / 12.0
"""A pixel is a unit square, not a point: its own second moment on each axis."""


def axis_ratio(mu20, mu02, mu11, own: float = 0.0):
    """Minor/major axis ratio (0..1) of regions with central second moments ``mu20``, ``mu02``,
    ``mu11`` (per unit area; arrays or floats), each point's ``own`` moment added on both axes."""
    mean_var = 0.5 * (mu20 + mu02) + own
    spread = np.sqrt(0.25 * (mu20 - mu02) ** 2 + mu11 * mu11)
    return np.sqrt(np.clip(mean_var - spread, 0.0, None) / (mean_var + spread))


def _coverage(patch_bgr: np.ndarray, patch_labels: np.ndarray, filled: np.ndarray, colour: int) -> np.ndarray:
    """Estimated coverage 0..1 of each patch pixel by the region (module doc: unmixing).

    Args:
        patch_bgr: (h, w, 3) uint8 pixels of the patch.
        patch_labels: (h, w) uint8 labels of the patch.
        filled: (h, w) uint8 0/1 region with holes filled.
        colour: palette index of the region.

    Returns:
        (h, w) float32 weights: 1 inside, coverage on the region's edge and the ring around it,
        0 elsewhere.
    """
    inner = cv2.erode(filled, _K3, borderType=cv2.BORDER_REPLICATE)
    grown = cv2.dilate(filled, _K3)
    outer = cv2.dilate(filled, _K7)
    own = patch_labels == colour + 1
    core = inner.view(bool) & own  # interior pixels of the marker's colour (not a specular hole)
    if not core.any():
        core = filled.view(bool) & own
    weights = filled.astype(np.float32)
    m = np.array(cv2.mean(patch_bgr, mask=core.view(np.uint8))[:3], dtype=np.float32)
    norm = float(np.sqrt(m @ m))
    if norm <= 0.0:
        return weights
    m /= norm
    background = ((outer > grown) & ~own).view(np.uint8)
    size = (_BG_WINDOW_PX, _BG_WINDOW_PX)
    count = cv2.boxFilter(background, cv2.CV_32F, size, normalize=False, borderType=cv2.BORDER_CONSTANT)
    sums = cv2.boxFilter(cv2.bitwise_and(patch_bgr, patch_bgr, mask=background), cv2.CV_32F, size,
                         normalize=False, borderType=cv2.BORDER_CONSTANT)
    pix = patch_bgr.astype(np.float32)
    along = pix @ m  # brightness along the marker's colour direction
    # the darkest interior pixel within 2 px: what a fully covered pixel there would at least show
    darkest = cv2.erode(np.where(core, along, _FAR).astype(np.float32), _K5,
                        borderType=cv2.BORDER_CONSTANT, borderValue=_FAR)
    unknown = np.nonzero(grown > inner)  # the region's edge and the ring around it
    n = count[unknown]
    b = sums[unknown] / np.maximum(n, 1.0)[:, None]
    p_m = along[unknown]
    b_m = b @ m
    # least squares p = a m + c b: with q, r the parts of p, b across m, c = q.r / r.r
    q = pix[unknown] - p_m[:, None] * m
    r = b - b_m[:, None] * m
    rr = (r * r).sum(axis=1)
    # no background sample nearby, or too little background colour across the marker's (black,
    # or the marker's own hue) for the noise: keep the binary region there
    solvable = (n > 0) & (rr >= _MIN_BACKGROUND_CHROMA**2)
    c = (q * r).sum(axis=1) / np.where(solvable, rr, 1.0)
    alpha = 1.0 - c
    # 1 - c assumes the background is as bright there as around; a darker patch of background
    # (a shaded arm) would pass for marker. The marker part a must back the coverage up.
    ref = darkest[unknown]
    marker_part = p_m - c * b_m
    alpha = np.minimum(alpha, np.where(ref < _FAR, _MARKER_SHADING_RATIO * marker_part / np.maximum(ref, 1.0), 1.0))
    weights[unknown] = np.where(solvable, np.clip(alpha, 0.0, 1.0), weights[unknown])
    return weights


ARC_INSIDE_TOL_PX = (1.0, 1.0, 0.7, 0.5)
"""Per Gauss-Newton iteration: an edge point this far inside the circle fitted so far is taken for
the occluder's outline, not the ball's (loose while the start, the centroid, is still far off)."""
ARC_EDGE_SHRINK_PX = 0.2
"""How much smaller the binary region of a full ball is than its projected radius (mean over the
simulated studio's balls of 2.5-8 px: 0.14-0.27 px; the colour test drops the dark limb)."""

ARC_SUBPIXEL_TOL_PX = (1.0, 0.7, 0.5, 0.5)
"""The inside tolerances of the sub-pixel arc fit (:func:`arc_centres` with ``colours``), which
starts nearer than the centroid: from the searched start (:func:`_arc_starts`) on small balls,
from the binary fit on larger ones."""
ARC_SUBPIXEL_MAX_SHIFT_PX = 0.7
"""A sub-pixel fit further than this from the binary region's fit is taken for a failed colour
model (another object in the background sample, a highlight next to the edge): the binary fit
stays. On the simulated walk at 320x240 @15 / @30 (14 noise seeds) the right supination's worst
run was 2.27 / 2.13 degrees with no limit (1.5 px), 1.92 / 1.94 with 0.6, 1.91 / 1.96 with 0.8
and 2.11 / 2.16 with 0.4 (too few fits then replace the binary ones: the two kinds of error mix)."""
ARC_UNMIX_MIN_CONTRAST = 20.0
"""Counts (distance in RGB) between the ball's colour inside and the background beyond an edge
pair below which the pair keeps its binary midpoint: too little contrast to unmix."""

ARC_ENCLOSING_BELOW = 0.85
"""A region with less than this fraction of the whole ball's area starts from its enclosing circle."""
ARC_ENCLOSING_MIN_PX = 4.0
"""The enclosing-circle start is for balls of at least this radius (on smaller ones it is noise)."""
# the 4 neighbours of a pixel (+x, -x, +y, -y): steps, the edge point halfway, which coordinate
# and side of the searched box each tests (columns of [box_hi, -box_lo])
_ARC_STEP = np.array([[[1], [-1], [0], [0]], [[0], [0], [1], [-1]]], dtype=np.intp)
_ARC_HALF_STEP = 0.5 * _ARC_STEP
_ARC_AXIS = np.array([0, 0, 1, 1])
_ARC_SIGN = np.array([[1.0], [-1.0], [1.0], [-1.0]])
_ARC_BOUND_ROWS = np.array([0, 2, 1, 3])


ARC_START_TAU_PX = 0.5
"""The start of a small partly hidden ball's arc fit: edge points more than this inside the circle
cost no more than at this distance (the occluder's outline, wherever it runs)."""
ARC_START_MIN_SHARE = 0.4
"""The searched start is for regions of at least this share of the ball's area: a sliver of a few
pixels fits circles on every side of it (its centroid, within a radius of the centre, is kept)."""
ARC_START_EDGE_SIGMA_PX = 0.7
"""Where the prediction is known, a small ball's start minimises its edge cost over this squared
(px, the edge points' misfit taken as noise of this size) plus the squared distance from the
predicted centre over the prediction's variance: a region of a few pixels may fit a circle from
either side (the occluder's straight edge taken for the arc), and the prediction tells the sides
apart as far as it is sure. On the simulated walk at 320x240 @15 a ball half hidden by the hand
(a 3 x 5 pixel block) took the mirror side 1.7 px off, and its styloid 11 mm off, under the
earlier fixed tie-break (costs within 0.3 px^2); that run's right supination went 2.11 -> 2.07 /
2.00 / 1.91 / 1.92 degrees with 0.3 / 0.5 / 0.7 / 1.0 here."""
_ARC_START_GRID = 11  # candidate centres per axis, coarse pass (the fine pass: 5 per axis)
# the candidates' offsets: coarse in grid spacings from the box's corner, fine around the best
_ARC_COARSE = np.stack(np.meshgrid(*[np.arange(float(_ARC_START_GRID))] * 2, indexing="ij")).reshape(2, -1)
_ARC_FINE_STEPS = np.linspace(-1.0, 1.0, 5)
_ARC_FINE = np.stack(np.meshgrid(*[_ARC_FINE_STEPS] * 2, indexing="ij")).reshape(2, -1)


def _arc_starts(q: np.ndarray, first: Sequence[int], count: Sequence[int], radius: Sequence[float],
                prior: np.ndarray | None = None, prior_sigma: np.ndarray | None = None,
                compiled: bool = False) -> np.ndarray:
    """Starting centres for the arc fits of small, partly hidden balls: per region, the centre c
    on a grid that minimises ``sum rho(|q - c| - r)`` over its edge points q, with ``rho(d) = d^2``
    outside the circle (the visible pixels are the ball's: none lies outside it) and
    ``min(d^2, tau^2)`` inside (the occluder's edge runs anywhere inside).

    The grid spans the centres that the edge points allow (within ``r + tau`` of each, per axis),
    11 x 11, then 5 x 5 around the best at half the spacing (a search, not a descent: the cost is
    flat where the start is far off). A region of a few pixels may fit a circle from either side
    (the occluder's straight edge taken for the arc): with a ``prior`` (the predicted centre,
    uncertain by ``prior_sigma``) the cost is a posterior's, ``sum rho / s^2 + |c - prior|^2 /
    prior_sigma^2`` with ``s = ARC_START_EDGE_SIGMA_PX``.

    Args:
        q: (2, E) edge points of all regions, grouped by region.
        first, count: for each small region, its first edge point and their number (>= 3).
        radius: the regions' radii.
        prior: (S, 2) predicted centres (None: the edges alone).
        prior_sigma: (S,) their uncertainty, px (None: 1 px).
        compiled: search in one compiled loop (:func:`_arc_starts_loop`, numba where installed).
    Returns:
        (S, 2) starting centres.
    """
    loop = _arc_starts_compiled() if compiled else None
    if loop is not None:
        return _arc_starts_by_loop(loop, q, first, count, radius, prior, prior_sigma)
    return _arc_starts_numpy(q, first, count, radius, prior, prior_sigma)


def _arc_starts_by_loop(loop, q: np.ndarray, first: Sequence[int], count: Sequence[int], radius: Sequence[float],
                        prior: np.ndarray | None, prior_sigma: np.ndarray | None) -> np.ndarray:
    """:func:`_arc_starts` by its compiled ``loop`` (:func:`_arc_starts_loop`)."""
    n_reg = len(count)
    out = np.empty((n_reg, 2))
    if prior is None:
        prior_a, weight = np.zeros((n_reg, 2)), np.zeros(n_reg)
    else:
        sigma = np.ones(n_reg) if prior_sigma is None else np.asarray(prior_sigma, dtype=np.float64)
        prior_a, weight = np.ascontiguousarray(prior, dtype=np.float64), (ARC_START_EDGE_SIGMA_PX / sigma) ** 2
    loop(np.ascontiguousarray(q[0]), np.ascontiguousarray(q[1]), np.asarray(first, dtype=np.int64),
         np.asarray(count, dtype=np.int64), np.asarray(radius, dtype=np.float64), ARC_START_TAU_PX, prior_a,
         weight, _ARC_START_GRID, _ARC_FINE_STEPS, out)
    return out


def _arc_starts_numpy(q: np.ndarray, first: Sequence[int], count: Sequence[int], radius: Sequence[float],
                      prior: np.ndarray | None, prior_sigma: np.ndarray | None) -> np.ndarray:
    """:func:`_arc_starts` in numpy: every region's candidates at once."""
    n_reg = len(count)
    sel = np.concatenate([np.arange(a, a + n) for a, n in zip(first, count)])
    px, py = q[0].take(sel), q[1].take(sel)  # the selected regions' edge points, region after region
    bounds = np.zeros(n_reg, dtype=np.intp)
    np.cumsum(count[:-1], out=bounds[1:])
    region = np.repeat(np.arange(n_reg), count)
    member = (region == np.arange(n_reg)[:, None]).astype(np.float64)  # (S, E): sums by one product
    r = np.asarray(radius, dtype=np.float64)
    reach = (r + ARC_START_TAU_PX)[:, None]
    # the box of centres within r + tau of every edge point, per axis (its middle if empty)
    pts = np.stack((px, py), axis=1)
    lo = np.maximum.reduceat(pts, bounds, axis=0) - reach  # (S, 2)
    hi = np.minimum.reduceat(pts, bounds, axis=0) + reach
    mid = 0.5 * (lo + hi)
    lo, hi = np.minimum(lo, mid), np.maximum(hi, mid)
    spacing = (hi - lo) / (_ARC_START_GRID - 1)
    r_e = r.take(region)[:, None]
    rows = np.arange(n_reg)

    def costs(cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
        """(S, G) cost of the (S, G) candidate centres."""
        dx = px[:, None] - cx.take(region, axis=0)  # (E, G)
        dy = py[:, None] - cy.take(region, axis=0)
        dx *= dx
        dy *= dy
        dx += dy
        dist = np.sqrt(dx, out=dx)
        dist -= r_e
        np.maximum(dist, -ARC_START_TAU_PX, out=dist)  # rho(d) = max(d, -tau)^2
        dist *= dist
        return member @ dist

    cx = lo[:, :1] + _ARC_COARSE[0] * spacing[:, :1]  # (S, G) candidate centres
    cy = lo[:, 1:] + _ARC_COARSE[1] * spacing[:, 1:]
    total = costs
    if prior is not None:
        sigma = np.ones(n_reg) if prior_sigma is None else np.asarray(prior_sigma, dtype=np.float64)
        weight = (ARC_START_EDGE_SIGMA_PX / sigma)[:, None] ** 2  # prior term, in the edge cost's units
        px0, py0 = prior[:, :1], prior[:, 1:]

        def total(cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
            dx, dy = cx - px0, cy - py0
            return costs(cx, cy) + weight * (dx * dx + dy * dy)
    best = total(cx, cy).argmin(axis=1)
    bx, by = cx[rows, best], cy[rows, best]
    cx = bx[:, None] + _ARC_FINE[0] * spacing[:, :1]  # the fine pass around it
    cy = by[:, None] + _ARC_FINE[1] * spacing[:, 1:]
    best = total(cx, cy).argmin(axis=1)
    bx, by = cx[rows, best], cy[rows, best]
    return np.stack((bx, by), axis=1)


def _arc_gauss_newton(q, pw, radius, c, tols):
    """The Gauss-Newton iterations of :func:`arc_centres` (one per tolerance) as one loop over
    the edge points: q (2, E) edge points grouped by region pw (E,), radius (K,), c (2, K)
    centres updated in place (compiled by numba; plain Python runs it too)."""
    k_count = c.shape[1]
    sums = np.zeros((k_count, 6))
    for tol in tols:
        sums[:] = 0.0
        for e in range(pw.shape[0]):
            k = pw[e]
            dx, dy = q[0, e] - c[0, k], q[1, e] - c[1, k]
            dist = math.sqrt(dx * dx + dy * dy)
            r = radius[k]
            if dist > r - tol:
                ux, uy = dx / dist, dy / dist
                sums[k, 0] += ux * ux
                sums[k, 1] += ux * uy
                sums[k, 2] += uy * uy
                sums[k, 3] += ux * (dist - r)
                sums[k, 4] += uy * (dist - r)
                sums[k, 5] += 1.0
        for k in range(k_count):
            sxx, sxy, syy = sums[k, 0] + 1e-6, sums[k, 1], sums[k, 2] + 1e-6  # no kept point: no step
            det = sxx * syy - sxy * sxy
            if det == 0.0:
                pinned = math.nan
            else:
                pinned = (1.0 if sums[k, 5] >= 3 else 0.0) / det  # three points pin a circle
            c[0, k] += (syy * sums[k, 3] - sxy * sums[k, 4]) * pinned
            c[1, k] += (sxx * sums[k, 4] - sxy * sums[k, 3]) * pinned


def _arc_loop():
    return compile_loop(_arc_gauss_newton)


def _subpixel_edges(xy: np.ndarray, pixel: np.ndarray, direction: np.ndarray, region: np.ndarray,
                    inner_inside: np.ndarray, colours, compiled: bool = False) -> np.ndarray:
    """Edge points of :func:`arc_centres` placed by the pixels' coverage instead of halfway.

    An edge pair is a region pixel i and its outside neighbour o one step s away. Each pixel's
    colour is taken as a mix ``p = a c + (1 - a) b`` of the ball's colour c there (the pixel one
    step inwards, or i itself where that is not in the region) and the background b (the pixel one
    step beyond o), solved for the coverage a in least squares over the three channels. The
    ball's edge then lies ``a_i + a_o - 0.5`` px from i's centre along s (0.5: the midpoint of a
    binary edge). Against a dark background a partly covered pixel keeps the ball's hue, so the
    binary region grows into it by up to half a pixel, and against a bright one it shrinks;
    coverage puts the edge where it is on both. A pair with too little contrast between c and b
    (``ARC_UNMIX_MIN_CONTRAST``), or whose background pixel is off the image, keeps its midpoint.

    Args:
        xy: (2, P) region pixels (relative to each region's origin); pixel, direction, region:
            (E,) each edge point's pixel index, neighbour 0-3 (+x, -x, +y, -y) and region;
            inner_inside: (E,) whether the pixel one step inwards is in the region.
        colours: (images, camera (K,), origin (K, 2)): the BGR uint8 images, each region's image
            and the full-image pixel of its coordinates' origin.
        compiled: one compiled loop over the edge pairs (numba, where installed) instead of
            numpy per camera: the same arithmetic in the same order.
    Returns:
        (2, E) edge points, the coordinates of ``xy``.
    """
    images, camera, origin = colours
    step = _ARC_STEP[:, direction, 0]  # (2, E)
    share = np.full(pixel.size, 0.5)
    at = xy[:, pixel].astype(np.intp) + np.asarray(origin, dtype=np.intp)[region].T  # (2, E) full-image pixel
    cam = np.asarray(camera)[region]
    loop = _subpixel_loop() if compiled and plain_images(images) else None
    if loop is not None:
        loop(tuple(images), cam.astype(np.int64), at[0].astype(np.int64), at[1].astype(np.int64),
             step[0].astype(np.int64), step[1].astype(np.int64), inner_inside.astype(np.int64),
             ARC_UNMIX_MIN_CONTRAST ** 2, share)
        return xy[:, pixel] + share * step
    for c in np.unique(cam).tolist():
        sel = np.flatnonzero(cam == c)
        img = images[c]
        h, w = img.shape[:2]
        x, y = at[0, sel], at[1, sel]
        sx, sy = step[0, sel], step[1, sel]
        bx, by = x + 2 * sx, y + 2 * sy
        on = (bx >= 0) & (bx < w) & (by >= 0) & (by < h)
        inward = inner_inside[sel]
        p_i = img[y, x].astype(np.float64)
        p_o = img[y + sy, x + sx].astype(np.float64)
        p_b = img[np.clip(by, 0, h - 1), np.clip(bx, 0, w - 1)].astype(np.float64)
        p_c = img[y - sy * inward, x - sx * inward].astype(np.float64)
        dv = p_c - p_b
        den = (dv * dv).sum(axis=1)
        ok = on & (den >= ARC_UNMIX_MIN_CONTRAST ** 2)
        den = np.where(ok, den, 1.0)
        a_i = np.clip(((p_i - p_b) * dv).sum(axis=1) / den, 0.0, 1.0)
        a_o = np.clip(((p_o - p_b) * dv).sum(axis=1) / den, 0.0, 1.0)
        share[sel] = np.where(ok, a_i + a_o - 0.5, 0.5)
    return xy[:, pixel] + share * step


def _subpixel_share_loop(images, cam, ex, ey, sx, sy, inward, min_den2, share):
    """:func:`_subpixel_edges`' coverage per edge pair as one loop (compiled by numba; plain Python
    runs it too): ``share`` (E,) receives ``a_i + a_o - 0.5``, or 0.5 where the pair keeps its
    midpoint."""
    for e in range(ex.shape[0]):
        img = images[cam[e]]
        h, w = img.shape[0], img.shape[1]
        x, y, dx, dy = ex[e], ey[e], sx[e], sy[e]
        bx, by = x + 2 * dx, y + 2 * dy
        share[e] = 0.5
        if bx < 0 or bx >= w or by < 0 or by >= h:
            continue
        cx, cy = x - dx * inward[e], y - dy * inward[e]
        den = 0.0
        num_i = 0.0
        num_o = 0.0
        for ch in range(3):
            b = float(img[by, bx, ch])
            d = float(img[cy, cx, ch]) - b
            den += d * d
            num_i += (float(img[y, x, ch]) - b) * d
            num_o += (float(img[y + dy, x + dx, ch]) - b) * d
        if den < min_den2:
            continue
        share[e] = min(max(num_i / den, 0.0), 1.0) + min(max(num_o / den, 0.0), 1.0) - 0.5


def _subpixel_loop():
    return compile_loop(_subpixel_share_loop)


def _arc_start_cost(px, py, first, n, cx, cy, r, tau, prior_x, prior_y, weight):
    """One candidate centre's cost in :func:`_arc_starts_loop` (as ``total`` in :func:`_arc_starts`)."""
    cost = 0.0
    for e in range(first, first + n):
        dx, dy = px[e] - cx, py[e] - cy
        d = max(math.sqrt(dx * dx + dy * dy) - r, -tau)
        cost += d * d
    if weight > 0.0:
        dx, dy = cx - prior_x, cy - prior_y
        cost += weight * (dx * dx + dy * dy)
    return cost


def _arc_starts_loop(px, py, first, count, radius, tau, prior, weight, grid, fine, out):
    """:func:`_arc_starts`' search as one loop over the regions and candidates (compiled by numba;
    plain Python runs it too): the same box, the same coarse and fine candidates in the same
    order, the first of equal minima; the costs summed point by point (equal to ~1e-15)."""
    for s in range(count.shape[0]):
        a, n, r = first[s], count[s], radius[s]
        reach = r + tau
        lo_x, lo_y, hi_x, hi_y = -math.inf, -math.inf, math.inf, math.inf
        for e in range(a, a + n):
            lo_x = max(lo_x, px[e])
            lo_y = max(lo_y, py[e])
            hi_x = min(hi_x, px[e])
            hi_y = min(hi_y, py[e])
        lo_x, lo_y, hi_x, hi_y = lo_x - reach, lo_y - reach, hi_x + reach, hi_y + reach
        mid_x, mid_y = 0.5 * (lo_x + hi_x), 0.5 * (lo_y + hi_y)
        lo_x, lo_y, hi_x, hi_y = min(lo_x, mid_x), min(lo_y, mid_y), max(hi_x, mid_x), max(hi_y, mid_y)
        step_x, step_y = (hi_x - lo_x) / (grid - 1), (hi_y - lo_y) / (grid - 1)
        best = math.inf
        bx, by = lo_x, lo_y
        for i in range(grid):
            for j in range(grid):
                cx, cy = lo_x + i * step_x, lo_y + j * step_y
                cost = _arc_start_cost(px, py, a, n, cx, cy, r, tau, prior[s, 0], prior[s, 1], weight[s])
                if cost < best:
                    best, bx, by = cost, cx, cy
        best = math.inf
        fx, fy = bx, by
        for i in range(fine.shape[0]):
            for j in range(fine.shape[0]):
                cx, cy = bx + fine[i] * step_x, by + fine[j] * step_y
                cost = _arc_start_cost(px, py, a, n, cx, cy, r, tau, prior[s, 0], prior[s, 1], weight[s])
                if cost < best:
                    best, fx, fy = cost, cx, cy
        out[s, 0] = fx
        out[s, 1] = fy


def _arc_starts_compiled():
    return compile_loop(_arc_starts_loop, helpers=(_arc_start_cost,))


def _fit_arcs(q: np.ndarray, pw: np.ndarray, radius_px: np.ndarray, cx: list, cy: list,
              tols: Sequence[float], compiled: bool) -> tuple[list, list]:
    """The Gauss-Newton iterations of :func:`arc_centres` from (cx, cy), one per tolerance."""
    k_count = len(cx)
    loop = _arc_loop() if compiled else None
    if loop is not None:
        c = np.array([cx, cy])
        loop(np.ascontiguousarray(q), pw, np.ascontiguousarray(radius_px, dtype=np.float64), c,
             np.asarray(tols, dtype=np.float64))
        return c.tolist()
    cx, cy = list(cx), list(cy)
    member = (pw == np.arange(k_count)[:, None]).astype(np.float64)
    r = radius_px[pw]
    terms = np.empty((6, pw.size))  # per edge point: uxx, uxy, uyy, ux res, uy res, kept
    for tol in tols:
        d = q - np.array([cx, cy]).take(pw, axis=1)  # (2, E) from the centre to each edge point
        dist = np.sqrt((d * d).sum(axis=0))
        keep = np.greater(dist, r - tol, out=terms[5])
        u = d * (keep / np.where(keep, dist, 1.0))  # unit directions of the kept points, 0 elsewhere
        np.multiply(u, u[0], out=terms[0:2])
        np.multiply(u[1], u[1], out=terms[2])
        np.multiply(u, dist - r, out=terms[3:5])
        for k, (sxx, sxy, syy, sx, sy, kept) in enumerate((member @ terms.T).tolist()):
            sxx += 1e-6  # a region with no kept point gets no step
            syy += 1e-6
            det = sxx * syy - sxy * sxy
            pinned = (kept >= 3) / det if det else math.nan  # three points pin a circle
            cx[k] += (syy * sx - sxy * sy) * pinned
            cy[k] += (sxx * sy - sxy * sx) * pinned
    return cx, cy


def arc_centres(win: np.ndarray, x: np.ndarray, y: np.ndarray, start_px: np.ndarray, radius_px: np.ndarray,
                box_lo: np.ndarray, box_hi: np.ndarray, *,
                inside_tol_px: Sequence[float] = ARC_INSIDE_TOL_PX, prior_px: np.ndarray | None = None,
                prior_sigma_px: np.ndarray | None = None, compiled: bool = False,
                colours: tuple | None = None) -> np.ndarray:
    """Centres of partly hidden balls, each from the visible arc of its region's outline.

    A ball partly hidden by something in front of it (an arm) or behind whose outline it sits
    leaves a region cut by a chord-like edge; the region's centroid lies towards its visible part
    (by 0.17 radii when a fifth of the disc is hidden). The outline of the region is the ball's
    circle where the ball shows and the occluder's edge elsewhere, and the occluder's edge lies
    inside the circle. So each centre is fitted by Gauss-Newton to the region's edge points with
    the radius known, starting from the centroid (or, for a region under ``ARC_ENCLOSING_BELOW``
    of the ball's area, from its smallest enclosing circle; on balls under ``ARC_ENCLOSING_MIN_PX``,
    where that circle is noise, from the best of a grid of centres, :func:`_arc_starts`), and at
    every iteration only the edge
    points farther from the centre than ``radius - inside_tol_px[i]`` are kept (the occluder's
    edge drops out as the centre moves). Edge points are the midpoints between a region pixel and each of
    its 4-neighbours outside the region (a binary disc's region has the area of the circle
    through them); neighbours outside the searched box are not edges (a ball cut by the window
    or the image border).

    All regions are fitted at once (vectorized over regions); pixel coordinates are integers
    relative to any origin of the caller's choice per region, e.g. a window's centre pixel.

    Args:
        win: (P,) int64 region index 0..K-1 of each pixel.
        x, y: (P,) float64 integer pixel coordinates (column, row) of the region pixels; no pixel
            twice.
        start_px: (K, 2) float64 starting centres (the regions' centroids), same coordinates.
        radius_px: (K,) float64 radius of each ball's binary region when whole (the projected
            radius less ``ARC_EDGE_SHRINK_PX``).
        box_lo, box_hi: (K, 2) float64 first and last (inclusive) pixel x, y searched for each
            region.
        inside_tol_px: one tolerance per iteration: edge points nearer the centre than the
            radius less it are left out.
        prior_px: (K, 2) predicted centres, same coordinates: a small region's searched start
            weighs its distance from the prediction against the arc's misfit (a region of a few
            pixels may fit a circle from either side; None: the better fit alone).
        prior_sigma_px: (K,) the predictions' uncertainty, px (None: 1 px).
        compiled: run the Gauss-Newton iterations as one compiled loop (numba, where installed):
            the same steps, summed point by point instead of by a matrix product (the centres
            agree to ~1e-12 px).
        colours: (images, camera (K,), origin (K, 2)): the BGR images the regions come from, each
            region's image and the full-image pixel of its coordinates' origin. Given, each
            region is fitted a second time on edge points placed by coverage
            (:func:`_subpixel_edges`) with the ball's full radius (``radius_px`` +
            ``ARC_EDGE_SHRINK_PX``), a ball under ``ARC_ENCLOSING_MIN_PX`` from the searched start
            (:func:`_arc_starts`) and a larger one from its binary fit, and that fit replaces the
            binary one where it lies within ``ARC_SUBPIXEL_MAX_SHIFT_PX`` of it.

    Returns:
        (K, 2) float64 fitted centres; the start where fewer than three edge points remain or the
        points do not pin the centre.
    """
    k_count = start_px.shape[0]
    if k_count == 0 or win.size == 0:
        return np.array(start_px, dtype=np.float64)
    edges = _arc_edges(win, x, y, box_lo, box_hi, k_count)
    # (the few per-region numbers in plain floats: numpy's per-call cost exceeds their work)
    radius = radius_px.tolist()
    start = start_px.tolist()
    cx, cy = _arc_fit_starts(edges, win, k_count, radius, start, prior_px, prior_sigma_px)
    # Gauss-Newton for min sum (|q - c| - r)^2 over the kept edge points q of each region (in
    # numpy the per-region sums of one iteration are one product with the (K, E) region indicator)
    cx, cy = _fit_arcs(edges.q, edges.pw, radius_px, cx, cy, inside_tol_px, compiled)
    # a fit that wandered off (too few edge points for the radius) is not a better centre
    for k in range(k_count):
        if not math.hypot(cx[k] - start[k][0], cy[k] - start[k][1]) <= radius[k]:  # (NaN too)
            cx[k], cy[k] = start[k]
    if colours is not None:
        _subpixel_arcs(edges, k_count, radius_px, cx, cy, colours, prior_px, prior_sigma_px, compiled)
    return np.array([cx, cy]).T


@dataclass(frozen=True, slots=True, eq=False)
class _ArcEdges:
    """The regions' pixels in one occupancy grid and their edge points (:func:`arc_centres`).

    Attributes:
        grid: (K * h_grid * w_grid,) whether each cell of the grid is a region pixel; flat: (P,)
            each pixel's cell; w_grid: the grid's width.
        xy: (2, P) the pixels' coordinates.
        at: (E,) each edge point's neighbour d of pixel i as ``d * P + i``, grouped by region;
            pw: (E,) its region; q: (2, E) the edge points (midpoints to the outside neighbours).
        counts, firsts: each region's number of edge points and its first.
    """

    grid: np.ndarray
    flat: np.ndarray
    w_grid: int
    xy: np.ndarray
    at: np.ndarray
    pw: np.ndarray
    q: np.ndarray
    counts: list
    firsts: list


def _arc_edges(win: np.ndarray, x: np.ndarray, y: np.ndarray, box_lo: np.ndarray, box_hi: np.ndarray,
               k_count: int) -> _ArcEdges:
    """The edge points of every region of :func:`arc_centres` (its arguments)."""
    # every region's pixels in one occupancy grid (K regions x rows x columns, a border of one
    # empty pixel all round); the 4 neighbours of every pixel at once, by flat offsets in it
    x0, y0 = float(x.min()) - 1.0, float(y.min()) - 1.0
    ix, iy = (x - x0).astype(np.intp), (y - y0).astype(np.intp)
    w_grid, h_grid = int(ix.max()) + 2, int(iy.max()) + 2
    flat = (win * h_grid + iy) * w_grid + ix
    grid = np.zeros(k_count * h_grid * w_grid, dtype=bool)
    grid[flat] = True
    # a neighbour is an edge unless it is in the region or outside the searched box; the box test
    # of all 4 at once: s * coordinate < the box's bound on that side (integers), s = +1 for the
    # neighbour after the pixel (bound: the last pixel), -1 before it (bound: minus the first)
    n_px = x.size
    xy = np.concatenate((x, y)).reshape(2, n_px)
    bound = np.concatenate((box_hi, -box_lo), axis=1).T[_ARC_BOUND_ROWS].take(win, axis=1)  # (4, P)
    edge = ~grid[flat + (_ARC_STEP[1] * w_grid + _ARC_STEP[0])] & (xy[_ARC_AXIS] * _ARC_SIGN < bound)
    # edge points (midpoints to the outside neighbours), grouped by region
    at = np.flatnonzero(edge)  # neighbour d of pixel i at d * P + i
    pw = win.take(at % n_px)
    by_region = np.argsort(pw, kind="stable")
    at = at.take(by_region)
    pw = pw.take(by_region)
    q = (xy[:, None, :] + _ARC_HALF_STEP).reshape(2, 4 * n_px).take(at, axis=1)  # (2, E) edge points
    counts = np.bincount(pw, minlength=k_count).tolist()
    firsts = [0] + list(itertools.accumulate(counts))[:-1]  # each region's first edge point
    return _ArcEdges(grid, flat, w_grid, xy, at, pw, q, counts, firsts)


def _arc_fit_starts(edges: _ArcEdges, win: np.ndarray, k_count: int, radius: list, start: list,
                    prior_px: np.ndarray | None, prior_sigma_px: np.ndarray | None) -> tuple[list, list]:
    """The binary arc fits' starting centres (cx, cy): each region's centroid ``start``, its
    smallest enclosing circle where much is hidden, the searched start on small balls."""
    q, counts, firsts = edges.q, edges.counts, edges.firsts
    # a ball hidden by much is a poor start: its centroid lies so far towards the visible part that
    # the arc opposite the cut looks inside the circle; the smallest circle enclosing the edge
    # points is the ball's while more than half of it shows (too noisy on balls of a few pixels)
    area = np.bincount(win, minlength=k_count).tolist()
    cx, cy = [p[0] for p in start], [p[1] for p in start]
    q32 = None
    for k in range(k_count):
        r_k, n_k, first = radius[k], counts[k], firsts[k]
        if area[k] < ARC_ENCLOSING_BELOW * np.pi * (r_k * r_k) and r_k >= ARC_ENCLOSING_MIN_PX and n_k >= 3:
            if q32 is None:
                q32 = np.ascontiguousarray(q.T, dtype=np.float32)
            (ex, ey), enclosing_r = cv2.minEnclosingCircle(q32[first:first + n_k])
            if abs(enclosing_r - r_k) < 1.0:  # else the region is not a cut disc
                cx[k], cy[k] = ex, ey
    # a small ball (the enclosing circle is noise there) hidden by much: its centroid is too far
    # off for the fit below, whose first iterations would drop the visible arc as inside the
    # circle; it starts from the centre that best puts the arc on the circle instead
    small = [k for k in range(k_count) if counts[k] >= 3 and radius[k] < ARC_ENCLOSING_MIN_PX
             and ARC_START_MIN_SHARE <= area[k] / (np.pi * radius[k] * radius[k]) < ARC_ENCLOSING_BELOW]
    if small:
        starts = _arc_starts(q, [firsts[k] for k in small], [counts[k] for k in small],
                             [radius[k] for k in small], None if prior_px is None else prior_px[small],
                             None if prior_sigma_px is None else prior_sigma_px[small])
        for k, (sx, sy) in zip(small, starts.tolist()):
            cx[k], cy[k] = sx, sy
    return cx, cy


def _subpixel_arcs(edges: _ArcEdges, k_count: int, radius_px: np.ndarray, cx: list, cy: list, colours: tuple,
                   prior_px: np.ndarray | None, prior_sigma_px: np.ndarray | None, compiled: bool) -> None:
    """The same arcs on edge points placed by coverage (:func:`_subpixel_edges`), with the ball's
    full radius: each fit replaces the binary one (``cx``, ``cy``, in place) where it keeps an arc
    within ``ARC_SUBPIXEL_MAX_SHIFT_PX`` of it (:func:`arc_centres`' ``colours``)."""
    counts, firsts, pw, at = edges.counts, edges.firsts, edges.pw, edges.at
    fit = [k for k in range(k_count) if counts[k] >= 3]
    if not fit:
        return
    n_px = edges.xy.shape[1]
    pixel, direction = at % n_px, at // n_px
    inner = edges.grid[edges.flat.take(pixel) - (_ARC_STEP[1, direction, 0] * edges.w_grid
                                                 + _ARC_STEP[0, direction, 0])]
    q_sub = _subpixel_edges(edges.xy, pixel, direction, pw, inner, colours, compiled)
    full_r = radius_px + ARC_EDGE_SHRINK_PX
    # a small ball's sub-pixel fit starts from the searched start (from the binary fit, a region
    # hidden by its occluder's edge may keep that edge for its arc); a larger one's from the binary
    # fit, which is sure there (and the search costs ~0.1 ms per frame set at 640x480)
    sx, sy = list(cx), list(cy)
    radius = radius_px.tolist()
    small = [k for k in fit if radius[k] < ARC_ENCLOSING_MIN_PX]
    if small:
        starts = _arc_starts(q_sub, [firsts[k] for k in small], [counts[k] for k in small], full_r[small].tolist(),
                             None if prior_px is None else prior_px[small],
                             None if prior_sigma_px is None else prior_sigma_px[small], compiled=compiled)
        for k, (ax, ay) in zip(small, starts.tolist()):
            sx[k], sy[k] = ax, ay
    sx, sy = _fit_arcs(q_sub, pw, full_r, sx, sy, ARC_SUBPIXEL_TOL_PX, compiled)
    # kept: at least three edge points outside the last tolerance (else the fit has no arc)
    d = q_sub - np.array([sx, sy]).take(pw, axis=1)
    kept = np.bincount(pw, weights=np.sqrt((d * d).sum(axis=0)) > full_r[pw] - ARC_SUBPIXEL_TOL_PX[-1],
                       minlength=k_count)
    for k in fit:
        if kept[k] >= 3 and math.hypot(sx[k] - cx[k], sy[k] - cy[k]) <= ARC_SUBPIXEL_MAX_SHIFT_PX:
            cx[k], cy[k] = sx[k], sy[k]
