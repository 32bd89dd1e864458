"""The pinhole camera with OpenCV distortion: smoke -> errors -> round trips -> cross-check with OpenCV."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from calibration.camera import Camera, CameraStack, check_rotation, rotation_from_rvec, rvec_from_rotation
from calibration.errors import CalibrationError, RehabError

# ----------------------------------------------------------------------------- strategies
finite = dict(allow_nan=False, allow_infinity=False)


@st.composite
def rvecs(draw) -> np.ndarray:
    """Rodrigues vectors of every direction with angles in [0, pi)."""
    axis = np.array(draw(st.tuples(*[st.floats(-1, 1, **finite)] * 3)))
    if np.linalg.norm(axis) < 1e-3:
        axis = np.array([0.0, 1.0, 0.0])
    angle = draw(st.floats(0.0, 3.1, **finite))
    return axis / np.linalg.norm(axis) * angle


@st.composite
def intrinsics(draw, skew: bool = False) -> tuple[tuple[int, int], np.ndarray]:
    """(size_px, K) with focal lengths 200-3000 px and the principal point near the centre."""
    w = draw(st.integers(160, 1920))
    h = draw(st.integers(120, 1080))
    fx = draw(st.floats(200, 3000, **finite))
    fy = fx * draw(st.floats(0.9, 1.1, **finite))
    cx = (w - 1) / 2 + draw(st.floats(-0.1, 0.1, **finite)) * w
    cy = (h - 1) / 2 + draw(st.floats(-0.1, 0.1, **finite)) * h
    s = draw(st.floats(-0.01, 0.01, **finite)) * fx if skew else 0.0
    return (w, h), np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


@st.composite
def moderate_distortions(draw) -> np.ndarray:
    """k1, k2, p1, p2, k3 of ordinary lenses: the distortion is invertible for |x|, |y| <= 0.5."""
    k1 = draw(st.floats(-0.3, 0.3, **finite))
    k2 = draw(st.floats(-0.1, 0.1, **finite))
    p1 = draw(st.floats(-0.005, 0.005, **finite))
    p2 = draw(st.floats(-0.005, 0.005, **finite))
    k3 = draw(st.floats(-0.02, 0.02, **finite))
    n = draw(st.sampled_from([4, 5]))
    return np.array([k1, k2, p1, p2, k3][:n])


@st.composite
def cameras(draw, distorted: bool, skew: bool = False) -> Camera:
    size, K = draw(intrinsics(skew=skew))
    dist = draw(moderate_distortions()) if distorted else np.zeros(4)
    t = np.array(draw(st.tuples(*[st.floats(-3, 3, **finite)] * 3)))
    return Camera("cam", size, K, dist, draw(rvecs()), t)


@st.composite
def points_in_front(draw, n: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(n, 2) ideal normalized coordinates in [-0.5, 0.5] and (n,) depths 0.2-10 m."""
    xy = np.array(draw(st.lists(st.tuples(st.floats(-0.5, 0.5, **finite), st.floats(-0.5, 0.5, **finite)),
                                min_size=n, max_size=n)))
    z = np.array(draw(st.lists(st.floats(0.2, 10.0, **finite), min_size=n, max_size=n)))
    return xy, z


def world_points(cam: Camera, xy_norm: np.ndarray, z_m: np.ndarray) -> np.ndarray:
    """(N, 3) world metres of the points with camera-frame normalized coordinates xy and depth z."""
    p_cam = np.column_stack([xy_norm * z_m[:, None], z_m])
    return (p_cam - cam.t_m) @ cam.R  # R^T (p_cam - t) per row


def simple_camera(**overrides) -> Camera:
    args = dict(
        name="cam1",
        size_px=(640, 480),
        K=np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]]),
        dist=np.zeros(4),
        rvec=np.array([0.1, -2.9, 0.0]),
        t_m=np.array([0.05, 1.1, 2.3]),
    )
    args.update(overrides)
    return Camera(**args)


def assert_one_line(exc: pytest.ExceptionInfo, *fragments: str) -> None:
    msg = str(exc.value)
    assert "\n" not in msg, msg
    for fragment in fragments:
        assert fragment in msg, msg


# ----------------------------------------------------------------------------- smoke and shapes
def test_derived_quantities_are_consistent():
    cam = simple_camera()
    assert cam.size_px == (640, 480)
    np.testing.assert_allclose(cam.R @ cam.R.T, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(cam.R, rotation_from_rvec(cam.rvec))
    np.testing.assert_allclose(cam.extrinsic, np.hstack([cam.R, cam.t_m[:, None]]))
    np.testing.assert_allclose(cam.world_to_camera(cam.centre_m), np.zeros((1, 3)), atol=1e-15)
    p = np.array([[0.1, 1.0, 0.2], [-0.3, 1.2, -0.1]])
    ph = np.hstack([p, np.ones((2, 1))]) @ cam.P.T
    np.testing.assert_allclose(cam.project(p), ph[:, :2] / ph[:, 2:], rtol=1e-12)
    assert not cam.has_distortion


def test_camera_is_frozen_and_its_arrays_are_read_only():
    cam = simple_camera()
    with pytest.raises(dataclasses.FrozenInstanceError):
        cam.name = "other"  # type: ignore[misc]
    for arr in (cam.K, cam.dist, cam.rvec, cam.t_m, cam.R):
        with pytest.raises(ValueError):
            arr[0] = 1.0


def test_project_shapes_and_points_behind_the_camera():
    cam = simple_camera()
    assert cam.project(np.zeros((0, 3))).shape == (0, 2)
    assert cam.project(np.array([0.0, 1.0, 0.0])).shape == (1, 2)
    behind = cam.centre_m - 1.0 * cam.R[2]  # one metre behind the optical centre
    on_plane = cam.centre_m + 1.0 * cam.R[0]  # in the plane z_cam = 0
    uv = cam.project(np.stack([behind, on_plane, cam.centre_m + cam.R[2]]))
    assert np.all(np.isnan(uv[:2])) and np.all(np.isfinite(uv[2]))
    assert cam.undistort_points(np.zeros((0, 2))).shape == (0, 2)


# ----------------------------------------------------------------------------- validation errors
@pytest.mark.parametrize(
    "K, fragment",
    [
        (np.eye(2), "3x3"),
        (np.array([[600.0, 0, 320], [0, 600, 240], [0, 0, np.nan]]), "finite"),
        (np.array([[0.0, 0, 320], [0, 600, 240], [0, 0, 1]]), "fx, fy > 0"),
        (np.array([[600.0, 0, 320], [0, -600, 240], [0, 0, 1]]), "fx, fy > 0"),
        (np.array([[600.0, 0, 320], [0, 600, 240], [0, 0, 2]]), "[0,0,1]"),
        (np.array([[600.0, 0, 320], [0, 600, 240], [0.1, 0, 1]]), "[0,0,1]"),
        (np.array([[600.0, 0, 320], [3.0, 600, 240], [0, 0, 1]]), "[0,fy,cy]"),  # regression: was accepted
    ],
)
def test_bad_intrinsic_matrix_is_rejected(K, fragment):
    with pytest.raises(CalibrationError) as exc:
        simple_camera(K=K)
    assert_one_line(exc, "camera 'cam1'", fragment)


@pytest.mark.parametrize("n", [0, 1, 3, 6, 7, 9, 14])
def test_distortion_length_must_be_4_5_or_8(n):
    with pytest.raises(CalibrationError) as exc:
        simple_camera(dist=np.zeros(n))
    assert_one_line(exc, "distortions", f"got {n}")


@pytest.mark.parametrize(
    "field, value",
    [
        ("dist", [0.1, np.inf, 0.0, 0.0]),
        ("dist", [np.nan, 0.0, 0.0, 0.0]),
        ("rvec", [0.0, np.nan, 0.0]),
        ("t_m", [0.0, 0.0, np.inf]),
        ("rvec", [0.0, 0.0]),
        ("t_m", [0.0, 0.0, 1.0, 1.0]),
        ("size_px", (np.nan, 480)),  # regression: was a ValueError
        ("size_px", (640, np.inf)),
        ("size_px", (0, 480)),
        ("size_px", (640, -480)),
        ("size_px", (640, 480, 3)),
        ("size_px", 640),  # regression: was a TypeError
    ],
)
def test_non_finite_or_misshapen_values_are_rejected(field, value):
    with pytest.raises(CalibrationError) as exc:
        simple_camera(**{field: value})
    assert_one_line(exc, "camera 'cam1'")


def test_calibration_errors_are_rehab_errors():
    assert issubclass(CalibrationError, RehabError)


@pytest.mark.parametrize(
    "R",
    [
        np.diag([1.0, 1.0, -1.0]),  # a reflection: det -1
        2.0 * np.eye(3),  # scaled
        np.array([[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),  # sheared
        np.zeros((3, 3)),
    ],
)
def test_from_rotation_rejects_a_matrix_that_is_not_a_rotation(R):
    with pytest.raises(CalibrationError) as exc:
        Camera.from_rotation("cam2", (640, 480), simple_camera().K, np.zeros(4), R, np.zeros(3))
    assert_one_line(exc, "camera 'cam2'", "not a rotation")


@pytest.mark.parametrize("R", [np.eye(2), np.full((3, 3), np.nan)])
def test_from_rotation_rejects_a_misshapen_or_non_finite_matrix(R):
    with pytest.raises(CalibrationError) as exc:
        Camera.from_rotation("cam2", (640, 480), simple_camera().K, np.zeros(4), R, np.zeros(3))
    assert_one_line(exc, "camera 'cam2'", "finite 3x3")


@given(rvecs(), st.tuples(*[st.floats(-5, 5, **finite)] * 3))
def test_from_rotation_round_trips_rodrigues(rvec, t):
    R = rotation_from_rvec(rvec)
    cam = Camera.from_rotation("c", (640, 480), simple_camera().K, np.zeros(4), R, t)
    np.testing.assert_allclose(cam.R, R, atol=1e-12)
    np.testing.assert_allclose(rotation_from_rvec(rvec_from_rotation(R)), R, atol=1e-12)
    check_rotation(cam.R, "c")


def test_check_image_size_names_camera_source_and_fix():
    cam = simple_camera(name="cam2")
    cam.check_image_size((640, 480), "cam2.avi")
    with pytest.raises(CalibrationError) as exc:
        cam.check_image_size((1280, 720), "cam2.avi")
    assert_one_line(exc, "the calibration of cam2 is for 640x480 but cam2.avi delivers 1280x720", "recalibrate")
    with pytest.raises(CalibrationError):
        cam.check_image_size((480, 640), "cam2.avi")  # rotated frames are a mismatch too


# ----------------------------------------------------------------------------- look_at
@settings(max_examples=100, deadline=None)
@given(
    st.tuples(*[st.floats(-4, 4, **finite)] * 3),
    st.tuples(*[st.floats(-1, 1, **finite)] * 3),
    st.floats(200, 2000, **finite),
    st.sampled_from([(640, 480), (1280, 720), (641, 479)]),
)
def test_look_at_centres_the_target_with_world_up_appearing_up(eye, offset, f_px, size):
    eye = np.array(eye)
    target = eye + np.array(offset)
    distance = np.linalg.norm(target - eye)
    direction = (target - eye) / max(distance, 1e-12)
    if distance < 0.2 or abs(direction[1]) > 0.95:  # too close, or looking nearly straight up/down
        return
    cam = Camera.look_at("c", size, f_px, eye, target)
    R = cam.R
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(cam.centre_m, eye, atol=1e-9)
    w, h = size
    uv = cam.project(np.stack([target, target + [0.0, 0.05 * distance, 0.0]]))
    np.testing.assert_allclose(uv[0], [(w - 1) / 2, (h - 1) / 2], atol=1e-7)
    assert uv[1, 1] < uv[0, 1]  # +Y world up is up in the image (smaller v)
    assert abs(uv[1, 0] - uv[0, 0]) < 1e-6 * f_px  # straight up: no sideways drift


def test_look_at_patient_facing_camera_sees_patient_right_on_image_left():
    """A camera in front of the seated patient (who faces -Z) looks along +Z."""
    cam = Camera.look_at("front", (640, 480), 600.0, eye_m=[0.0, 1.2, -2.5], target_m=[0.0, 1.2, 0.0])
    uv = cam.project(np.array([[0.0, 1.2, 0.0], [0.2, 1.2, 0.0]]))  # +X is the patient's right
    assert uv[1, 0] < uv[0, 0]
    np.testing.assert_allclose(cam.R[2], [0.0, 0.0, 1.0], atol=1e-15)


def test_look_at_rejects_degenerate_directions():
    with pytest.raises(CalibrationError) as exc:
        Camera.look_at("top", (640, 480), 600.0, eye_m=[0.0, 3.0, 0.0], target_m=[0.0, 0.0, 0.0])
    assert_one_line(exc, "camera 'top'", "parallel to 'up'")
    with pytest.raises(CalibrationError) as exc:  # regression: produced NaN before the rotation check
        Camera.look_at("same", (640, 480), 600.0, eye_m=[1.0, 1.0, 1.0], target_m=[1.0, 1.0, 1.0])
    assert_one_line(exc, "camera 'same'", "distinct")


# ----------------------------------------------------------------------------- round trips
@settings(max_examples=200, deadline=None)
@given(st.data(), st.booleans())
def test_back_project_then_intersect_at_the_true_depth_recovers_the_point(data, distorted):
    cam = data.draw(cameras(distorted=distorted))
    xy, z = data.draw(points_in_front())
    p_world = world_points(cam, xy, z)
    uv = cam.project(p_world)
    assert np.all(np.isfinite(uv))
    origin, dirs = cam.back_project(uv)
    np.testing.assert_allclose(origin, cam.centre_m, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-12)
    depth_per_metre = dirs @ cam.R[2]  # camera z gained per metre along each ray
    p_back = origin + dirs * (z / depth_per_metre)[:, None]
    np.testing.assert_allclose(p_back, p_world, rtol=0, atol=1e-9)


@settings(max_examples=200, deadline=None)
@given(st.data(), st.booleans())
def test_undistort_points_inverts_distortion(data, skew):
    size, K = data.draw(intrinsics(skew=skew))
    dist = data.draw(moderate_distortions())
    cam = Camera("c", size, K, dist, np.zeros(3), np.zeros(3))
    xy, _ = data.draw(points_in_front())
    uv = cam.distort_normalized(xy)
    np.testing.assert_allclose(cam.undistort_points(uv), xy, rtol=0, atol=1e-11)


def test_undistort_points_honours_skew_with_distortion():
    """Regression: OpenCV ignores K[0, 1], so undistort_points used to disagree with project."""
    K = np.array([[600.0, 6.0, 320.0], [0.0, 610.0, 240.0], [0.0, 0.0, 1.0]])
    cam = Camera("c", (640, 480), K, [0.1, -0.05, 0.001, 0.002, 0.01], np.zeros(3), np.zeros(3))
    xy = np.array([[0.3, -0.2], [-0.4, 0.35], [0.0, 0.0]])
    np.testing.assert_allclose(cam.undistort_points(cam.distort_normalized(xy)), xy, atol=1e-12)


def test_undistort_points_inverts_the_rational_model():
    cam = simple_camera(dist=[0.2, -0.1, 0.001, -0.002, 0.01, 0.05, -0.02, 0.005])
    xy = np.random.default_rng(3).uniform(-0.5, 0.5, (200, 2))
    np.testing.assert_allclose(cam.undistort_points(cam.distort_normalized(xy)), xy, atol=1e-11)


def test_undistort_points_passes_nan_through():
    cam = simple_camera(dist=[0.1, 0.0, 0.0, 0.0])
    xn = cam.undistort_points(np.array([[np.nan, np.nan], [320.0, 240.0]]))
    assert np.all(np.isnan(xn[0]))
    np.testing.assert_allclose(xn[1], [0.0, 0.0], atol=1e-15)


# ----------------------------------------------------------------------------- cross-check with OpenCV
@settings(max_examples=100, deadline=None)
@given(st.data(), st.sampled_from([0, 4, 5, 8]))
def test_project_matches_cv2_project_points(data, n_dist):
    cam = data.draw(cameras(distorted=False))
    if n_dist:
        coeffs = data.draw(st.lists(st.floats(-0.1, 0.1, **finite), min_size=n_dist, max_size=n_dist))
        cam = Camera(cam.name, cam.size_px, cam.K, coeffs, cam.rvec, cam.t_m)
    xy, z = data.draw(points_in_front())
    p_world = world_points(cam, xy, z)
    uv_cv, _ = cv2.projectPoints(p_world, cam.rvec, cam.t_m, cam.K, cam.dist)
    np.testing.assert_allclose(cam.project(p_world), uv_cv.reshape(-1, 2), rtol=0, atol=1e-8)


def test_undistort_image_keeps_an_undistorted_image_and_removes_distortion():
    img = np.zeros((480, 640, 3), np.uint8)
    assert simple_camera().undistort_image(img) is img
    cam = simple_camera(dist=[-0.2, 0.05, 0.0, 0.0])
    out = cam.undistort_image(img)
    assert out.shape == img.shape and out.dtype == np.uint8


# ----------------------------------------------------------------------------- with_size
@settings(max_examples=100, deadline=None)
@given(st.data(), st.booleans(), st.sampled_from([0.5, 2.0, 1.5, 0.25]), st.sampled_from([0.5, 2.0, 1.5, 0.25]))
def test_with_size_scales_pixel_coordinates_about_pixel_centres(data, distorted, sx, sy):
    cam = data.draw(cameras(distorted=distorted, skew=True))
    w, h = cam.size_px
    new_size = (round(w * sx), round(h * sy))
    sx, sy = new_size[0] / w, new_size[1] / h
    scaled = cam.with_size(new_size)
    assert scaled.size_px == new_size
    assert scaled.name == cam.name and scaled.fisheye == cam.fisheye
    np.testing.assert_array_equal(scaled.dist, cam.dist)
    np.testing.assert_array_equal(scaled.R, cam.R)
    xy, z = data.draw(points_in_front())
    p_world = world_points(cam, xy, z)
    uv = cam.project(p_world)
    # Pixel (0, 0) covers [-0.5, 0.5]^2, so the image edge -0.5 stays put and centres scale about it.
    expected = (uv + 0.5) * [sx, sy] - 0.5
    np.testing.assert_allclose(scaled.project(p_world), expected, rtol=0, atol=1e-8)
    back = scaled.with_size(cam.size_px)
    np.testing.assert_allclose(back.K, cam.K, rtol=1e-12, atol=1e-9)


def test_with_size_maps_image_corners_to_image_corners():
    cam = simple_camera(K=np.array([[600.0, 0.0, 319.5], [0.0, 600.0, 239.5], [0.0, 0.0, 1.0]]))
    half = cam.with_size((320, 240))
    np.testing.assert_allclose(half.K[:2, 2], [159.5, 119.5])
    np.testing.assert_allclose(np.diag(half.K)[:2], [300.0, 300.0])


def test_with_size_rejects_a_bad_size():
    with pytest.raises(CalibrationError) as exc:
        simple_camera().with_size((0, 480))
    assert_one_line(exc, "camera 'cam1'", "size")


@pytest.mark.parametrize("base_rad", [0.0, np.pi])
@pytest.mark.parametrize("offset_rad", [0.0, 1e-9, 1e-6, 1e-5, 1e-4])
def test_rvec_from_rotation_is_exact_near_identity_and_half_turn(base_rad, offset_rad):
    """Regression: cv2.Rodrigues snapped rotations within 1e-5 rad of these to them (2e-5 rad error)."""
    rng = np.random.default_rng(7)
    for _ in range(20):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        R = rotation_from_rvec(axis * (base_rad - offset_rad if base_rad else offset_rad))
        np.testing.assert_allclose(rotation_from_rvec(rvec_from_rotation(R)), R, rtol=0, atol=1e-14)


def test_from_rotation_keeps_a_tiny_tilt():
    tilt = rotation_from_rvec([2e-6, 0.0, 0.0])
    cam = Camera.from_rotation("c", (640, 480), simple_camera().K, np.zeros(4), tilt, [0.0, 0.0, 3.0])
    np.testing.assert_allclose(cam.rvec, [2e-6, 0.0, 0.0], rtol=1e-9, atol=0)


# ----------------------------------------------------------------------------- several cameras at once
@settings(max_examples=25, deadline=None)
@given(st.data())
def test_camera_stack_projects_and_undistorts_like_each_camera(data):
    """CameraStack (the tracker's fast path) gives each camera's own numbers (to 1e-9 px and m: the
    batched and the per-camera arithmetic may round the last bit differently)."""
    cams = [data.draw(cameras(distorted=d, skew=k)) for d, k in ((False, False), (True, False), (True, True),
                                                                  (False, True))]
    cams.append(simple_camera(dist=np.array([0.1, -0.05, 0.001, -0.002, 0.01, 0.02, 0.0, 0.001])))  # rational
    stack = CameraStack(cams)
    xy, z = data.draw(points_in_front(n=6))
    p = np.vstack([world_points(cams[1], xy, z), [[np.nan] * 3], cams[0].centre_m + [0.0, 0.0, 0.0]])
    uv, depth = stack.project(p)
    assert uv.shape == (len(p), len(cams), 2) and depth.shape == (len(p), len(cams))
    for c, cam in enumerate(cams):
        np.testing.assert_allclose(uv[:, c], cam.project(p), rtol=0, atol=1e-9)
        np.testing.assert_allclose(depth[:, c], cam.world_to_camera(p)[:, 2], rtol=0, atol=1e-9)
        np.testing.assert_allclose(stack.world_to_cameras(p)[:, c], cam.world_to_camera(p), rtol=0, atol=1e-9)
    xn = stack.undistort_points(uv)
    for c, cam in enumerate(cams):
        seen = np.isfinite(uv[:, c]).all(axis=1)
        assert np.isnan(xn[~seen, c]).all()
        np.testing.assert_allclose(xn[seen, c], cam.undistort_points(uv[seen, c]), rtol=0, atol=1e-12)
    assert stack.distorted.tolist() == [c.has_distortion for c in cams]
    np.testing.assert_array_equal(stack.focal_px, [(c.K[0, 0] + c.K[1, 1]) / 2 for c in cams])


def test_camera_stack_needs_a_camera():
    with pytest.raises(CalibrationError, match="at least one camera"):
        CameraStack(())
