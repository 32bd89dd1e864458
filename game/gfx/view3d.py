"""Cameras of the 3D views: view and projection matrices, projecting points, pointer rays.

Pure numpy. Matrices are (4, 4) float64 acting on column vectors (``clip = proj @ view @ p``);
hand them to GL transposed (``m.T.astype('f4').tobytes()`` is column-major).

The live view is a mirror: the patient faces the screen, so their right hand must appear on the
screen's right, as in a mirror. A camera in front of the patient sees the patient's right on its
left; :func:`mirrored` flips the image's x, which also reverses the winding of every triangle
(front faces become clockwise: renderers that cull must be told).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def look_at(eye_m, target_m, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """(4, 4) view matrix (camera from world) of a camera at ``eye_m`` looking at ``target_m``.

    Camera axes as in OpenGL: x right, y up, looking down -z.
    """
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye_m, target_m, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = right, true_up, -forward
    view[:3, 3] = -view[:3, :3] @ eye
    return view


def perspective(fovy_deg: float, aspect: float, near_m: float = 0.1, far_m: float = 50.0) -> np.ndarray:
    """(4, 4) OpenGL perspective projection (clip from camera)."""
    f = 1.0 / math.tan(math.radians(fovy_deg) / 2.0)
    proj = np.zeros((4, 4))
    proj[0, 0] = f / aspect
    proj[1, 1] = f
    proj[2, 2] = (far_m + near_m) / (near_m - far_m)
    proj[2, 3] = 2.0 * far_m * near_m / (near_m - far_m)
    proj[3, 2] = -1.0
    return proj


def mirrored(proj: np.ndarray) -> np.ndarray:
    """``proj`` with the image's x flipped (a mirror image)."""
    return np.diag([-1.0, 1.0, 1.0, 1.0]) @ proj


@dataclass(frozen=True, slots=True)
class Viewport:
    """A rectangle of the window, pixels from the top-left corner (y down)."""

    x: float
    y: float
    w: float
    h: float

    @property
    def aspect(self) -> float:
        return self.w / self.h

    def gl(self, window_h: int) -> tuple[int, int, int, int]:
        """The same rectangle for ``ctx.viewport`` (GL counts y from the bottom)."""
        return (round(self.x), round(window_h - self.y - self.h), round(self.w), round(self.h))


def project_px(p_world_m: np.ndarray, clip_from_world: np.ndarray, viewport: Viewport) -> np.ndarray:
    """(N, 3) world points -> (N, 2) window pixels (NaN for points behind the camera or NaN)."""
    p = np.asarray(p_world_m, dtype=np.float64).reshape(-1, 3)
    clip = np.concatenate([p, np.ones((len(p), 1))], axis=1) @ clip_from_world.T
    with np.errstate(invalid="ignore", divide="ignore"):
        ndc = clip[:, :2] / clip[:, 3:4]
    ndc[~(clip[:, 3] > 0)] = np.nan
    x = viewport.x + (ndc[:, 0] + 1.0) / 2.0 * viewport.w
    y = viewport.y + (1.0 - ndc[:, 1]) / 2.0 * viewport.h
    return np.stack([x, y], axis=1)


def pointer_ray(x_px: float, y_px: float, clip_from_world: np.ndarray,
                viewport: Viewport) -> tuple[np.ndarray, np.ndarray]:
    """The world ray under a window pixel: (origin on the near plane, unit direction)."""
    ndc_x = (x_px - viewport.x) / viewport.w * 2.0 - 1.0
    ndc_y = 1.0 - (y_px - viewport.y) / viewport.h * 2.0
    inverse = np.linalg.inv(clip_from_world)
    near = inverse @ np.array([ndc_x, ndc_y, -1.0, 1.0])
    far = inverse @ np.array([ndc_x, ndc_y, 1.0, 1.0])
    near, far = near[:3] / near[3], far[:3] / far[3]
    direction = far - near
    return near, direction / np.linalg.norm(direction)


def intersect_plane(origin_m: np.ndarray, direction: np.ndarray, point_m, normal) -> np.ndarray | None:
    """Where the ray meets the plane through ``point_m`` with ``normal`` (None: parallel or behind)."""
    normal = np.asarray(normal, dtype=np.float64)
    denom = float(direction @ normal)
    if abs(denom) < 1e-9:
        return None
    s = float((np.asarray(point_m, dtype=np.float64) - origin_m) @ normal) / denom
    return None if s < 0 else origin_m + s * direction
