"""The guided calibration's logic after the lenses: shared board views (or wand frames), the pairs
they link, the rig solved with the world frame from the floor board, and a quality report in
millimetres.

Pure: detections in, cameras and figures out (the application's calibration screen shows them,
:mod:`game.scenes.calibrate`). A board view counts when two or more cameras found the board at
once, a wand frame when two or more saw both balls; cameras are linked by ``MIN_SHARED_VIEWS``
views (``MIN_WAND_FRAMES`` frames), and the rig can be solved when the links join every camera.
The quality report measures with the finished calibration alone: the board's corners and the
wand's balls (frames waved after the solve) triangulated from every camera that saw them, the
board's edges and diagonal and the wand's length against the known ones, each camera's fit, and
each camera's lens near the picture's edge (the balls' radial drift, :func:`edge_drift`: a
distortion error the wand's length does not show).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from calibration.board import Detection
from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.intrinsics import coverage_of

MIN_SHARED_VIEWS = 3  # board views two cameras must share to count as linked
GOOD_RMS_PX, USABLE_RMS_PX = 0.5, 1.0
GOOD_LENGTH_MM, USABLE_LENGTH_MM = 1.0, 2.5
MIN_WAND_FRAMES = 20  # wand frames two cameras must both see whole to count as linked
WAND_FRAMES = 150  # wand frames to keep before solving
CHECK_FRAMES = 30  # wand frames the report measures before its verdict counts the wand


@dataclass
class RigViews:
    """Board views taken by all cameras at once, by view name (``"000"``, ...)."""

    names: Sequence[str]
    views: dict[str, list[Detection | None]] = field(default_factory=dict)

    def add(self, detections: Sequence[Detection | None]) -> str | None:
        """Keep a view when two or more cameras found the board; returns its name, or None."""
        if len(detections) != len(self.names):
            raise CalibrationError(f"{len(detections)} detections for {len(self.names)} cameras")
        if sum(d is not None for d in detections) < 2:
            return None
        name = f"{len(self.views):03d}"
        self.views[name] = list(detections)
        return name

    def pair_counts(self) -> np.ndarray:
        """(C, C) int: views each pair of cameras shared (0 on the diagonal)."""
        seen = np.array([[d is not None for d in row] for row in self.views.values()], dtype=int).reshape(-1, len(self.names))
        counts = seen.T @ seen
        np.fill_diagonal(counts, 0)
        return counts

    def groups(self, min_views: int = MIN_SHARED_VIEWS) -> list[list[int]]:
        """The cameras joined by links of ``min_views`` shared views, as groups (largest first)."""
        return linked_groups(self.pair_counts(), min_views)

    def linked(self, min_views: int = MIN_SHARED_VIEWS) -> bool:
        return len(self.groups(min_views)) == 1

    def advice(self, min_views: int = MIN_SHARED_VIEWS) -> str:
        """What to do next, in plain words."""
        return link_advice(self.names, self.pair_counts(), min_views, "Hold the board", "view",
                           "Every camera is linked: go on to the floor board")


def linked_groups(counts: np.ndarray, min_count: int) -> list[list[int]]:
    """Cameras joined by pairs that shared ``min_count`` views or frames, as groups (largest first)."""
    linked = np.asarray(counts) >= min_count
    left = set(range(len(linked)))
    out = []
    while left:
        todo, group = [min(left)], set()
        while todo:
            c = todo.pop()
            if c in group:
                continue
            group.add(c)
            todo += [int(k) for k in np.flatnonzero(linked[c]) if k not in group]
        out.append(sorted(group))
        left -= group
    return sorted(out, key=len, reverse=True)


def link_advice(names: Sequence[str], counts: np.ndarray, min_count: int, doing: str, unit: str, done: str) -> str:
    """The pair to link next, in plain words ("Hold the board where cam2 and cam3 both see it (2 more views)")."""
    groups = linked_groups(counts, min_count)
    if len(groups) == 1:
        return done
    main, other = groups[0], groups[1]
    a, b = max(((i, j) for i in main for j in other), key=lambda p: counts[p])
    need = min_count - int(counts[a, b])
    return f"{doing} where {names[a]} and {names[b]} both see it ({need} more {unit}{'s' if need != 1 else ''})"


def solve_rig(cameras: Sequence[Camera], board, rig: RigViews, floor: Sequence[Detection | None], *,
              origin_m=(0.0, 0.0, 0.0), turn_deg: float = 0.0, lens_information=None):
    """The cameras' positions from the shared views, the world frame from the floor board; the
    lens data of cameras with an information matrix in ``lens_information`` refined with them
    (:func:`calibration.extrinsics.calibrate_extrinsics`).

    Returns:
        :class:`calibration.extrinsics.ExtrinsicsResult`.
    Raises:
        CalibrationError: cameras not linked, no camera sees the floor board, or a world frame no
            room has (:func:`calibration.extrinsics.check_world_frame`).
    """
    # lazy: calibration.extrinsics (scipy.optimize) only to solve the rig; the game imports this module
    from calibration.extrinsics import calibrate_extrinsics

    if not rig.linked():
        raise CalibrationError(rig.advice())
    if not any(d is not None for d in floor):
        raise CalibrationError("no camera sees the floor board: lay it face up on the seat, in view of the cameras")
    views = dict(rig.views)
    views["floor"] = list(floor)
    return calibrate_extrinsics(cameras, board, views, floor_view="floor", origin_m=origin_m, turn_deg=turn_deg,
                                lens_information=lens_information)


@dataclass
class WandViews:
    """Wand frames taken by all cameras at once: the two balls' centroids of each camera.

    A frame is kept when two or more cameras saw both balls; two cameras are linked by
    ``MIN_WAND_FRAMES`` frames that both saw whole, and the rig can be solved once the links join
    every camera and ``WAND_FRAMES`` frames are kept (about 2.5 mm per camera on the simulator
    from 300 frames, docs/CALIBRATION.md).
    """

    names: Sequence[str]
    frames: list[np.ndarray] = field(default_factory=list)

    def add(self, uv_px: np.ndarray) -> bool:
        """Keep a (C, 2, 2) frame (NaN where a ball was not seen) when two or more cameras saw both balls."""
        uv = np.asarray(uv_px, np.float64)
        if uv.shape != (len(self.names), 2, 2):
            raise CalibrationError(f"wand frame of shape {uv.shape} for {len(self.names)} cameras")
        if int(np.all(np.isfinite(uv), axis=(1, 2)).sum()) < 2:
            return False
        self.frames.append(uv)
        return True

    def uv_px(self) -> np.ndarray:
        """(C, T, 2, 2) every kept frame, as :func:`calibration.wand.calibrate_wand` takes them."""
        if not self.frames:
            return np.full((len(self.names), 0, 2, 2), np.nan)
        return np.stack(self.frames, axis=1)

    def pair_counts(self) -> np.ndarray:
        """(C, C) int: frames where both cameras of a pair saw both balls (0 on the diagonal)."""
        both = np.all(np.isfinite(self.uv_px()), axis=(2, 3)).astype(int)  # (C, T)
        counts = both @ both.T
        np.fill_diagonal(counts, 0)
        return counts

    def linked(self) -> bool:
        return len(linked_groups(self.pair_counts(), MIN_WAND_FRAMES)) == 1

    def ready(self) -> bool:
        return self.linked() and len(self.frames) >= WAND_FRAMES

    def advice(self) -> str:
        """What to do next, in plain words."""
        if not self.linked():
            return link_advice(self.names, self.pair_counts(), MIN_WAND_FRAMES, "Wave the wand", "frame", "")
        if len(self.frames) < WAND_FRAMES:
            return (f"Every camera is linked: keep waving the wand through the whole volume "
                    f"({len(self.frames)} of {WAND_FRAMES} frames)")
        return "Enough wand frames: go on to the floor board"


def solve_rig_wand(cameras: Sequence[Camera], wand: WandViews, length_m: float, board, floor: Sequence[Detection | None], *,
                   origin_m=(0.0, 0.0, 0.0), turn_deg: float = 0.0):
    """The cameras' positions from the wand frames, the world frame from the floor board.

    Returns:
        :class:`calibration.extrinsics.ExtrinsicsResult` (``rms_px``: the wand balls' reprojection).
    Raises:
        CalibrationError: cameras not linked, no camera sees the floor board, the wand solve fails,
            or a world frame no room has.
    """
    # lazy: calibration.extrinsics (scipy.optimize) only to solve the rig; the game imports this module
    from calibration.extrinsics import ExtrinsicsResult, world_from_floor_board
    # lazy: calibration.wand (scipy.optimize) only to solve the rig; the game imports this module
    from calibration.wand import calibrate_wand

    if not wand.linked():
        raise CalibrationError(wand.advice())
    if not any(d is not None for d in floor):
        raise CalibrationError("no camera sees the floor board: lay it face up on the seat, in view of the cameras")
    res = calibrate_wand(cameras, wand.uv_px(), length_m)
    placed, _ = world_from_floor_board(res.cameras, floor, board, origin_m=origin_m, turn_deg=turn_deg)
    n_frames = np.all(np.isfinite(wand.uv_px()), axis=(2, 3)).sum(axis=1)
    return ExtrinsicsResult(placed, res.rms_px, n_frames, True, res.warnings)


@dataclass(frozen=True, slots=True)
class WandCheck:
    """The wand measured by a finished calibration (frames not used to make it).

    Attributes:
        length_error_mm: (F,) triangulated minus known ball distance, one per frame seen whole
            by two or more cameras.
        rms_px: (C,) each camera's RMS distance between the balls it saw and the triangulated balls
            projected into it, pixels (NaN for a camera that saw none).
        edge_drift_px: (C,) the balls' systematic radial offset at the outer edge of where they
            were seen (:func:`edge_drift`), pixels, + outwards (NaN: too few balls).
        edge_drift_se_px: (C,) its standard error, pixels.
        drift_mm_per_px: (C,) what one pixel at that camera means in the volume (the balls'
            median distance over the focal length), mm.
        coverage: (C,) share of the cells of an 8 x 6 grid over the picture that hold a ball
            (the lens is checked only where the balls went).
    """

    length_error_mm: np.ndarray
    rms_px: np.ndarray
    edge_drift_px: np.ndarray
    edge_drift_se_px: np.ndarray
    drift_mm_per_px: np.ndarray
    coverage: np.ndarray

    def edge_drift_mm(self, c: int) -> float:
        """Camera ``c``'s edge drift as a distance in the volume, mm (NaN when unknown)."""
        return float(abs(self.edge_drift_px[c]) * self.drift_mm_per_px[c])

    def drift_found(self, c: int) -> bool:
        """A systematic drift: over three standard errors (and known)."""
        if not np.isfinite(self.edge_drift_px[c]):
            return False
        return bool(abs(self.edge_drift_px[c]) > 3.0 * self.edge_drift_se_px[c])

    @property
    def n_frames(self) -> int:
        return int(self.length_error_mm.size)

    @property
    def length_rms_mm(self) -> float:
        e = self.length_error_mm
        return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")


def wand_check(cameras: Sequence[Camera], uv_px: np.ndarray, length_m: float) -> WandCheck:
    """Measure the wand with a finished calibration: (C, T, 2, 2) ball centroids (NaN: not seen)."""
    # lazy: calibration.wand (scipy.optimize) only to check the wand; the game imports this module
    from calibration.wand import triangulate

    uv = np.asarray(uv_px, np.float64)
    C, T = uv.shape[:2]
    whole = np.all(np.isfinite(uv), axis=3)  # (C, T, 2)
    xn = np.full((C, T * 2, 2), np.nan)
    for c, cam in enumerate(cameras):
        ok = whole[c].reshape(-1)
        if ok.any():
            xn[c, ok] = cam.undistort_points(uv[c].reshape(-1, 2)[ok])
    pts = triangulate([c.R for c in cameras], [c.t_m for c in cameras], xn).reshape(T, 2, 3)
    lengths = np.linalg.norm(pts[:, 1] - pts[:, 0], axis=1)
    errors = 1000.0 * (lengths[np.isfinite(lengths)] - length_m)
    rms = np.full(C, np.nan)
    drift, drift_se, mm_per_px = (np.full(C, np.nan) for _ in range(3))
    cover = np.zeros(C)
    flat = pts.reshape(-1, 3)
    for c, cam in enumerate(cameras):
        ok = whole[c].reshape(-1) & np.all(np.isfinite(flat), axis=1)
        seen = uv[c].reshape(-1, 2)[whole[c].reshape(-1)]
        if seen.size:
            cover[c] = coverage_of([Detection(seen, cam.size_px)], cam.size_px)[0]
        if ok.any():
            d = uv[c].reshape(-1, 2)[ok] - cam.project(flat[ok])
            rms[c] = float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
            drift[c], drift_se[c] = edge_drift(cam, uv[c].reshape(-1, 2)[ok], d)
            depth = (flat[ok] @ cam.R.T + cam.t_m)[:, 2]
            mm_per_px[c] = 1000.0 * float(np.median(depth)) / float(cam.K[0, 0])
    return WandCheck(errors, rms, drift, drift_se, mm_per_px, cover)


def edge_drift(cam: Camera, uv_px: np.ndarray, residual_px: np.ndarray) -> tuple[float, float]:
    """The radial pattern of one camera's residuals (seen minus projected), as the offset at the
    outer edge of where they lie: a lens whose distortion is off moves points near the picture's
    edge in or out, while the fit of the whole stays small and the wand's length, measured where
    the balls were, barely changes (docs/CALIBRATION.md, "What the report can see").

    The radial component of each residual, fitted as ``a r^3 + b r`` over the distance ``r`` from
    the picture's centre in focal lengths (a radial distortion error, and the small scale term a
    pose absorbs), evaluated at the 95th percentile of ``r``. Returns the offset and its standard
    error, pixels (NaN with fewer than 10 points).
    """
    if len(uv_px) < 10:
        return float("nan"), float("nan")
    centre = cam.K[:2, 2]
    out = uv_px - centre
    norm = np.linalg.norm(out, axis=1)
    keep = norm > 1e-6
    r = np.linalg.norm(cam.undistort_points(uv_px[keep]), axis=1)
    radial = np.sum(residual_px[keep] * out[keep] / norm[keep, None], axis=1)
    A = np.stack([r**3, r], axis=1)
    coef, *_ = np.linalg.lstsq(A, radial, rcond=None)
    left = radial - A @ coef
    var = float(left @ left) / max(len(radial) - 2, 1)
    edge = float(np.quantile(r, 0.95))
    g = np.array([edge**3, edge])
    try:
        se = float(np.sqrt(var * g @ np.linalg.solve(A.T @ A, g)))
    except np.linalg.LinAlgError:
        return float("nan"), float("nan")
    return float(g @ coef), se


@dataclass(frozen=True, slots=True)
class QualityReport:
    """How well the finished calibration measures.

    Attributes:
        names: the cameras' names.
        rms_px: (C,) each camera's RMS reprojection error over the views that made the rig, pixels.
        length_error_mm: (L,) measured minus printed length of the board's edges and diagonal,
            over every view seen by two or more cameras.
        verdict: "good", "usable" or "redo".
        advice: what to redo, in plain words (empty when good).
        wand: the wand measured with the finished calibration (None: not waved yet).
        wand_length_m: the wand's known ball distance.
    """

    names: tuple[str, ...]
    rms_px: np.ndarray
    length_error_mm: np.ndarray
    verdict: str
    advice: tuple[str, ...]
    wand: WandCheck | None = None
    wand_length_m: float = float("nan")

    @property
    def length_rms_mm(self) -> float:
        e = self.length_error_mm
        return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")

    def lines(self) -> list[str]:
        """The report in plain words, one line each: verdict, lengths, each camera, what to redo."""
        head = {"good": "Good: the cameras measure to about a millimetre",
                "usable": "Usable, but better is possible",
                "redo": "Not good enough yet"}[self.verdict]
        out = [head]
        if self.length_error_mm.size:
            out.append(f"Board lengths measured by the cameras: {self.length_rms_mm:.2f} mm RMS from the printed ones "
                       f"(worst {np.max(np.abs(self.length_error_mm)):.2f} mm)")
        wand = self.wand
        if wand is not None and wand.n_frames:
            out.append(f"Wand ({1000 * self.wand_length_m:.0f} mm) measured in {wand.n_frames} frames: "
                       f"{wand.length_rms_mm:.2f} mm RMS (worst {np.max(np.abs(wand.length_error_mm)):.2f} mm)")
        for k, (n, r) in enumerate(zip(self.names, self.rms_px)):
            w = "" if wand is None or not np.isfinite(wand.rms_px[k]) else f", wand balls {wand.rms_px[k]:.2f} px"
            if wand is not None and np.isfinite(wand.edge_drift_px[k]):
                w += f" (near the edge {wand.edge_drift_px[k]:+.2f} px, balls in {100 * wand.coverage[k]:.0f} % of the picture)"
            out.append(f"{n}: {r:.2f} px{w}")
        return out + list(self.advice)


def _corner_ids(det: Detection, board) -> np.ndarray:
    return np.arange(board.n_corners) if det.ids is None else det.ids


def board_lengths_mm(cameras: Sequence[Camera], board, views: dict[str, list[Detection | None]]) -> np.ndarray:
    """Measured minus printed length (mm) of the board's two edges and diagonal between its outer
    inner corners, in every view where two or more cameras saw those corners."""
    # lazy: calibration.wand (scipy.optimize) only to measure the board; the game imports this module
    from calibration.wand import triangulate

    cols, rows = board.cols, board.rows
    ends = (0, cols - 1, (rows - 1) * cols, rows * cols - 1)  # the four outer inner corners
    pairs = [(0, cols - 1), (0, (rows - 1) * cols), (0, rows * cols - 1), ((rows - 1) * cols, cols - 1)]
    obj = board.object_points()
    R = [c.R for c in cameras]
    t = [c.t_m for c in cameras]
    errors = []
    for dets in views.values():
        xn = np.full((len(cameras), len(ends), 2), np.nan)
        for c, det in enumerate(dets):
            if det is None:
                continue
            ids = _corner_ids(det, board)
            for k, corner in enumerate(ends):
                hit = np.flatnonzero(ids == corner)
                if hit.size:
                    xn[c, k] = cameras[c].undistort_points(det.uv_px[hit[:1]])[0]
        pts = triangulate(R, t, xn)
        index = {corner: k for k, corner in enumerate(ends)}  # noqa: C416
        for a, b in pairs:
            pa, pb = pts[index[a]], pts[index[b]]
            if np.all(np.isfinite(pa)) and np.all(np.isfinite(pb)):
                errors.append(1000.0 * (np.linalg.norm(pa - pb) - np.linalg.norm(obj[a] - obj[b])))
    return np.array(errors)


def quality_report(cameras: Sequence[Camera], board, views: dict[str, list[Detection | None]],
                   rms_px: np.ndarray, *, wand: WandCheck | None = None, wand_length_m: float = float("nan")) -> QualityReport:
    """The report of a solved rig from its board views and, once ``CHECK_FRAMES`` frames are
    measured, the wand (see the module docstring). The worse of the two length figures decides."""
    names = tuple(c.name for c in cameras)
    lengths = board_lengths_mm(cameras, board, views)
    rms = np.asarray(rms_px, float)
    figures = [float(np.sqrt(np.mean(lengths**2)))] if lengths.size else []
    use_wand = wand is not None and wand.n_frames >= CHECK_FRAMES
    if use_wand:
        figures.append(wand.length_rms_mm)
        rms = np.fmax(rms, wand.rms_px)  # the worse of the two fits (NaN ignored)
    # a lens whose distortion is off: the balls drift in or out near the picture's edge, as a
    # distance in the volume; it counts like a length error (the wand's length barely shows it)
    drift_mm = np.array([wand.edge_drift_mm(c) if use_wand and wand.drift_found(c) else 0.0 for c in range(len(names))])
    length_rms = max(figures) if figures else float("inf")
    worst = float(np.nanmax(rms)) if np.isfinite(rms).any() else float("inf")
    drift = float(np.max(drift_mm, initial=0.0))
    if worst < GOOD_RMS_PX and length_rms < GOOD_LENGTH_MM and drift < GOOD_LENGTH_MM:
        verdict = "good"
    elif worst < USABLE_RMS_PX and length_rms < USABLE_LENGTH_MM and drift < USABLE_LENGTH_MM:
        verdict = "usable"
    else:
        verdict = "redo"
    advice = []
    for c, (n, r) in enumerate(zip(names, rms)):
        if not np.isfinite(r):
            advice.append(f"Redo the positions: {n} saw no board view or wand")
        elif r >= GOOD_RMS_PX:
            advice.append(f"Redo {n}'s lens step: its corners or wand balls fit to {r:.2f} px (blurred views, or the lens moved)")
        elif drift_mm[c] >= GOOD_LENGTH_MM:
            way = "outwards" if wand.edge_drift_px[c] > 0 else "inwards"
            advice.append(f"Redo {n}'s lens step with the board also near the edges and corners of the picture: the wand "
                          f"balls drift {abs(wand.edge_drift_px[c]):.2f} px {way} near the edge (about {drift_mm[c]:.1f} mm "
                          "in the volume), its lens distortion is off")
    if not figures:
        advice.append("Redo the positions: neither the board nor the wand was seen whole by two cameras, "
                      "so no length could be measured")
    elif lengths.size and figures[0] >= GOOD_LENGTH_MM:
        advice.append("Measure the printed square again and give its exact size; then redo the positions")
    if use_wand and wand.length_rms_mm >= GOOD_LENGTH_MM:
        advice.append("The wand measures off: check its length between the ball centres, then redo the positions")
    if wand is not None and not use_wand:
        advice.append(f"Wave the wand through the volume to measure it ({wand.n_frames} of {CHECK_FRAMES} frames)")
    return QualityReport(names, np.asarray(rms_px, float), lengths, verdict, tuple(advice), wand if use_wand else None,
                         float(wand_length_m))
