"""The seed's hidden-marker experiment across the population: patients wearing misplaced markers
through a motion, and the report's figures (without rendering)."""

import numpy as np

from tracking.markerset import load_markerset
from tracking.sim.body import BodyModel
from tracking.sim.hidden_eval import PlacedBody, PopulationPatient, Score, DrawScore, _skin_bases, population_report
from tracking.sim.motions import load_motion


def test_a_misplaced_marker_stays_on_the_skin_and_moves_with_its_segment():
    ms = load_markerset()
    patient = PopulationPatient.draw(3, ms)
    size = np.linalg.norm(patient.skin_offsets_m, axis=1)
    assert size.max() <= 0.015 + 1e-9 and size.max() > 0.003
    placed, bare = PlacedBody(patient.dims, ms, patient.skin_offsets_m), BodyModel(patient.dims, ms)
    motion = load_motion("right_external_rotation", patient.dims)
    w1, e1 = ms.index("MRW1"), ms.index("MRE1")
    seen = []
    for t in np.linspace(0.0, motion.duration_s, 7):
        pose = motion.pose_at(float(t))
        off = placed.markers_m(pose) - bare.markers_m(pose)
        _, normal = bare.landmarks_m(pose)
        # along the skin, the drawn size, in every pose
        assert np.allclose(np.sum(off * normal, axis=1), 0.0, atol=1e-9)
        assert np.allclose(np.linalg.norm(off, axis=1), size, atol=1e-9)
        # fixed on the segment: the same coordinates along the forearm and upper arm axes
        c = bare.joint_centres_m(pose, "right")
        seen.append((np.dot(off[w1], (c["wrist"] - c["elbow"]) / np.linalg.norm(c["wrist"] - c["elbow"])),
                     np.dot(off[e1], (c["elbow"] - c["gh"]) / np.linalg.norm(c["elbow"] - c["gh"]))))
        # the render's balls are the same as the markers
        scene = placed.scene(pose)
        balls = scene.sphere_marker_index >= 0
        assert np.allclose(scene.sphere_centre_m[balls][np.argsort(scene.sphere_marker_index[balls])],
                           placed.markers_m(pose))
    seen = np.array(seen)
    assert np.ptp(seen, axis=0).max() < 1e-9, seen


def test_the_skin_directions_are_unit_and_perpendicular_to_the_normal():
    ms = load_markerset()
    body = BodyModel(PopulationPatient.draw(5, ms).dims, ms)
    pose = load_motion("reach", body.dims).pose_at(1.0)
    b = _skin_bases(body, pose)
    _, normal = body.landmarks_m(pose)
    assert np.allclose(np.linalg.norm(b, axis=2), 1.0)
    assert np.allclose(np.einsum("mkd,md->mk", b, normal), 0.0, atol=1e-12)
    assert np.allclose(np.einsum("md,md->m", b[:, 0], b[:, 1]), 0.0, atol=1e-12)


def _score(errors_mm, markers):
    e = np.array(errors_mm, dtype=float)
    return Score(len(e), e, np.array(markers, dtype=np.intp), 10, 10, np.zeros(10), 0.1)


def test_population_report_pools_events_and_spreads_over_patients():
    names = load_markerset().names
    w, e = names.index("MRW2"), names.index("MRE2")
    scores = [DrawScore(1, 15.0, _score([2.0, 10.0], [e, w]), _score([2.0, np.nan], [e, w])),
              DrawScore(2, 15.0, _score([4.0], [w]), _score([4.0], [w]))]
    text = population_report(scores, names)
    lines = text.splitlines()
    raw = next(line for line in lines if "all markers" in line)
    # pooled over the 3 events: 16/3; per patient: 6 and 4
    assert "3 events, pooled mean 5.3 mm, worst event 10.0 mm" in raw
    assert "worst 6.0" in raw
    gated = [line for line in lines if "all markers" in line][1]
    assert "withheld 1 (33 %)" in gated and "pooled mean 3.0 mm" in gated
    wrists = [line for line in lines if line.strip().startswith("wrists")][0]
    assert "2 events, pooled mean 7.0 mm" in wrists


def _moving_body(frames, step_m):
    """The seed marker set on a body translating by ``step_m`` per frame (world metres)."""
    from tracking.sim.body import BodyDimensions

    ms = load_markerset()
    dims = BodyDimensions.from_percentile(50, "female")
    p0 = BodyModel(dims, ms).markers_m(load_motion("reference", dims).pose_at(0.0))
    return ms, p0[None] + np.arange(frames)[:, None, None] * np.asarray(step_m)[None, None, :]


def test_a_whole_arm_hidden_for_a_moment_coasts_on_its_velocity():
    """All four chain markers of the right arm hidden: they keep their velocity (not left where
    they were) while 0.5 a t^2 stays within max_extrapolation_m; then the other estimators (and
    their gates) take over."""
    from tracking.hidden import Estimator, Method, estimator_config
    from tracking.marker_status import MarkerStatus

    ms, truth = _moving_body(20, [0.01, 0.0, 0.0])  # 10 mm per frame, 0.3 m/s at 30 frames/s
    chain = [ms.index(n) for n in ("MRE1", "MRE2", "MRW1", "MRW2")]
    est = Estimator(**estimator_config(ms), fps=30.0)  # 3 m/s^2, 15 mm: 6.7 mm after 2 frames, 15 after 3
    measured = np.ones(ms.n_markers, dtype=bool)
    for t in range(10):
        est.update(truth[t], measured)
    measured[chain] = False
    for t in range(10, 14):
        p, s = est.update(np.where(measured[:, None], truth[t], np.nan), measured)
        if t < 12:
            assert (s[chain] == MarkerStatus.ESTIMATED).all()
            assert (est.used[chain] == Method.CONSTANT_VELOCITY).all()
            assert np.abs(p[chain] - truth[t, chain]).max() < 1e-6
    assert not (est.used[chain] == Method.CONSTANT_VELOCITY).any()
    # the same gap without motion before it: the coasting markers stay put
    ms, still = _moving_body(20, [0.0, 0.0, 0.0])
    est = Estimator(**estimator_config(ms), fps=30.0)
    measured[:] = True
    for t in range(10):
        est.update(still[t], measured)
    measured[chain] = False
    p, s = est.update(np.where(measured[:, None], still[10], np.nan), measured)
    assert np.abs(p[chain] - still[10, chain]).max() < 1e-9


def test_the_flexion_speed_is_learned_through_fits_to_one_styloid():
    """One styloid hidden while the arm moves: the fits to the other pin flexion, so the arm's
    flexion speed is learned from them (steady-state Kalman gain) rather than decaying to 0."""
    from tracking.hidden import Estimator, estimator_config

    ms = load_markerset()
    from tracking.sim.body import BodyDimensions

    dims = BodyDimensions.from_percentile(50, "female")
    body = BodyModel(dims, ms)
    motion = load_motion("elbow_flexion_supination", dims)
    fps = 30.0
    w2 = ms.index("MRW2")
    est = Estimator(**estimator_config(ms), fps=fps)
    measured = np.ones(ms.n_markers, dtype=bool)
    speeds = []
    for i in range(60):
        pose = motion.pose_at(1.0 + i / fps)
        measured[w2] = i < 20
        est.update(np.where(measured[:, None], body.markers_m(pose), np.nan), measured)
        speeds.append(est.arms.velocity[0, 0] if est.layout.arms[0][0] == ms.index("MRW1") else est.arms.velocity[1, 0])
    speeds = np.abs(np.nan_to_num(np.array(speeds)))
    # the speed while both styloids were measured is kept (not decayed to a tenth) through 40 fits
    assert speeds[19] > 1e-3
    assert speeds[59] > 0.3 * speeds[19]
