"""The tracker withholds an angle that its markers cannot pin (simulated patient, against the truth).

In right_shoulder_extension the arm swings back straight while the forearm pronates and the inner
elbow marker MRE2 hides behind the body. With the elbow straight nothing measured shows the
elbow axis' turn about the arm: the marker's estimate serves the elbow centre (the shoulder's
angles), but the supination read from it was 10-20 degrees off (4 RMS since a weak hinge condition
is averaged in). The tracker reports no
supination there (``Estimator.axis_guessed``) and keeps every other angle (``rehab track``'s
angles CSV writes the tracker's angles).
"""

import numpy as np
import pytest

from tracking.angles import joint_angles
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.sim.validate import track_frames
from tracking.tracker import Tracker

SUPINATION = "right_forearm_supination"


@pytest.fixture(scope="module")
def run():
    settings = SimulationSettings(motion="right_shoulder_extension", size_px=(320, 240), fps=15.0)
    studio, motion = studio_from_settings(settings)
    with studio:
        tracker = Tracker(studio.cameras, studio.markerset, fps=15.0)
        frames = studio.play(motion, 15.0, noise_sigma=1.5, seed=0, with_visibility=False)
        return track_frames(tracker, ((sf.frames.images, sf.frames.time_s, sf.markers_m) for sf in frames))


def _rmse(values, truth):
    diff = (values - truth + 180.0) % 360.0 - 180.0
    return float(np.sqrt(np.nanmean(diff**2)))


def test_supination_is_withheld_where_the_straight_elbow_leaves_its_axis_free(run):
    from_positions = joint_angles(run.positions_m, run.names)
    truth = joint_angles(run.truth_m, run.names)
    reported = run.angles_deg
    withheld = np.isfinite(from_positions[SUPINATION]) & ~np.isfinite(reported[SUPINATION])
    assert withheld.sum() >= 15
    # the withheld values were the bad ones (10.2 degrees RMS off with the turn extrapolated, 4.2
    # since a weak hinge condition is averaged in); what is reported follows the truth
    withheld_rmse = _rmse(np.where(withheld, from_positions[SUPINATION], np.nan), truth[SUPINATION])
    reported_rmse = _rmse(reported[SUPINATION], truth[SUPINATION])
    assert withheld_rmse > 3.0 and reported_rmse < 2.0 and withheld_rmse > 2.0 * reported_rmse
    # only that angle: the others are the positions' (the estimate still gives the elbow centre);
    # the tracker computes one frame in Python floats and joint_angles the array in numpy, which
    # may round the last bit differently: 1e-9 degrees is far below any real difference
    for name, values in reported.items():
        if name != SUPINATION:
            np.testing.assert_allclose(values, from_positions[name], rtol=0, atol=1e-9, equal_nan=True)
    assert np.isfinite(reported["right_shoulder_flexion"][withheld]).all()
    # scored as lost frames of that angle (with those where a marker is lost), not in its RMSE
    score = run.score().angles[SUPINATION]
    assert score.lost == pytest.approx(np.mean(np.isfinite(truth[SUPINATION]) & ~np.isfinite(reported[SUPINATION])))
    assert score.rmse_deg < 2.0
