"""Free-running cameras and rolling shutters in the simulated studio: each image shows its instant."""

import numpy as np
import pytest

from calibration.files import load_calibration
from tracking.colour.table import ColourTable
from tracking.full_frame import FrameMeasurer
from tracking.io.recording import read_timestamps
from tracking.sim.clocks import CameraClocks
from tracking.sim.studio import SimulationSettings, simulate_recording, studio_from_settings

FPS = 30.0


def test_capture_times_stay_within_half_a_period_and_drift():
    clocks = CameraClocks((0.0, 0.45, -0.3), (0.0, 0.001, -0.001), (0.0, 0.0, 0.0))
    nominal = np.arange(3000) / FPS
    stamps = np.stack([clocks.capture_times(i, FPS) for i in range(3000)])
    skew = (stamps - nominal[:, None]) * FPS  # frame periods
    assert np.all(np.abs(skew) <= 0.5 + 1e-9)
    assert skew[0] == pytest.approx([0.0, 0.45, -0.3])
    # camera 2 runs 0.1 % slow: its phase grows by 0.001 frame per frame until it wraps (one image twice)
    assert skew[40, 1] - skew[0, 1] == pytest.approx(0.04, abs=1e-9)
    assert (np.diff(stamps[:, 1]) == 0).sum() >= 1
    assert (np.diff(stamps[:, 2]) > 1.5 / FPS).sum() >= 1  # the fast one skips one
    assert np.all(CameraClocks.synchronized(3).capture_times(7, FPS) == 7 / FPS)


def test_drawn_clocks_follow_the_seed():
    a = CameraClocks.drawn(4, 3, drift=0.001, readout_s=0.025)
    assert a == CameraClocks.drawn(4, 3, drift=0.001, readout_s=0.025)
    assert a != CameraClocks.drawn(4, 4, drift=0.001, readout_s=0.025)
    assert max(map(abs, a.offsets_frames)) <= 0.5 and max(map(abs, a.rate_error)) <= 0.001
    assert a.readout_s == (0.025,) * 4


def row_instant_markers(studio, motion, cam, stamp, readout, n_iter=4):
    """Each marker where it is at the instant of its own image row, by exact poses (not the
    renderer's linear interpolation)."""
    p = studio.body.markers_m(motion.pose_at(stamp))
    out = p.copy()
    for m in range(len(p)):
        t = stamp
        for _ in range(n_iter):
            q = studio.body.markers_m(motion.pose_at(t))[m]
            t = stamp + readout * cam.project(q[None])[0, 1] / cam.size_px[1]
        out[m] = studio.body.markers_m(motion.pose_at(t))[m]
    return out


def test_each_image_shows_its_own_instant_and_rows():
    settings = SimulationSettings(motion="shoulder_flexion", size_px=(320, 240), fps=FPS)
    studio, motion = studio_from_settings(settings)
    # ten of the frame sets where the arm moves fastest
    n = int(motion.duration_s * FPS)
    speed = [np.abs(studio.body.markers_m(motion.pose_at((i + 0.5) / FPS))
                    - studio.body.markers_m(motion.pose_at((i - 0.5) / FPS))).max() for i in range(1, n, 3)]
    frames = 1 + 3 * np.argsort(speed)[-10:]
    clocks = CameraClocks((0.0, 0.45, -0.45, 0.3), (0.0,) * 4, (0.0, 0.025, 0.025, 0.0))
    ms = studio.markerset
    measurer = FrameMeasurer(studio.cameras, ColourTable.build(ms.palette), ms.radius_m)
    at_own, at_nominal = [], []
    with studio:
        for i in frames.tolist():
            scenes = studio.timed_scenes(motion, i, FPS, clocks)
            sf = studio.render(motion.pose_at(i / FPS), i, i / FPS, camera_scenes=scenes, noise_sigma=0.0)
            assert np.allclose(sf.markers_m, studio.body.markers_m(motion.pose_at(i / FPS)))
            blobs = measurer.blobs(sf.frames.images)
            for c, cam in enumerate(studio.cameras):
                own = row_instant_markers(studio, motion, cam, sf.stamps_s[c], clocks.readout_s[c])
                whole = (sf.visible_fraction[c] > 0.97) & ~sf.merged[c]
                for m in np.flatnonzero(whole):
                    same = blobs[c].colour == ms.colour_index[m]
                    d_own = np.linalg.norm(blobs[c].uv_px[same] - cam.project(own[m][None])[0], axis=1).min()
                    d_nom = np.linalg.norm(blobs[c].uv_px[same] - cam.project(sf.markers_m[m][None])[0],
                                           axis=1).min()
                    at_own.append(d_own)
                    at_nominal.append(d_nom)
    at_own, at_nominal = np.array(at_own), np.array(at_nominal)
    moving = np.abs(at_nominal - at_own) > 0.5  # balls that moved half a pixel between the instants
    assert moving.sum() > 30
    # the centroids sit where the balls are at their own instants (sub-pixel), not at the frame set's
    assert np.median(at_own[moving]) < 0.2 and np.percentile(at_own[moving], 90) < 0.4
    assert np.median(at_nominal[moving]) > 0.8


def test_simulate_writes_the_stamps_the_clocks_and_the_readout(tmp_path):
    settings = SimulationSettings(motion="right_external_rotation", size_px=(320, 240), fps=FPS, seconds=0.5,
                                  camera_offsets=(0.0, 0.4, -0.3, 0.2), clock_drift=0.001,
                                  rolling_shutter_s=0.025, images=True, seed=5)
    simulate_recording(tmp_path / "rec", settings)
    cams = load_calibration(tmp_path / "rec" / "calibration.toml")
    assert [c.rolling_shutter_s for c in cams] == [0.025] * 4
    times, stamps = read_timestamps(tmp_path / "rec", [c.name for c in cams])
    clocks = settings.clocks(4)
    assert times == pytest.approx(np.arange(16) / FPS, abs=1e-6)
    assert stamps == pytest.approx(np.stack([clocks.capture_times(i, FPS) for i in range(16)]), abs=1e-6)
    assert stamps[0] == pytest.approx(np.array([0.0, 0.4, -0.3, 0.2]) / FPS, abs=1e-6)
