"""The tracker's scoring against the truth (rehab validate --tracker), on poses of the body model
without rendering: which markers each angle reads, the per-angle RMSE over frames where its
markers are measured or estimated, and the shares of estimated and lost angle frames."""

import numpy as np
import pytest

from tracking.angles import joint_angles
from tracking.markerset import load_markerset
from tracking.sim.body import BodyDimensions, BodyModel
from tracking.sim.motions import load_motion
from tracking.sim.validate import angle_markers, score_tracking
from tracking.marker_status import MarkerStatus


@pytest.fixture(scope="module")
def motion_truth():
    ms = load_markerset("upper_limb_seated")
    dims = BodyDimensions.from_percentile(50, "female")
    body, motion = BodyModel(dims, ms), load_motion("elbow_flexion_supination", dims)
    truth = np.array([body.markers_m(motion.pose_at(i / 15.0)) for i in range(int(motion.duration_s * 15.0))])
    return ms, truth


def test_angle_markers_are_the_spec_definitions(motion_truth):
    ms, truth = motion_truth
    uses = angle_markers(truth, ms.names)
    names = lambda angle: {ms.names[i] for i in np.flatnonzero(uses[angle])}  # noqa: E731
    assert names("right_forearm_supination") == {"MRE1", "MRE2", "MRW1", "MRW2"}
    assert names("trunk_forward_lean") == {"MB", "MP"}
    assert {"MRE1", "MRE2", "MRW1", "MRW2"} <= names("right_elbow_flexion")
    assert not names("left_elbow_flexion") & {"MRE1", "MRE2", "MRW1", "MRW2"}


def test_angle_rmse_counts_measured_and_estimated_frames_and_reports_lost_ones(motion_truth):
    ms, truth = motion_truth
    t = len(truth)
    status = np.full(truth.shape[:2], MarkerStatus.MEASURED, dtype=np.uint8)
    pos = truth.copy()
    w2, e2 = ms.index("MRW2"), ms.index("MRE2")
    est = slice(10, 40)
    status[est, w2] = MarkerStatus.ESTIMATED
    pos[est, w2] += np.array([0.0, 0.0, 0.01])  # a 1 cm estimate error
    lost = slice(60, 70)
    status[lost, e2] = MarkerStatus.LOST
    pos[lost, e2] = np.nan
    acc = score_tracking(pos, status, truth, ms.names, frames=t, identified_at=0, swaps=0)

    true_sup = joint_angles(truth, ms.names)["right_forearm_supination"]
    sup = joint_angles(pos, ms.names)["right_forearm_supination"]
    diff = (sup - true_sup + 180.0) % 360.0 - 180.0
    a = acc.angles["right_forearm_supination"]
    assert a.frames == t
    assert a.rmse_deg == pytest.approx(np.sqrt(np.nanmean(diff**2)))
    assert a.rmse_deg > 0.1 and a.rmse_measured_deg == pytest.approx(0.0, abs=1e-9)
    assert a.rmse_estimated_deg == pytest.approx(np.sqrt(np.mean(diff[est] ** 2)))
    assert a.estimated == pytest.approx(30 / t) and a.lost == pytest.approx(10 / t)
    # the other arm is untouched; the right shoulder angles read the elbow, not the wrist
    assert acc.angles["left_forearm_supination"].lost == 0.0
    assert acc.angles["right_shoulder_abduction"].estimated == 0.0
    assert acc.angles["right_shoulder_abduction"].lost == pytest.approx(10 / t)
    assert acc.estimated == pytest.approx(30 / (t * ms.n_markers))
    assert acc.estimated_mean_mm == pytest.approx(10.0)
    assert acc.worst_angle()[0] in acc.angle_rmse_deg


def test_frames_where_an_angle_is_ill_conditioned_are_reported_apart(motion_truth):
    """Shoulder flexion (a planar angle) of an upper arm straight out to the side: 1 mm of elbow
    error turns it by tens of degrees. Such frames are counted and left out of the RMSE (kept in
    rmse_all_deg); other frames and angles are unaffected."""
    ms, truth = motion_truth
    truth = truth[:20].copy()
    s, e1, e2 = ms.index("MRS"), ms.index("MRE1"), ms.index("MRE2")
    trunk_x = truth[0, ms.index("MRH")] - truth[0, ms.index("MLH")]
    trunk_x /= np.linalg.norm(trunk_x)
    centre = 0.5 * (truth[:, e1] + truth[:, e2])
    move = truth[:, s] + 0.3 * trunk_x - centre  # the elbow centre 30 cm straight out from the shoulder
    truth[:5, e1] += move[:5]
    truth[:5, e2] += move[:5]
    assert np.all(np.isfinite(joint_angles(truth, ms.names)["right_shoulder_flexion"]))
    pos = truth.copy()
    pos[:, e1, 1] += 0.001  # 1 mm up in every frame
    status = np.full(truth.shape[:2], MarkerStatus.MEASURED, dtype=np.uint8)
    acc = score_tracking(pos, status, truth, ms.names, frames=20, identified_at=0, swaps=0)

    a = acc.angles["right_shoulder_flexion"]
    assert a.ill_conditioned == 5
    diff = (joint_angles(pos, ms.names)["right_shoulder_flexion"]
            - joint_angles(truth, ms.names)["right_shoulder_flexion"] + 180.0) % 360.0 - 180.0
    assert np.abs(diff[:5]).min() > 5.0  # what 1 mm does there
    assert a.rmse_deg == pytest.approx(np.sqrt(np.mean(diff[5:] ** 2))) and a.rmse_deg < 0.5
    assert a.rmse_all_deg == pytest.approx(np.sqrt(np.mean(diff**2)))
    assert acc.angles["right_elbow_flexion"].ill_conditioned == 0
    assert "right_shoulder_flexion 5 frames" in acc.summary()


def test_angles_the_tracker_withheld_count_as_lost_not_in_the_rmse(motion_truth):
    """The tracker reports no supination while an elbow marker's axis is a guess: given its
    reported angles, those frames are lost for that angle only, and out of its RMSE."""
    ms, truth = motion_truth
    t = len(truth)
    status = np.full(truth.shape[:2], MarkerStatus.MEASURED, dtype=np.uint8)
    pos = truth.copy()
    e2 = ms.index("MRE2")
    guessed = slice(20, 50)
    status[guessed, e2] = MarkerStatus.ESTIMATED
    pos[guessed, e2] += np.array([0.0, 0.0, 0.03])  # the axis turned by a guess
    reported = joint_angles(pos, ms.names)
    reported["right_forearm_supination"][guessed] = np.nan
    plain = score_tracking(pos, status, truth, ms.names, frames=t, identified_at=0, swaps=0)
    told = score_tracking(pos, status, truth, ms.names, frames=t, identified_at=0, swaps=0, angles_deg=reported)

    sup, sup_told = plain.angles["right_forearm_supination"], told.angles["right_forearm_supination"]
    assert sup.rmse_deg > 1.0 and sup.lost == 0.0
    assert sup_told.rmse_deg == pytest.approx(0.0, abs=1e-9) and sup_told.lost == pytest.approx(30 / t)
    assert told.angles["right_elbow_flexion"].rmse_deg == plain.angles["right_elbow_flexion"].rmse_deg > 0.1


def test_validate_population_prints_the_figures(capsys):
    """rehab validate --population: the labelling's figures per colour scheme and the rendered draws'."""
    from game.cli import main

    assert main(["validate", "--population", "6", "--rendered", "1", "--size", "320x240"]) == 0
    out = capsys.readouterr().out
    assert "labelling of the points (6 draws, seeds 100000-100005" in out
    assert "swaps" in out and "rendered and tracked (1 draws" in out and "per frame set" in out
