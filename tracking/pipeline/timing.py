"""The time-aware measurement: images taken off the frame set's instant (free-running clocks,
rolling shutters) have their windows placed where each camera saw the marker, and their centroids
brought to the set's instant with the motion each marker's views show (docs/TRACKING.md)."""

from __future__ import annotations

import numpy as np

from calibration.camera import CameraStack
from calibration.errors import RehabError
from tracking.pipeline.state import FrameState, MarkerMemory, Setup

#: two cameras seeing a marker along nearly one line leave a direction of its velocity unknown:
#: the normal equations' determinant below this share of their scale cubed
VELOCITY_DET_FLOOR = 1e-9


def frame_skew(setup: Setup, time_s: float, stamps_s: np.ndarray | None) -> np.ndarray | None:
    """(C,) each image's instant minus the set's (unknown: 0); None when every image is at the
    set's instant and no camera has a rolling shutter."""
    n_cams = len(setup.cameras)
    skew_s = None
    if stamps_s is not None:
        skew = np.nan_to_num(np.asarray(stamps_s, dtype=np.float64).reshape(-1) - time_s)  # (unknown: 0)
        if skew.size != n_cams:
            raise RehabError(f"the tracker has {n_cams} cameras but got {skew.size} time stamps")
        if skew.any():
            skew_s = skew
    if skew_s is None and setup.rolling:
        skew_s = np.zeros(n_cams)
    return skew_s


def at_image_instants(setup: Setup, frame: FrameState, seen_velocity: np.ndarray, fps: float) -> np.ndarray:
    """(M, C, 3) camera-frame positions of the markers predicted at each camera's image
    instant: the prediction (the frame set's instant) moved by the marker's velocity for the
    image's skew, plus, under a rolling shutter, the time to the predicted row. Keeps the
    prediction and the velocity in camera frames (``frame.pred_cam``, ``frame.moving_cam``) for
    :func:`to_set_instant`."""
    stack = setup.stack
    cam = stack.world_to_cameras(frame.pred)
    # velocity in m/s (the tracker's velocity is the displacement per frame set)
    frame.moving_cam = stack.rotate_to_cameras(seen_velocity * fps)
    frame.pred_cam = cam
    dt = np.broadcast_to(frame.skew_s, cam.shape[:2])
    moved = cam + frame.moving_cam * dt[..., None]
    if setup.rolling:
        rows = stack.project_camera_points(moved)[0][..., 1]
        dt = frame.skew_s + setup.row_s * np.nan_to_num(rows)
        moved = cam + frame.moving_cam * dt[..., None]
    return moved


def to_set_instant(setup: Setup, frame: FrameState, xn: np.ndarray, uv: np.ndarray, moving: np.ndarray | None = None,
                   cam: np.ndarray | None = None) -> np.ndarray:
    """(M, C, 2) normalized centroids seen at each image's instant (``uv`` their pixel rows)
    -> where each marker's motion puts them at the frame set's instant. ``moving``: (M, C, 3)
    the markers' camera-frame velocities (m/s), ``cam`` their camera-frame positions (default:
    the prediction's, :func:`at_image_instants`)."""
    dt = frame.skew_s + setup.row_s * uv[..., 1]  # NaN where no centroid
    cam = frame.pred_cam if cam is None else cam
    then = cam + (frame.moving_cam if moving is None else moving) * dt[..., None]
    with np.errstate(invalid="ignore"):  # (NaN for unknown markers: not seen)
        return xn + cam[..., :2] / cam[..., 2:] - then[..., :2] / then[..., 2:]


def image_velocity(stack: CameraStack, pred_cam: np.ndarray, now: np.ndarray, before: np.ndarray) -> np.ndarray:
    """(M, 3) each marker's velocity (m/s, NaN where fewer than two cameras saw it in both frame
    sets) from its views' image motion: ``now`` and ``before`` (M, C, 3) the views as seen
    (normalized x, y, instant); ``pred_cam`` (M, C, 3) the camera-frame prediction. Each camera's
    displacement ``dx_c`` over its own interval ``dt_c`` is ``J_c v dt_c`` (``J_c`` the
    projection's derivative at the prediction), solved for ``v`` by least squares over the cameras
    that saw the marker twice: a view that joins or leaves the set, or two cameras' instants far
    apart, do not move the point as a point triangulated from changing views did (that made single
    frame sets 10-16 mm off), and a camera whose phase wrapped (an interval of a few milliseconds)
    weighs by its interval."""
    dt = now[..., 2] - before[..., 2]  # (M, C), NaN unless seen in both
    dx = now[..., :2] - before[..., :2]
    ok = np.isfinite(dt) & np.isfinite(dx).all(axis=2) & (dt > 0)
    v = np.full((len(now), 3), np.nan)
    rows = np.flatnonzero(ok.sum(axis=1) >= 2)
    if rows.size == 0:
        return v
    cam = pred_cam[rows]  # (K, C, 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        x = cam[..., :2] / cam[..., 2:]
        rot = stack.rotation  # (C, 3, 3) world -> camera
        jac = (rot[None, :, :2, :] - x[..., :, None] * rot[None, :, 2:3, :]) / cam[..., 2, None, None]
    a = (np.nan_to_num(jac) * np.where(ok[rows], dt[rows], 0.0)[..., None, None]).reshape(rows.size, -1, 3)
    b = np.where(ok[rows][..., None], dx[rows], 0.0).reshape(rows.size, -1, 1)  # (K, 2C, 1)
    at = a.transpose(0, 2, 1)
    normal = at @ a  # (K, 3, 3)
    # (two cameras seeing the marker along nearly one line leave a direction unknown)
    scale = np.trace(normal, axis1=1, axis2=2)
    good = np.linalg.det(normal) > VELOCITY_DET_FLOOR * scale**3
    v[rows[good]] = np.linalg.solve(normal[good], (at @ b)[good])[..., 0]
    return v


def correct_to_set_instant(setup: Setup, frame: FrameState, memory: MarkerMemory, fps: float, uv: np.ndarray,
                           xn: np.ndarray, xn_seen: np.ndarray, seen: np.ndarray, measured: np.ndarray,
                           new_pos: np.ndarray) -> None:
    """The measured markers triangulated once more, their views brought to the set's instant with the
    velocity their image motion shows (``new_pos`` and ``xn`` updated in place); keeps the views as
    seen and that velocity in ``frame`` for :func:`remember_views`."""
    # the views as seen, with their instants: their image motion since the last frame set is
    # the markers' velocity over the last period (not the prediction's, a period older: it
    # lagged a fast swing's acceleration), which brings the views to the set's instant once more
    use = seen & measured[:, None]
    at = frame.time_s + frame.skew_s + setup.row_s * uv[..., 1]
    frame.seen_views = np.concatenate([np.where(use[..., None], xn_seen, np.nan), at[..., None]], axis=2)
    # over the last period and the last two: twice the one minus the other is the velocity at
    # the views' instants for a steady acceleration (the last period's alone lagged by half
    # a period: a swing's acceleration times 16 ms, ~0.1 m/s)
    last = image_velocity(setup.stack, frame.pred_cam, frame.seen_views, memory.seen_pos[..., :3])
    two = image_velocity(setup.stack, frame.pred_cam, frame.seen_views, memory.seen_pos[..., 3:])
    frame.seen_now = np.where(np.isfinite(two), 2.0 * last - two, last) / fps
    if measured.any():
        velocity = np.where(np.isfinite(frame.seen_now), frame.seen_now, memory.seen_velocity)
        moving = setup.stack.rotate_to_cameras(velocity * fps)
        redo = np.flatnonzero(measured)
        xn_redo = to_set_instant(setup, frame, xn_seen[redo], uv[redo], moving[redo], frame.pred_cam[redo])
        new_pos[redo] = setup.triangulate(xn_redo, use[redo])
        xn[redo] = xn_redo


def remember_views(frame: FrameState, memory: MarkerMemory, measured: np.ndarray) -> None:
    """Keep this frame set's views as seen (and the velocity they show) for the next."""
    if frame.skew_s is not None:
        memory.seen_velocity = np.where((measured & np.isfinite(frame.seen_now).all(axis=1))[:, None],
                                        frame.seen_now, memory.velocity)
        memory.seen_pos = np.concatenate([np.where(measured[:, None, None], frame.seen_views, np.nan),
                                          memory.seen_pos[..., :3]], axis=2)
    else:
        memory.seen_pos[:] = np.nan

