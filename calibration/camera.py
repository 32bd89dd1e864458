"""Pinhole camera with OpenCV distortion, as a validated value object.

Conventions (docs/INTERFACES.md): world frame right-handed, metres, +Y up, patient faces -Z.
Extrinsics are world -> camera: ``x_cam = R @ x_world + t`` with ``R`` from the Rodrigues vector
``rvec``. The camera looks along its +Z axis, image x to the right, image y down (OpenCV).
Distortion coefficients are in OpenCV order (k1, k2, p1, p2[, k3[, k4, k5, k6]]), or for a
fisheye camera (``fisheye=True``, OpenCV's ``cv2.fisheye`` model, as aniposelib and Caliscope
write it) the four k1..k4 of ``theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)``
with ``theta`` the angle from the optical axis: projection, undistortion and so triangulation
follow the model of each camera.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from calibration.errors import CalibrationError

_ALLOWED_DIST_LENGTHS = (4, 5, 8)


def rotation_from_rvec(rvec: np.ndarray) -> np.ndarray:
    """(3,) Rodrigues vector -> (3, 3) rotation matrix."""
    rot, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    return rot


def rvec_from_rotation(rot: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix -> (3,) Rodrigues vector (angle in [0, pi]), exact to rounding.

    A matrix that is only nearly orthonormal is first replaced by the nearest rotation (as
    cv2.Rodrigues does). cv2.Rodrigues itself is not used: it snaps rotations within about 1e-5 rad
    of the identity or of a half turn (errors up to 2e-5 rad, 0.06 mm at 3 m), and half turns are
    common (a camera facing the patient along +Z is a half turn about Y from one facing -Z).
    The unit quaternion is taken with Shepperd's method (largest component first), which is well
    conditioned at every angle, and the angle from atan2.
    """
    R = np.asarray(rot, dtype=np.float64)
    U, _, Vt = np.linalg.svd(R)
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    tr = np.trace(R)
    i = int(np.argmax([tr, R[0, 0], R[1, 1], R[2, 2]]))
    if i == 0:
        w = 0.5 * np.sqrt(1.0 + tr)
        q = np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)])
    elif i == 1:
        x = 0.5 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = np.array([(R[2, 1] - R[1, 2]) / (4 * x), x, (R[0, 1] + R[1, 0]) / (4 * x), (R[0, 2] + R[2, 0]) / (4 * x)])
    elif i == 2:
        y = 0.5 * np.sqrt(1.0 - R[0, 0] + R[1, 1] - R[2, 2])
        q = np.array([(R[0, 2] - R[2, 0]) / (4 * y), (R[0, 1] + R[1, 0]) / (4 * y), y, (R[1, 2] + R[2, 1]) / (4 * y)])
    else:
        z = 0.5 * np.sqrt(1.0 - R[0, 0] - R[1, 1] + R[2, 2])
        q = np.array([(R[1, 0] - R[0, 1]) / (4 * z), (R[0, 2] + R[2, 0]) / (4 * z), (R[1, 2] + R[2, 1]) / (4 * z), z])
    if q[0] < 0:
        q = -q
    v = q[1:]
    s = np.linalg.norm(v)
    if s == 0.0:
        return np.zeros(3)
    return v * (2.0 * np.arctan2(s, q[0]) / s)


def fisheye_distort(x: np.ndarray, y: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ideal normalized x, y (any shape) -> distorted ones under OpenCV's fisheye model k1..k4
    (``k`` broadcasts against x and y, so one row per camera works too)."""
    k = np.asarray(k, dtype=np.float64)
    k1, k2, k3, k4 = (k[..., i] for i in range(4))
    r = np.sqrt(x * x + y * y)
    theta = np.arctan(r)
    t2 = theta * theta
    theta_d = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(r > 1e-12, theta_d / r, 1.0)
    return x * scale, y * scale


def check_rotation(rot: np.ndarray, what: str, tol: float = 1e-6) -> None:
    """Raise CalibrationError unless ``rot`` is a proper rotation (orthonormal, det +1)."""
    rot = np.asarray(rot, dtype=np.float64)
    if rot.shape != (3, 3) or not np.all(np.isfinite(rot)):
        raise CalibrationError(f"{what}: rotation must be a finite 3x3 matrix, got shape {rot.shape}")
    if np.abs(rot @ rot.T - np.eye(3)).max() > tol * 1e3 or abs(np.linalg.det(rot) - 1.0) > tol * 1e3:
        raise CalibrationError(
            f"{what}: the matrix is not a rotation (R R^T != I or det != 1); "
            "give a Rodrigues vector or an orthonormal matrix"
        )


@dataclass(frozen=True, slots=True, eq=False)
class Camera:
    """One calibrated camera.

    Attributes:
        name: camera name, e.g. ``"cam1"``.
        size_px: (width, height) of its images in pixels.
        K: (3, 3) float64 intrinsic matrix in pixels.
        dist: (n,) float64 OpenCV distortion coefficients, n in {4, 5, 8}.
        rvec: (3,) float64 Rodrigues vector, world -> camera.
        t_m: (3,) float64 translation in metres, world -> camera.
        fisheye: True for the OpenCV fisheye model (``dist`` holds k1..k4).
        rolling_shutter_s: rolling-shutter readout, seconds from the first image row to the last
            (row ``v`` is exposed ``v / height * rolling_shutter_s`` after the image's time stamp);
            0 for a global shutter (docs/FILES.md).
    """

    name: str
    size_px: tuple[int, int]
    K: np.ndarray
    dist: np.ndarray
    rvec: np.ndarray
    t_m: np.ndarray
    fisheye: bool = False
    rolling_shutter_s: float = 0.0
    R: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        what = f"camera {self.name!r}"
        # The size is checked first: with_size() derives K from it, so a bad size must be named as such.
        try:
            size_f = np.asarray(self.size_px, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            size_f = np.zeros(0)
        if size_f.size != 2 or not np.all(np.isfinite(size_f)) or size_f.min() < 0.5:
            raise CalibrationError(f"{what}: size must be [width, height] in pixels, got {self.size_px!r}")
        size = (int(round(size_f[0])), int(round(size_f[1])))
        K = np.asarray(self.K, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise CalibrationError(f"{what}: matrix must be a finite 3x3 array, got shape {K.shape}")
        if K[0, 0] <= 0 or K[1, 1] <= 0 or abs(K[2, 2] - 1.0) > 1e-9 or K[1, 0] != 0 or np.any(K[2, :2] != 0):
            raise CalibrationError(
                f"{what}: matrix must be [[fx,s,cx],[0,fy,cy],[0,0,1]] with fx, fy > 0"
            )
        dist = np.asarray(self.dist, dtype=np.float64).reshape(-1)
        if dist.size not in _ALLOWED_DIST_LENGTHS or not np.all(np.isfinite(dist)):
            raise CalibrationError(
                f"{what}: distortions must hold 4, 5 or 8 finite numbers (k1,k2,p1,p2[,k3...]), "
                f"got {dist.size}"
            )
        if self.fisheye and dist.size != 4:
            raise CalibrationError(f"{what}: a fisheye camera's distortions are the 4 numbers k1..k4, got {dist.size}")
        rvec = np.asarray(self.rvec, dtype=np.float64).reshape(-1)
        t_m = np.asarray(self.t_m, dtype=np.float64).reshape(-1)
        if rvec.size != 3 or t_m.size != 3 or not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(t_m))):
            raise CalibrationError(f"{what}: rotation and translation must be 3 finite numbers each")
        readout = self.rolling_shutter_s
        if isinstance(readout, bool) or not isinstance(readout, (int, float)) or not 0.0 <= readout < 1.0:
            raise CalibrationError(f"{what}: rolling_shutter_s must be the readout in seconds, 0 (global shutter) "
                                   f"up to 1, got {readout!r}")
        object.__setattr__(self, "rolling_shutter_s", float(readout))
        for arr in (K, dist, rvec, t_m):
            arr.setflags(write=False)
        R = rotation_from_rvec(rvec)
        R.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "rvec", rvec)
        object.__setattr__(self, "t_m", t_m)
        object.__setattr__(self, "size_px", size)
        object.__setattr__(self, "R", R)

    # ----------------------------------------------------------------- constructors
    @classmethod
    def from_rotation(cls, name: str, size_px, K, dist, R, t_m, fisheye: bool = False) -> "Camera":
        """Build from a (3, 3) world -> camera rotation matrix instead of a Rodrigues vector."""
        check_rotation(R, f"camera {name!r}")
        return cls(name, size_px, K, dist, rvec_from_rotation(R), t_m, fisheye)

    @classmethod
    def look_at(
        cls,
        name: str,
        size_px: tuple[int, int],
        f_px: float,
        eye_m,
        target_m,
        up=(0.0, 1.0, 0.0),
        dist=(0.0, 0.0, 0.0, 0.0),
    ) -> "Camera":
        """A camera at ``eye_m`` looking at ``target_m`` (world metres), principal point centred."""
        eye = np.asarray(eye_m, dtype=np.float64)
        z = np.asarray(target_m, dtype=np.float64) - eye
        if not np.linalg.norm(z) > 1e-12:  # also catches NaN
            raise CalibrationError(f"camera {name!r}: eye and target must be distinct finite points")
        z /= np.linalg.norm(z)
        x = np.cross(z, np.asarray(up, dtype=np.float64))  # image right = forward x up
        if np.linalg.norm(x) < 1e-9:
            raise CalibrationError(f"camera {name!r}: viewing direction is parallel to 'up'")
        x /= np.linalg.norm(x)
        y = np.cross(z, x)  # image down
        R = np.stack([x, y, z])  # rows: camera axes in world coordinates
        w, h = size_px
        K = np.array([[f_px, 0.0, (w - 1) / 2.0], [0.0, f_px, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
        return cls.from_rotation(name, (w, h), K, np.asarray(dist, float), R, -R @ eye)

    def with_size(self, size_px: tuple[int, int]) -> "Camera":
        """The same camera at another resolution (intrinsics scaled; pixel centres kept consistent)."""
        sx = size_px[0] / self.size_px[0]
        sy = size_px[1] / self.size_px[1]
        K = self.K.copy()
        K[0, 0] *= sx
        K[0, 1] *= sx
        K[1, 1] *= sy
        K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
        return Camera(self.name, size_px, K, self.dist, self.rvec, self.t_m, self.fisheye, self.rolling_shutter_s)

    # ----------------------------------------------------------------- derived quantities
    @property
    def centre_m(self) -> np.ndarray:
        """(3,) optical centre in world metres."""
        return -self.R.T @ self.t_m

    @property
    def extrinsic(self) -> np.ndarray:
        """(3, 4) [R | t], world -> camera (normalized-coordinate projection matrix)."""
        return np.hstack([self.R, self.t_m[:, None]])

    @property
    def P(self) -> np.ndarray:
        """(3, 4) pixel projection matrix K [R | t] of the ideal (undistorted) pinhole."""
        return self.K @ self.extrinsic

    @property
    def has_distortion(self) -> bool:
        """False for an ideal pinhole; a fisheye camera is never one (its angle maps like no pinhole)."""
        return self.fisheye or bool(np.any(self.dist != 0.0))

    # ----------------------------------------------------------------- geometry
    def world_to_camera(self, p_world_m: np.ndarray) -> np.ndarray:
        """(N, 3) world metres -> (N, 3) camera-frame metres."""
        p = np.asarray(p_world_m, dtype=np.float64).reshape(-1, 3)
        return p @ self.R.T + self.t_m

    def project(self, p_world_m: np.ndarray) -> np.ndarray:
        """(N, 3) world metres -> (N, 2) float64 distorted pixel coordinates.

        Points behind the camera (z <= 0) give NaN.
        """
        p_cam = self.world_to_camera(p_world_m)
        z = p_cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # z = 0 -> NaN below
            xn = p_cam[:, :2] / z[:, None]
            uv = self.distort_normalized(xn)
        uv[z <= 1e-9] = np.nan
        return uv

    def distort_normalized(self, xn: np.ndarray) -> np.ndarray:
        """(N, 2) ideal normalized coordinates -> (N, 2) distorted pixel coordinates."""
        xn = np.asarray(xn, dtype=np.float64).reshape(-1, 2)
        x, y = xn[:, 0], xn[:, 1]
        if self.fisheye:
            xd, yd = fisheye_distort(x, y, self.dist)
        elif self.has_distortion:
            d = np.zeros(8)
            d[: self.dist.size] = self.dist
            k1, k2, p1, p2, k3, k4, k5, k6 = d
            r2 = x * x + y * y
            radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
            xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
            yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        else:
            xd, yd = x, y
        K = self.K
        u = K[0, 0] * xd + K[0, 1] * yd + K[0, 2]
        v = K[1, 1] * yd + K[1, 2]
        return np.stack([u, v], axis=1)

    def undistort_points(self, uv_px: np.ndarray) -> np.ndarray:
        """(N, 2) distorted pixel coordinates -> (N, 2) ideal normalized coordinates (x/z, y/z)."""
        uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 1, 2)
        if uv.shape[0] == 0:
            return np.zeros((0, 2))
        if self.fisheye:
            crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-12)
            return cv2.fisheye.undistortPoints(uv, self.K, self.dist, criteria=crit).reshape(-1, 2)
        if not self.has_distortion:
            K = self.K
            y = (uv[:, 0, 1] - K[1, 2]) / K[1, 1]
            x = (uv[:, 0, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
            return np.stack([x, y], axis=1)
        # OpenCV ignores the skew K[0, 1]; remove it here so that this inverts distort_normalized():
        # the distorted normalized y is (v - cy) / fy whatever the skew, and u - s*y = fx*x + cx.
        K = self.K
        if K[0, 1] != 0.0:
            uv = uv.copy()
            uv[:, 0, 0] -= K[0, 1] * (uv[:, 0, 1] - K[1, 2]) / K[1, 1]
            K = K.copy()
            K[0, 1] = 0.0
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x
            xn = cv2.undistortPointsIter(uv, K, self.dist, None, None, crit)
        else:  # OpenCV 5.x folded the criteria into undistortPoints
            xn = cv2.undistortPoints(uv, K, self.dist, R=None, P=None, criteria=crit)
        return xn.reshape(-1, 2)

    def back_project(self, uv_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates -> rays in the world.

        Args:
            uv_px: (N, 2) distorted pixel coordinates.
        Returns:
            origin_m: (3,) optical centre in world metres.
            dir_world: (N, 3) unit ray directions in world coordinates.
        """
        xn = self.undistort_points(uv_px)
        d_cam = np.hstack([xn, np.ones((xn.shape[0], 1))])
        d_world = d_cam @ self.R  # R^T d for each row
        d_world /= np.linalg.norm(d_world, axis=1, keepdims=True)
        return self.centre_m, d_world

    def undistort_image(self, image: np.ndarray) -> np.ndarray:
        """Remove lens distortion from an image of this camera (same K, same size)."""
        if not self.has_distortion:
            return image
        if self.fisheye:
            return cv2.fisheye.undistortImage(image, self.K, self.dist, Knew=self.K)
        return cv2.undistort(image, self.K, self.dist)

    def check_image_size(self, size_px: tuple[int, int], source: str) -> None:
        """Raise CalibrationError if images from ``source`` do not have this camera's size."""
        w, h = (int(size_px[0]), int(size_px[1]))
        if (w, h) != tuple(self.size_px):
            cw, ch = self.size_px
            raise CalibrationError(
                f"the calibration of {self.name} is for {cw}x{ch} but {source} delivers {w}x{h}: "
                "recalibrate or set the camera to the calibrated size"
            )


@dataclass(frozen=True, slots=True, eq=False)
class CameraStack:
    """Several cameras' projection parameters stacked into arrays, to work on all at once.

    The per-frame tracker projects every marker into every camera and undistorts every centroid;
    one set of array operations for all cameras costs a fraction of one :meth:`Camera.project` call
    per camera. The results equal those of the cameras' own methods (tests check it).

    Attributes:
        cameras: the cameras, in order.
        rotation: (C, 3, 3) float64 world -> camera rotations.
        t_m: (C, 3) float64 world -> camera translations, metres.
        K: (C, 3, 3) float64 intrinsic matrices, pixels.
        dist: (C, 8) float64 distortion coefficients, zero-padded to (k1, k2, p1, p2, k3, k4, k5, k6).
        distorted: (C,) bool, True for a camera with distortion (``Camera.has_distortion``).
        fisheye: (C,) bool, True for a camera with the fisheye model.
        focal_px: (C,) float64 mean focal length (fx + fy) / 2.
    """

    cameras: tuple[Camera, ...]
    rotation: np.ndarray = field(init=False, repr=False)
    t_m: np.ndarray = field(init=False, repr=False)
    K: np.ndarray = field(init=False, repr=False)
    dist: np.ndarray = field(init=False, repr=False)
    distorted: np.ndarray = field(init=False, repr=False)
    fisheye: np.ndarray = field(init=False, repr=False)
    focal_px: np.ndarray = field(init=False, repr=False)
    _rotation_t: np.ndarray = field(init=False, repr=False)
    _k: tuple[np.ndarray, ...] = field(init=False, repr=False)
    _t_col: np.ndarray = field(init=False, repr=False)
    _distorted_list: tuple[int, ...] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        cams = tuple(self.cameras)
        if not cams:
            raise CalibrationError("a camera stack needs at least one camera")
        dist = np.zeros((len(cams), 8))
        for c, cam in enumerate(cams):
            dist[c, : cam.dist.size] = cam.dist
        values = {
            "cameras": cams,
            "rotation": np.stack([c.R for c in cams]),
            "t_m": np.stack([c.t_m for c in cams]),
            "K": np.stack([c.K for c in cams]),
            "dist": dist,
            "distorted": np.array([c.has_distortion for c in cams]),
            "fisheye": np.array([c.fisheye for c in cams]),
            "focal_px": np.array([(c.K[0, 0] + c.K[1, 1]) / 2.0 for c in cams]),
            "_distorted_list": tuple(c for c, cam in enumerate(cams) if cam.has_distortion),
        }
        values["_rotation_t"] = np.ascontiguousarray(values["rotation"].transpose(0, 2, 1))
        K = values["K"]
        # the intrinsics fx, skew, cx, fy, cy of every camera as (C,) arrays, so that a call pays
        # for no indexing of K; the distorted cameras as a plain tuple
        values["_k"] = tuple(np.ascontiguousarray(K[:, i, j]) for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2)))
        values["_t_col"] = np.ascontiguousarray(values["t_m"][:, None, :])
        for name, value in values.items():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.cameras)

    def world_to_cameras(self, p_world_m: np.ndarray) -> np.ndarray:
        """(N, 3) world metres -> (N, C, 3) camera-frame metres of each point in each camera."""
        p = np.asarray(p_world_m, dtype=np.float64).reshape(-1, 3)
        return (np.matmul(p, self._rotation_t) + self._t_col).transpose(1, 0, 2)

    def rotate_to_cameras(self, v_world: np.ndarray) -> np.ndarray:
        """(N, 3) world vectors (e.g. velocities) -> (N, C, 3) the same in each camera's frame."""
        return np.matmul(np.asarray(v_world, dtype=np.float64).reshape(-1, 3), self._rotation_t).transpose(1, 0, 2)

    def project(self, p_world_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project points into every camera.

        Args:
            p_world_m: (N, 3) float64 world metres (NaN rows allowed).
        Returns:
            uv_px: (N, C, 2) float64 distorted pixel coordinates, NaN behind a camera (z <= 0), as
                :meth:`Camera.project`.
            depth_m: (N, C) float64 camera-frame z of each point in each camera.
        """
        # the same products as Camera.world_to_camera, camera by camera
        return self.project_camera_points(self.world_to_cameras(p_world_m))

    def project_camera_points(self, p_cam_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """As :meth:`project` for points already in each camera's frame: (N, C, 3) camera-frame
        metres (e.g. each camera seeing a moving point at its own instant) -> uv_px (N, C, 2),
        depth_m (N, C)."""
        p_cam = np.asarray(p_cam_m, dtype=np.float64).transpose(1, 0, 2)
        z = p_cam[..., 2]
        fx, skew, cx, fy, cy = (k[:, None] for k in self._k)  # (C, 1): broadcast over the points
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            x = p_cam[..., 0] / z
            y = p_cam[..., 1] / z
            if self._distorted_list:
                x, y = self._distort(x, y)
            uv = np.empty((p_cam.shape[1], len(self.cameras), 2))
            uv[..., 0] = (fx * x + skew * y + cx).T
            uv[..., 1] = (fy * y + cy).T
        depth = z.T
        uv[depth <= 1e-9] = np.nan
        return uv, depth

    def _distort(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(C, N) ideal normalized x, y -> distorted normalized x, y (Camera.distort_normalized)."""
        k1, k2, p1, p2, k3, k4, k5, k6 = (self.dist[:, i, None] for i in range(8))
        r2 = x * x + y * y
        radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        if self.fisheye.any():
            fx_, fy_ = fisheye_distort(x, y, self.dist[:, None, :4])
            xd = np.where(self.fisheye[:, None], fx_, xd)
            yd = np.where(self.fisheye[:, None], fy_, yd)
        # a camera without distortion keeps its coordinates bit for bit, as in Camera.project
        plain = ~self.distorted[:, None]
        return np.where(plain, x, xd), np.where(plain, y, yd)

    def undistort_points(self, uv_px: np.ndarray) -> np.ndarray:
        """(N, C, 2) distorted pixel coordinates -> (N, C, 2) ideal normalized coordinates.

        NaN (no observation) stays NaN. Cameras without distortion are inverted in closed form for
        all points at once; the others go through :meth:`Camera.undistort_points` (OpenCV).
        """
        uv = np.asarray(uv_px, dtype=np.float64)
        fx, skew, cx, fy, cy = self._k
        xn = np.empty(uv.shape)
        y = np.divide(uv[..., 1] - cy, fy, out=xn[..., 1])
        np.divide(uv[..., 0] - cx - skew * y, fx, out=xn[..., 0])
        for c in self._distorted_list:
            ok = np.isfinite(uv[:, c]).all(axis=1)
            if ok.any():
                xn[ok, c] = self.cameras[c].undistort_points(uv[ok, c])
        return xn
