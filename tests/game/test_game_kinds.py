"""Game kinds as plug-ins: the built-in kinds are found by name, a game of an unknown kind is one
line, and a kind that is not built in (``dummy_game_kind.py``, one module) with one game YAML
appears in the game menu and plays: the avatar's angle scores its targets, the session is stored."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from game.app import App, Services, Settings
from game.db import Database
from game.exergames import kinds
from game.exergames.session import Phase
from game.exergames.spec import available_games, load_all_games, load_game
from game.input import Action, Pointer, PointerKind, Press
from game.scenes.game_menu import ChooseGameScene
from game.scenes.game_play import GameScene
from tests.game.test_scenes_live import BodyLink, Clock
from tracking.errors import ContentError
from tracking.sim.body import reference_pose

SIZE = (1280, 720)

GAME_YAML = """\
name: bend_elbow
title: Bend the elbow
kind: elbow_bend
exercises: elbow flexion
instructions: Bend your elbow until the needle points at the mark, and hold it there.
rom:
  positive: {test: elbow_flexion, default_deg: 140}
  negative: {test: elbow_flexion, default_deg: 140}
comfort_fraction: 0.4
difficulty:
  start: 0.3
  top_fraction: {easy: 0.75, hard: 1.05}
  size: {easy: 12, hard: 6}
  hold_s: {easy: 0.3, hard: 0.8}
  time_limit_s: {easy: 12, hard: 6}
duration_s: 30
colour: [250, 120, 90]
"""


@pytest.fixture
def elbow_bend():
    """The kind's module loaded from its file (as a clinic's own module would be), forgotten after."""
    spec = importlib.util.spec_from_file_location("dummy_game_kind", Path(__file__).with_name("dummy_game_kind.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    yield module.KIND
    kinds.unregister("elbow_bend")


def test_the_built_in_kinds_are_registered_by_name_and_every_game_finds_its_own():
    assert {"reach", "rotation", "forearm"} <= set(kinds.kind_names())
    for name in available_games():
        spec = load_game(name)
        assert spec.game_kind is kinds.game_kind(spec.kind) and spec.game_kind.name == spec.kind


def test_a_game_of_an_unknown_kind_is_one_line_naming_the_known_kinds(tmp_path):
    path = tmp_path / "dance.yaml"
    path.write_text(GAME_YAML.replace("kind: elbow_bend", "kind: dance"), encoding="utf-8")
    with pytest.raises(ContentError, match="unknown game kind 'dance': one of .*forearm.*reach.*rotation") as info:
        load_game(path)
    assert "\n" not in str(info.value)


def test_two_modules_claiming_one_kind_are_refused(elbow_bend):
    class Other(kinds.GameKind):
        name = "elbow_bend"

    with pytest.raises(ValueError, match="registered twice"):
        kinds.register(Other())


def _pose(elbow_deg: float):
    return reference_pose(elbow_flexion_deg=elbow_deg)


def test_a_new_kind_is_one_module_and_its_game_appears_in_the_menu_and_plays(elbow_bend, open_headless, tmp_path):
    path = tmp_path / "bend_elbow.yaml"
    path.write_text(GAME_YAML, encoding="utf-8")
    spec = load_game(path)
    assert spec.game_kind is elbow_bend
    db_path = tmp_path / "rehab.sqlite3"
    with Database(db_path) as db:
        db.add_patient("P001")

    clock = Clock()
    link = BodyLink(clock)
    app = App(open_headless(SIZE), Settings(show_fps=False, max_fps=0), clock=clock, sleep=lambda s: None,
              services=Services(link), events=lambda: [])
    scenes = []

    def open_game(spec, patient_id, **kw):
        scenes.append(GameScene(link, spec, kw["side"], db_path, patient_id, auto=False, mute=True,
                                therapist=kw["limits"]))
        return scenes[-1]

    try:
        # the menu lists it beside the built-in games; a click chooses it, Play opens it
        menu = ChooseGameScene("P001", open_game, games=[*load_all_games(), spec], db_path=db_path)
        app.push(menu)
        assert [g.name for g in menu.games][-1] == "bend_elbow"
        _, rows, _, _, _, play = menu._layout()
        gx, gy, gw, gh = rows[-1]
        menu.handle(Pointer(PointerKind.PRESS, (gx + gw / 2) / SIZE[0], (gy + gh / 2) / SIZE[1], button=1))
        assert menu.game.name == "bend_elbow"
        assert app.frame()
        menu.handle(Pointer(PointerKind.PRESS, (play[0] + play[2] / 2) / SIZE[0], (play[1] + play[3] / 2) / SIZE[1],
                            button=1))
        scene, = scenes
        assert app.stack[-1] is scene and scene.session.spec.name == "bend_elbow"

        # the patient sits still for the baseline, then bends the elbow to each target and holds it
        elbow = 20.0
        for _ in range(400):
            session = scene.session
            t = session.target
            if t is not None and t.arrived:
                measured = session.value_now()
                if measured == measured:    # finite: follow the needle to the mark, as a patient would
                    elbow += 0.5 * (t.target.value_deg - measured)
            link.feed(_pose(elbow))
            assert app.frame()                              # the app's services tick the link
            clock.now_s += 1.0 / 30.0
            if session.reached >= 2:
                break
        session = scene.session
        assert session.phase is Phase.PLAYING and session.reached >= 2
        targets = session.log.targets
        assert all(tg["reached"] and 0 < tg["value_deg"] <= 140 * 1.05 for tg in targets)   # bends only
        assert set(session.log.range_used) == {"elbow_flexion"}                  # the kind's logged angle
        app.screen.read_rgb()   # the gauge and the panel drew
        scene.handle(Press(Action.BACK))
        assert scene.stored_uid
        with Database(db_path) as db:
            game, = db.exercise_results("P001")
        assert game.game == "bend_elbow" and game.repetitions == session.reached
        assert json.loads(game.details)["range_used"]["elbow_flexion"][1] > 40.0
    finally:
        app.close()
