"""The guided calibration's logic after the lenses: shared board views, the pairs they link, the
rig solved with the world frame from the floor board, and a quality report in millimetres.

Pure: detections in, cameras and figures out (the application's calibration screen shows them,
:mod:`game.scenes.calibrate`). A view counts when two or more cameras found the board at once;
two cameras are linked by ``MIN_SHARED_VIEWS`` such views, and the rig can be solved when the links
join every camera. The quality report measures the board with the finished calibration alone:
its corners triangulated from every camera that saw them (no board model), and the lengths of the
board's edges and diagonal compared with the printed ones, like a wand of known length.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from calibration.board import Detection
from calibration.camera import Camera
from calibration.errors import CalibrationError

MIN_SHARED_VIEWS = 3  # board views two cameras must share to count as linked
GOOD_RMS_PX, USABLE_RMS_PX = 0.5, 1.0
GOOD_LENGTH_MM, USABLE_LENGTH_MM = 1.0, 2.5


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
        linked = self.pair_counts() >= min_views
        left = set(range(len(self.names)))
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

    def linked(self, min_views: int = MIN_SHARED_VIEWS) -> bool:
        return len(self.groups(min_views)) == 1

    def advice(self, min_views: int = MIN_SHARED_VIEWS) -> str:
        """What to do next, in plain words."""
        groups = self.groups(min_views)
        if len(groups) == 1:
            return "Every camera is linked: go on to the floor board"
        main, other = groups[0], groups[1]
        counts = self.pair_counts()
        a, b = max(((i, j) for i in main for j in other), key=lambda p: counts[p])
        need = min_views - int(counts[a, b])
        return (f"Hold the board where {self.names[a]} and {self.names[b]} both see it "
                f"({need} more view{'s' if need != 1 else ''})")


def solve_rig(cameras: Sequence[Camera], board, rig: RigViews, floor: Sequence[Detection | None], *,
              origin_m=(0.0, 0.0, 0.0), turn_deg: float = 0.0):
    """The cameras' positions from the shared views, the world frame from the floor board.

    Returns:
        :class:`calibration.extrinsics.ExtrinsicsResult`.
    Raises:
        CalibrationError: cameras not linked, no camera sees the floor board, or a world frame no
            room has (:func:`calibration.extrinsics.check_world_frame`).
    """
    from calibration.extrinsics import calibrate_extrinsics

    if not rig.linked():
        raise CalibrationError(rig.advice())
    if not any(d is not None for d in floor):
        raise CalibrationError("no camera sees the floor board: lay it face up on the seat, in view of the cameras")
    views = dict(rig.views)
    views["floor"] = list(floor)
    return calibrate_extrinsics(cameras, board, views, floor_view="floor", origin_m=origin_m, turn_deg=turn_deg)


@dataclass(frozen=True, slots=True)
class QualityReport:
    """How well the finished calibration measures.

    Attributes:
        names: the cameras' names.
        rms_px: (C,) each camera's RMS reprojection error over the board views, pixels.
        length_error_mm: (L,) measured minus printed length of the board's edges and diagonal,
            over every view seen by two or more cameras.
        verdict: "good", "usable" or "redo".
        advice: what to redo, in plain words (empty when good).
    """

    names: tuple[str, ...]
    rms_px: np.ndarray
    length_error_mm: np.ndarray
    verdict: str
    advice: tuple[str, ...]

    @property
    def length_rms_mm(self) -> float:
        e = self.length_error_mm
        return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")

    def lines(self) -> list[str]:
        """The report in plain words, one line each."""
        head = {"good": "Good: the cameras measure to about a millimetre",
                "usable": "Usable, but better is possible",
                "redo": "Not good enough yet"}[self.verdict]
        out = [head, f"Board lengths measured by the cameras: {self.length_rms_mm:.2f} mm RMS from the printed ones "
                     f"(worst {np.max(np.abs(self.length_error_mm)) if self.length_error_mm.size else float('nan'):.2f} mm)"]
        out += [f"{n}: {r:.2f} px" for n, r in zip(self.names, self.rms_px)]
        return out + list(self.advice)


def _corner_ids(det: Detection, board) -> np.ndarray:
    return np.arange(board.n_corners) if det.ids is None else det.ids


def board_lengths_mm(cameras: Sequence[Camera], board, views: dict[str, list[Detection | None]]) -> np.ndarray:
    """Measured minus printed length (mm) of the board's two edges and diagonal between its outer
    inner corners, in every view where two or more cameras saw those corners."""
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
                   rms_px: np.ndarray) -> QualityReport:
    """The report of a solved rig from its board views (see the module docstring)."""
    names = tuple(c.name for c in cameras)
    lengths = board_lengths_mm(cameras, board, views)
    rms = np.asarray(rms_px, float)
    length_rms = float(np.sqrt(np.mean(lengths**2))) if lengths.size else float("inf")
    worst = float(np.nanmax(rms)) if np.isfinite(rms).any() else float("inf")
    if worst < GOOD_RMS_PX and length_rms < GOOD_LENGTH_MM:
        verdict = "good"
    elif worst < USABLE_RMS_PX and length_rms < USABLE_LENGTH_MM:
        verdict = "usable"
    else:
        verdict = "redo"
    advice = []
    for n, r in zip(names, rms):
        if not np.isfinite(r):
            advice.append(f"Redo the positions: {n} saw no board view")
        elif r >= GOOD_RMS_PX:
            advice.append(f"Redo {n}'s lens step: its board corners fit to {r:.2f} px (blurred views, or the lens moved)")
    if lengths.size == 0:
        advice.append("Redo the positions: no view showed the whole board to two cameras, so no length could be measured")
    elif length_rms >= GOOD_LENGTH_MM:
        advice.append("Measure the printed square again and give its exact size; then redo the positions")
    return QualityReport(names, rms, lengths, verdict, tuple(advice))
