"""The guided calibration's logic: views linking camera pairs, the advice, the rig solved in the world
frame of the floor board, and the quality report in millimetres (exact and noisy projections)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.board import Checkerboard
from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.extrinsics import rig_errors
from calibration.guided import RigViews, quality_report, solve_rig
from tracking.sim.calibration_material import extrinsics_poses, seat_board_pose
from tests.calibration.test_calib_extrinsics import _projected_views
from tracking.sim.rigs import load_rig

BOARD = Checkerboard(9, 6, 0.06)


def _detections(cams, pose, noise_px, rng):
    """Exact corner projections (+ noise) of one board pose in every camera that sees it whole."""
    return _projected_views(cams, [pose], ["v"], noise_px, seed=int(rng.integers(1 << 30)))["v"]


@pytest.mark.parametrize("rig", ["ring4", "tri3"])
def test_views_link_the_cameras_and_the_rig_is_solved_with_a_report_in_mm(rig):
    cams = load_rig(rig, (640, 480))
    lens_only = [Camera(c.name, c.size_px, c.K, c.dist, np.zeros(3), np.zeros(3)) for c in cams]
    rng = np.random.default_rng(0)
    poses = extrinsics_poses(cams, BOARD, 3, np.random.default_rng(1))
    views = RigViews([c.name for c in cams])
    assert views.add(_detections(cams[:1], poses[0], 0.0, rng) + [None] * (len(cams) - 1)) is None  # one camera: no view
    advice = []
    for pose in poses:
        views.add(_detections(cams, pose, 0.1, rng))
        advice.append(views.advice())
    assert "both see it" in advice[0] and advice[-1].startswith("Every camera is linked") and views.linked()
    with pytest.raises(CalibrationError, match="no camera sees the floor board"):
        solve_rig(lens_only, BOARD, views, [None] * len(cams))
    seat = seat_board_pose(BOARD)
    res = solve_rig(lens_only, BOARD, views, _detections(cams, seat, 0.1, rng), origin_m=seat.t_m)
    pos, ang = rig_errors(res.cameras, cams)
    assert pos.max() < 5.0 and ang.max() < 0.2
    report = quality_report(res.cameras, BOARD, views.views, res.rms_px)
    assert report.verdict == "good" and report.length_error_mm.size >= 3 * len(poses)
    assert report.length_rms_mm < 1.0 and not report.advice
    assert report.lines()[0].startswith("Good")
    # the same views measured with a square 2 % too small: lengths off, the advice says so
    small = Checkerboard(9, 6, 0.0588)
    res2 = solve_rig(lens_only, small, views, _detections(cams, seat, 0.1, rng), origin_m=seat.t_m)
    bad = quality_report(res2.cameras, BOARD, views.views, res2.rms_px)
    assert bad.verdict != "good" and any("square" in a for a in bad.advice)


def test_unlinked_cameras_are_named():
    cams = load_rig("ring4", (640, 480))
    views = RigViews([c.name for c in cams])
    with pytest.raises(CalibrationError, match="both see it"):
        solve_rig(cams, BOARD, views, [None] * 4)
