"""The application's sign-in screen: where the database has accounts and ``rehab play`` got none, the
app opens on it; a wrong name or PIN is said in one line; a therapist reaches the home screen, a
patient account only its own patient's game menu (no limits, no other patient, no therapist screen)."""

from __future__ import annotations

import pytest

from game.app import Settings
from game.db import Database
from game.db.accounts import add_account
from game.input import Action, Press, Typed
from game.play import PlayOptions, build_app, needs_sign_in
from game.scenes.game_menu import ChooseGameScene
from game.scenes.home import HomeScene
from game.scenes.sign_in import WRONG, SignInScene

from test_scene_calibrate import IdleLink
from test_text_fits import SIZES, assert_text_fits, frame_texts


@pytest.fixture
def clinic(tmp_path, monkeypatch):
    """Two patients, a therapist ``anna`` (PIN 4711) and a patient account ``p1`` for P001 (PIN 1234)."""
    for var in ("REHAB_USER", "REHAB_PIN"):
        monkeypatch.delenv(var, raising=False)
    path = tmp_path / "clinic.sqlite3"
    with Database(path) as db:
        db.add_patient("P001")
        db.add_patient("P002")
        add_account(db, "anna", "therapist", "4711")
        add_account(db, "p1", "patient", "1234", "P001")
    return path


def _app(open_headless, clinic, size=(1280, 720), **kw):
    options = PlayOptions(settings=Settings(window_px=size, max_fps=0, show_fps=False), db_path=clinic,
                          sign_in=True, **kw)
    return build_app(open_headless(size), options, IdleLink())


def _type(app, name: str, secret: str) -> None:
    """Type as the keyboard does: the text, a field change, Enter (after a wrong try the name stays,
    the PIN field is chosen and empty: go up and erase the name first)."""
    scene = app.scene
    if scene.field == 1:
        app.dispatch(Press(Action.UP, key="up"))
    for _ in scene.fields[0]:
        app.dispatch(Press(Action.BACK, key="backspace"))
    assert scene.fields == ["", ""] and scene.field == 0 and app.running
    app.dispatch(Typed(name))
    app.dispatch(Press(Action.DOWN, key="down"))
    for ch in secret:   # a letter key's action (W is Up) must not change the field
        app.dispatch(Press(Action.UP if ch == "w" else Action.SELECT, key=ch))
        app.dispatch(Typed(ch))
    app.dispatch(Press(Action.SELECT, key="return"))


def test_the_app_opens_on_sign_in_where_the_database_has_accounts(clinic, tmp_path, monkeypatch):
    monkeypatch.setattr("sys.stdin.isatty", lambda: False)   # started from a desktop launcher
    assert needs_sign_in(PlayOptions(db_path=clinic))
    assert needs_sign_in(PlayOptions(db_path=clinic, user="anna"))          # no PIN, no terminal to ask it
    monkeypatch.setenv("REHAB_PIN", "4711")
    assert not needs_sign_in(PlayOptions(db_path=clinic, user="anna"))      # scripts sign in as before
    with Database(tmp_path / "plain.sqlite3") as db:
        db.add_patient("P001")
    assert not needs_sign_in(PlayOptions(db_path=tmp_path / "plain.sqlite3"))   # no accounts: no sign-in


def test_a_wrong_pin_is_one_line_then_the_therapist_reaches_home(open_headless, clinic):
    app = _app(open_headless, clinic)
    try:
        scene = app.scene
        assert isinstance(scene, SignInScene)
        _type(app, "anna", "0000")
        assert app.scene is scene and scene.message == WRONG
        rec = frame_texts(app)
        assert [t for t, _ in rec.texts if t == WRONG] == [WRONG]
        assert not any("0000" in t for t, _ in rec.texts)   # the PIN is shown as dots only
        _type(app, "nobody", "4711")                        # a wrong name: the same words
        assert scene.message == WRONG
        _type(app, "anna", "4711")
        assert isinstance(app.scene, HomeScene) and scene.fields == ["", ""]
        entries = {e.label: e for e in app.scene.entries}
        # the signed-in name is what is audited: ROM results accepted, limits changed on the game menu
        rom = entries["ROM test"].open().then("P002")
        games = entries["Games"].open().then("P002")
        try:
            assert rom.visit.accepted_by == "anna" and games.account == "anna" and games.may_change_limits
        finally:
            rom.visit.close()
        app.dispatch(Press(Action.BACK, key="escape"))   # home: Esc twice quits, as without accounts
        app.dispatch(Press(Action.BACK, key="escape"))
        assert not app.running
    finally:
        app.close()


def test_three_wrong_tries_wait_before_the_next(open_headless, clinic):
    app = _app(open_headless, clinic)
    now = [100.0]
    try:
        scene = app.scene
        scene.clock = lambda: now[0]
        for _ in range(3):
            _type(app, "anna", "1111")
        _type(app, "anna", "4711")
        assert app.scene is scene and scene.message.startswith("Too many wrong tries")
        now[0] += 6.0
        app.dispatch(Typed("4711"))
        app.dispatch(Press(Action.SELECT))
        assert isinstance(app.scene, HomeScene)
    finally:
        app.close()


def test_a_patient_account_reaches_only_its_own_game_menu(open_headless, clinic):
    app = _app(open_headless, clinic)
    try:
        sign_in = app.scene
        _type(app, "p1", "1234")
        menu = app.scene
        assert isinstance(menu, ChooseGameScene) and menu.patient_id == "P001" and menu.account == "p1"
        assert not any(isinstance(s, HomeScene) for s in app.stack)   # no way to the therapist's screens
        before = dict(menu.limits)
        menu.change_limit("max_level", 1)
        assert menu.limits == before and "therapist" in menu.error
        with Database(clinic) as db:
            assert not db.conn.execute("SELECT 1 FROM audit WHERE action = 'limits'").fetchone()
        app.dispatch(Press(Action.BACK, key="escape"))
        assert app.scene is sign_in
    finally:
        app.close()
    # asked for another patient's games or a therapist's screen: refused on the sign-in screen
    for kw in ({"game": "reach", "patient": "P002"}, {"scene": "rom", "patient": "P001"}, {"scene": "live"}):
        app = _app(open_headless, clinic, **kw)
        try:
            scene = app.scene
            _type(app, "p1", "1234")
            assert app.scene is scene and "may not" in scene.message and len(app.stack) == 1, kw
        finally:
            app.close()


@pytest.mark.parametrize("size", SIZES)
def test_sign_in_text_fits(open_headless, clinic, size):
    app = _app(open_headless, clinic, size=size)
    try:
        scene = app.scene
        app.dispatch(Typed("a-rather-long-account-name-of-32"))
        app.dispatch(Press(Action.DOWN))
        app.dispatch(Typed("0123456789" * 6))
        scene.message = WRONG
        assert_text_fits(frame_texts(app), size)
        app.dispatch(Press(Action.SELECT))
        assert scene.message == WRONG
        assert_text_fits(frame_texts(app), size)
    finally:
        app.close()


def test_typed_text_and_key_names_come_from_the_keyboard(monkeypatch):
    import pygame

    from game.input import InputMapper

    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    E = pygame.event.Event
    out = InputMapper((800, 400)).map([E(pygame.KEYDOWN, key=pygame.K_BACKSPACE), E(pygame.KEYUP, key=pygame.K_BACKSPACE),
                                       E(pygame.KEYDOWN, key=pygame.K_w),
                                       E(pygame.TEXTINPUT, text="w"), E(pygame.KEYDOWN, key=pygame.K_ESCAPE)])
    assert out == [Press(Action.BACK), Press(Action.BACK, False), Press(Action.UP), Typed("w"), Press(Action.BACK)]
    assert [getattr(e, "key", None) for e in out] == ["backspace", "backspace", "w", None, "escape"]
