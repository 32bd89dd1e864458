"""Offscreen studio renderer: geometry against Camera.project, occlusion, visibility, sensor model.

Headless (EGL on Mesa llvmpipe); one GL context is shared by all tests.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calibration.camera import Camera
from calibration.errors import RehabError
from tracking.sim import renderer as renderer_module
from tracking.sim.renderer import (
    Lighting,
    OffscreenGLUnavailable,
    StudioRenderer,
    clip_from_camera,
    create_context,
    mannequin_scene,
    typical_studio_cameras,
)
from tracking.geometry.meshes import box, cone_band, icosphere
from tracking.sim.room import SEAT_TOP_M, build_room
from tracking.sim.scene import SceneFrame

FLAT = Lighting(ambient=1.0, directions=(), intensities=(), body_specular=0.0)
GREEN = (0.0, 200 / 255, 70 / 255)


@pytest.fixture(scope="module")
def ctx():
    try:
        context = create_context()
    except OffscreenGLUnavailable as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))
    yield context
    context.release()


def make_scene(spheres=(), capsules=(), ellipsoids=()) -> SceneFrame:
    """spheres: (centre, radius, rgb, marker_index); capsules: (p0, p1, r0, r1, rgb);
    ellipsoids: (centre, (3, 3) axes as columns, rgb)."""
    f3 = lambda rows: np.asarray(rows, np.float64).reshape(-1, 3)  # noqa: E731
    return SceneFrame(
        sphere_centre_m=f3([s[0] for s in spheres]),
        sphere_radius_m=np.asarray([s[1] for s in spheres], np.float64),
        sphere_rgb=f3([s[2] for s in spheres]).astype(np.float32),
        sphere_marker_index=np.asarray([s[3] for s in spheres], np.int32),
        capsule_p0_m=f3([c[0] for c in capsules]),
        capsule_p1_m=f3([c[1] for c in capsules]),
        capsule_r0_m=np.asarray([c[2] for c in capsules], np.float64),
        capsule_r1_m=np.asarray([c[3] for c in capsules], np.float64),
        capsule_rgb=f3([c[4] for c in capsules]).astype(np.float32),
        ellipsoid_centre_m=f3([e[0] for e in ellipsoids]),
        ellipsoid_axes_m=np.asarray([e[1] for e in ellipsoids], np.float64).reshape(-1, 3, 3),
        ellipsoid_rgb=f3([e[2] for e in ellipsoids]).astype(np.float32),
    )


def sphere_outline(cam: Camera, centre_m, radius_m: float) -> tuple[np.ndarray, float]:
    """Expected centroid (2,) and pinhole area (px^2) of a sphere's perspective outline ellipse.

    The outline cone {x : (x . C)^2 = (|C|^2 - r^2) |x|^2} meets the plane z = 1 in a conic whose
    centre solves M[:2, :2] c = -M[:2, 2]; an ellipse's centroid is its centre, and K (affine)
    preserves centroids. With distortion, the centre is mapped through the lens model (exact to
    second order in the outline size: keep those spheres small).
    """
    C = cam.world_to_camera(np.asarray(centre_m, float))[0]
    M = np.outer(C, C) - (C @ C - radius_m**2) * np.eye(3)
    A, b = M[:2, :2], M[:2, 2]
    c = np.linalg.solve(A, -b)
    # (x - c)^T A (x - c) = k with k = b^T A^-1 b - M[2, 2]: area pi |k| / sqrt(det A), times det K.
    k = b @ np.linalg.solve(A, b) - M[2, 2]
    area_px = np.pi * abs(k) / np.sqrt(np.linalg.det(A)) * cam.K[0, 0] * cam.K[1, 1]
    return cam.distort_normalized(c[None])[0], float(area_px)


def coverage_centroid(image: np.ndarray) -> tuple[np.ndarray, float]:
    """Centroid (u, v) and area in pixels of a flat white object on black: coverage = value / 255."""
    cov = image[..., 1].astype(np.float64) / 255.0
    v, u = np.mgrid[0 : image.shape[0], 0 : image.shape[1]]
    total = cov.sum()
    return np.array([(cov * u).sum(), (cov * v).sum()]) / total, total


# ----------------------------------------------------------------------------- pure geometry
def test_clip_from_camera_matches_camera_project():
    rng = np.random.default_rng(1)
    K = np.array([[410.0, 3.5, 161.2], [0.0, 398.0, 117.9], [0.0, 0.0, 1.0]])
    cam = Camera.from_rotation("c", (320, 240), K, np.zeros(4), np.eye(3), np.zeros(3))
    p = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50), rng.uniform(1, 5, 50)])
    clip = clip_from_camera(K, cam.size_px) @ np.vstack([p.T, np.ones(50)])
    ndc = clip[:3] / clip[3]
    window = (ndc[:2] + 1.0) / 2.0 * np.array([[320.0], [240.0]])
    uv = window.T - 0.5  # OpenCV pixel (0, 0) is the centre of window pixel (0, 0)
    np.testing.assert_allclose(uv, cam.project(p), atol=1e-9)
    assert np.all(np.abs(ndc[2]) < 1.0)


def test_meshes_are_wound_outward():
    for subdiv in (0, 1, 2):
        v, t = icosphere(subdiv)
        a, b, c = (v[t[:, k]].astype(float) for k in range(3))
        assert np.all(np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c) > 0)
        assert np.linalg.norm(v, axis=1).min() > 1.0  # inflated to the mean radius
    ring, t = cone_band(16)
    pts = ring.astype(float)  # reference cylinder: (cos, sin, t) is already a point
    a, b, c = (pts[t[:, k]] for k in range(3))
    radial = (a + b + c) / 3.0
    radial[:, 2] = 0.0
    assert np.all(np.einsum("ij,ij->i", np.cross(b - a, c - a), radial) > 0)
    pos, nrm = box((1.0, 2.0, 3.0), (0.5, 1.0, 2.0))
    tri = pos.reshape(-1, 3, 3)
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", face_n, nrm[::3]) > 0)


def test_room_has_chair_and_no_marker_coloured_clutter():
    import cv2

    room = build_room()
    pos = room.position_m
    seat = (np.abs(pos[:, 0]) < 0.24) & (np.abs(pos[:, 2]) < 0.24) & (np.abs(pos[:, 1] - SEAT_TOP_M) < 1e-6)
    assert seat.sum() >= 6, "the chair's seat top must be at y = 0.45 m around x = 0, z = 0"
    assert pos[:, 1].min() < 0.0 and pos[:, 1].max() > 2.5
    rgb = np.unique(np.round(room.rgb * 255).astype(np.uint8), axis=0)
    markers = np.array([[255, 214, 0], [0, 200, 70], [225, 0, 210]], np.uint8)
    hsv = cv2.cvtColor(rgb[None], cv2.COLOR_RGB2HSV)[0].astype(int)
    mhsv = cv2.cvtColor(markers[None], cv2.COLOR_RGB2HSV)[0].astype(int)
    for h, s, v in hsv:
        dh = np.minimum(np.abs(mhsv[:, 0] - h), 180 - np.abs(mhsv[:, 0] - h))
        assert not np.any((dh < 12) & (s > 150) & (v > 150)), "no bright saturated clutter may share a marker hue"


# ----------------------------------------------------------------------------- rendering
def test_images_shapes_orientation_and_bgr(ctx):
    cams = [
        Camera.look_at("a", (160, 120), 150.0, (0.0, 1.0, -2.0), (0.0, 1.0, 0.0)),
        Camera.look_at("b", (96, 64), 80.0, (2.0, 1.0, 0.0), (0.0, 1.0, 0.0)),
    ]
    red, blue = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    scene = make_scene(spheres=[((0.0, 1.3, 0.0), 0.05, red, -1), ((0.0, 0.7, 0.0), 0.05, blue, -1)])
    with StudioRenderer(cams, room=False, msaa=0, ctx=ctx, lighting=FLAT) as r:
        result = r.render(scene)
    assert [im.shape for im in result.images] == [(120, 160, 3), (64, 96, 3)]
    assert all(im.dtype == np.uint8 and im.flags.c_contiguous for im in result.images)
    for im in result.images:
        red_rows = np.nonzero(im[..., 2] > 200)[0]
        blue_rows = np.nonzero(im[..., 0] > 200)[0]
        assert red_rows.size and blue_rows.size
        assert red_rows.mean() < blue_rows.mean(), "+Y (the red ball above) must appear at the top"
        assert im[..., 1].max() == 0
    assert result.marker_pixels.shape == (2, 0)


@pytest.mark.parametrize("msaa", [0, 4])
def test_sphere_centroid_matches_projection(ctx, msaa):
    cam = Camera.from_rotation(
        "c", (320, 240), np.array([[300.0, 0.0, 158.3], [0.0, 302.0, 121.6], [0.0, 0.0, 1.0]]),
        np.zeros(4), np.eye(3), np.zeros(3),
    )
    targets = [(160.0, 120.0), (30.0, 25.0), (290.0, 215.0), (301.3, 18.7), (12.2, 230.4), (97.6, 143.1)]
    errors = []
    with StudioRenderer([cam], room=False, msaa=msaa, ctx=ctx, lighting=FLAT) as r:
        for u, v in targets:
            z = 2.0
            centre = np.array([(u - 158.3) / 300.0 * z, (v - 121.6) / 302.0 * z, z])
            scene = make_scene(spheres=[(centre, 0.025, (1.0, 1.0, 1.0), 0)])
            result = r.render(scene)
            got, area = coverage_centroid(result.images[0])
            expected, expected_area = sphere_outline(cam, centre, 0.025)
            errors.append(np.linalg.norm(got - expected))
            assert area == pytest.approx(expected_area, rel=0.03)
            assert result.marker_pixels[0, 0] == pytest.approx(expected_area, rel=0.1)
    assert max(errors) < 0.02, f"centroid errors {np.round(errors, 4)} px"


def test_sphere_centroid_with_lens_distortion(ctx):
    dist = (-0.28, 0.09, 0.0012, -0.0009, -0.01)
    cam = Camera.look_at("d", (320, 240), 280.0, (0.1, 1.2, -2.0), (0.0, 1.0, 0.0), dist=dist)
    # Ideal pinhole positions that the lens moves noticeably (corners included).
    targets = [(160.0, 120.0), (22.0, 18.0), (300.0, 224.0), (296.5, 16.2), (18.4, 221.7), (250.0, 60.0)]
    origin, _ = cam.back_project(np.zeros((1, 2)))
    errors, moved = [], []
    with StudioRenderer([cam], room=False, msaa=0, ctx=ctx, lighting=FLAT) as r:
        for uv in targets:
            _, ray = cam.back_project(np.array([uv]))
            centre = origin + 2.2 * ray[0]
            scene = make_scene(spheres=[(centre, 0.02, (1.0, 1.0, 1.0), 0)])
            result = r.render(scene)
            got, _ = coverage_centroid(result.images[0])
            expected, _ = sphere_outline(cam, centre, 0.02)
            ideal = (cam.K @ np.append(cam.world_to_camera(centre)[0][:2] / cam.world_to_camera(centre)[0][2], 1.0))[:2]
            moved.append(np.linalg.norm(expected - ideal))
            errors.append(np.linalg.norm(got - expected))
            assert result.marker_pixels[0, 0] > 0
    assert max(moved) > 5.0, "the test must exercise the distortion"
    assert max(errors) < 0.1, f"centroid errors {np.round(errors, 4)} px"


def test_marker_behind_body_is_hidden_and_counted_zero(ctx):
    cam = Camera.look_at("c", (320, 240), 300.0, (0.0, 1.0, -2.0), (0.0, 1.0, 0.0))
    trunk = ((0.0, 1.0, 0.0), np.diag([0.3, 0.35, 0.1]), (70 / 255, 95 / 255, 150 / 255))
    behind = ((0.02, 1.05, 0.3), 0.02, GREEN, 0)
    in_front = ((-0.05, 0.95, -0.4), 0.02, GREEN, 1)

    def green_pixels(image):
        b, g, r = (image[..., k].astype(int) for k in range(3))
        return (g > 60) & (g > r + 40) & (g > b + 25)

    for msaa in (0, 4):
        with StudioRenderer([cam], room=False, msaa=msaa, ctx=ctx) as r:
            hidden = r.render(make_scene(spheres=[behind], ellipsoids=[trunk]))
            assert not green_pixels(hidden.images[0]).any()
            assert hidden.marker_pixels.tolist() == [[0]]
            both = r.render(make_scene(spheres=[behind, in_front], ellipsoids=[trunk]))
        z = 2.0 - 0.4
        expected_area = np.pi * (300.0 * 0.02 / z) ** 2
        assert both.marker_pixels[0, 0] == 0
        assert both.marker_pixels[0, 1] == pytest.approx(expected_area, rel=0.15)
        mask = green_pixels(both.images[0])
        assert mask.sum() == pytest.approx(expected_area, rel=0.25)
        v, u = np.nonzero(mask)
        expected_uv = cam.project(np.array([in_front[0]]))[0]
        assert np.hypot(u.mean() - expected_uv[0], v.mean() - expected_uv[1]) < 0.5


def test_capsule_width_and_ellipsoid_extent(ctx):
    cam = Camera.look_at("c", (320, 240), 300.0, (0.0, 1.0, -2.0), (0.0, 1.0, 0.0))
    white = (1.0, 1.0, 1.0)
    with StudioRenderer([cam], room=False, msaa=0, ctx=ctx, lighting=FLAT) as r:
        # A horizontal capsule of radius 0.05 m at 2 m: 15 px half-width in the middle.
        image = r.render(make_scene(capsules=[((-0.3, 1.0, 0.0), (0.3, 1.0, 0.0), 0.05, 0.05, white)])).images[0]
        column = image[:, 160, 1] > 127
        assert column.sum() == pytest.approx(2 * 300.0 * 0.05 / 2.0, abs=1.5)
        # A rotated ellipsoid (semi-axes 0.2 and 0.05 along the image diagonals).
        c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
        axes = np.array([[0.2 * c, -0.05 * s, 0.0], [0.2 * s, 0.05 * c, 0.0], [0.0, 0.0, 0.05]])
        image = r.render(make_scene(ellipsoids=[((0.0, 1.0, 0.0), axes, white)])).images[0]
    mask = image[..., 1] > 127
    v, u = np.nonzero(mask)
    # Seen from the front (camera at -Z), world +x is image left and +y is up: the long axis
    # (+x, +y) runs up-left, i.e. along (u, v) = (-1, -1).
    _, vectors = np.linalg.eigh(np.cov(np.stack([u, v])))
    long_axis = vectors[:, 1] * np.sign(vectors[0, 1])
    np.testing.assert_allclose(long_axis, [np.sqrt(0.5), np.sqrt(0.5)], atol=0.02)
    assert mask.sum() == pytest.approx(np.pi * (300 * 0.2 / 2.0) * (300 * 0.05 / 2.0), rel=0.08)


def test_exposure_colour_cast_and_noise(ctx):
    cam = Camera.look_at("c", (128, 96), 120.0, (0.0, 1.0, -2.0), (0.0, 1.0, 0.0))
    grey = (0.5, 0.5, 0.5)
    scene = make_scene(ellipsoids=[((0.0, 1.0, 0.0), np.diag([2.0, 2.0, 0.1]), grey)])
    with StudioRenderer([cam], room=False, msaa=0, ctx=ctx, lighting=FLAT) as r:
        base = r.render(scene, with_visibility=False)
        assert base.marker_pixels is None
        centre = base.images[0][48, 64].astype(int)
        assert centre.tolist() == [128, 128, 128]
        cast = r.render(scene, exposure=1.5, colour_cast=(1.6, 1.0, 0.5)).images[0][48, 64].astype(int)
        np.testing.assert_allclose(cast, [0.5 * 1.5 * 0.5 * 255, 0.5 * 1.5 * 255, 255], atol=1.0)  # BGR, R clipped
        n1 = r.render(scene, noise_sigma=4.0, seed=7).images[0].astype(float)
        n1_again = r.render(scene, noise_sigma=4.0, seed=7).images[0].astype(float)
        n2 = r.render(scene, noise_sigma=4.0, seed=8).images[0].astype(float)
    np.testing.assert_array_equal(n1, n1_again)
    residual = n1 - base.images[0]
    # 0.5 * 255 = 127.5 rounds to 128 without noise, and to 127.5 on average with it.
    assert residual.mean() == pytest.approx(-0.5, abs=0.2)
    assert residual.std() == pytest.approx(4.0, rel=0.1)
    assert np.abs(np.corrcoef(residual[..., 0].ravel(), residual[..., 1].ravel())[0, 1]) < 0.05
    assert not np.array_equal(n1, n2)
    # With lens distortion the noise is added by the warp pass, after resampling.
    lens = Camera.look_at("d", (128, 96), 120.0, (0.0, 1.0, -2.0), (0.0, 1.0, 0.0), dist=(-0.2, 0.05, 0.0, 0.0))
    with StudioRenderer([lens], room=False, msaa=0, ctx=ctx, lighting=FLAT) as r:
        clean = r.render(scene).images[0].astype(float)
        noisy = r.render(scene, noise_sigma=3.0, seed=1).images[0].astype(float)
    assert (noisy - clean)[20:-20, 20:-20].std() == pytest.approx(3.0, rel=0.1)


def test_studio_preview_all_cameras_see_the_markers(ctx):
    cams = typical_studio_cameras((160, 120), dist=(-0.1, 0.02, 0.0, 0.0))
    with StudioRenderer(cams, ctx=ctx, msaa=0) as r:
        result = r.render(mannequin_scene(), noise_sigma=2.0)
    assert result.marker_pixels.shape == (4, 14)
    assert (result.marker_pixels > 0).sum(axis=1).min() >= 7
    for image in result.images:
        assert image.shape == (120, 160, 3)
        assert image.mean() > 60, "the room must be lit"


def test_release_and_errors(ctx, monkeypatch):
    cam = Camera.look_at("c", (64, 48), 60.0, (0.0, 1.0, -2.0), (0.0, 1.0, 0.0))
    with pytest.raises(RehabError):
        StudioRenderer([cam], msaa=3, ctx=ctx)
    with pytest.raises(RehabError):
        StudioRenderer([], ctx=ctx)
    r = StudioRenderer([cam], ctx=ctx, room=False)
    r.release()
    r.release()
    with pytest.raises(RehabError):
        r.render(SceneFrame.empty())

    def no_gl(**kwargs):
        raise RuntimeError("no display\nand no EGL")

    monkeypatch.setattr(renderer_module.moderngl, "create_standalone_context", no_gl)
    with pytest.raises(OffscreenGLUnavailable, match="libegl1") as info:
        StudioRenderer([cam])
    assert "\n" not in str(info.value)


def test_nothing_spills_into_a_neighbouring_viewport(ctx):
    near = Camera.look_at("near", (96, 64), 90.0, (0.0, 1.0, -1.0), (0.0, 1.0, 0.0))
    away = Camera.look_at("away", (96, 64), 90.0, (0.0, 1.0, -1.0), (0.0, 1.0, -5.0))
    white = (1.0, 1.0, 1.0)
    scene = make_scene(
        spheres=[((0.0, 1.0, 0.0), 0.6, white, -1), ((0.05, 1.05, -0.75), 0.02, GREEN, 0), ((0.0, 1.0, 0.0), 0.0, white, -1)],
        capsules=[((-3.0, 1.0, 0.2), (3.0, 1.0, 0.2), 0.3, 0.3, white)],
        ellipsoids=[((0.0, 0.5, 0.0), np.diag([0.8, 0.2, 0.8]), white)],  # behind "away"
    )
    with StudioRenderer([near, away, near], ctx=ctx, room=False, msaa=4) as r:
        result = r.render(scene)
    assert result.images[0].max(axis=2).min() > 0, "the near camera is filled by the big sphere"
    assert result.images[1].max() == 0, "the camera looking away sees nothing"
    np.testing.assert_array_equal(result.images[0], result.images[2])
    assert result.marker_pixels[:, 0].tolist()[1] == 0 and result.marker_pixels[0, 0] > 0


def test_empty_scene_and_many_instances(ctx):
    cam = Camera.look_at("c", (64, 48), 60.0, (0.0, 1.0, -2.0), (0.0, 1.0, 0.0))
    with StudioRenderer([cam], ctx=ctx, room=False) as r:
        assert r.render(SceneFrame.empty()).images[0].max() == 0
        rng = np.random.default_rng(0)
        spheres = [(rng.uniform(-0.5, 0.5, 3) + (0, 1, 0), 0.01, GREEN, i) for i in range(300)]
        result = r.render(make_scene(spheres=spheres))
    assert result.marker_pixels.shape == (1, 300)
    assert result.marker_pixels.sum() > 0
