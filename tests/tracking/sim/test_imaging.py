"""What a webcam does to the image (tracking/sim/imaging.py), each effect on its own."""

import numpy as np
import pytest

import yaml

from tracking.colour.table import ColourTable
from tracking.sim.imaging import (AutoCamera, Webcam, WebcamPipeline, add_sensor_noise, drawn_webcam,
                                  exposure_offsets_s, integrate_exposure, jpeg_roundtrip)


def scene(h=240, w=320, seed=0):
    """A room-like image: a grey gradient, a darker body, coloured balls, sensor noise."""
    y, x = np.mgrid[0:h, 0:w]
    img = np.stack([90 + 40 * x / w, 100 + 30 * y / h, 110 - 20 * x / w], axis=-1)
    img[(x - w / 2) ** 2 / 60**2 + (y - h / 2) ** 2 / 90**2 < 1] = (40, 40, 45)
    rng = np.random.default_rng(seed)
    for _ in range(12):
        cx, cy = rng.uniform(20, w - 20), rng.uniform(20, h - 20)
        img[(x - cx) ** 2 + (y - cy) ** 2 < 36] = rng.choice([(0, 200, 230), (200, 40, 200), (40, 160, 40)])
    return add_sensor_noise(img.astype(np.float32), 1.5, rng)


def psnr(a, b):
    return 10 * np.log10(255.0**2 / np.mean((a.astype(float) - b.astype(float)) ** 2))


def test_jpeg_quality_lowers_psnr_monotonically():
    img = scene()
    values = [psnr(img, jpeg_roundtrip(img, q)) for q in (95, 85, 70, 50, 30, 15)]
    assert all(a > b for a, b in zip(values, values[1:])), values
    assert values[0] > 35 and values[-1] < 32
    # chroma at half resolution across and down loses more than across only, full resolution least
    by_chroma = [psnr(img, jpeg_roundtrip(img, 75, c)) for c in ("444", "422", "420")]
    assert by_chroma[0] > by_chroma[1] > by_chroma[2], by_chroma


def disc_at(cx, h=64, w=160, r=5.0):
    y, x = np.mgrid[0:h, 0:w]
    img = np.full((h, w, 3), 30, np.uint8)
    img[(x - cx) ** 2 + (y - 32) ** 2 < r * r] = 230
    return img


@pytest.mark.parametrize("speed_px_s, exposure_s", [(900.0, 0.03), (1500.0, 0.02), (600.0, 0.05)])
def test_blur_length_is_speed_times_exposure(speed_px_s, exposure_s):
    offsets = exposure_offsets_s(exposure_s, speed_px_s * exposure_s)
    assert len(offsets) % 2 == 1 and offsets[len(offsets) // 2] == 0.0
    assert offsets[-1] - offsets[0] == pytest.approx(exposure_s * (1 - 1 / len(offsets)))
    smear = integrate_exposure([disc_at(80 + speed_px_s * dt) for dt in offsets])[32, :, 0]
    # a disc smeared by L > its diameter is at half its contrast L/2 either side of the middle
    half = (smear.max() + 30) / 2
    above = np.flatnonzero(smear >= half)
    length = above[-1] - above[0] + 1
    assert length == pytest.approx(speed_px_s * exposure_s, abs=2.5)
    assert abs((above[-1] + above[0]) / 2 - 80) <= 1.0  # centred on the exposure's middle
    assert np.array_equal(integrate_exposure([disc_at(80)]), disc_at(80).astype(np.float32))


def test_auto_exposure_converges_and_overshoots_on_a_step():
    img = scene()
    cam = AutoCamera(Webcam(auto_exposure=True, lag_frames=3, loop_gain=0.3))
    target = img.mean()
    means = []
    for k in range(80):
        raw = img if k < 10 else (img * 0.6).astype(np.uint8)  # the light drops by 40 % at frame 10
        means.append(cam.apply(raw).mean())
    means = np.array(means)
    assert np.allclose(means[:10], target, rtol=1e-6)  # settled: the image as it comes
    assert means[10] < 0.65 * target  # the first dark image is not corrected yet (lag)
    assert means[10:].max() > 1.03 * target  # the loop overshoots ...
    assert abs(means[-10:].mean() / target - 1) < 0.02  # ... and settles again
    # it comes back up late: still dark for the lag
    assert np.all(means[10:13] < 0.7 * target)


def test_auto_white_balance_removes_a_cast_with_lag():
    img = scene()
    cam = AutoCamera(Webcam(auto_white_balance=True, lag_frames=2, loop_gain=0.3))
    cast = np.array([0.8, 1.0, 1.25])  # B, G, R: a warm light from frame 5
    ratio = []
    for k in range(60):
        raw = img if k < 5 else np.clip(img * cast, 0, 255).astype(np.uint8)
        out = cam.apply(raw).reshape(-1, 3).mean(axis=0)
        ratio.append(out[2] / out[0])
    first = img.reshape(-1, 3).mean(axis=0)
    assert ratio[5] > 1.4 * first[2] / first[0]
    assert ratio[-1] == pytest.approx(first[2] / first[0], rel=0.03)
    assert cam.gains_rgb[1] == pytest.approx(1.0)  # green is the reference


def test_gains_stay_bounded_even_when_the_loop_is_unstable():
    img = scene()
    cam = AutoCamera(Webcam(auto_exposure=True, lag_frames=4, loop_gain=1.0))  # beyond the stability limit
    for k in range(100):
        cam.apply(img if k < 3 else img // 8)
    assert 0.25 - 1e-9 <= cam.gains_rgb.min() and cam.gains_rgb.max() <= 4.0 + 1e-9
    with pytest.raises(ValueError):
        Webcam(jpeg_quality=0)


def test_pipeline_is_identity_when_ideal_and_records_gains():
    imgs = [scene(seed=s) for s in range(3)]
    out, gains = WebcamPipeline(Webcam(), 3).apply(imgs)
    assert gains is None and all(np.array_equal(a, b) for a, b in zip(out, imgs))
    out, gains = WebcamPipeline(Webcam(jpeg_quality=70, auto_exposure=True), 3).apply(imgs)
    assert gains.shape == (3, 3) and np.allclose(gains, 1.0)
    assert all(np.array_equal(a, jpeg_roundtrip(b, 70, "422")) for a, b in zip(out, imgs))


def test_drawn_webcams_follow_the_seed_and_stay_stable():
    a = [drawn_webcam(np.random.default_rng(s)) for s in range(200)]
    assert a[:5] == [drawn_webcam(np.random.default_rng(s)) for s in range(5)]
    for w in a:
        assert w.loop_gain < 2 * np.sin(np.pi / (2 * (2 * w.lag_frames + 1)))
    assert 0.6 < np.mean([w.jpeg_quality is not None for w in a]) < 0.95
    assert 0.3 < np.mean([w.auto_exposure for w in a]) < 0.7


class Shifted:
    """A motion started ``start_s`` later (the studio renders from 0)."""

    def __init__(self, motion, start_s):
        self.motion, self.start_s = motion, start_s
        self.duration_s = motion.duration_s - start_s

    def pose_at(self, t):
        return self.motion.pose_at(t + self.start_s)


def test_studio_smears_a_fast_ball_along_its_image_motion():
    """The fastest ball at its fastest: the image changes along its path over the exposure (the
    disc's leading and trailing edges), about its image motion plus its diameter long."""
    from tracking.sim.studio import SimulationSettings, studio_from_settings

    studio, motion = studio_from_settings(SimulationSettings(motion="shoulder_abduction", size_px=(640, 480)))
    with studio:
        times = np.arange(1.0, motion.duration_s - 1, 0.05)
        step = [np.linalg.norm(studio.body.markers_m(motion.pose_at(t + 0.01))
                               - studio.body.markers_m(motion.pose_at(t - 0.01)), axis=1) for t in times]
        k = int(np.argmax([s.max() for s in step]))
        t_fast, m = float(times[k]), int(np.argmax(step[k]))
        exposure = 0.03
        ends = [studio.body.markers_m(motion.pose_at(t_fast + s * exposure / 2))[m] for s in (-1, 1)]
        shots = [next(studio.play(Shifted(motion, t_fast), 30.0, seconds=0.0, noise_sigma=0.0, with_visibility=False,
                                  webcam=Webcam(exposure_s=e))).frames.images for e in (0.0, exposure)]
        ratios = []
        for c, cam in enumerate(studio.cameras):
            a, b = cam.project(np.stack(ends))
            length = float(np.linalg.norm(b - a))
            centre = studio.body.markers_m(motion.pose_at(t_fast))[m]
            depth = cam.world_to_camera(centre[None])[0, 2]
            diameter = 2 * cam.K[0, 0] * studio.markerset.radius_m / depth
            if length < 6 or not (0 < min(a[0], b[0]) and max(a[0], b[0]) < 640 and 0 < min(a[1], b[1]) < max(a[1], b[1]) < 480):
                continue
            changed = np.abs(shots[1][c].astype(int) - shots[0][c]).max(axis=2) > 25
            v, u = np.nonzero(changed)
            rel = np.stack([u, v], 1) - (a + b) / 2
            along = rel @ ((b - a) / length)
            across = rel @ (np.array([-(b - a)[1], (b - a)[0]]) / length)
            on_path = (np.abs(across) < diameter / 4) & (np.abs(along) < length + diameter)
            extent = along[on_path].max() - along[on_path].min() + 1
            ratios.append(extent / (length + diameter))
        # (where the moving forearm's own edges lie on the ball's path, the change runs longer)
        assert len(ratios) >= 3 and min(ratios) > 0.75 and 0.8 < np.median(ratios) < 1.2, ratios


def test_simulate_writes_the_webcam_and_its_gains(tmp_path):
    from tracking.sim.studio import SimulationSettings, simulate_recording

    settings = SimulationSettings(motion="reference", size_px=(160, 120), seconds=0.2, jpeg_quality=60,
                                  auto_exposure=True, brightness_drop=0.5, drift_s=0.1)
    simulate_recording(tmp_path, settings)
    meta = yaml.safe_load((tmp_path / "meta.yaml").read_text())
    assert meta["webcam"]["jpeg_quality"] == 60 and meta["webcam"]["auto_exposure"] is True
    rows = (tmp_path / "truth_camera_gains.csv").read_text().splitlines()
    assert rows[0] == "frame,camera,gain_r,gain_g,gain_b" and len(rows) == 1 + 7 * 4
    assert float(rows[-1].split(",")[2]) > 1.05  # the camera brightens the darker room
    plain = tmp_path / "plain"
    simulate_recording(plain, SimulationSettings(motion="reference", size_px=(160, 120), seconds=0.2))
    assert "webcam" not in yaml.safe_load((plain / "meta.yaml").read_text())
    assert not (plain / "truth_camera_gains.csv").exists()


def test_population_draws_their_imaging_from_a_stream_of_their_own():
    from tracking.sim.population import draw_imaging

    a, b = draw_imaging(100_123, 30), draw_imaging(100_123, 30)
    assert a == b and a != draw_imaging(100_124, 30)
    assert a.light(0)["exposure"] == 1.0 and a.light(0)["colour_cast"] == (1.0, 1.0, 1.0)
    assert a.light(29)["exposure"] == pytest.approx(1.0 + a.brightness_change)
    assert all(1.5 <= draw_imaging(s, 30).noise_sigma <= 4.0 for s in range(50))
