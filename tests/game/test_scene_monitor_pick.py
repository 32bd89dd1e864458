"""The manual colour pick in the camera monitor, headless: simulated cameras under a warm cast and a
dim light that the nominal table loses the magenta balls in; Right arrows choose magenta, a click on a
magenta ball teaches it, the table is rebuilt (the ball is painted magenta on the screen where it
was not), the tracker link gets the colours, and Enter saves them into a calibration file."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.files import save_calibration_toml
from game.app import App, BaseScene, Services, Settings
from game.input import Action, Pointer, PointerKind, Press
from game.live_link import LinkState, LiveLink
from game.scenes.monitor import MonitorScene, image_to_screen
from tracking.colour.adapt import calibration_colours
from tracking.live import LiveSample, SourceConfig
from tracking.sim.body import reference_pose
from tracking.sim.studio import SimulationSettings, studio_from_settings

SIZE = (960, 540)
MAGENTA = [225, 0, 210]


class ImageLink:
    """Stands in for LiveLink: one frame set of simulated images and a sample of the true markers."""

    problem = LiveLink.problem  # the real words for the link's state

    def __init__(self, images, markerset, cameras, truth_m, source: SourceConfig) -> None:
        self.markerset, self.cameras, self._images = markerset, cameras, images
        self.state, self.error, self.warning = LinkState.RUNNING, "", ""
        m, c = markerset.n_markers, len(cameras)
        self.latest = LiveSample(frame_index=0, time_s=0.0, t_frame_ready_s=0.0, t_published_s=0.0, state=1,
                                 positions_m=truth_m, status=np.ones(m, np.uint8), angles_deg=np.zeros(0), message="",
                                 windows_px=np.full((m, c, 3), np.nan), uv_px=np.full((m, c, 2), np.nan),
                                 truth_m=truth_m, number=0, angle_names=())
        self.new_samples = []
        self.colours = []
        self.tracker = type("Tracker", (), {"source": source})()

    def tick(self) -> None:
        pass

    def summary(self) -> str:
        return "test link"

    def latest_images(self):
        return self._images

    def set_colours(self, models, label_hs) -> None:
        self.colours.append((models, label_hs))


@pytest.fixture(scope="module")
def cast_frame():
    studio, _ = studio_from_settings(SimulationSettings(motion="reference", size_px=(320, 240)))
    with studio:
        sf = studio.render(reference_pose(), 0, 0.0, exposure=0.6, colour_cast=(1.3, 1.0, 0.7), noise_sigma=1.5, seed=0)
    return studio.cameras, studio.markerset, sf


def test_a_click_on_a_magenta_ball_teaches_magenta(open_headless, cast_frame, tmp_path):
    cameras, markerset, sf = cast_frame
    calib = tmp_path / "calibration.toml"
    save_calibration_toml(calib, cameras)
    link = ImageLink(list(sf.frames.images), markerset, cameras, sf.markers_m,
                     SourceConfig(kind="cameras", devices=("0", "1", "2", "3"), calibration=str(calib)))
    screen = open_headless(SIZE)
    app = App(screen, Settings(show_fps=False, max_fps=0), services=Services(link), events=lambda: [])
    app.push(BaseScene())
    scene = MonitorScene(link, threaded=False)
    app.push(scene)
    scene._builder.join()   # the nominal table
    app.frame()
    app.frame()
    magenta = markerset.palette.tolist().index(MAGENTA)
    for _ in range(magenta):
        app.dispatch(Press(Action.RIGHT))
    assert scene.teach_colour == magenta
    # The most visible magenta ball in camera 1 (index 0), where it is on the screen.
    m = max((k for k in range(markerset.n_markers) if markerset.colour_index[k] == magenta),
            key=lambda k: sf.visible_fraction[0, k])
    uv = cameras[0].project(sf.markers_m[m][None])[0]
    ih, iw = sf.frames.images[0].shape[:2]
    xy = image_to_screen(uv[None], scene.rects[0], (iw, ih))[0]
    before = screen.read_rgb()[int(xy[1]) - 1 : int(xy[1]) + 2, int(xy[0]) - 1 : int(xy[0]) + 2].reshape(-1, 3).astype(int)
    labels = scene.colour_table.classify(sf.frames.images[0])
    assert labels[int(round(uv[1])), int(round(uv[0]))] == 0   # the nominal table misses the cast magenta

    app.dispatch(Pointer(PointerKind.PRESS, xy[0] / SIZE[0], xy[1] / SIZE[1], button=1))
    assert scene.manual is not None and scene.manual.picks[magenta] == 1, scene.message
    assert "Learnt magenta" in scene.message
    labels = scene.colour_table.classify(sf.frames.images[0])
    assert labels[int(round(uv[1])), int(round(uv[0]))] == magenta + 1
    # Every magenta ball the cameras see well is now found, in every camera.
    for c, cam in enumerate(cameras):
        labels = scene.colour_table.classify(sf.frames.images[c])
        for k in np.flatnonzero(markerset.colour_index == magenta):
            if sf.visible_fraction[c, k] > 0.9:
                u, v = cam.project(sf.markers_m[k][None])[0]
                assert labels[int(round(v)), int(round(u))] == magenta + 1
    (models, label_hs), = link.colours
    assert len(models) == markerset.palette.shape[0] and label_hs.shape == (256, 256)
    app.frame()
    after = screen.read_rgb()[int(xy[1]) - 1 : int(xy[1]) + 2, int(xy[0]) - 1 : int(xy[0]) + 2].reshape(-1, 3).astype(int)
    # Painted now, in the learnt magenta (the table's colour for it: the cast one, red and blue high, green low).
    painted = scene.colour_table.palette_rgb[magenta].astype(int)
    assert painted[0] > 150 and painted[2] > 80 and painted[1] < 60
    assert np.median(np.abs(after - painted).sum(axis=1)) < 30 < np.median(np.abs(before - painted).sum(axis=1))

    app.dispatch(Press(Action.SELECT))
    assert "saved" in scene.message
    models, _ = calibration_colours(calib, markerset)
    assert abs(models[magenta].hue_deg - scene.manual.models[magenta].hue_deg) < 0.01


def test_a_click_off_the_balls_says_why_and_learns_nothing(open_headless, cast_frame):
    cameras, markerset, sf = cast_frame
    link = ImageLink(list(sf.frames.images), markerset, cameras, sf.markers_m, SourceConfig())
    screen = open_headless(SIZE)
    app = App(screen, Settings(show_fps=False, max_fps=0), services=Services(link), events=lambda: [])
    app.push(BaseScene())
    scene = MonitorScene(link, paint_colours=False, threaded=False)
    app.push(scene)
    app.frame()
    x, y, w, h = scene.rects[1]
    app.dispatch(Pointer(PointerKind.PRESS, (x + 3) / SIZE[0], (y + 3) / SIZE[1], button=1))  # a corner: the wall
    assert scene.manual.picks.sum() == 0 and not link.colours
    assert scene.message.startswith(("No coloured pixel", "That coloured region", "Only"))
    app.dispatch(Press(Action.SELECT))
    assert "Nothing taught yet" in scene.message
