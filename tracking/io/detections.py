"""What the cameras saw of each tracked marker: 2D detections, camera masks, residuals.

The tracker reports, per frame set, the image position in each camera from which each marker's
position was triangulated (``TrackerSample.uv_px``, distorted pixels, NaN where that camera's view
was not used). From those the result files derive:

- the **2D detections CSV** (``rehab track --detections``), for triangulating again elsewhere
  (Pose2Sim, anipose, another calibration), long format, one row per marker seen by a camera::

      frame,time,camera,marker,u_px,v_px
      0,0.000000,cam1,MB,161.2345,80.5432

  frames are the recording's frame indices and times seconds (as in the status CSV), cameras are
  named as in the calibration file, pixels follow OpenCV (centre of the top-left pixel = (0, 0))
  and are the distorted image positions (undistort with the calibration's intrinsics);
- the C3D **camera masks** (the cameras whose views made each position) and **residuals** (the
  mean reprojection distance of those views, converted to millimetres at the marker's depth).

A marker measured in the full frame (the frame set that identifies the markers, or a marker found
again after it was lost) has the centroids of the full-frame point it took, so every measured
position names its views.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from calibration.camera import Camera, CameraStack

DETECTIONS_HEADER: tuple[str, ...] = ("frame", "time", "camera", "marker", "u_px", "v_px")


def seen_by(uv_px: np.ndarray) -> np.ndarray:
    """(..., M, C, 2) centroids -> (..., M, C) bool: camera c's view made marker m's position."""
    return np.isfinite(np.asarray(uv_px, dtype=np.float64)).all(axis=-1)


def reprojection_residuals_mm(cameras: Sequence[Camera], positions_m: np.ndarray, uv_px: np.ndarray) -> np.ndarray:
    """Mean distance between each marker's used centroids and its position projected back.

    Args:
        cameras: the C cameras, calibration order.
        positions_m: (T, M, 3) world metres (NaN where lost).
        uv_px: (T, M, C, 2) centroids the positions were triangulated from (NaN where unused).

    Returns:
        (T, M) float64 millimetres: each view's pixel distance times the marker's depth over the
        camera's focal length (the distance across the line of sight at the marker), averaged over
        the views used; NaN where no view was used.
    """
    p = np.asarray(positions_m, dtype=np.float64)
    uv = np.asarray(uv_px, dtype=np.float64)
    n_frames, n_markers = p.shape[:2]
    if uv.shape != (n_frames, n_markers, len(cameras), 2):
        raise ValueError(f"uv_px must be ({n_frames}, {n_markers}, {len(cameras)}, 2), got {uv.shape}")
    projected, depth_m = CameraStack(tuple(cameras)).project(p.reshape(-1, 3))
    projected = projected.reshape(uv.shape)
    depth_m = depth_m.reshape(uv.shape[:3])
    focal_px = np.array([(cam.K[0, 0] + cam.K[1, 1]) / 2.0 for cam in cameras])
    across_mm = np.linalg.norm(projected - uv, axis=-1) * depth_m / focal_px * 1000.0  # NaN where unused
    used = np.isfinite(across_mm)
    with np.errstate(invalid="ignore"):
        return np.where(used.any(axis=-1), np.nansum(across_mm, axis=-1) / used.sum(axis=-1), np.nan)


def write_detections_csv(
    path: str | Path,
    frames: np.ndarray,
    times_s: np.ndarray,
    camera_names: Sequence[str],
    marker_names: Sequence[str],
    uv_px: np.ndarray,
) -> int:
    """Write the 2D detections CSV (module docstring); returns the number of rows written.

    Args:
        path: CSV file to write.
        frames: (T,) frame indices; times_s: (T,) seconds.
        camera_names: the C camera names; marker_names: the M marker names.
        uv_px: (T, M, C, 2) centroids, NaN where the camera's view was not used.
    """
    f = np.asarray(frames, dtype=np.int64)
    t = np.asarray(times_s, dtype=np.float64)
    uv = np.asarray(uv_px, dtype=np.float64)
    if uv.shape != (len(f), len(marker_names), len(camera_names), 2) or t.shape != f.shape:
        raise ValueError(f"uv_px must be ({len(f)}, {len(marker_names)}, {len(camera_names)}, 2) for {len(f)} frames, "
                         f"got {uv.shape}")
    bad = [n for n in (*camera_names, *marker_names) if not n or any(c in n for c in ',"\r\n')]
    if bad:
        raise ValueError(f"names {bad} cannot be written to a CSV cell")
    # rows in frame, camera, marker order
    ti, mi, ci = np.nonzero(seen_by(uv))
    order = np.lexsort((mi, ci, ti))
    ti, mi, ci = ti[order], mi[order], ci[order]
    with open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(",".join(DETECTIONS_HEADER) + "\n")
        fh.writelines(
            f"{f[a]},{t[a]:.6f},{camera_names[c]},{marker_names[m]},{uv[a, m, c, 0]:.4f},{uv[a, m, c, 1]:.4f}\n"
            for a, m, c in zip(ti.tolist(), mi.tolist(), ci.tolist())
        )
    return len(ti)
