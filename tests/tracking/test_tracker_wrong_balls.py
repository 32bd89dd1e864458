"""A marker is never measured on a wrong ball in one view (simulated patient, against the truth).

Markers of one colour come close in the images: the inner elbow and the inner wrist markers when
the arm is raised (shoulder_flexion), the inner elbow marker against the other arm's while the
trunk leans (trunk_lean_compensation). A window that holds the other ball, alone or merged with
the marker's own, gave a point 25-66 mm off that passed as measured, and a correct epicondyle
marker was then dropped on the broken elbow width: forearm supination 40-48 degrees off for a
few frames. The views' blob sizes, the leave-one-out check of three or more views and the order
in which markers are dropped on a broken segment length keep them out.
"""

import numpy as np
import pytest

from tracking.angles import joint_angles
from tracking.pipeline.views import view_to_drop
from tracking.pipeline.windows import one_ball_one_marker
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.sim.validate import track_frames
from tracking.marker_status import MarkerStatus
from tracking.tracker import Tracker


def _track(motion: str, seconds: float):
    settings = SimulationSettings(motion=motion, size_px=(320, 240), fps=15.0, seconds=seconds)
    studio, mot = studio_from_settings(settings)
    with studio:
        tracker = Tracker(studio.cameras, studio.markerset, fps=15.0)
        frames = studio.play(mot, 15.0, seconds=seconds, noise_sigma=1.5, seed=0, with_visibility=False)
        return track_frames(tracker, ((sf.frames.images, sf.frames.time_s, sf.markers_m) for sf in frames))


# (motion, seconds: the frames where a wrong ball was taken before, angle that it spoiled)
CASES = [
    ("trunk_lean_compensation", 7.0, "right_forearm_supination"),  # frames 44 and 90-91
    ("shoulder_flexion", 11.0, "left_forearm_supination"),  # frames 152-153 and 159
]


@pytest.fixture(scope="module", params=CASES, ids=[c[0] for c in CASES])
def tracked(request):
    motion, seconds, angle = request.param
    return _track(motion, seconds), angle


def test_measured_markers_are_on_their_own_ball(tracked):
    run, _ = tracked
    assert run.identified_at == 0 and run.swaps == 0
    err = np.linalg.norm(run.positions_m - run.truth_m, axis=-1)
    measured = run.status == MarkerStatus.MEASURED
    # partly hidden views leave a few millimetres; another ball in a view leaves 25 mm or more
    assert err[measured].max() < 0.02
    estimated = run.status == MarkerStatus.ESTIMATED
    assert err[estimated].max(initial=0.0) < 0.03


def test_forearm_supination_follows_the_truth(tracked):
    run, angle = tracked
    tracked_deg = joint_angles(run.positions_m, run.names)[angle]
    true_deg = joint_angles(run.truth_m, run.names)[angle]
    ok = np.isfinite(tracked_deg) & np.isfinite(true_deg)
    assert ok.sum() > 0.95 * np.isfinite(true_deg).sum()
    rmse = float(np.sqrt(np.mean((tracked_deg[ok] - true_deg[ok]) ** 2)))
    assert rmse < 3.0, rmse  # before: 7.7 and 3.2 degrees over these frames
    assert np.abs(tracked_deg[ok] - true_deg[ok]).max() < 15.0  # before: 40 and 30 degrees


def test_of_two_views_that_each_fit_the_third_the_one_off_the_prediction_is_dropped():
    """Cam 1 sees the ball whole; cam 2 sees it partly hidden (centroid 2 px off); cam 3 sees
    another ball of the colour 45 mm behind it along cam 1's ray, so cam 1 and cam 3 meet exactly
    and cam 1 and cam 2 within a pixel: the prediction decides (shoulder_flexion at 640x480 @30,
    MRE2, before: 45 mm off)."""
    from tracking.markerset import load_markerset
    from tracking.sim.rigs import load_rig

    tracker = Tracker(load_rig("ring4", (640, 480)), load_markerset())
    stack = tracker.setup.stack
    ball = np.array([0.25, 1.0, 0.1])
    centre1 = tracker.cameras[0].centre_m
    ray = (ball - centre1) / np.linalg.norm(ball - centre1)
    other = ball + 0.045 * ray
    uv_ball, _ = stack.project(ball[None])
    uv_other, _ = stack.project(other[None])
    uv = np.full((1, 4, 2), np.nan)
    uv[0, 0] = uv_ball[0, 0]
    uv[0, 1] = uv_ball[0, 1] + np.array([2.0, 0.0])  # partly hidden: shifted centroid
    uv[0, 2] = uv_other[0, 2]
    assert np.linalg.norm(uv_other[0, 0] - uv_ball[0, 0]) < 1e-6  # the same image in camera 1
    seen = np.isfinite(uv[0, :, 0])
    xn = stack.undistort_points(uv)[0]
    assert view_to_drop(tracker.setup, tracker.params, seen, xn, ball + 0.005, worst=1) == 2
    # predicted near the other ball, the same views give the other answer
    assert view_to_drop(tracker.setup, tracker.params, seen, xn, other, worst=1) == 1


def test_one_ball_is_one_markers_view():
    # the walking capture: seen along the hanging forearm, a camera has the hidden thumb-side
    # wrist marker behind the thumb-side elbow marker, a ball of the same colour; both windows
    # found that one ball, and with one other view the wrist marker was measured 20 mm off (frame
    # 45). The ball is now the view of the marker predicted nearer to it only.
    run = _track("qualisys_walk", 3.3)
    assert run.swaps == 0
    err = np.linalg.norm(run.positions_m - run.truth_m, axis=-1)
    measured = run.status == MarkerStatus.MEASURED
    assert err[measured].max() < 0.015, err[measured].max()


def test_a_shared_ball_goes_to_the_marker_whose_prediction_makes_it_likelier():
    """Two markers of one colour whose windows found the same blob in a camera: the walking
    capture at 320x240 @15 (frame 59) had the left radial styloid, estimated for a while (window
    uncertainty ~10 px), predicted 0.7 px from the lateral elbow marker's ball, which that marker,
    measured last frame (~5 px), predicted 2.2 px away: the wrist marker took the ball and was
    measured 25 mm off. The likelier prediction keeps the ball; with equal uncertainties, still
    the nearer one."""
    from tracking.markerset import load_markerset
    from tracking.sim.rigs import load_rig

    ms = load_markerset()
    tracker = Tracker(load_rig("ring4", (320, 240)), ms)
    elbow, wrist = ms.names.index("MLE1"), ms.names.index("MLW1")
    assert tracker.colour[elbow] == tracker.colour[wrist]
    m_count, n_cams = ms.n_markers, len(tracker.cameras)

    def winner(d_elbow_px, sigma_elbow_px, d_wrist_px, sigma_wrist_px):
        uv = np.full((m_count, n_cams, 2), 100.0)
        ball = np.array([115.2, 160.1])
        uv[elbow, 3] = ball + [d_elbow_px, 0.0]
        uv[wrist, 3] = ball + [0.0, d_wrist_px]
        sigma = np.full((m_count, n_cams), 2.0)
        sigma[elbow, 3], sigma[wrist, 3] = sigma_elbow_px, sigma_wrist_px
        found = np.full((m_count, n_cams, 2), np.nan)
        found[elbow, 3] = found[wrist, 3] = ball
        rad = np.where(np.isnan(found[..., 0]), np.nan, 3.0)
        one_ball_one_marker(tracker.setup, tracker.params, uv, sigma, np.full((m_count, n_cams), 3.0), found, rad)
        kept = [m for m in (elbow, wrist) if np.isfinite(found[m, 3, 0])]
        assert len(kept) == 1 and np.isfinite(rad[kept[0], 3])
        return kept[0]

    assert winner(2.2, 1.9, 0.7, 10.6) == elbow  # the walk's case: the sharp prediction wins
    assert winner(2.2, 2.0, 0.7, 2.0) == wrist  # equally sure: the nearer
    assert winner(0.7, 2.0, 2.2, 2.0) == elbow
