"""The avatar on screen (headless EGL): pixels where the projected body is, colours by state."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from game.avatar.renderer import AvatarRenderer, look_at, mirror_view, perspective
from game.avatar.shapes import body_shapes
from game.avatar.skeleton import SEGMENTS, SkeletonTracker
from tracking.markerset import load_markerset
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose, reference_pose
from tracking.marker_status import MarkerStatus

MS = load_markerset()
W, H = 320, 240
BACKGROUND = (0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def gl():
    from tracking.sim.renderer import OffscreenGLUnavailable, create_context

    try:
        ctx = create_context()
    except OffscreenGLUnavailable as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))
    fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((W, H))], depth_attachment=ctx.depth_renderbuffer((W, H)))
    renderer = AvatarRenderer(ctx)
    yield ctx, fbo, renderer
    renderer.release()
    fbo.release()
    ctx.release()


def skeleton(pose: Pose, p: float = 50, sex: str = "male"):
    model = BodyModel(BodyDimensions.from_percentile(p, sex), MS)
    return SkeletonTracker(MS.names).update(model.markers_m(pose), np.ones(MS.n_markers, np.uint8))


def draw(gl, sk, view, proj, *, floor=False, background=False) -> np.ndarray:
    """(H, W, 3) uint8 RGB image, row 0 at the top."""
    ctx, fbo, renderer = gl
    fbo.use()
    fbo.clear(*BACKGROUND, 1.0, depth=1.0)
    if background:
        renderer.render_background()
    renderer.render(sk, view, proj, floor=floor)
    return np.frombuffer(fbo.read(components=3), np.uint8).reshape(H, W, 3)[::-1]


def project(view, proj, p_world) -> np.ndarray:
    """(N, 3) world points -> (N, 2) pixel (column, row from the top)."""
    p = np.atleast_2d(p_world)
    clip = (proj @ view @ np.hstack([p, np.ones((len(p), 1))]).T).T
    ndc = clip[:, :2] / clip[:, 3:4]
    return np.stack([(ndc[:, 0] + 1) / 2 * W, (1 - ndc[:, 1]) / 2 * H], axis=1)


def covered(img: np.ndarray, px: np.ndarray) -> np.ndarray:
    cols = np.clip(np.floor(px[:, 0]).astype(int), 0, W - 1)
    rows = np.clip(np.floor(px[:, 1]).astype(int), 0, H - 1)
    return img[rows, cols].astype(int).sum(axis=1) > 0


def body_points(sk) -> tuple[list[str], np.ndarray]:
    """Joint centres and points along the limbs, which must all be covered by the body."""
    names, pts = [], []
    for j in ("head", "neck", "sternum", "pelvis", "right_shoulder", "left_shoulder", "right_elbow", "left_elbow",
              "right_wrist", "left_wrist", "right_hand", "left_hand", "right_hip", "left_hip"):
        names.append(j)
        pts.append(sk.joint(j))
    for side in ("right", "left"):
        for a, b in (("shoulder", "elbow"), ("elbow", "wrist")):
            for t in (0.25, 0.5, 0.75):
                names.append(f"{side}_{a}-{b}@{t}")
                pts.append((1 - t) * sk.joint(f"{side}_{a}") + t * sk.joint(f"{side}_{b}"))
    return names, np.array(pts)


@pytest.mark.parametrize("pose", [
    reference_pose(),
    Pose(right=ArmPose.clinical(flexion_deg=90), left=ArmPose.clinical(abduction_deg=90)),
    Pose(trunk_forward_lean_deg=20, right=ArmPose.clinical(flexion_deg=45, elbow_flexion_deg=90, forearm_supination_deg=-80)),
], ids=["reference", "arms_raised", "lean_pronated"])
@pytest.mark.parametrize("mirror", [True, False])
def test_avatar_pixels_cover_the_projected_body_and_nothing_far_away(gl, pose, mirror):
    sk = skeleton(pose)
    view, proj = mirror_view(sk, W / H, yaw_deg=25.0, mirror=mirror)
    img = draw(gl, sk, view, proj)
    names, pts = body_points(sk)
    hit = covered(img, project(view, proj, pts))
    assert hit.all(), [n for n, h in zip(names, hit) if not h]
    # Far from the body: beside the head, above it, far below the chair, and the corners.
    up = np.array([0.0, 1.0, 0.0])
    far = np.array([sk.joint("head") + [0.6, 0.0, 0.0], sk.joint("head") - [0.6, 0.0, 0.0],
                    sk.joint("head") + 0.95 * up, sk.joint("pelvis") - 1.2 * up])
    assert not covered(img, project(view, proj, far)).any()
    corners = img[[0, 0, -1, -1], [0, -1, 0, -1]]
    assert (corners == 0).all()


def test_mirror_view_puts_the_patients_right_hand_on_the_right(gl):
    sk = skeleton(Pose(right=ArmPose.clinical(abduction_deg=90)))
    for mirror, right_side in ((True, True), (False, False)):
        view, proj = mirror_view(sk, W / H, mirror=mirror)
        px = project(view, proj, sk.joint("right_hand"))[0]
        assert (px[0] > W / 2) == right_side
        assert covered(draw(gl, sk, view, proj), px[None])[0]


def test_body_proportions_follow_the_patient(gl):
    """A small and a tall patient seen by the same camera: the tall one covers more pixels."""
    view = look_at(np.array([0.0, 1.0, -4.0]), np.array([0.0, 0.8, 0.0]))
    proj = perspective(35.0, W / H)
    small = (draw(gl, skeleton(reference_pose(), 5, "female"), view, proj).sum(axis=2) > 0).sum()
    tall = (draw(gl, skeleton(reference_pose(), 95, "male"), view, proj).sum(axis=2) > 0).sum()
    assert tall > 1.2 * small


def with_state(sk, segment: str, state: MarkerStatus):
    s = sk.state.copy()
    s[SEGMENTS.index(segment)] = state
    return dataclasses.replace(sk, state=s)


def test_estimated_and_lost_segments_change_their_pixels_only(gl):
    sk = skeleton(Pose(right=ArmPose.clinical(abduction_deg=60, elbow_flexion_deg=20)))
    view, proj = mirror_view(sk, W / H)
    normal = draw(gl, sk, view, proj).astype(int)
    estimated = draw(gl, with_state(sk, "right_forearm", MarkerStatus.ESTIMATED), view, proj).astype(int)
    lost = draw(gl, with_state(sk, "right_forearm", MarkerStatus.LOST), view, proj).astype(int)
    mid = project(view, proj, 0.5 * (sk.joint("right_elbow") + sk.joint("right_wrist")))[0].astype(int)
    c, r = mid
    n_px, e_px, l_px = normal[r, c], estimated[r, c], lost[r, c]
    # Amber: more red than blue and more so than the skin; lost: grey (channels close) and darker
    # than skin over the black background (translucent).
    assert e_px[0] - e_px[2] > n_px[0] - n_px[2] + 20
    assert np.ptp(l_px) < np.ptp(n_px) / 2
    assert 60 < l_px.sum() < n_px.sum()
    # The head and the trunk are untouched.
    head = project(view, proj, np.array([sk.joint("head"), sk.joint("sternum"), sk.joint("left_elbow")])).astype(int)
    for c, r in head:
        assert (normal[r, c] == estimated[r, c]).all() and (normal[r, c] == lost[r, c]).all()
    # Each state differs from normal only around the right forearm and hand.
    for img in (estimated, lost):
        rows, cols = np.nonzero(np.abs(img - normal).sum(axis=2) > 0)
        pts = project(view, proj, np.array([sk.joint("right_elbow"), sk.joint("right_hand")]))
        lo, hi = pts.min(axis=0) - 25, pts.max(axis=0) + 25
        assert len(rows) > 20
        assert ((cols >= lo[0]) & (cols <= hi[0]) & (rows >= lo[1]) & (rows <= hi[1])).all()


def test_background_and_floor_fill_the_frame(gl):
    sk = skeleton(reference_pose())
    view, proj = mirror_view(sk, W / H)
    with_floor = draw(gl, sk, view, proj, floor=True, background=True).astype(int)
    without = draw(gl, sk, view, proj, floor=False, background=True).astype(int)
    assert (with_floor.sum(axis=2) > 300).mean() > 0.95  # a light scene everywhere
    floor = np.abs(with_floor - without).sum(axis=2) > 0
    assert floor.mean() > 0.05
    # The darkest floor pixels are the contact shadows under the chair and the feet.
    shapes = body_shapes(sk)
    blobs = np.column_stack([shapes.shadow_blobs[:3, 0], np.full(3, shapes.floor_y_m), shapes.shadow_blobs[:3, 1]])
    brightness = np.where(floor, with_floor.sum(axis=2), 10**6)
    r, c = np.unravel_index(np.argmin(brightness), brightness.shape)
    assert np.min(np.hypot(*(project(view, proj, blobs) - [c, r]).T)) < 0.12 * W
    assert brightness[r, c] < np.percentile(with_floor.sum(axis=2)[floor], 50) - 60


def test_shapes_are_finite_and_right_handed():
    sh = body_shapes(skeleton(reference_pose()))
    assert np.isfinite(sh.ellipsoid_centre_m).all() and np.isfinite(sh.capsule_p0_m).all()
    assert (np.linalg.det(sh.ellipsoid_axes_m) > 0).all()
    assert sh.floor_y_m < sh.ellipsoid_centre_m[:, 1].min()


def test_bench_reports_a_frame_rate(gl):
    from game.avatar.fps_bench import avatar_fps

    fps = avatar_fps((160, 120), seconds=0.2, ctx=gl[0])
    assert 0.5 < fps < 10_000


@pytest.mark.parametrize("p, sex", [(5, "female"), (95, "male")])
def test_mirror_view_frames_the_whole_body_from_the_floor_to_a_raised_hand(p, sex):
    sk = skeleton(Pose(right=ArmPose.clinical(flexion_deg=180), left=ArmPose.clinical(abduction_deg=90)), p, sex)
    shapes = body_shapes(sk)
    for aspect in (16 / 9, 4 / 3, 3 / 4):
        view, proj = mirror_view(sk, aspect, yaw_deg=20.0)
        top = sk.joint("right_hand") + np.array([0.0, 0.06, 0.0])
        pts = np.vstack([sk.joints_m, top[None], shapes.ellipsoid_centre_m])
        clip = (proj @ view @ np.hstack([pts, np.ones((len(pts), 1))]).T).T
        ndc = clip[:, :2] / clip[:, 3:4]
        assert (np.abs(ndc) < 1.0).all()
        # Not lost in the frame either: the body spans most of the height.
        assert np.ptp(ndc[:, 1]) > 1.3


def test_live_avatar_draws_the_interpolated_patient_from_a_still_camera(gl):
    from game.avatar.live import LiveAvatar

    ctx, fbo, _ = gl
    model = BodyModel(BodyDimensions.from_percentile(50, "female"), MS)
    avatar = LiveAvatar(ctx, MS.names)
    status = np.ones(MS.n_markers, np.uint8)
    rng = np.random.default_rng(0)
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
    assert avatar.render((W, H), 0.0) is None  # no sample yet: background only
    cameras = []
    for k in range(12):  # 30 Hz samples, the right arm rising, 3 mm marker noise
        m = model.markers_m(Pose(right=ArmPose.clinical(abduction_deg=8.0 * k)))
        avatar.push(k / 30.0, m + rng.normal(0.0, 0.003, m.shape), status)
        fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
        pose = avatar.render((W, H), k / 30.0 + 0.01, background=False)
        cameras.append(avatar.camera(pose, W / H)[0])
    img = np.frombuffer(fbo.read(components=3), np.uint8).reshape(H, W, 3)[::-1]
    view, proj = avatar.camera(pose, W / H)
    assert covered(img, project(view, proj, np.array([pose.joint("right_hand"), pose.joint("head")]))).all()
    # Shown one sample interval late: the hand is where the sample before last put it.
    assert 70.0 < np.degrees(np.arctan2(*(pose.joint("right_elbow") - pose.joint("right_shoulder"))[[0, 1]] * [1, -1])) < 90.0
    # Marker noise does not shake the camera; moving the chair re-aims it.
    assert all(np.array_equal(c, cameras[1]) for c in cameras[1:])
    avatar.push(1.0, model.markers_m(Pose()) + [0.3, 0.0, 0.0], status)
    moved = avatar.render((W, H), 1.5, background=False)
    assert not np.array_equal(avatar.camera(moved, W / H)[0], cameras[-1])
    avatar.release()


@pytest.mark.parametrize("gradient", [True, False])
def test_background_resets_colour_and_depth(gl, gradient):
    from game.avatar.renderer import AvatarStyle

    ctx, fbo, _ = gl
    style = AvatarStyle(background_gradient=gradient)
    renderer = AvatarRenderer(ctx, style)
    sk = skeleton(reference_pose())
    view, proj = mirror_view(sk, W / H)
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 1.0, depth=0.0)  # a depth buffer that would hide everything
    renderer.render_background()
    renderer.render(sk, view, proj, floor=False)
    img = np.frombuffer(fbo.read(components=3), np.uint8).reshape(H, W, 3)[::-1].astype(int)
    top, bottom = np.array(style.background_top_rgb), np.array(style.background_bottom_rgb)
    if gradient:
        assert np.abs(img[0, 0] - 255 * top).max() <= 3 and np.abs(img[-1, 0] - 255 * bottom).max() <= 3
    else:
        assert np.abs(img[0, 0] - 255 * (top + bottom) / 2).max() <= 1
    head = project(view, proj, sk.joint("head")[None])[0].astype(int)
    assert np.abs(img[head[1], head[0]] - img[head[1], 0]).sum() > 30  # the body shows
    renderer.release()
