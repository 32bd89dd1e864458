"""The layout grid search's scoring and candidate pairs (pure numpy; no rendering)."""

import numpy as np

from tracking.sim.layout_search import Place, best_layouts, layout_cost, mirrored_pairs, place_camera
from tracking.sim.rigs import load_rig


def test_a_marker_is_seen_with_one_whole_view_and_a_second_good_one():
    # one layout of 3 cameras, 2 cases, 3 markers: (L, K, cases, markers)
    vis = np.zeros((1, 3, 2, 3))
    vis[0, :, 0, 0] = [1.0, 0.85, 0.0]   # whole + good: seen
    vis[0, :, 0, 1] = [0.85, 0.85, 0.0]  # no whole view: not seen
    vis[0, :, 0, 2] = [0.8, 0.8, 0.8]    # three good views: seen
    vis[0, :, 1, :] = [[1.0], [0.5], [0.0]]  # second view too small: all three unseen in case 1
    over, missed, second = layout_cost(vis, max_unseen=2)
    assert missed.tolist() == [4] and over.tolist() == [1]
    assert second[0] == 0.0


def test_pairs_are_mirrored_and_at_different_heights():
    places = [Place(a, 2.0, h) for a in (-45.0, 45.0, 180.0) for h in (1.5, 1.6, 1.9)]
    pairs = mirrored_pairs(places, min_height_step_m=0.2)
    assert pairs
    for i, j in pairs:
        assert places[i].azimuth_deg == -places[j].azimuth_deg == 45.0
        assert abs(places[i].height_m - places[j].height_m) >= 0.2 - 1e-9


def test_the_best_layout_sees_what_the_others_miss():
    places = [Place(a, 2.0, h) for a in (-45.0, 45.0, -135.0, 135.0) for h in (1.5, 1.9)]
    rng = np.random.default_rng(0)
    vis = rng.uniform(0.0, 0.5, (4, len(places), 5))  # (cases, places, markers)
    wanted = [places.index(Place(45.0, 2.0, 1.5)), places.index(Place(-45.0, 2.0, 1.9)),
              places.index(Place(135.0, 2.0, 1.9)), places.index(Place(-135.0, 2.0, 1.5))]
    # each marker is seen well by two of the wanted places only: all four are needed
    for m, (a, b) in enumerate([(0, 1), (0, 1), (2, 3), (2, 3), (0, 2)]):
        vis[:, [wanted[a], wanted[b]], m] = 1.0
    over, missed, _, idx = best_layouts(vis, places, 4, top=1)[0]
    assert (over, missed) == (0, 0) and sorted(idx) == sorted(wanted)


def test_places_make_the_same_cameras_as_rig_files():
    cam = load_rig("ring4", (640, 480))[1]  # azimuth 40, 2.0 m, 1.85 m high, 52 degrees
    again = place_camera(Place(40.0, 2.0, 1.85), (640, 480), 52.0, (0.0, 0.95, 0.0))
    assert np.allclose(cam.K, again.K) and np.allclose(cam.centre_m, again.centre_m)
    assert np.allclose(cam.R, again.R, atol=1e-12)
