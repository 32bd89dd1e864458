"""The game menu drawn: the games, the Play button and the therapist's limits in large type; the
mouse changes a limit with its + and - and the change is stored for the patient. The rotation
game's river on the screen: the mouse steering, the boat on the water, gates that fit the boat
exactly within their tolerance."""

from __future__ import annotations

import pytest

from game.app import App, Settings
from game.db import Database
from game.exergames.limits import LIMIT_KEYS, load_limits
from game.input import Pointer, PointerKind
from game.scenes.game_menu import ChooseGameScene

SIZE = (1280, 720)


@pytest.fixture
def menu_app(open_headless, tmp_path):
    db_path = tmp_path / "rehab.sqlite3"
    with Database(db_path) as db:
        db.add_patient("P001")
    opened = []
    app = App(open_headless(SIZE), Settings(show_fps=False), clock=lambda: 0.0, events=lambda: [])
    menu = ChooseGameScene("P001", lambda spec, pid, **kw: opened.append((spec.name, kw)) or _Dummy(), db_path=db_path)
    app.push(menu)
    yield app, menu, db_path, opened
    app.close()


class _Dummy:
    def __getattr__(self, name):
        return lambda *a, **k: None


def _click(menu, app, x, y):
    w, h = SIZE
    menu.handle(Pointer(PointerKind.PRESS, x / w, y / h, button=1))


def test_mouse_sets_a_limit_stores_it_and_plays(menu_app, tmp_path):
    app, menu, db_path, opened = menu_app
    s, games, limits, buttons, r, play = menu._layout()
    rot = [g.name for g in menu.games].index("rotation")
    gx, gy, gw, gh = games[rot]
    _click(menu, app, gx + gw / 2, gy + gh / 2)                    # choose the rotation game
    assert menu.game.name == "rotation" and menu.column == 0
    j = LIMIT_KEYS.index("min_size")
    plus = buttons[j][1]
    for _ in range(2):
        _click(menu, app, *plus)                                   # the smallest gate: 2 degrees bigger
    spec = menu.game
    stored = load_limits(db_path, "P001", [spec])["rotation"]
    assert stored.min_size == pytest.approx(spec.difficulty.size.hard + 2)
    shot = tmp_path / "menu.png"
    assert app.frame(screenshot=shot)
    rgb = app.screen.read_rgb()
    # the limit clicked has the focus (the accent border) and its value is drawn in large light text
    lx, ly, lw, lh = (round(v) for v in limits[j])
    edge = rgb[ly + 20:ly + lh - 20, lx:lx + 3].astype(int)
    assert (abs(edge - (94, 200, 190)).max(axis=2) < 30).mean() > 0.5
    assert (rgb[ly + 30:ly + lh - 6, lx + 18:lx + 200].max(axis=2) > 200).sum() > 100
    _click(menu, app, play[0] + play[2] / 2, play[1] + play[3] / 2)
    (name, kw), = opened
    assert name == "rotation" and kw["limits"].min_size == stored.min_size


def test_river_geometry_on_the_screen_boat_fits_a_gate_exactly_within_its_tolerance(open_headless):
    from game.exergames.river import river_for
    from game.exergames.targets import RomLimits
    from game.scenes.river_view import RiverView

    screen = open_headless((640, 360))
    for side in ("right", "left"):
        river = river_for(RomLimits(50.0, 40.0), 1.05, side)
        view = RiverView(screen.ctx, (230, 6, 200, 348), 0.5, (90, 210, 255))
        try:
            for v in (-35.0, -10.0, 0.0, 20.0, 48.0):
                assert view.rotation_at_px(river, view.x_px(river, v)) == pytest.approx(v)   # the mouse steering
            left, width = view.lane_px
            # the boat never leaves the water: its hull stays off the banks at the extremes
            assert left - view.boat_half_w >= 230 + view.bank - 1e-6
            assert left + width + view.boat_half_w <= 430 - view.bank + 1e-6
            # a gate of tolerance 8 at 20: the boat's hull is between the buoys from 12 to 28 degrees
            gate_x, half = view.x_px(river, 20.0), view.half_width_px(river, 8.0)
            for v, inside in ((12.5, True), (27.5, True), (11.0, False), (29.0, False)):
                bx = view.x_px(river, v)
                fits = gate_x - half <= bx - view.boat_half_w and bx + view.boat_half_w <= gate_x + half
                assert fits == inside, (side, v)
            # a gate comes down the river to the bow, then along the boat
            ys = [view.gate_y(d) for d in (1.0, 0.5, 0.0, -0.5, -1.0)]
            assert ys == sorted(ys) and ys[2] == pytest.approx(view.bow_y)
        finally:
            view.release()
