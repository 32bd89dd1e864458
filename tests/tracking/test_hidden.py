"""Hidden-marker estimation: each estimator on synthetic motion with known truth, the Estimator's
status handling, and the seed's experiment (MRE2 behind the elbow) on the simulated patient."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tracking.hidden import (
    Estimator,
    Forearm,
    Hinge,
    Method,
    ForearmShape,
    constant_velocity,
    elbow_frame,
    fit_forearm,
    forearm_angles,
    forearm_markers,
    estimator_config,
    hinge_axis,
    kabsch,
    neighbour_motion,
    rigid_estimate,
    trunk_rotation,
    wrist_centre,
)
from tracking.markerset import load_markerset
from tracking.marker_status import MarkerStatus

LOST, MEASURED, ESTIMATED = MarkerStatus.LOST, MarkerStatus.MEASURED, MarkerStatus.ESTIMATED


def rotation(axis, angle_rad):
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle_rad) * k + (1 - math.cos(angle_rad)) * k @ k


def random_rotation(rng):
    return rotation(rng.normal(size=3), rng.uniform(-math.pi, math.pi))


# A small rigid body (4 markers, 10-20 cm apart) and its motion: rotation about a moving axis and
# a translation, 30 frames/s.
BODY = np.array([[0.0, 0.0, 0.0], [0.12, 0.0, 0.0], [0.0, 0.15, 0.02], [0.05, 0.04, 0.18]])


def rigid_motion(n_frames):
    frames = []
    for i in range(n_frames):
        t = i / 30.0
        r = rotation([0.3, 1.0, 0.2 * math.sin(t)], 0.8 * math.sin(1.3 * t)) @ rotation([1, 0, 0], 0.4 * t)
        frames.append(BODY @ r.T + np.array([0.1 * t, 0.5 + 0.05 * math.sin(2 * t), -0.2 * t]))
    return np.array(frames)


def run(estimator, truth, measured, noise_m=0.0, seed=0):
    rng = np.random.default_rng(seed)
    out_p, out_s = [], []
    for t in range(len(truth)):
        x = truth[t] + rng.normal(0.0, noise_m, truth[t].shape)
        p, s = estimator.update(np.where(measured[t][:, None], x, np.nan), measured[t])
        out_p.append(p)
        out_s.append(s)
    return np.array(out_p), np.array(out_s)


# ---------------------------------------------------------------------------------- pure functions

@settings(max_examples=50, deadline=None)
@given(st.integers(0, 10_000))
def test_kabsch_recovers_rotation_and_translation(seed):
    rng = np.random.default_rng(seed)
    src = rng.normal(size=(5, 3))
    r, t = random_rotation(rng), rng.normal(size=3)
    r_est, t_est = kabsch(src, src @ r.T + t)
    np.testing.assert_allclose(r_est, r, atol=1e-9)
    np.testing.assert_allclose(t_est, t, atol=1e-9)


def test_kabsch_never_returns_a_reflection():
    rng = np.random.default_rng(3)
    src = rng.normal(size=(6, 3))
    mirrored = src * np.array([-1.0, 1.0, 1.0])
    r, _ = kabsch(src, mirrored)
    assert np.linalg.det(r) == pytest.approx(1.0)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)


def test_rigid_estimate_exact_and_with_noise():
    rng = np.random.default_rng(0)
    r, t = random_rotation(rng), np.array([0.2, -0.1, 0.4])
    cur = BODY @ r.T + t
    est = rigid_estimate(BODY[:3], cur[:3], BODY[3])
    np.testing.assert_allclose(est, cur[3], atol=1e-12)
    errs = []
    for _ in range(200):
        noisy = cur[:3] + rng.normal(0, 0.001, (3, 3))
        errs.append(np.linalg.norm(rigid_estimate(BODY[:3], noisy, BODY[3]) - cur[3]))
    assert np.mean(errs) < 0.003  # 1 mm noise on 3 supports 12-15 cm apart, target ~18 cm away


def test_rigid_estimate_two_supports_needs_the_prior():
    r = rotation([0, 0, 1], 0.3)
    cur = BODY @ r.T
    assert rigid_estimate(BODY[:2], cur[:2], BODY[3]) is None
    # with the true position as prior the free rotation about the supports' line is resolved
    est = rigid_estimate(BODY[:2], cur[:2], BODY[3], prior_m=cur[3])
    np.testing.assert_allclose(est, cur[3], atol=1e-9)


def test_constant_velocity_is_equation_5():
    p = np.array([[0.0, 1.0, 2.0], [1.0, 1.0, 1.0]])
    v = np.array([[0.01, 0.0, -0.02], [np.nan, np.nan, np.nan]])
    np.testing.assert_allclose(constant_velocity(p, v), [[0.01, 1.0, 1.98], [1.0, 1.0, 1.0]])


def test_neighbour_motion_is_equation_6():
    prev = np.zeros((3, 3))
    own_v = np.array([[0.0, 0.0, 0.01], [0, 0, 0], [0, 0, 0]])
    d = np.array([[0, 0, 0], [0.02, 0.0, 0.0], [0.0, 0.04, 0.0]])
    w = np.array([[0, 3.0, 1.0], [1, 0, 0], [1, 0, 0]])
    ok = np.array([False, True, True])
    est, est_ok = neighbour_motion(prev, own_v, d, ok, w, own_velocity=True)
    np.testing.assert_allclose(est[0], [0.015, 0.01, 0.01])  # (3 * 0.02 x + 1 * 0.04 y) / 4 + own
    est, _ = neighbour_motion(prev, own_v, d, ok, w, own_velocity=False)
    np.testing.assert_allclose(est[0], [0.015, 0.01, 0.0])
    assert est_ok.tolist() == [True, False, False]  # markers 1 and 2 have no moving neighbour
    assert np.isnan(est[1]).all()


def test_hinge_axis_intersects_two_constraints_and_keeps_the_prediction_where_free():
    n_true = np.array([0.6, 0.0, 0.8])
    rows = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0]])
    values = rows @ n_true
    n = hinge_axis(rows, values, np.array([0.5, 0.5, 0.7]) / np.linalg.norm([0.5, 0.5, 0.7]))
    np.testing.assert_allclose(n, n_true, atol=1e-12)
    # the other intersection when the prediction lies on its side
    n2 = hinge_axis(rows, values, np.array([0.6, 0.7, -0.4]))
    np.testing.assert_allclose(rows @ n2, values, atol=1e-12)
    assert np.linalg.norm(n2) == pytest.approx(1.0)
    # nearly parallel constraints: only their common direction binds, the rest follows the prediction
    rows = np.array([[1.0, 0.0, 0.0], [-1.0, 0.05, 0.0]])
    pred = np.array([0.0, 0.6, 0.8])
    n3 = hinge_axis(rows, np.array([0.0, 0.0]), pred)
    np.testing.assert_allclose(n3, pred, atol=0.02)


def test_trunk_rotation_is_the_spec_frame():
    r = trunk_rotation(np.array([0, 1.2, 0.0]), np.array([0, 1.0, 0.0]), np.array([-0.1, 0.9, 0.05]),
                       np.array([0.1, 0.9, 0.05]))
    np.testing.assert_allclose(r, np.eye(3), atol=1e-12)


def forearm_pose(flexion_rad, supination_rad):
    """Elbow markers on the x axis, forearm turning about it; styloids about the forearm's axis."""
    e1, e2 = np.array([0.055, 0.0, 0.0]), np.array([-0.055, 0.0, 0.0])
    f = np.array([0.0, -math.cos(flexion_rad), -math.sin(flexion_rad)])  # forearm direction
    side = np.cross(f, [1.0, 0.0, 0.0])
    ulnar = math.cos(supination_rad) * side + math.sin(supination_rad) * np.array([1.0, 0.0, 0.0])
    wc = 0.25 * f
    return e1, e2, wc - 0.05 * ulnar, wc + 0.05 * ulnar


@pytest.mark.parametrize("flexion, supination", [(0.2, 0.0), (1.5, 0.7), (2.2, -1.0), (0.9, 1.4)])
def test_wrist_centre_follows_flexion_and_supination(flexion, supination):
    e1, e2, w1, w2 = forearm_pose(flexion, supination)
    pred = 0.5 * (w1 + w2) + np.array([0.0, 0.02, 0.02])  # a rough prediction picks the solution
    wc = wrist_centre(w2, e1, e2, 0.0, 0.25, pred)
    np.testing.assert_allclose(2 * wc - w2, w1, atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(st.floats(-2.5, 2.5), st.floats(-3.0, 3.0), st.integers(0, 1000))
def test_forearm_angles_invert_forearm_markers(theta, psi, seed):
    rng = np.random.default_rng(seed)
    e1 = rng.normal(0.0, 0.2, 3)
    e2 = e1 + 0.1 * _unit_vec(rng.normal(size=3))
    frame = elbow_frame(e1, e2, e1 + 0.3 * _unit_vec(rng.normal(size=3)))
    if frame is None:
        return
    shape = ForearmShape(along=0.004, radius=0.24, half=0.05, tilt=0.05)
    wa, wb = forearm_markers(frame, shape, theta, psi)
    th, ps, learned = forearm_angles(frame, wa, wb)
    assert math.remainder(th - theta, math.tau) == pytest.approx(0.0, abs=1e-9)
    assert math.remainder(ps - psi, math.tau) == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose([learned.along, learned.radius, learned.half, learned.tilt],
                               [shape.along, shape.radius, shape.half, shape.tilt], atol=1e-9)


def _unit_vec(v):
    return v / np.linalg.norm(v)


def test_fit_forearm_finds_both_angles_from_one_styloid_and_keeps_the_prediction_where_confounded():
    frame = elbow_frame(np.array([0.055, 0.0, 0.0]), np.array([-0.055, 0.0, 0.0]), np.array([0.0, 0.3, 0.0]))
    shape = ForearmShape(0.0, 0.24, 0.05, 0.0)
    # styloid line across the flexion axis (thumb up): one styloid fixes flexion and supination
    wa, _ = forearm_markers(frame, shape, 1.2, 1.5)
    th, ps = fit_forearm(frame, shape, [(0, wa)], 1.17, 1.47, 1.0, 1.0)  # weak prior: the styloid alone
    assert th == pytest.approx(1.2, abs=1e-4) and ps == pytest.approx(1.5, abs=1e-3)
    # a firm prior (0.03 rad against 2 mm: a styloid only 5 cm off the axis) smooths supination
    # between the prediction and the styloid; flexion (24 cm lever) still follows the styloid
    th, ps = fit_forearm(frame, shape, [(0, wa)], 1.17, 1.47, 0.03, 0.03)
    assert th == pytest.approx(1.2, abs=0.002) and 1.47 < ps < 1.5
    # styloid line along the flexion axis (palm up): the styloid moves by R dtheta + half dpsi, so a
    # supination the prediction does not know is read as a little flexion, not the other way round
    wa, _ = forearm_markers(frame, shape, 1.2, 0.0)
    th, ps = fit_forearm(frame, shape, [(0, wa)], 1.2, 0.1, 0.03, 0.03)
    assert abs(th - 1.2) < 0.03 and abs(ps) < 0.1


def forearm_run(measured_rows, n=60, fps=30.0, camera=None, miss=(0.0, 0.0, 0.0), **kw):
    """Shoulder, elbows and styloids (markers 0-4) of an arm flexing and supinating; returns
    (truth, positions, status) with the rows of ``measured_rows`` hidden as given. With a
    ``camera`` position, each hidden marker is also seen by that one camera (a ray to its true
    centre plus ``miss``, 1 mrad off, through :meth:`Estimator.observe_views`)."""
    truth = []
    for i in range(n):
        t = i / fps
        e1, e2, w1, w2 = forearm_pose(0.4 + 0.8 * t, 1.3 * math.sin(1.5 * t))
        truth.append(np.stack([np.array([0.0, 0.32, 0.0]), e1, e2, w1, w2]))
    truth = np.array(truth)
    cfg = dict(methods=[Method.NEIGHBOURS, Method.HINGE, Method.HINGE, Method.FOREARM, Method.FOREARM],
               weights=np.ones((5, 5)), segments=[(1, 2, 3, 4)],
               hinges=[Hinge(1, 2, 0, (3, 4)), Hinge(2, 1, 0, (3, 4))],
               forearms=[Forearm(3, 4, (1, 2)), Forearm(4, 3, (1, 2))], fps=fps, scapular_rhythm=0.0)
    cfg.update(kw)
    est = Estimator(**cfg)
    if camera is None:
        p, s = run(est, truth, measured_rows, noise_m=0.0005)
        return truth, p, s
    rng = np.random.default_rng(1)
    out_p, out_s = [], []
    for t in range(n):
        hidden = np.flatnonzero(~measured_rows[t])
        d = truth[t][hidden] + np.asarray(miss) - camera
        d = d / np.linalg.norm(d, axis=1, keepdims=True) + rng.normal(0.0, 0.001, d.shape)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        est.observe_views(hidden, np.repeat(camera[None], len(hidden), axis=0), d, np.full(len(hidden), 0.001))
        x = truth[t] + rng.normal(0.0, 0.0005, truth[t].shape)
        p, s = est.update(np.where(measured_rows[t][:, None], x, np.nan), measured_rows[t])
        out_p.append(p)
        out_s.append(s)
    return truth, np.array(out_p), np.array(out_s)


def test_forearm_fit_follows_flexion_and_supination_with_one_styloid_hidden():
    measured = np.ones((60, 5), dtype=bool)
    measured[15:, 4] = False
    truth, p, s = forearm_run(measured, drop_unpinned=False)  # the fit alone, never dropped
    assert (s[15:, 4] == ESTIMATED).all()
    err = np.linalg.norm(p[15:, 4] - truth[15:, 4], axis=1)
    # supination up to 110 deg/s, through palm up and down (where one styloid cannot tell
    # supination from flexion): no runaway, a few millimetres
    assert err.mean() < 0.005 and err.max() < 0.02, (err.mean(), err.max())


def test_a_styloid_that_cannot_pin_the_supination_leaves_the_other_lost_until_it_can():
    # supination from thumb up (0) towards palm up (74 deg) and back: near palm up one styloid
    # leaves flexion and supination confounded; once that has lasted longer than the
    # extrapolation allows (3 degrees), the hidden styloid is LOST, not a guess, and it is
    # estimated again when the measured one pins both angles
    measured = np.ones((60, 5), dtype=bool)
    measured[15:, 4] = False
    truth, p, s = forearm_run(measured)
    assert (s[15:18, 4] == ESTIMATED).all()
    assert (s[25:45, 4] == LOST).all()
    assert (s[52:, 4] == ESTIMATED).all()
    est = s[15:, 4] == ESTIMATED
    err = np.linalg.norm(p[15:, 4][est] - truth[15:, 4][est], axis=1)
    assert err.mean() < 0.005 and err.max() < 0.01, (err.mean(), err.max())


def test_a_view_of_the_hidden_styloid_pins_the_supination():
    # the same motion, the hidden styloid seen by one camera 2 m away along the flexion axis:
    # its ray fixes the direction that one styloid leaves free, so it stays estimated, closely
    measured = np.ones((60, 5), dtype=bool)
    measured[15:, 4] = False
    truth, p, s = forearm_run(measured, camera=np.array([2.0, -0.1, -0.2]))
    assert (s[15:, 4] == ESTIMATED).all()
    err = np.linalg.norm(p[15:, 4] - truth[15:, 4], axis=1)
    assert err.mean() < 0.003 and err.max() < 0.008, (err.mean(), err.max())


def test_fit_forearm_with_a_ray_separates_flexion_from_supination():
    frame = elbow_frame(np.array([0.055, 0.0, 0.0]), np.array([-0.055, 0.0, 0.0]), np.array([0.0, 0.3, 0.0]))
    shape = ForearmShape(0.0, 0.24, 0.05, 0.0)
    wa, wb = forearm_markers(frame, shape, 1.2, 0.15)  # near palm up: confounded for one styloid
    th, ps = fit_forearm(frame, shape, [(0, wa)], 1.2, 0.0, 0.06, 0.06)
    assert abs(ps - 0.15) > 0.1  # the styloid alone: mostly read as flexion
    camera = wb + np.array([1.5, 0.5, 0.3])  # a camera that sees the hidden styloid
    d = (wb - camera) / np.linalg.norm(wb - camera)
    pinned = [False]
    th, ps = fit_forearm(frame, shape, [(0, wa)], 1.2, 0.0, 0.06, 0.06, pinned=pinned,
                         rays=[(1, camera.tolist(), d.tolist(), 0.0002)])
    # the measured styloid's 2 mm over the styloids' 10 cm: supination to ~0.02 rad, against the
    # prior's 0.06: mostly the data
    assert pinned[0] and th == pytest.approx(1.2, abs=0.005) and ps == pytest.approx(0.15, abs=0.02)
    th, ps = fit_forearm(frame, shape, [(0, wa)], 1.2, 0.0, 1.0, 1.0, rays=[(1, camera.tolist(), d.tolist(), 0.0002)])
    assert th == pytest.approx(1.2, abs=0.001) and ps == pytest.approx(0.15, abs=0.002)
    # a ray alone (both styloids hidden) pins both angles too
    da = (wa - camera) / np.linalg.norm(wa - camera)
    th, ps = fit_forearm(frame, shape, [], 1.15, 0.05, 0.06, 0.06, pinned=pinned,
                         rays=[(1, camera.tolist(), d.tolist(), 0.0002), (0, camera.tolist(), da.tolist(), 0.0002)])
    assert pinned[0] and th == pytest.approx(1.2, abs=0.005) and ps == pytest.approx(0.15, abs=0.01)


def test_a_view_far_from_the_prediction_is_another_ball_and_ignored():
    measured = np.ones((60, 5), dtype=bool)
    measured[15:, 4] = False
    camera = np.array([2.0, -0.1, -0.2])
    truth, p_ref, s_ref = forearm_run(measured, camera=camera, miss=(0.0, 5.0, 0.0))  # no view near
    # the one camera's ray misses the hidden styloid by 5 cm: left out, as if there were no view
    truth, p, s = forearm_run(measured, camera=camera, miss=(0.0, 0.05, 0.0))
    np.testing.assert_array_equal(s, s_ref)
    np.testing.assert_array_equal(p, p_ref)
    assert (s[25:45, 4] == LOST).all()


def test_forearm_with_both_styloids_hidden_is_dropped_when_its_turn_is_guesswork():
    measured = np.ones((60, 5), dtype=bool)
    measured[20:50, 3:] = False
    truth, p, s = forearm_run(measured)
    assert (s[20:22, 3:] == ESTIMATED).all()  # a short gap: extrapolated
    assert (s[35:50, 3:] == LOST).all()       # the forearm keeps turning: lost, not a guess
    assert (s[50:, 3:] == MEASURED).all()


def test_a_lost_styloid_comes_back_from_the_other():
    measured = np.ones((60, 5), dtype=bool)
    measured[20:32, 3:] = False  # both hidden: lost
    measured[32:, 4] = False     # one styloid back: the other is estimated again
    truth, p, s = forearm_run(measured, drop_unpinned=False)
    assert (s[30:32, 4] == LOST).all()
    assert (s[33:, 4] == ESTIMATED).all()
    assert np.linalg.norm(p[40:, 4] - truth[40:, 4], axis=1).max() < 0.015
    # with the drop rule it is estimated where the measured styloid pins the angles (thumb up)
    truth, p, s = forearm_run(measured)
    assert (s[52:, 4] == ESTIMATED).all()
    assert np.linalg.norm(p[52:, 4] - truth[52:, 4], axis=1).max() < 0.01


def test_the_shoulder_pivot_turns_with_the_scapula_when_the_arm_rises():
    """Reach of the simulated patient (truth from the body model): the inner elbow marker hidden
    whenever the arm is raised; the scapulohumeral rhythm keeps the hinge's humerus condition."""
    from tracking.angles import joint_angles
    from tracking.sim.body import BodyDimensions, BodyModel
    from tracking.sim.motions import load_motion

    ms = load_markerset("upper_limb_seated")
    dims = BodyDimensions.from_percentile(50, "female")
    body, motion = BodyModel(dims, ms), load_motion("reach", dims)
    fps = 15.0
    truth = np.array([body.markers_m(motion.pose_at(i / fps)) for i in range(int(5.0 * fps))])
    k = ms.index("MRE2")
    elevation = joint_angles(truth, ms.names)["right_shoulder_elevation"]
    measured = np.ones(truth.shape[:2], dtype=bool)
    measured[:, k] = elevation < 25.0
    assert (~measured[:, k]).sum() > 10
    errs = {}
    for rhythm in (0.0, 0.5):
        est = Estimator(**{**estimator_config(ms), "scapular_rhythm": rhythm}, fps=fps)
        p, s = run(est, truth, measured, noise_m=0.0005)
        hid = ~measured[:, k]
        errs[rhythm] = np.linalg.norm(p[hid, k] - truth[hid, k], axis=1).mean()
    assert errs[0.5] < 0.006 and errs[0.5] < 0.6 * errs[0.0], errs


# ---------------------------------------------------------------------------------- the Estimator

def rigid_estimator(method, **kw):
    w = np.ones((4, 4))
    return Estimator([method] * 4, w, segments=[(0, 1, 2, 3)], length_pairs=[(0, 1), (0, 2), (0, 3)],
                     fps=30.0, **kw)


def test_rigid_estimator_follows_a_rotating_segment_to_the_noise():
    truth = rigid_motion(120)
    measured = np.ones((120, 4), dtype=bool)
    measured[30:110, 3] = False  # hidden for 2.7 s while the segment turns by ~1 rad
    p, s = run(rigid_estimator(Method.RIGID), truth, measured)
    assert (s[30:110, 3] == ESTIMATED).all()
    np.testing.assert_allclose(p[30:110, 3], truth[30:110, 3], atol=1e-9)
    # 1 mm noise on the supports now and in the reference frame: a few mm on the hidden marker
    p, s = run(rigid_estimator(Method.RIGID), truth, measured, noise_m=0.001)
    err = np.linalg.norm(p[30:110, 3] - truth[30:110, 3], axis=1)
    assert err.mean() < 0.005 and err.max() < 0.015
    # equation 6 (translation of the neighbours only) cannot follow the rotation
    p6, _ = run(rigid_estimator(Method.NEIGHBOURS), truth, measured, noise_m=0.001)
    assert np.linalg.norm(p6[109, 3] - truth[109, 3]) > 0.03


def test_constant_velocity_estimator_is_exact_on_constant_velocity():
    t = np.arange(60)[:, None, None] / 30.0
    truth = BODY[None] + t * np.array([0.3, -0.1, 0.05])
    measured = np.ones((60, 4), dtype=bool)
    measured[20:50, 1] = False
    p, s = run(rigid_estimator(Method.CONSTANT_VELOCITY), truth, measured)
    assert (s[20:50, 1] == ESTIMATED).all()
    np.testing.assert_allclose(p[20:50, 1], truth[20:50, 1], atol=1e-9)


def test_neighbour_estimator_follows_a_translating_neighbour():
    # marker 1 rests, then its neighbour 0 carries the pair off while 1 is hidden
    truth = np.zeros((40, 2, 3))
    truth[:, 1, 0] = 0.1
    shift = np.clip(np.arange(40) - 10, 0, None)[:, None] * np.array([0.004, 0.002, 0.0])
    truth += shift[:, None, :]
    measured = np.ones((40, 2), dtype=bool)
    measured[8:35, 1] = False
    e = Estimator([Method.NEIGHBOURS] * 2, {1: {0: 1.0}, 0: {1: 1.0}}, fps=30.0)
    p, s = run(e, truth, measured)
    np.testing.assert_allclose(p[8:35, 1], truth[8:35, 1], atol=1e-12)
    # the paper's formula adds the own last velocity too: with a resting marker the same here,
    # but once the estimate moves its own step is added again each frame and runs ahead
    e_lit = Estimator([Method.NEIGHBOURS] * 2, {1: {0: 1.0}, 0: {1: 1.0}}, fps=30.0, own_velocity=True)
    p_lit, _ = run(e_lit, truth, measured)
    assert np.linalg.norm(p_lit[34, 1] - truth[34, 1]) > 0.1


def test_status_measured_estimated_lost_and_reappearance():
    truth = rigid_motion(40)
    measured = np.ones((40, 4), dtype=bool)
    measured[:, 2] = False            # never seen
    measured[10:20, 3] = False        # hidden, then back
    e = rigid_estimator(Method.RIGID)
    p, s = run(e, truth, measured)
    assert (s[:, 2] == LOST).all() and np.isnan(p[:, 2]).all()
    assert (s[:10, 3] == MEASURED).all() and (s[10:20, 3] == ESTIMATED).all() and (s[20:, 3] == MEASURED).all()
    assert (s[:, :2] == MEASURED).all()
    np.testing.assert_allclose(p[20:, 3], truth[20:, 3])  # measured positions pass through
    assert s.dtype == np.uint8


def test_hidden_too_long_is_lost_until_measured_again():
    truth = rigid_motion(60)
    measured = np.ones((60, 4), dtype=bool)
    measured[10:50, 3] = False
    e = rigid_estimator(Method.RIGID, max_hidden_s=0.5)  # 15 frames
    _, s = run(e, truth, measured)
    assert (s[10:25, 3] == ESTIMATED).all()
    assert (s[25:50, 3] == LOST).all()
    assert (s[50:, 3] == MEASURED).all()


def test_drift_beyond_the_learned_lengths_is_lost():
    # constant velocity carries marker 3 straight on while the segment turns back: its distance
    # to marker 0 leaves the learned range by more than the tolerance
    truth = rigid_motion(150)
    measured = np.ones((150, 4), dtype=bool)
    measured[40:150, 3] = False
    e = rigid_estimator(Method.CONSTANT_VELOCITY, tolerance_m=0.03)
    p, s = run(e, truth, measured)
    est = s[40:, 3] == ESTIMATED
    assert est[0] and not est.all()
    first_lost = 40 + int(np.argmin(est))
    assert (s[first_lost:, 3] == LOST).all()  # lost stays lost while hidden
    d = np.linalg.norm(p[first_lost - 1, 3] - p[first_lost - 1, 0])
    d_true = np.linalg.norm(BODY[3] - BODY[0])
    assert abs(d - d_true) <= 0.03 + 1e-9  # what was reported stayed within the tolerance
    # the rigid estimator stays within the body's lengths all along
    _, s_rigid = run(rigid_estimator(Method.RIGID, tolerance_m=0.03), truth, measured)
    assert (s_rigid[40:, 3] == ESTIMATED).all()


def test_reset_forgets():
    truth = rigid_motion(10)
    e = rigid_estimator(Method.RIGID)
    run(e, truth, np.ones((10, 4), dtype=bool))
    e.reset()
    p, s = e.update(np.full((4, 3), np.nan), np.zeros(4, dtype=bool))
    assert (s == LOST).all() and np.isnan(p).all()


def test_configuration_errors():
    with pytest.raises(ValueError, match="weights"):
        Estimator([Method.RIGID] * 3, np.ones((2, 2)))
    with pytest.raises(ValueError, match="hinge"):
        Estimator([Method.HINGE] * 2, np.ones((2, 2)))
    with pytest.raises(ValueError, match="segment"):
        Estimator([Method.RIGID] * 2, np.ones((2, 2)), segments=[(0, 5)])
    with pytest.raises(ValueError, match="constant_velocity, neighbours, rigid, hinge"):
        Method.parse("spline")
    assert Method.parse("rigid") is Method.RIGID


# ---------------------------------------------------------------------------------- configuration

def test_config_of_the_seed_marker_set_from_its_yaml():
    ms = load_markerset("upper_limb_seated")
    cfg = estimator_config(ms)
    m = ms.n_markers
    w = cfg["weights"]
    assert w.shape == (m, m) and np.all(np.diag(w) == 0)
    mirror = {n: n.replace("L", "#").replace("R", "L").replace("#", "R") if n.startswith(("ML", "MR")) else n
              for n in ms.names}
    perm = [ms.index(mirror[n]) for n in ms.names]
    np.testing.assert_array_equal(w, w[np.ix_(perm, perm)])  # both arms alike
    assert all(w[i].sum() > 0 for i in range(m))             # every marker has neighbours
    assert w[ms.index("MRW1"), ms.index("MRW2")] == 4.0 and w[ms.index("MRW1"), ms.index("MRE1")] == 0.5
    methods = cfg["methods"]
    assert methods[ms.index("MRE2")] == Method.HINGE and methods[ms.index("MRW1")] == Method.FOREARM
    assert {f.marker for f in cfg["forearms"]} == {ms.index(n) for n in ("MLW1", "MLW2", "MRW1", "MRW2")}
    assert all(isinstance(f, Forearm) for f in cfg["forearms"])
    assert {h.marker for h in cfg["hinges"]} == {ms.index(n) for n in ("MLE1", "MLE2", "MRE1", "MRE2")}
    assert (ms.index("MRE1"), ms.index("MRW2")) in cfg["length_pairs"]
    assert cfg["tolerance_m"] == pytest.approx(0.03)
    Estimator(**cfg, fps=15.0)
    eq5 = estimator_config(ms, method="constant_velocity")
    assert set(eq5["methods"]) == {Method.CONSTANT_VELOCITY}


TINY_SET = """
name: tiny
marker_diameter_mm: 40
markers:
  - {name: A, colour: [255, 0, 0], segment: arm}
  - {name: B, colour: [0, 255, 0], segment: arm}
  - {name: C, colour: [0, 0, 255], segment: arm}
  - {name: D, colour: [255, 255, 0], segment: leg}
"""


def write_set(tmp_path, text):
    path = tmp_path / "tiny.yaml"
    path.write_text(text)
    return path


def test_a_marker_set_without_hidden_markers_gets_equation_6_on_its_segments(tmp_path):
    ms = load_markerset(write_set(tmp_path, TINY_SET))
    cfg = estimator_config(ms)
    np.testing.assert_array_equal(cfg["weights"], [[0, 1, 1, 0], [1, 0, 1, 0], [1, 1, 0, 0], [0, 0, 0, 0]])
    assert set(cfg["methods"]) == {Method.NEIGHBOURS} and cfg["hinges"] == cfg["forearms"] == []
    assert cfg["trunk"] is None and cfg["length_pairs"] == []
    Estimator(**cfg)


def test_another_marker_set_chooses_its_own_estimators(tmp_path):
    """A marker set file decides estimators, weights, rigid groups and limits; the Estimator
    built from it behaves accordingly (a hidden marker follows its rigid group exactly)."""
    text = TINY_SET + """
hidden_markers:
  markers:
    A: {estimator: rigid, neighbours: {B: 2, C: 0.5}}
    D: {estimator: constant_velocity}
  rigid_groups: [[A, B, C, D]]
  limits:
    length_pairs: [[A, B]]
    drift_tolerance_mm: 10
    max_hidden_s: {rigid: 1.5}
"""
    ms = load_markerset(write_set(tmp_path, text))
    cfg = estimator_config(ms)
    assert cfg["methods"] == [Method.RIGID, Method.NEIGHBOURS, Method.NEIGHBOURS, Method.CONSTANT_VELOCITY]
    np.testing.assert_array_equal(cfg["weights"][0], [0, 2, 0.5, 0])
    np.testing.assert_array_equal(cfg["weights"][1], [1, 0, 1, 0])  # not listed: its segment, weight 1
    assert cfg["segments"] == [(0, 1, 2, 3)] and cfg["length_pairs"] == [(0, 1)]
    assert cfg["tolerance_m"] == pytest.approx(0.01) and cfg["max_hidden_s"][0] == 1.5
    truth = rigid_motion(60)
    measured = np.ones((60, 4), dtype=bool)
    measured[20:50, 0] = False
    p, s = run(Estimator(**cfg, fps=30.0), truth, measured)
    assert (s[20:50, 0] == ESTIMATED).all() and (s[:, 1:] == MEASURED).all()
    np.testing.assert_allclose(p[20:50, 0], truth[20:50, 0], atol=1e-9)
    measured[:, 0] = True
    measured[10:59, 3] = False  # constant velocity, 1.5 s limit not its own: 0.5 s (15 frames)
    _, s = run(Estimator(**cfg, fps=30.0), truth, measured)
    assert (s[10:25, 3] == ESTIMATED).all() and (s[26:59, 3] == LOST).all()


@pytest.mark.parametrize("section, expected", [
    ("  markers:\n    A: {estimator: spline}", "hidden_markers.markers.A.estimator"),
    ("  markers:\n    A: {estimator: rigid, neighbours: {Z: 1}}", "hidden_markers.markers.A.neighbours: unknown marker 'Z'"),
    ("  markers:\n    A: {estimator: rigid, neighbours: {B: -1}}", "hidden_markers.markers.A.neighbours"),
    ("  markers:\n    A: {estimator: hinge}", "hidden_markers.markers.A: estimator hinge needs A in an 'elbows' entry"),
    ("  markers:\n    A: {estimator: forearm}", "estimator forearm needs A in a 'forearms' entry"),
    ("  rigid_groups: [[A, Q]]", "hidden_markers.rigid_groups.0: unknown marker 'Q'"),
    ("  rigid_groups: [[A, A]]", "hidden_markers.rigid_groups.0: a marker appears twice"),
    ("  limits: {length_pairs: [[A, M*B]]}", "hidden_markers.limits.length_pairs.0: '*' needs identification.sides"),
    ("  limits: {drift_tolerance_mm: 0}", "hidden_markers.limits.drift_tolerance_mm"),
    ("  limits: {max_hidden_s: {rigid: -1}}", "hidden_markers.limits.max_hidden_s"),
    ("  limits: {max_hiden_s: {rigid: 1}}", "hidden_markers.limits.max_hiden_s: unknown key"),
    ("  markers:\n    A: {estimator: rigid}\n  elbows: [{markers: [A, B], shoulder: C}]", "hidden_markers.elbows.0.wrist"),
])
def test_bad_hidden_marker_sections_are_one_line_errors(tmp_path, section, expected):
    from tracking.errors import ContentError

    path = write_set(tmp_path, TINY_SET + "hidden_markers:\n" + section + "\n")
    with pytest.raises(ContentError) as info:
        load_markerset(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path)) and expected in message, message


def test_hinge_estimator_on_the_simulated_arm_without_rendering():
    """The elbow hinge through the seed experiment's motion, MRE2 hidden while the elbow flexes
    and the humerus turns (truth from the body model, 1 mm noise)."""
    from tracking.sim.body import BodyDimensions, BodyModel
    from tracking.sim.motions import load_motion

    ms = load_markerset("upper_limb_seated")
    dims = BodyDimensions.from_percentile(50, "female")
    body, motion = BodyModel(dims, ms), load_motion("right_external_rotation", dims)
    fps = 15.0
    truth = np.array([body.markers_m(motion.pose_at(i / fps)) for i in range(int(motion.duration_s * fps))])
    k = ms.index("MRE2")
    measured = np.ones(truth.shape[:2], dtype=bool)
    measured[30:90, k] = False  # 2 s to 6 s: elbow to the side and flexed, forearm turned out
    est = Estimator(**estimator_config(ms), fps=fps)
    p, s = run(est, truth, measured, noise_m=0.001)
    assert (s[30:90, k] == ESTIMATED).all()
    err = np.linalg.norm(p[30:90, k] - truth[30:90, k], axis=1)
    assert err.mean() < 0.006 and err.max() < 0.015


# ---------------------------------------------------------------------------------- the seed's experiment

@pytest.fixture(scope="module")
def seed_experiment():
    from tracking.sim.hidden_eval import occlusion_data
    from tracking.sim.renderer import OffscreenGLUnavailable

    try:
        return occlusion_data("right_external_rotation", fps=15.0)
    except OffscreenGLUnavailable as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))


def test_seed_experiment_mre2_reappears_within_5_mm(seed_experiment):
    """docs/METHOD.md 'Experiment': MRE2 hidden between elbow and trunk, then found again. The seed
    reports ~10 mm at reappearance; the recommended estimators must do 5 mm or better on average
    (over both occlusions and five noise draws), equation 6 as the paper writes it does not."""
    from tracking.sim.hidden_eval import make_estimator, run_estimator

    ms = load_markerset("upper_limb_seated")
    data = seed_experiment
    k = ms.index("MRE2")
    assert not data.measured[:, k].all(), "the simulated experiment must hide MRE2"
    best, paper = [], []
    for seed in range(5):
        best.append(run_estimator(data, make_estimator(ms, "recommended (per marker)", data.fps), seed=seed).for_marker(k))
        paper.append(run_estimator(data, make_estimator(ms, "eq. 6 as written (+ own velocity)", data.fps), seed=seed).for_marker(k))
    best, paper = np.array(best) / 1000.0, np.array(paper) / 1000.0
    assert best.shape[1] >= 1 and np.isfinite(best).all()
    assert best.mean() <= 0.005, best
    assert best.max() <= 0.015, best
    assert paper.mean() > best.mean()


def test_a_whole_segment_hidden_is_lost_after_a_while():
    truth = rigid_motion(40)
    measured = np.ones((40, 4), dtype=bool)
    measured[10:40, 2:] = False  # markers 2 and 3 form a body segment; both hidden
    w = np.ones((4, 4))
    e = Estimator([Method.NEIGHBOURS] * 4, w, body_segments=["a", "a", "b", "b"], max_unsupported_s=0.2,
                  fps=30.0)
    _, s = run(e, truth, measured)
    assert (s[10:16, 2:] == ESTIMATED).all()
    assert (s[17:, 2:] == LOST).all()
    with pytest.raises(ValueError, match="body_segments"):
        Estimator([Method.NEIGHBOURS] * 4, w, body_segments=["a"])


def test_forearm_switches_to_the_wrist_circle_when_the_forearm_turns():
    """Elbow markers and one styloid measured, the other hidden while the forearm flexes (rigid
    fit exact) and then pronates (the rigid fit's misfit grows: the wrist circle takes over)."""
    frames = [forearm_pose(0.3 + 0.02 * i, 0.0) for i in range(30)]
    frames += [forearm_pose(0.9, 0.03 * i) for i in range(1, 31)]
    truth = np.array([np.stack(f) for f in frames])  # (T, 4, 3): E1, E2, W1, W2
    measured = np.ones((60, 4), dtype=bool)
    measured[10:, 3] = False
    cfg = dict(methods=[Method.HINGE, Method.HINGE, Method.HINGE, Method.HINGE], weights=np.ones((4, 4)),
               segments=[(0, 1, 2, 3)], forearms=[Forearm(2, 3, (0, 1)), Forearm(3, 2, (0, 1))],
               hinges=[], fps=30.0)
    cfg["methods"] = [Method.RIGID, Method.RIGID, Method.FOREARM, Method.FOREARM]
    p, s = run(Estimator(**cfg), truth, measured)
    assert (s[10:, 3] == ESTIMATED).all()
    np.testing.assert_allclose(p[10:30, 3], truth[10:30, 3], atol=1e-9)  # flexion: rigid, exact
    # pronation: the rigid fit holds until its misfit passes the gate, then the wrist circle is exact
    err = np.linalg.norm(p[30:, 3] - truth[30:, 3], axis=1)
    assert err[-10:].max() < 1e-6
    # the rigid fit alone misses the pronation
    cfg["methods"] = [Method.RIGID] * 4
    p_rigid, _ = run(Estimator(**cfg), truth, measured)
    assert np.linalg.norm(p_rigid[59, 3] - truth[59, 3]) > 0.03


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.0, 0.9))
def test_any_input_gives_consistent_statuses(seed, p_hidden):
    """Random (even degenerate) positions and masks never raise; status and NaN agree."""
    ms = load_markerset("upper_limb_seated")
    rng = np.random.default_rng(seed)
    est = Estimator(**estimator_config(ms), fps=15.0)
    base = rng.normal(0.0, 0.3, (ms.n_markers, 3))
    for t in range(25):
        x = base + rng.normal(0.0, 0.01, base.shape) * (t % 5 != 0)  # every 5th frame: a repeat
        if t == 7:
            x[:] = 0.0  # every marker at one point
        measured = rng.random(ms.n_markers) > p_hidden
        p, s = est.update(np.where(measured[:, None], x, np.nan), measured)
        assert np.array_equal(s == MEASURED, measured)
        assert np.array_equal(np.isnan(p).any(axis=1), s == LOST)
        np.testing.assert_array_equal(p[measured], x[measured])


def _arm_estimator(**tuning) -> Estimator:
    """A shoulder, two elbow markers on a hinge and two styloids on a forearm, at 30 frames/s."""
    return Estimator([Method.NEIGHBOURS, Method.HINGE, Method.HINGE, Method.FOREARM, Method.FOREARM],
                     np.ones((5, 5)), segments=[(1, 2, 3, 4)],
                     hinges=[Hinge(1, 2, 0, (3, 4)), Hinge(2, 1, 0, (3, 4))],
                     forearms=[Forearm(3, 4, (1, 2)), Forearm(4, 3, (1, 2))], fps=30.0, scapular_rhythm=0.0, **tuning)


def _flexing_arm(flexion_at):
    """21 frames of (shoulder, elbow markers, styloids) flexing by ``flexion_at(i)`` radians, the
    inner elbow marker hidden in the last frame: (truth (21, 5, 3), measured (21, 5))."""
    truth = []
    for i in range(21):
        e1, e2, w1, w2 = forearm_pose(flexion_at(i), 0.3)
        truth.append(np.stack([np.array([0.0, 0.32, 0.0]), e1, e2, w1, w2]))
    measured = np.ones((21, 5), dtype=bool)
    measured[20, 2] = False
    return np.array(truth), measured


def test_the_hinge_takes_the_mirror_image_on_the_side_the_elbow_bends():
    # elbow flexed, the inner epicondyle marker hidden; its last position (the previous axis) on
    # the wrong side, as after a bad estimate or a re-entry from LOST: the elbow bends one way
    # only, so the learned sense picks the right one of the two solutions
    truth, measured = _flexing_arm(lambda i: 0.4 + 0.8 * i / 30)
    errors = []
    for learned in (True, False):
        est = _arm_estimator()
        for t in range(20):
            est.update(truth[t], measured[t])
        if not learned:
            est.elbows.sense[:] = 0.0  # as before the sense was learned: the previous axis decides
        est.positions[2] = 2 * truth[19, 1] - truth[19, 2]  # the mirror image through the partner
        p, s = est.update(np.where(measured[20][:, None], truth[20], np.nan), measured[20])
        assert s[2] == ESTIMATED
        errors.append(np.linalg.norm(p[2] - truth[20, 2]))
    assert errors[0] < 0.003 and errors[1] > 0.05, errors


def test_a_view_of_a_hidden_elbow_marker_corrects_the_hinge_across_its_ray():
    truth, measured = _flexing_arm(lambda i: 0.8 + 0.3 * i / 30)
    camera = truth[20, 2] + np.array([0.0, 0.3, -2.0])  # looks across the elbow's axis
    errors = []
    for view in (False, True):
        est = _arm_estimator()
        for t in range(20):
            est.update(truth[t], measured[t])
        est.elbows.length[:] *= 1.1  # a hinge 1 cm off along the axis (a wrong learned width)
        if view:
            d = (truth[20, 2] - camera) / np.linalg.norm(truth[20, 2] - camera)
            est.observe_views([2], camera[None], d[None], [0.001])
        p, s = est.update(np.where(measured[20][:, None], truth[20], np.nan), measured[20])
        assert s[2] == ESTIMATED
        errors.append(np.linalg.norm(p[2] - truth[20, 2]))
    assert errors[0] > 0.008 and errors[1] < 0.003, errors


def test_an_elbow_marker_estimated_on_a_straight_arm_has_its_axis_guessed():
    """Inner elbow marker hidden while the forearm pronates: with the elbow bent the hinge pins the
    axis from the measured wrists; with the arm straight nothing measured shows the axis' turn
    about the arm (its estimate still serves the elbow centre), unless a view of the marker does."""
    shoulder = np.array([0.0, 0.32, 0.0])
    for flexion, view, guessed in ((0.9, False, False), (0.02, False, True), (0.02, True, False)):
        est = _arm_estimator()
        flags = []
        for i in range(45):
            x = np.stack([shoulder, *forearm_pose(flexion, 0.4 - 0.02 * i)])
            measured = np.ones(5, dtype=bool)
            measured[2] = i < 20
            if view and i >= 20:
                camera = x[2] + np.array([0.0, 0.3, -2.0])
                est.observe_views([2], camera[None], ((x[2] - camera) / np.linalg.norm(x[2] - camera))[None], [0.001])
            p, s = est.update(np.where(measured[:, None], x, np.nan), measured)
            assert not est.axis_guessed[s != ESTIMATED].any()
            if i >= 20 and s[2] == ESTIMATED:
                flags.append(bool(est.axis_guessed[2]))
        assert len(flags) >= 10 and set(flags) == {guessed}, (flexion, view, flags)


def test_a_straight_elbows_weak_condition_is_averaged_with_the_prediction():
    """Arm straight, wrists measured, inner elbow marker hidden while the forearm pronates: the
    second hinge condition is weak (singular value ~0.28), so the rigid fit's prediction, which
    turns with the forearm, leaves the axis' turn free and the marker drifts; averaged with the
    weak condition's solution (exact here) it drifts half as far. The turn stays a guess."""
    shoulder = np.array([0.0, 0.32, 0.0])
    drift = {}
    for weak in (0.3, 0.25):  # 0.3 = min_singular: the weak band switched off
        est = _arm_estimator(weak_singular=weak)
        for i in range(45):
            x = np.stack([shoulder, *forearm_pose(0.0, 0.4 - 0.02 * i)])
            measured = np.ones(5, dtype=bool)
            measured[2] = i < 20
            p, s = est.update(np.where(measured[:, None], x, np.nan), measured)
        assert s[2] == ESTIMATED and est.axis_guessed[2]
        drift[weak] = float(np.linalg.norm(p[2] - x[2]))
    assert drift[0.3] > 0.04  # 28 degrees of pronation carried into the axis
    assert drift[0.25] == pytest.approx(0.5 * drift[0.3], rel=0.1)


def test_of_two_views_of_a_hidden_styloid_only_the_nearer_is_fitted():
    """The tracker passes a marker's full-sized single views when they made no consistent point:
    of two, at most one is the marker's. A second ball of the colour 18 mm off, seen by another
    camera, moved the estimate 5.4 mm; only the view nearest the prediction counts."""
    shoulder = np.array([0.0, 0.32, 0.0])

    def estimate(with_wrong_view):
        est = _arm_estimator()
        for i in range(25):
            x = np.stack([shoulder, *forearm_pose(0.9, 0.3 + 0.01 * i)])
            measured = np.ones(5, dtype=bool)
            pos = x.copy()
            if i >= 20:
                measured[3] = False
                pos[4] += np.array([0.0015, -0.001, 0.001])  # the measured styloid a little off
                cams = [np.array([0.0, 0.3, -2.0])]
                targets = [x[3]]
                if with_wrong_view:
                    cams.append(np.array([1.5, 0.5, -1.5]))
                    targets.append(x[3] + np.array([0.0, 0.018, 0.0]))
                rays = [(t - c) / np.linalg.norm(t - c) for c, t in zip(cams, targets)]
                est.observe_views([3] * len(cams), np.array(cams), np.array(rays), [0.001] * len(cams))
            p, s = est.update(np.where(measured[:, None], pos, np.nan), measured)
        assert s[3] == ESTIMATED
        return p[3], x[3]

    alone, truth = estimate(False)
    both, _ = estimate(True)
    assert np.linalg.norm(alone - truth) < 0.002
    np.testing.assert_allclose(both, alone, atol=1e-9)


def test_styloid_markers_estimated_with_neither_measured_have_their_axis_guessed():
    """Both styloid markers hidden: the forearm's angles are extrapolated, so the wrist axis'
    direction is a guess; with one measured it is fitted, not guessed."""
    shoulder = np.array([0.0, 0.32, 0.0])
    for hidden, guessed in (((3,), False), ((3, 4), True)):
        est = _arm_estimator()
        flags = []
        for i in range(30):
            x = np.stack([shoulder, *forearm_pose(0.9 + 0.005 * i, 0.3 - 0.005 * i)])
            measured = np.ones(5, dtype=bool)
            if i >= 20:
                measured[list(hidden)] = False
            p, s = est.update(np.where(measured[:, None], x, np.nan), measured)
            for k in hidden:
                if i >= 20 and s[k] == ESTIMATED:
                    flags.append(bool(est.axis_guessed[k]))
        assert len(flags) >= 3 and set(flags) == {guessed}, (hidden, flags)


@pytest.mark.parametrize("rhythm", [0.0, 0.5])
def test_the_per_frame_forearm_angles_in_floats_match_the_elbow_frame_and_forearm_angles(rhythm):
    # _learn computes the arm's angles every frame in plain floats (speed); they must stay the
    # numpy definitions' (elbow_frame with the learned, scapula-turned pivot; forearm_angles)
    est = Estimator([Method.NEIGHBOURS, Method.HINGE, Method.HINGE, Method.FOREARM, Method.FOREARM],
                    np.ones((5, 5)), segments=[(1, 2, 3, 4)],
                    hinges=[Hinge(1, 2, 0, (3, 4)), Hinge(2, 1, 0, (3, 4))],
                    forearms=[Forearm(3, 4, (1, 2)), Forearm(4, 3, (1, 2))], fps=30.0, scapular_rhythm=rhythm)
    truth, _ = _flexing_arm(lambda i: 0.3 + 0.06 * i)
    # the shoulder up and to the side (humerus elevation ~45 degrees: the scapula turns), moving
    truth[:, 0] = np.array([-0.2, 0.2, 0.0]) + np.linspace(0.0, 0.05, len(truth))[:, None]
    measured = np.ones(5, dtype=bool)
    turned = []
    for p in truth:
        est.update(p, measured)
        turned.append(not np.allclose(est.pivot_offset(0, 0.5 * (p[1] + p[2]), p[0]), est.pivot_offset(0)))
        fast = est.arms.forearm_angles_f(0, p.tolist(), measured.tolist())
        theta, psi, shape = forearm_angles(est.arms.elbow_frame(0, p, measured, square=0.0), p[3], p[4])
        assert fast[0] == pytest.approx(theta, abs=1e-12) and fast[1] == pytest.approx(psi, abs=1e-12)
        assert np.allclose([fast[2].along, fast[2].radius, fast[2].half, fast[2].tilt],
                           [shape.along, shape.radius, shape.half, shape.tilt], atol=1e-12)
    assert any(turned) == (rhythm > 0)


def test_the_forearm_axis_square_to_the_humerus_steadies_a_hidden_styloid():
    """One styloid hidden for 2 s while the nearly straight arm (11 +- 17 degrees of flexion)
    turns +-57 degrees, markers 1.5 mm noisy (320x240 at 2-3 m): the wrist centre lies in the
    plane perpendicular to the flexion axis, 25 cm from the elbow, so the epicondyle markers' noise
    (1.1 degrees of axis tilt) moves the hidden styloid's estimate ~10 mm. With the axis made
    perpendicular to the humerus (``axis_square=1``), the tilt towards the forearm is gone:
    ~35 % less error."""
    def hidden_styloid_rms(square, seed):
        truth = []
        for i in range(90):
            t = i / 30.0
            e1, e2, w1, w2 = forearm_pose(0.2 + 0.3 * math.sin(2.0 * t), 1.0 * math.sin(1.5 * t))
            truth.append(np.stack([np.array([0.0, 0.32, 0.0]), e1, e2, w1, w2]))
        truth = np.array(truth)
        measured = np.ones((90, 5), dtype=bool)
        measured[30:, 3] = False
        est = Estimator([Method.NEIGHBOURS, Method.HINGE, Method.HINGE, Method.FOREARM, Method.FOREARM],
                        np.ones((5, 5)), segments=[(1, 2, 3, 4)],
                        hinges=[Hinge(1, 2, 0, (3, 4)), Hinge(2, 1, 0, (3, 4))],
                        forearms=[Forearm(3, 4, (1, 2)), Forearm(4, 3, (1, 2))], fps=30.0, scapular_rhythm=0.0,
                        drop_unpinned=False, axis_square=square)
        p, s = run(est, truth, measured, noise_m=0.0015, seed=seed)
        assert (s[30:, 3] == ESTIMATED).all()
        return float(np.sqrt(np.mean(np.sum((p[30:, 3] - truth[30:, 3]) ** 2, axis=1))))

    as_measured = np.mean([hidden_styloid_rms(0.0, seed) for seed in range(3)])
    square = np.mean([hidden_styloid_rms(1.0, seed) for seed in range(3)])
    assert as_measured > 0.008
    assert square < 0.75 * as_measured, (square, as_measured)
