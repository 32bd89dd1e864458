"""The calibration scene on camera sources (videos through OpenCV, as a real camera is read) and with a
ChArUco board: views auto-captured from a board moved about, the focal length against the truth, a
ChArUco view partly out of the picture captured and drawn, the cameras released on leaving."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.camera import Camera
from calibration.charuco import CharucoBoard
from game.app import App, BaseScene, Settings
from game.input import Action, Press
from game.scenes.calibrate import CalibrateScene, CameraBoardFeed, SimBoardFeed, camera_feeds
from game.scenes.monitor import image_to_screen
from tests.fake_cameras import FakeDevice
from tracking.sim.calibration_material import DEFAULT_BOARD, BoardRaycaster, partial_poses
from tracking.sources.base import SourceError

SIZE = (640, 360)
CAMERA_PX = (320, 240)
LENS = (-0.12, 0.03, 0.0005, -0.0004)
TRUTH = Camera.look_at("cam1", CAMERA_PX, 330.0, (0.5, 1.6, -2.0), (0.0, 1.0, 0.0), dist=LENS)


def background():
    rows = np.linspace(70, 150, CAMERA_PX[1])[:, None, None]
    return np.broadcast_to(rows + np.linspace(0, 30, CAMERA_PX[0])[None, :, None], (CAMERA_PX[1], CAMERA_PX[0], 3)).astype(np.uint8)


class Clock:
    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def make_app(screen, feeds, board, tmp_path):
    clock = Clock()
    app = App(screen, Settings(show_fps=False, max_fps=0), clock=clock, sleep=lambda s: None, events=lambda: [])
    app.push(BaseScene())
    scene = CalibrateScene(feeds, board, out_path=tmp_path / "cal.toml", auto=True, threaded=False)
    app.push(scene)
    return app, scene, clock


@pytest.fixture(scope="module")
def videos(tmp_path_factory):
    """Two videos of a simulated helper moving the checkerboard in front of the true camera."""
    folder = tmp_path_factory.mktemp("feeds")
    paths = []
    for k in range(2):
        feed = SimBoardFeed(TRUTH, background(), DEFAULT_BOARD, n_poses=10, hold=3, move=2, seed=5 + k)
        path = folder / f"cam{k + 1}.avi"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 10.0, CAMERA_PX)
        for _ in range(len(feed._path)):
            writer.write(feed.next_frame())
        writer.release()
        paths.append(str(path))
    return paths


def test_the_scene_calibrates_cameras_read_through_opencv(open_headless, videos, tmp_path):
    from calibration.files import load_calibration

    feeds = camera_feeds(videos)
    assert [f.name for f in feeds] == ["cam1", "cam2"] and feeds[0].size_px == CAMERA_PX and feeds[0].truth is None
    app, scene, clock = make_app(open_headless(SIZE), feeds, DEFAULT_BOARD, tmp_path)
    for k in range(2):
        for _ in range(60):
            clock.now_s += 0.1
            app.frame()
            if len(scene.current.views) >= 8:
                break
        assert len(scene.current.views) >= 8
        app.dispatch(Press(Action.MONITOR))
        result = scene.current.result
        assert result is not None and result.rms_px < 0.5
        assert abs(result.camera.K[0, 0] / TRUTH.K[0, 0] - 1) < 0.015
        app.dispatch(Press(Action.SWITCH_ARM))
    app.dispatch(Press(Action.DOWN))   # S: the lens data, under their own name
    assert len(load_calibration(scene.lens_path)) == 2 and scene.lens_path.name == "intrinsics.toml"
    released = [f._capture for f in feeds]
    app.dispatch(Press(Action.BACK))
    assert not any(cap.isOpened() for cap in released)  # the cameras are free for the tracker again


def test_a_charuco_view_partly_out_of_the_picture_is_found_drawn_and_captured(open_headless, tmp_path):
    board = CharucoBoard.parse("10x7", 40.0)
    pose = partial_poses(TRUTH, board, 1, np.random.default_rng(1))[0]
    caster = BoardRaycaster(TRUTH, board)
    image = caster.draw(background(), pose)
    device = FakeDevice(0.0, 1e6, frames=[image])
    app, scene, clock = make_app(open_headless(SIZE), [CameraBoardFeed("cam1", device)], board, tmp_path)
    clock.now_s += 0.1
    app.frame()
    assert scene.detection is not None and scene.detection.ids is not None
    assert 6 <= len(scene.detection.ids) < board.n_corners
    assert len(scene.current.views) == 1   # auto-capture took the partial view
    app.frame()
    rgb = app.screen.read_rgb()
    true_uv = caster.corners_px(pose)[scene.detection.ids]
    xy = image_to_screen(true_uv, scene.image_rect, CAMERA_PX)
    green = [rgb[int(round(y - 0.5)), int(round(x - 0.5))] for x, y in xy]
    assert np.mean([g[1] > 170 and g[1] > g[0] + 60 and g[1] > g[2] + 60 for g in green]) > 0.8


def test_a_camera_that_delivers_nothing_is_refused_in_one_line():
    dead = FakeDevice(0.0, 1e6, stop_after=0, mode="fail")
    with pytest.raises(SourceError, match="cam1: the camera delivered no image"):
        CameraBoardFeed("cam1", dead)
    with pytest.raises(SourceError, match="cannot be opened"):
        camera_feeds(["/nonexistent/video.avi"])
