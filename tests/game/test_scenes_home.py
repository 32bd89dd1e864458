"""The home screen driven through actions and pointer events, and what it draws."""

from __future__ import annotations

import numpy as np
import pytest

from game.app import App, BaseScene, Settings
from game.gfx import theme
from game.gfx.screen import GraphicsUnavailable, open_screen
from game.input import Action, Pointer, PointerKind, Press
from game.scenes.home import HomeScene, MenuEntry, hit, menu_rects

SIZE = (640, 360)


@pytest.fixture
def app(monkeypatch):
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    try:
        screen = open_screen(SIZE, "test", headless=True)
    except GraphicsUnavailable as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))
    a = App(screen, Settings(show_fps=False), clock=lambda: 0.0, events=lambda: [])
    yield a
    a.close()
    screen.close()


class Mode(BaseScene):
    def __init__(self, name):
        self.name = name

    def handle(self, event):
        if isinstance(event, Press) and event.down and event.action is Action.BACK:
            self.app.pop()


def home_for(app) -> HomeScene:
    home = HomeScene([
        MenuEntry("Live avatar", "See yourself move", lambda: Mode("live")),
        MenuEntry("Camera check", "What the cameras see", lambda: Mode("cameras")),
        MenuEntry("Quit", "", None),
    ], status=lambda: "Simulated patient: tracking")
    app.push(home)
    return home


def test_keyboard_navigation_opens_modes_and_comes_back(app):
    home = home_for(app)
    app.dispatch(Press(Action.UP))
    assert home.selected == 2                       # wraps around
    app.dispatch(Press(Action.DOWN))
    app.dispatch(Press(Action.DOWN))
    app.dispatch(Press(Action.DOWN, down=False))    # releases do nothing
    assert home.selected == 1
    app.dispatch(Press(Action.SELECT))
    assert isinstance(app.scene, Mode) and app.scene.name == "cameras"
    app.dispatch(Press(Action.BACK))
    assert app.scene is home and app.running
    app.dispatch(Press(Action.DOWN))
    app.dispatch(Press(Action.SELECT))              # "Quit"
    assert not app.running


def test_escape_on_home_asks_first_and_a_second_escape_quits(monkeypatch):
    """One Esc too many (coming back from a mode) only asks; a second within 3 s quits, a second
    later than that asks again."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    try:
        screen = open_screen(SIZE, "test", headless=True)
    except GraphicsUnavailable as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))
    now = [0.0]
    app = App(screen, Settings(show_fps=False), clock=lambda: now[0], events=lambda: [])
    try:
        home = home_for(app)
        app.dispatch(Press(Action.BACK))
        assert app.running and home.quit_asked
        app.frame()
        words = screen.read_rgb().astype(int)[SIZE[1] - 40:, :]
        assert (np.abs(words - theme.ATTENTION).max(axis=2) < 40).sum() > 50   # "Press Esc again to quit"
        now[0] = 5.0                                          # too late: asks again
        app.dispatch(Press(Action.BACK))
        assert app.running and home.quit_asked
        now[0] = 6.0
        app.dispatch(Press(Action.BACK))
        assert not app.running
    finally:
        app.close()
        screen.close()


def test_opening_a_mode_says_so_while_it_is_built(app):
    """A mode that takes a while to build: the screen shows "Opening ..." over the home screen
    while it is built, then the mode is on top."""
    seen = []

    def slow():
        rgb = app.screen.read_rgb().astype(int)
        h, w = rgb.shape[:2]
        middle = rgb[h // 2 - 20:h // 2 + 20, w // 2 - 150:w // 2 + 150]
        seen.append(int((middle.min(axis=2) > 200).sum()))   # light text of the words in the middle
        return Mode("slow")

    home = HomeScene([MenuEntry("Slow mode", "takes seconds", slow), MenuEntry("Quit", "", None)])
    app.push(home)
    app.frame()
    app.dispatch(Press(Action.SELECT))
    assert isinstance(app.scene, Mode) and app.scene.name == "slow"
    assert seen and seen[0] > 50


def test_mouse_hover_selects_and_click_opens(app):
    home = home_for(app)
    rects = menu_rects(SIZE, 3)
    x, y, w, h = rects[1]
    centre = ((x + w / 2) / SIZE[0], (y + h / 2) / SIZE[1])
    app.dispatch(Pointer(PointerKind.MOVE, *centre))
    assert home.selected == 1 and app.scene is home
    app.dispatch(Pointer(PointerKind.MOVE, 0.01, 0.01))   # outside every button: selection stays
    assert home.selected == 1
    x, y, w, h = rects[0]
    app.dispatch(Pointer(PointerKind.PRESS, (x + 5) / SIZE[0], (y + 5) / SIZE[1], button=1))
    assert isinstance(app.scene, Mode) and app.scene.name == "live"


def test_hit():
    rects = [(0, 0, 10, 10), (0, 20, 10, 10)]
    assert hit(rects, 5, 5) == 0 and hit(rects, 5, 25) == 1 and hit(rects, 5, 15) is None


def test_home_draws_the_selected_button_highlighted(app):
    home = home_for(app)
    app.dispatch(Press(Action.DOWN))
    app.run(frames=3)
    rgb = app.screen.read_rgb().astype(int)
    rects = menu_rects(SIZE, 3)

    def border_pixel(i):
        x, y, w, h = rects[i]
        return rgb[int(y + h / 2), int(x + 1)]

    assert np.abs(border_pixel(1) - theme.ACCENT).max() < 40          # selected: accent border
    assert np.abs(border_pixel(0) - theme.ACCENT).max() > 60
    x, y, w, h = rects[0]
    label = rgb[int(y + 8):int(y + h / 2), int(x + 20):int(x + w / 2)]
    assert (label.max(axis=2) > 130).sum() > 100                       # the label's text is drawn
    assert home.selected == 1


def test_the_patient_picker_counts_in_words():
    """Issue 25's walk-through: the picker read "1 ROM results, 1 games"."""
    from game.scenes.patients import patient_counts

    assert patient_counts(1, 1) == "1 ROM result, 1 game"
    assert patient_counts(0, 2) == "0 ROM results, 2 games"
