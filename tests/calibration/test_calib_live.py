"""Intrinsics from a live feed: the view selector's choices, and `rehab calibrate intrinsics --live` on a
video of a simulated helper moving the board (and on fake cameras that fail)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.board import Detection, detect_board
from calibration.camera import Camera
from calibration.errors import CalibrationError, RehabError
from calibration.view_selection import ViewSelector
from game.cli import main
from game.cli_calibrate import run_live_intrinsics
from game.scenes.calibrate import SimBoardFeed
from tests.fake_cameras import FakeDevice
from tracking.sim.calibration_material import DEFAULT_BOARD

SIZE = (320, 240)
LENS = (-0.12, 0.03, 0.0005, -0.0004)


def grid_detection(centre, scale=40.0, size=SIZE):
    j, i = np.mgrid[0:6, 0:9]
    uv = np.stack([i.ravel() - 4.0, j.ravel() - 2.5], axis=1) * scale / 9 + np.asarray(centre, float)
    return Detection(uv, size)


@pytest.fixture(scope="module")
def feed_frames():
    """A simulated helper holding the board still in 10 places (4 frames each), moving in between."""
    truth = Camera.look_at("cam1", SIZE, 330.0, (0.5, 1.6, -2.0), (0.0, 1.0, 0.0), dist=LENS)
    rows = np.linspace(70, 150, SIZE[1])[:, None, None]
    background = np.broadcast_to(rows + np.linspace(0, 30, SIZE[0])[None, :, None], (SIZE[1], SIZE[0], 3)).astype(np.uint8)
    feed = SimBoardFeed(truth, background, DEFAULT_BOARD, n_poses=10, hold=4, move=2, seed=2)
    frames = [feed.next_frame() for _ in range(len(feed._path))]
    return truth, frames


def test_a_view_is_kept_only_when_still_and_new():
    sel = ViewSelector(SIZE, min_views=4, target_coverage=0.5, max_views=10)
    a = grid_detection((100, 100))
    assert not sel.offer(a)                      # first sight: not yet known to be still
    assert sel.offer(grid_detection((100.5, 100)))  # held still: kept
    assert not sel.offer(grid_detection((100.6, 100)))  # same place again: not new
    assert not sel.offer(grid_detection((200, 150)))    # moving fast: not still
    assert sel.offer(grid_detection((200.3, 150)))      # still in a new place
    assert not sel.offer(None) and not sel.offer(grid_detection((200.3, 150)))
    prog = sel.progress()
    assert prog.n_views == 2 and not prog.done and 0 < prog.coverage < 0.5 and prog.hint.startswith("Move the board")


def test_enough_views_with_enough_coverage_end_the_collection():
    sel = ViewSelector(SIZE, min_views=4, target_coverage=0.5, max_views=6, still_px=None)
    for c in [(60, 50), (260, 50), (60, 190), (260, 190), (160, 120)]:
        sel.offer(grid_detection(c, scale=90))
    assert sel.progress().done and sel.progress().n_views in (4, 5)
    assert not sel.offer(grid_detection((100, 120), scale=90))  # done: nothing more is kept
    with pytest.raises(CalibrationError, match="keep one camera setting"):
        ViewSelector(SIZE, still_px=None).offer(grid_detection((100, 100), size=(640, 480)))


def test_live_intrinsics_from_a_video_of_the_board_moved_about(feed_frames, tmp_path, capsys):
    truth, frames = feed_frames
    videos = []
    for name in ("cam1", "cam2"):  # a calibration file holds two cameras or more: the same video twice
        path = tmp_path / f"{name}.avi"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 10.0, SIZE)
        for f in frames:
            writer.write(f)
        writer.release()
        videos.append(str(path))
    out = tmp_path / "intrinsics.toml"
    assert main(["calibrate", "intrinsics", "--live", videos[0], "--live", videos[1], "--board", "9x6", "--square-mm", "60",
                 "--views", "8", "--coverage", "60", "--out", str(out), "--save-views", str(tmp_path / "kept")]) == 0
    text = capsys.readouterr().out
    kept = [line for line in text.splitlines() if "cam1: view" in line]
    assert len(kept) >= 8 and "coverage" in kept[0]
    assert "cam1: view 1 kept" in kept[0]
    from calibration.files import load_calibration

    for cam in load_calibration(out):
        assert abs(cam.K[0, 0] / truth.K[0, 0] - 1) < 0.01
    saved = sorted((tmp_path / "kept" / "cam1").glob("*.png"))
    assert len(saved) == len(kept)
    # The saved views are sharp still frames: every one has the board.
    assert all(detect_board(cv2.imread(str(p)), DEFAULT_BOARD)[0] is not None for p in saved)


def test_live_views_are_the_still_distinct_ones(feed_frames):
    truth, frames = feed_frames
    device = FakeDevice(0.0, 1e6, frames=frames, stop_after=len(frames), mode="fail")
    (res,) = run_live_intrinsics([("cam1", device)], DEFAULT_BOARD, min_views=30, max_views=30, target_coverage=1.0,
                                 verbose=False)
    # 10 places held still; one view per place at most (the rounds repeat the places: not new).
    assert 6 <= len(res.per_view_rms_px) <= 10
    assert abs(res.camera.K[0, 0] / truth.K[0, 0] - 1) < 0.02


def test_a_camera_without_frames_or_boards_gives_a_one_line_error(tmp_path, capsys):
    blank = [np.full((SIZE[1], SIZE[0], 3), 100, np.uint8)]
    dead = FakeDevice(0.0, 1e6, frames=blank, stop_after=0, mode="fail")
    with pytest.raises(RehabError, match="0 board views kept from 0 frames before the camera delivered no frame"):
        run_live_intrinsics([("cam1", dead)], DEFAULT_BOARD, verbose=False)
    empty = FakeDevice(0.0, 1e6, frames=blank, stop_after=30, mode="fail")
    with pytest.raises(RehabError, match="from 30 frames before the camera stopped delivering frames"):
        run_live_intrinsics([("cam1", empty)], DEFAULT_BOARD, verbose=False)
    assert main(["calibrate", "intrinsics", "--board", "9x6", "--square-mm", "60", "--out", str(tmp_path / "x.toml")]) == 1
    assert "--live DEVICE" in capsys.readouterr().err
    assert main(["calibrate", "intrinsics", "--live", str(tmp_path / "none.avi"), "--board", "9x6", "--square-mm", "60",
                 "--out", str(tmp_path / "x.toml")]) == 1
    err = capsys.readouterr().err
    assert "cannot open this camera or video" in err and len(err.strip().splitlines()) == 1
