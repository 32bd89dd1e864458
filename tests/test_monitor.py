"""The camera monitor: colour regions, search windows, marker labels and titles drawn on images."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from game.gfx.camera_overlay import MonitorTexture, grid_shape, overlay_camera, overlay_cameras, paint_labels, tile_images
from tracking.colour.table import ColourTable
from tracking.marker_status import MarkerStatus

NAMES = ("MA", "MB", "MC")
RGB = np.array([[0, 200, 70], [225, 0, 210], [0, 190, 235]], np.uint8)


def grey(w: int = 320, h: int = 240) -> np.ndarray:
    return np.full((h, w, 3), 100, np.uint8)


def test_search_windows_are_drawn_where_the_tracker_put_them():
    win = np.array([[100.0, 80.0, 12.0], [np.nan] * 3, [250.5, 150.25, 20.0]])
    img = grey()
    out = overlay_camera(img, NAMES, RGB, windows_px=win)
    changed = np.abs(out.astype(int) - img).sum(axis=2) > 30
    # Each square's edges changed, its inside and far away did not.
    for u, v, half in win[[0, 2]]:
        for px in ((u - half, v), (u + half, v), (u, v - half), (u, v + half)):
            c, r = int(round(px[0])), int(round(px[1]))
            assert changed[r - 1 : r + 2, c - 1 : c + 2].any()
        assert not changed[int(v) - 3 : int(v) + 4, int(u) - 3 : int(u) + 4].any()
    assert not changed[200:, :60].any()
    # In the marker's colour (BGR): the first window's left edge is green.
    edge = out[74:86, 87:90].reshape(-1, 3).astype(int)
    assert (edge[:, 1] - edge[:, 2]).max() > 80
    assert (img == 100).all()  # the input is untouched


def test_labels_and_footer_name_the_markers():
    uv = np.array([[60.0, 60.0], [np.nan, np.nan], [200.0, 120.0]])
    status = np.array([MarkerStatus.MEASURED, MarkerStatus.LOST, MarkerStatus.ESTIMATED], np.uint8)
    out = overlay_camera(grey(), NAMES, RGB, uv_px=uv, status=status, title="cam1", footer="not seen here: MB")
    diff = np.abs(out.astype(int) - 100).sum(axis=2) > 30
    assert diff[48:60, 64:110].any()  # text right of and above the first centroid
    assert diff[108:120, 204:250].any()
    assert diff[:20, :60].any()  # title
    assert diff[-16:, :120].any()  # footer
    assert not diff[150:200, 20:60].any()


@pytest.mark.parametrize("width", [320, 640, 1280])
def test_text_outline_ends_where_the_text_ends(width):
    """Issue 25: the camera check's footer showed leftover letters after its text ("... MRW2 W2"):
    the dark outline, drawn as the same text with thicker strokes, was wider than the text. Every
    dark pixel of the title and footer lies within a pixel or two of the text's own letters."""
    img = grey(width, 240)
    footer = "not seen here: MB, MP, MLE1, MLE2, MLW1, MLW2, MRW1, MRW2"
    out = overlay_camera(img, NAMES, RGB, title="cam1  TRACKING", footer=footer)
    bgr = out.astype(int)
    dark = (bgr < 60).all(axis=2)                      # the outline (the image is grey 100)
    light = (bgr > 140).any(axis=2)                    # the letters (white title, pale blue footer)
    for rows in (slice(0, 60), slice(180, 240)):       # the title's band, the footer's band
        d_cols, l_cols = np.flatnonzero(dark[rows].any(axis=0)), np.flatnonzero(light[rows].any(axis=0))
        assert l_cols.size and d_cols.size
        assert d_cols.max() <= l_cols.max() + 2 and d_cols.min() >= l_cols.min() - 2, (d_cols.max(), l_cols.max())
        # and the outline surrounds the letters: most pixels just around them are dark
        near = cv2.dilate(light[rows].astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & ~light[rows]
        assert dark[rows][near].mean() > 0.5


def test_colour_regions_are_painted_in_the_palette_colour():
    table = ColourTable.build(RGB)
    img = grey()
    img[50:60, 50:60] = RGB[1, ::-1]  # a magenta patch (BGR)
    labels = table.classify(img)
    out = paint_labels(img, labels, table.palette_rgb)
    assert (out[55, 55] == RGB[1, ::-1]).all()
    assert (out[100, 100] < 100).all()  # the rest is dimmed


def test_overlay_cameras_uses_each_cameras_windows_and_lists_lost_markers():
    m, c = len(NAMES), 2
    win = np.full((m, c, 3), np.nan)
    win[0, 1] = (160.0, 120.0, 15.0)
    uv = np.full((m, c, 2), np.nan)
    uv[0, 1] = (160.0, 120.0)
    status = np.array([1, 0, 1], np.uint8)
    images = [grey(), grey()]
    out = overlay_cameras(images, NAMES, RGB, windows_px=win, uv_px=uv, status=status, state=1,
                          message="", colour_table=ColourTable.build(RGB))
    assert len(out) == 2
    # The window only in camera 2.
    assert np.abs(out[1][105, 150:170].astype(int) - out[1][200, 150:170]).sum() > 0
    edge0 = out[0][105, 150:170].astype(int)
    assert (edge0 == edge0[0]).all()


def test_tiles_and_grid_shape():
    assert grid_shape(4) == (2, 2)
    assert grid_shape(3)[0] * grid_shape(3)[1] >= 3
    a, b = grey(), np.zeros((120, 160, 3), np.uint8)
    out = tile_images([a, b, a], columns=2, gap_px=4)
    assert out.shape == (2 * 240 + 4, 2 * 320 + 4, 3)
    assert (out[0, 0] == 100).all() and (out[0, 330] == 0).all()
    with pytest.raises(ValueError):
        tile_images([])


def test_bad_images_are_rejected():
    with pytest.raises(ValueError, match="uint8"):
        overlay_camera(np.zeros((10, 10)), NAMES, RGB)


def test_monitor_texture_shows_the_image_in_its_viewport():
    from tracking.sim.renderer import OffscreenGLUnavailable, create_context

    try:
        ctx = create_context()
    except OffscreenGLUnavailable as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))
    fbo = ctx.framebuffer(color_attachments=[ctx.renderbuffer((200, 100))])
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 1.0)
    img = np.zeros((30, 41, 3), np.uint8)  # odd width: rows are not 4-byte aligned
    img[:15] = (255, 0, 0)  # top half blue (BGR)
    img[15:] = (0, 0, 255)  # bottom half red
    tex = MonitorTexture(ctx)
    tex.upload(img)
    assert tex.size == (41, 30)
    tex.draw((100, 0, 100, 100))  # right half of the framebuffer
    out = np.frombuffer(fbo.read(components=3), np.uint8).reshape(100, 200, 3)[::-1]  # RGB, top row first
    assert (out[50, 50] == 0).all()  # left half untouched
    assert out[10, 150, 2] > 200 and out[10, 150, 0] < 50  # top: blue
    assert out[90, 150, 0] > 200 and out[90, 150, 2] < 50  # bottom: red
    tex.release()
    fbo.release()
    ctx.release()


def test_window_arrays_must_match_markers_and_cameras():
    with pytest.raises(ValueError, match=r"\(3, 2, 3\)"):
        overlay_cameras([grey(), grey()], NAMES, RGB, windows_px=np.zeros((3, 4, 3)))
