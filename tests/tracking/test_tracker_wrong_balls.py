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
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.sim.validate import track_frames
from tracking.status import MarkerStatus
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
