"""Identification through the tracker on rendered images: bodies x perturbations x rigs (a fast
subset of ``python -m tracking.sim.identify_sweep``), wrong poses, a marker unseen at
identification found later, re-identification on request and after a long loss."""

import numpy as np
import pytest

from tracking.colour.table import ColourTable
from tracking.markerset import load_markerset
from tracking.sim.body import BodyDimensions, reference_pose
from tracking.sim.identify_sweep import perturbed_poses, sweep, table_markdown, wrong_poses
from tracking.sim.rigs import load_rig
from tracking.sim.studio import Studio
from tracking.marker_status import MarkerStatus
from tracking.tracker import Tracker, TrackerParams, TrackingState

MS = load_markerset()
SIZE = (320, 240)


@pytest.fixture(scope="module")
def table():
    return ColourTable.build(MS.palette)


# --------------------------------------------------------------------------- the sweep, small


RIGS = ["front4", "tri3", "front3"]


@pytest.fixture(scope="module")
def small_sweep():
    """The redesigned 4- and 3-camera rigs, the smallest and largest body, the reference pose and
    three of its corners (all angles +10; all -10, which only the largest body can take: four or
    more markers seen by one camera only; a mixed one), and the three wrong poses."""
    ref = perturbed_poses(n_corners=4, n_random=0)
    # (each case's noise is seeded by its place in the list: the adducted pose goes last)
    poses = [ref[0], ref[1], ref[4]] + wrong_poses() + [ref[2]]
    return list(sweep(RIGS, [(5, "female"), (95, "male")], poses, size_px=SIZE, frames=2))


def test_reference_poses_are_named_right(small_sweep):
    """Every case is named, every name is right; the markers seen by one camera only (up to six
    with the arms close to the body) are left for re-acquisition."""
    ref = [r for r in small_sweep if not r.wrong_pose and not r.clash]
    assert len(ref) == len(RIGS) * (2 * 4 - 1)
    assert not [r for r in ref if r.wrong], table_markdown(ref)
    assert all(r.identified for r in ref), table_markdown(ref)
    assert all(len(r.unseen) <= 6 for r in ref), table_markdown(ref)
    adducted = [r for r in ref if r.pose.startswith("corner2")]
    assert len(adducted) == len(RIGS) and max(len(r.unseen) for r in adducted) >= 4


def test_wrong_poses_are_explained_never_named(small_sweep):
    bad = [r for r in small_sweep if r.wrong_pose]
    assert len(bad) == len(RIGS) * 2 * 3
    assert not [r for r in bad if r.identified], table_markdown(bad)
    assert all(r.message and "\n" not in r.message for r in bad), table_markdown(bad)
    explained = [r for r in bad if r.rule_message]
    assert len(explained) >= 0.75 * len(bad), table_markdown(bad)
    against = [r for r in explained if r.pose.startswith("arms against the body")]
    assert against and all("wrist is not outside the" in r.message or "elbow is not above" in r.message
                           for r in against), [r.message for r in against]


# --------------------------------------------------------------------------- unseen, re-identified


def _paint_out(images, cameras, centre_m, radius_m, keep_camera):
    """Grey out one ball in every camera but ``keep_camera`` (a marker seen by one camera only)."""
    out = []
    for c, (img, cam) in enumerate(zip(images, cameras)):
        img = img.copy()
        if c != keep_camera:
            u, v = cam.project(centre_m[None])[0]
            depth = cam.world_to_camera(centre_m[None])[0, 2]
            r = cam.K[0, 0] * radius_m / depth + 3.0
            yy, xx = np.mgrid[: img.shape[0], : img.shape[1]]
            img[(xx - u) ** 2 + (yy - v) ** 2 <= r * r] = (90, 90, 90)
        out.append(img)
    return out


@pytest.fixture(scope="module")
def ring4_studio():
    cameras = load_rig("ring4", SIZE)
    with Studio(cameras, MS, BodyDimensions.from_percentile(50, "female")) as studio:
        yield studio


def _frames(studio, n, seed=0):
    return [studio.render(reference_pose(), k, k / 15.0, noise_sigma=1.5, seed=seed + k, with_visibility=False)
            for k in range(n)]


def test_a_marker_unseen_at_identification_is_found_later(ring4_studio, table):
    """MRE2 seen by one camera only: the others are named at once, MRE2 as soon as it shows."""
    studio = ring4_studio
    tracker = Tracker(studio.cameras, MS, table=table, fps=15.0)
    m = MS.index("MRE2")
    frames = _frames(studio, 8)
    truth = frames[0].markers_m
    samples = []
    for k, sf in enumerate(frames):
        images = sf.frames.images
        if k < 3:
            images = _paint_out(images, studio.cameras, truth[m], MS.radius_m, keep_camera=0)
        samples.append(tracker.step(images))
    first = samples[0]
    assert first.state == TrackingState.TRACKING
    assert first.status[m] == MarkerStatus.LOST and np.isnan(first.positions_m[m]).all()
    others = np.arange(MS.n_markers) != m
    assert np.linalg.norm(first.positions_m[others] - truth[others], axis=1).max() < 0.01
    last = samples[-1]
    assert last.status[m] == MarkerStatus.MEASURED
    assert np.linalg.norm(last.positions_m - truth, axis=1).max() < 0.01


def test_reidentification_on_request(ring4_studio, table):
    studio = ring4_studio
    tracker = Tracker(studio.cameras, MS, table=table, fps=15.0)
    frames = _frames(studio, 3, seed=10)
    assert tracker.step(frames[0].frames.images).state == TrackingState.TRACKING
    tracker.step(frames[1].frames.images)
    tracker.reidentify()
    assert tracker.state == TrackingState.WAITING
    again = tracker.step(frames[2].frames.images)
    assert again.state == TrackingState.TRACKING
    assert np.linalg.norm(again.positions_m - frames[2].markers_m, axis=1).max() < 0.01


def test_reidentification_after_a_long_loss(ring4_studio, table):
    """Every marker gone (a covered lens, the patient out of view) for long: the tracker waits for
    the reference pose again and names the markers right."""
    studio = ring4_studio
    params = TrackerParams(reidentify_after=4)
    tracker = Tracker(studio.cameras, MS, table=table, params=params, fps=15.0)
    frames = _frames(studio, 2, seed=20)
    assert tracker.step(frames[0].frames.images).state == TrackingState.TRACKING
    blank = [np.zeros_like(img) for img in frames[0].frames.images]
    states = [tracker.step(blank).state for _ in range(60)]
    assert states[-1] == TrackingState.WAITING  # gave up and waits for the reference pose
    waiting_from = states.index(TrackingState.WAITING)
    assert waiting_from < 59
    back = tracker.step(frames[1].frames.images)
    assert back.state == TrackingState.TRACKING
    assert np.linalg.norm(back.positions_m - frames[1].markers_m, axis=1).max() < 0.01
