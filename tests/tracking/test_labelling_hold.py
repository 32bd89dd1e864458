"""The tracker with the hold of a still reference pose (TrackerParams.identify_hold_s): the markers are
named only once the patient has held still, the message shows the progress, a moving body is never
named; the issue's arm with the elbow crease forward is named in one colour and in four."""

import math

import numpy as np
import pytest

from tracking.markerset import load_markerset
from tracking.sim.body import reference_pose
from tracking.sim.population import ONE_COLOUR_RGB
from tracking.sim.rigs import load_rig
from tracking.sim.studio import SimulationSettings, Studio, studio_from_settings
from tracking.sim.body import BodyDimensions
from tracking.marker_status import MarkerStatus
from tracking.tracker import Tracker, TrackerParams, TrackingState

HELD = TrackerParams(identify_hold_s=0.2)
FOUR = load_markerset()


def _held(ms, rig, pose):
    cams = load_rig(rig, (640, 480))
    with Studio(cams, ms, BodyDimensions.from_percentile(50, "female")) as studio:
        tracker = Tracker(cams, ms, fps=15.0, params=HELD)
        out = []
        for k in range(tracker.hold_frames + 2):
            sf = studio.render(pose, k, k / 15.0, noise_sigma=1.5, seed=k, with_visibility=False)
            out.append((tracker.step(sf.frames.images, k / 15.0), sf.markers_m))
    return tracker.hold_frames, out


@pytest.mark.parametrize("ms, rig, abduction", [(FOUR, "ring4", 16.0), (FOUR.with_colours([ONE_COLOUR_RGB]), "corners4", 30.0)],
                         ids=["four colours", "one colour"])
def test_named_once_held_with_the_elbow_crease_forward(ms, rig, abduction):
    """The upper arm in neutral rotation (the thumb-side elbow marker ~1 cm in front of the inner one,
    which the rules' 10 mm ordering refused): named right after the hold (four colours with the
    inner elbow markers seen by one camera only; one colour where every marker is seen twice)."""
    pose = reference_pose(abduction_deg=abduction, external_rotation_deg=0.0, forearm_supination_deg=0.0)
    hold, out = _held(ms, rig, pose)
    assert hold == 3
    for k, (s, _) in enumerate(out[:hold]):
        assert s.state == TrackingState.WAITING and s.message == f"hold the reference pose still ({100 * k / hold:.0f} %)"
    s, truth = out[hold]
    assert s.state == TrackingState.TRACKING
    named = s.status == MarkerStatus.MEASURED
    assert named.sum() >= 12
    assert np.linalg.norm(s.positions_m[named] - truth[named], axis=1).max() < 0.01


def test_one_colour_with_an_unseen_partner_named_right_or_waits():
    """One colour, both inner elbow markers seen by one camera only: each lone thumb-side point could be
    either marker of its elbow but for the inner marker's single-camera ray, which the fit places the
    inner marker on. Named right (the inner markers join later), or waiting with a one-line message."""
    pose = reference_pose(external_rotation_deg=0.0, forearm_supination_deg=0.0)
    _, out = _held(FOUR.with_colours([ONE_COLOUR_RGB]), "ring4", pose)
    for s, truth in out:
        if s.state == TrackingState.TRACKING:
            named = s.status == MarkerStatus.MEASURED
            assert np.linalg.norm(s.positions_m[named] - truth[named], axis=1).max() < 0.01
        else:
            assert s.message and "\n" not in s.message


def test_a_moving_body_is_never_named():
    studio, motion = studio_from_settings(SimulationSettings(motion="shoulder_abduction", size_px=(320, 240), fps=15.0))
    with studio:
        tracker = Tracker(studio.cameras, studio.markerset, fps=15.0, params=HELD)
        states = []
        for k, t in enumerate(np.arange(2.0, 3.0, 1 / 15.0)):  # the arms rising
            sf = studio.render(motion.pose_at(t), k, t, noise_sigma=1.5, seed=k, with_visibility=False)
            s = tracker.step(sf.frames.images, t)
            states.append(s.state)
            assert s.state == TrackingState.WAITING and s.message.startswith("hold the reference pose still"), s.message


def test_the_fit_is_judged_once_per_pose():
    """While the points stay within a few millimetres (and the rays' colours stay), the judgement
    stands for up to max_age frame sets; a moved point, another count or ray judges again."""
    from tracking.labelling.still import Snapshot

    rng = np.random.default_rng(0)
    p, c = rng.uniform(-0.5, 0.5, (12, 3)), np.arange(12) % 4
    snap = Snapshot(step_m=0.004, max_age=5)
    assert not snap.same(p, c, np.array([1]))
    assert all(snap.same(p + rng.normal(scale=0.001, size=p.shape), c, np.array([1])) for _ in range(5))
    assert not snap.same(p, c, np.array([1]))          # older than max_age: judged again
    assert not snap.same(p, c, np.array([1, 2]))       # another ray
    q = p.copy()
    q[3] += 0.02
    assert not snap.same(q, c, np.array([1, 2]))       # a point moved
    assert not snap.same(q[:-1], c[:-1], np.array([1, 2]))  # a point fewer


def test_more_markers_without_a_point_than_the_fit_places_get_the_counts_without_a_search(monkeypatch):
    """Two cameras of front4 seeing 2 of 14 markers with four colours (reported-seed draw 100037, its
    webcam images): more markers without a point than the fit ever places, so the rules' search on
    the single-camera rays (5-15 s per frame set here, and no confident naming possible) is not run:
    the message gives the counts at once."""
    import tracking.pipeline.naming
    from tracking.sim.population import track_draws

    def no_search(*args, **kwargs):
        raise AssertionError("the rules' search on rays ran")

    monkeypatch.setattr(tracking.pipeline.naming, "try_identify", no_search)
    (result,) = track_draws([100037], size_px=(640, 480), fps=15.0, seconds=0.6)
    assert result.layout == "front4:2" and not result.one_colour
    assert math.isnan(result.identified_s)
    assert "of the 4 yellow markers are seen" in result.message
