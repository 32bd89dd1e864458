"""The game menu drawn: the games, the Play button and the therapist's limits in large type; the
mouse changes a limit with its + and - and the change is stored for the patient."""

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
