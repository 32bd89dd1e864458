"""The interim ``rehab play`` viewer: drawing on synthetic data, pacing with a fake clock, the
headless command end to end (pixels of the screenshot), and the one-line no-display path.

All headless: SDL's dummy video driver, the studio on EGL (llvmpipe).
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pygame
import pytest

from game import display
from game.cli import main
from game.viewer import (
    WINDOW_SIZE,
    Action,
    Fonts,
    Layout,
    LiveFrame,
    LiveSimulation,
    Playhead,
    PlayOptions,
    RigInfo,
    Status,
    actions_from_events,
    draw_live_view,
    frame_count,
    nearest_distance_m,
    stick_figure_links,
)
from tracking.blobs import Blobs
from tracking.markerset import load_markerset
from tracking.reconstruction import Points3D
from tracking.sim.rigs import load_rig

IMAGE_PX = (320, 240)


class FakeClock:
    """A clock the test moves by hand."""

    def __init__(self, now_s: float = 100.0) -> None:
        self.now_s = now_s

    def __call__(self) -> float:
        return self.now_s


@pytest.fixture
def dummy_video(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    yield
    pygame.quit()


@pytest.fixture
def fonts(dummy_video):
    pygame.font.init()
    return Fonts.load()


@pytest.fixture(scope="module")
def egl():
    from tracking.sim.renderer import OffscreenGLUnavailable, create_context

    try:
        create_context().release()
    except OffscreenGLUnavailable as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))


def pixel_rgb(surface_or_image, xy) -> tuple[int, int, int]:
    x, y = (int(round(v)) for v in xy)
    if isinstance(surface_or_image, pygame.Surface):
        return tuple(surface_or_image.get_at((x, y)))[:3]
    b, g, r = surface_or_image[y, x]
    return int(r), int(g), int(b)


# --------------------------------------------------------------------------- drawing
def synthetic_frame():
    """Four ring4 cameras looking at three known points; the images are noise, the centroids the
    exact projections of the points."""
    rng = np.random.default_rng(3)
    cams = load_rig("ring4", IMAGE_PX)
    ms = load_markerset()
    p_world_m = np.array([[0.10, 1.20, -0.05], [-0.15, 1.00, -0.10], [0.20, 0.80, -0.20]])
    colour = np.array([0, 1, 3])
    images, blobs = [], []
    for cam in cams:
        images.append(rng.integers(40, 90, (IMAGE_PX[1], IMAGE_PX[0], 3), dtype=np.uint8))
        uv = cam.project(p_world_m)
        n = len(uv)
        blobs.append(Blobs(uv, np.full(n, 30.0), colour.copy(), np.ones(n), np.full(n, 3.0)))
    points = Points3D(p_world_m, colour, np.full(3, 4), np.full(3, 0.2), np.zeros((3, 4), int))
    truth = np.zeros((ms.n_markers, 3)) + [0.0, 1.0, 0.0]
    truth[:3] = p_world_m + 0.002
    frame = LiveFrame(
        index=7, motion="right_external_rotation", time_s=0.5, duration_s=12.5, images=tuple(images),
        blobs=tuple(blobs), points=points, truth_m=truth, error_m=nearest_distance_m(p_world_m, truth),
        extent_m=np.array([[-0.6, 0.4, -0.5], [0.6, 1.6, 0.2]]), render_s=0.02, measure_s=0.01,
    )
    rig = RigInfo(cams, ms.palette, ms.colour_index, stick_figure_links(ms.names))
    return frame, rig


def test_draw_live_view_marks_centroids_and_reprojected_points(fonts):
    frame, rig = synthetic_frame()
    surface = pygame.Surface(WINDOW_SIZE)
    layout = draw_live_view(surface, frame, rig, Status(simulation_fps=50.0, measurement_fps=80.0), fonts)
    assert len(layout.tiles) == 4
    for tile, cam, blobs in zip(layout.tiles, rig.cameras, frame.blobs):
        assert tile.rect.right <= round(WINDOW_SIZE[0] * 2 / 3)
        xy = tile.to_screen(cam.project(frame.points.p_world_m))
        for (x, y), k in zip(xy, frame.points.colour):
            rgb = tuple(int(v) for v in rig.palette_rgb[k])
            # The cross's centre and arms, in the marker's colour ...
            assert pixel_rgb(surface, (x, y)) == rgb
            assert pixel_rgb(surface, (x + 4, y)) == rgb
            assert pixel_rgb(surface, (x, y - 4)) == rgb
        for (x, y), r_px, k in zip(tile.to_screen(blobs.uv_px), blobs.radius_px, blobs.colour):
            # ... and the centroid's circle around it.
            r = int(round(max(r_px * tile.scale + 5, 7)))
            ring = [pixel_rgb(surface, (x + (r - 1) * math.cos(a), y + (r - 1) * math.sin(a))) for a in np.radians([45, 135, 225, 315])]
            assert tuple(int(v) for v in rig.palette_rgb[k]) in ring


def test_tile_mapping_follows_the_opencv_pixel_convention():
    layout = Layout.for_window(WINDOW_SIZE, IMAGE_PX, 4)
    tile = layout.tiles[1]
    corners = tile.to_screen(np.array([[-0.5, -0.5], [IMAGE_PX[0] - 0.5, IMAGE_PX[1] - 0.5]]))
    np.testing.assert_allclose(corners[0], np.array(tile.rect.topleft) - 0.5)
    np.testing.assert_allclose(corners[1], np.array(tile.rect.bottomright) - 0.5)
    # Tiles keep the image's aspect and do not overlap the status column or each other.
    rects = [t.rect for t in layout.tiles]
    assert all(abs(r.w / r.h - 4 / 3) < 0.01 for r in rects)
    assert all(not a.colliderect(b) for i, a in enumerate(rects) for b in rects[i + 1:])
    assert all(not r.colliderect(layout.status) and not r.colliderect(layout.views) for r in rects)


# --------------------------------------------------------------------------- pacing and keys
def test_playhead_steps_when_headless():
    clock = FakeClock()
    ph = Playhead(15.0, clock, realtime=False)
    clock.now_s += 10.0  # wall time does not matter
    ph.advance()
    assert ph.index == 1 and ph.wait_s() == 0.0


def test_playhead_realtime_waits_skips_and_pauses():
    clock = FakeClock()
    ph = Playhead(10.0, clock, realtime=True)
    ph.advance()
    assert ph.index == 1 and ph.wait_s() == pytest.approx(0.1)
    clock.now_s += 0.55  # the loop fell behind: frames 2..4 are skipped, frame 5 is due
    assert ph.advance() == 3 and ph.index == 5 and ph.wait_s() == pytest.approx(0.0)
    ph.set_paused(True)
    clock.now_s += 60.0
    ph.set_paused(False)
    ph.advance()
    assert ph.index == 6 and ph.wait_s() == pytest.approx(0.05)
    ph.restart()
    assert ph.index == 0


def test_keys_become_actions():
    events = [
        pygame.event.Event(pygame.KEYDOWN, key=pygame.K_SPACE),
        pygame.event.Event(pygame.KEYDOWN, key=pygame.K_RIGHT),
        pygame.event.Event(pygame.KEYDOWN, key=pygame.K_x),
        pygame.event.Event(pygame.KEYDOWN, key=pygame.K_r),
        pygame.event.Event(pygame.KEYDOWN, key=pygame.K_q),
        pygame.event.Event(pygame.QUIT),
    ]
    assert actions_from_events(events) == [Action.TOGGLE_PAUSE, Action.NEXT_MOTION, Action.RESTART, Action.QUIT, Action.QUIT]


# --------------------------------------------------------------------------- display detection
@pytest.mark.parametrize(
    ("environ", "platform", "expected"),
    [
        ({}, "linux", False),
        ({"DISPLAY": ":0"}, "linux", True),
        ({"WAYLAND_DISPLAY": "wayland-0"}, "linux", True),
        ({"DISPLAY": ":0", "SDL_VIDEODRIVER": "dummy"}, "linux", False),
        ({"SDL_VIDEODRIVER": "kmsdrm"}, "linux", True),
        ({}, "win32", True),
        ({}, "darwin", True),
    ],
)
def test_has_display(environ, platform, expected):
    assert display.has_display(environ, platform) is expected


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="DISPLAY decides only on Linux")
def test_play_without_display_says_so_in_one_line(monkeypatch, capsys):
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER"):
        monkeypatch.delenv(name, raising=False)

    def must_not_open(*args, **kwargs):
        raise AssertionError("the no-display check must come before SDL's display")

    monkeypatch.setattr(pygame.display, "init", must_not_open)
    monkeypatch.setattr(pygame.display, "set_mode", must_not_open)
    assert main(["play"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("rehab: ") and display.NO_DISPLAY_MESSAGE in err
    assert "rehab play --headless --seconds 5 --screenshot play.png" in err


# --------------------------------------------------------------------------- end to end
def test_play_headless_writes_the_screenshot(egl, dummy_video, tmp_path, capsys):
    shot = tmp_path / "x.png"
    assert main(["play", "--headless", "--seconds", "1", "--screenshot", str(shot)]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1 and out[0].startswith("rehab play: played 15 frame sets")

    image = cv2.imread(str(shot))
    assert image is not None and image.shape == (WINDOW_SIZE[1], WINDOW_SIZE[0], 3)
    layout = Layout.for_window(WINDOW_SIZE, IMAGE_PX, 4)
    for tile in layout.tiles:
        r = tile.rect
        assert image[r.top:r.bottom, r.left:r.right].std() > 10.0, "a camera tile is uniform"

    # The same frame again (the simulation is deterministic): its measured points, reprojected
    # into every camera, sit under crosses of their marker's colour in the screenshot.
    with LiveSimulation.create(PlayOptions(), clock=FakeClock()) as sim:
        frame = sim.frame(frame_count(1.0, 15.0) - 1)
        palette = sim.rig.palette_rgb
        cams = sim.rig.cameras
    assert len(frame.points) >= 8
    hits = total = 0
    for tile, cam in zip(layout.tiles, cams):
        uv = cam.project(frame.points.p_world_m)
        inside = np.isfinite(uv).all(axis=1) & (uv >= 0).all(axis=1) & (uv < IMAGE_PX).all(axis=1)
        for (x, y), k in zip(tile.to_screen(uv[inside]), frame.points.colour[inside]):
            total += 1
            hits += pixel_rgb(image, (x, y)) == tuple(int(v) for v in palette[k])
    assert total >= 20
    # A later cross's arm may cover an earlier cross's centre where two points project together.
    assert hits >= 0.85 * total, f"{hits} of {total} reprojected points carry their colour"


@pytest.mark.parametrize("image_px", [(320, 240), (640, 480), (1280, 720), (333, 250)])
def test_tiles_fit_any_image_size(image_px):
    for n in (2, 3, 4, 6):
        layout = Layout.for_window(WINDOW_SIZE, image_px, n)
        for tile in layout.tiles:
            assert tile.rect.w > 100 and abs(tile.rect.w / tile.rect.h - image_px[0] / image_px[1]) < 0.01
            assert tile.rect.bottom <= layout.help.top and tile.rect.right <= layout.status.left


def test_keys_drive_the_loop(egl, dummy_video, tmp_path):
    """Right arrow switches motion, Space pauses (no new frames), Q quits; the keys arrive while
    the loop sleeps, as from a user."""
    from game.viewer import PAUSED_POLL_S, run_viewer

    keys = {1: pygame.K_RIGHT, 2: pygame.K_SPACE, 5: pygame.K_q}
    naps: list[float] = []

    def sleep(seconds: float) -> None:
        naps.append(seconds)
        if len(naps) in keys:
            pygame.event.post(pygame.event.Event(pygame.KEYDOWN, key=keys[len(naps)]))

    shot = tmp_path / "keys.png"
    summary = run_viewer(PlayOptions(headless=True, screenshot=shot), clock=FakeClock(), sleep=sleep)
    assert summary.frames == 2  # the first motion's frame 0, then the next motion's frame 0
    assert naps[2:5] == [PAUSED_POLL_S] * 3
    assert shot.is_file()


@pytest.mark.skipif(shutil.which("xvfb-run") is None, reason="needs Xvfb (apt-get install xvfb)")
def test_real_x11_window_leaves_the_studio_context_alone(egl, tmp_path):
    """Regression: SDL presented the X11 window through its own GLX renderer, which displaced the
    studio's EGL context on the same thread (BadAccess or a crash in moderngl). Studio first,
    window second made it fail every time."""
    script = tmp_path / "x11.py"
    script.write_text(
        "import numpy as np, pygame\n"
        "from game.display import open_window, close_window\n"
        "from tracking.sim.studio import SimulationSettings, studio_from_settings\n"
        "studio, motion = studio_from_settings(SimulationSettings(size_px=(160, 120)))\n"
        "surface = open_window((320, 240), 'test', headless=False)\n"
        "for i in range(3):\n"
        "    images = studio.render(motion.pose_at(i / 15), i, i / 15).frames.images\n"
        "    surface.fill((int(np.mean(images[0])), 0, 0))\n"
        "    pygame.display.flip()\n"
        "studio.close()\n"
        "close_window()\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("SDL_VIDEODRIVER", "SDL_FRAMEBUFFER_ACCELERATION")}
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[2])
    run = subprocess.run(["xvfb-run", "-a", sys.executable, str(script)], env=env, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
