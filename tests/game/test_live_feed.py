"""The scenes' one live feed (:mod:`game.scenes.live_feed`): samples read once per frame, the avatar
made once the marker set is known and moved only by samples that know enough markers, one
staleness rule for the live mirror, the games and the ROM test, the patient's input sent at most
every 1/60 s and only when it changed."""

from __future__ import annotations

import numpy as np
import pytest

from game.app import App, BaseScene, Services, Settings
from game.db import Database
from game.exergames.spec import load_game
from game.live_link import LinkState
from game.rom.spec import load_rom_test
from game.scenes.game_play import GameScene
from game.scenes.live import LiveScene
from game.scenes.live_feed import (INPUT_PERIOD_S, MIN_KNOWN_MARKERS, STALE_SAMPLE_S, STOPPED_LINE, WAITING_LINE,
                                   LiveFeed)
from game.scenes.rom_test import RomTestScene, RomVisit
from tests.game.test_scenes_live import BodyLink, Clock
from tracking.sim.body import reference_pose


class FakeApp:
    def __init__(self, clock) -> None:
        self.frames = 0
        self.clock = clock
        self.screen = type("Screen", (), {"ctx": "ctx"})()


class FakeAvatar:
    def __init__(self, ctx, names, roles) -> None:
        self.made_with = (ctx, tuple(names), roles)
        self.pushed: list = []
        self.released = False

    def push_sample(self, sample) -> None:
        self.pushed.append(sample)

    def release(self) -> None:
        self.released = True


def test_samples_are_read_once_per_frame_and_move_the_avatar_when_they_know_enough_markers():
    clock = Clock()
    link = BodyLink(clock)
    app = FakeApp(clock)
    made = []
    feed = LiveFeed(link, lambda ctx, names, roles: made.append(FakeAvatar(ctx, names, roles)) or made[-1])
    assert feed.problem(clock()) == (WAITING_LINE, False) and not feed.is_live(clock())
    good = link.feed(reference_pose())
    status = np.zeros(len(link.markerset.names), np.uint8)
    status[:MIN_KNOWN_MARKERS - 1] = 1
    waiting = link.feed(reference_pose(), state=0, status=status)   # the tracker still finds the markers
    link.tick()
    assert feed.take(app) == [good, waiting]
    avatar, = made
    assert avatar.made_with == ("ctx", tuple(link.markerset.names), link.markerset.roles)
    assert avatar.pushed == [good]                       # too few known markers pose no body
    link.tick()                                          # a second look in the same frame: the same samples
    assert feed.take(app) == [good, waiting] and avatar.pushed == [good]
    app.frames += 1
    assert feed.take(app) == [] and len(made) == 1
    feed.release()
    assert avatar.released and feed.avatar is None


def test_one_staleness_rule_and_the_links_own_problems_first():
    clock = Clock()
    link = BodyLink(clock)
    app = FakeApp(clock)
    feed = LiveFeed(link)
    link.feed(reference_pose())
    link.tick()
    feed.take(app)
    assert feed.is_live(clock())
    clock.now_s += STALE_SAMPLE_S - 0.01
    assert feed.problem(clock()) is None
    clock.now_s += 0.02
    assert feed.problem(clock()) == (STOPPED_LINE, False) and feed.stopped(clock())
    link.state = LinkState.RESTARTING
    assert feed.problem(clock())[0] == "The tracker stopped: restarting..."
    link.state = LinkState.RUNNING
    app.frames += 1
    link.feed(reference_pose())
    link.tick()
    feed.take(app)
    assert feed.is_live(clock())


def test_the_input_is_sent_at_most_every_period_and_only_when_it_changed():
    link = BodyLink(Clock())
    feed = LiveFeed(link)
    dt = 1.0 / 240.0
    due = [feed.input_due(dt) for _ in range(16)]
    sent_at = [i for i, d in enumerate(due) if d is not None]
    assert sent_at == [3, 7, 11, 15] and due[3] == pytest.approx(INPUT_PERIOD_S)
    for value in ("a", "a", "b", "b"):
        feed.send(value)
    assert link.sent == ["a", "b"]
    feed.send("b", force=True)
    assert link.sent == ["a", "b", "b"]


def test_the_mirror_the_game_and_the_rom_test_say_the_samples_stopped_at_the_same_age(open_headless, tmp_path):
    db_path = tmp_path / "rehab.sqlite3"
    with Database(db_path) as db:
        db.add_patient("P001")
    scenes = {
        "mirror": lambda link: LiveScene(link),
        "game": lambda link: GameScene(link, load_game("turn_key"), "right", db_path, "P001", mute=True),
        "rom test": lambda link: RomTestScene(link, RomVisit(db_path, "P001"), load_rom_test("shoulder_flexion"),
                                              "right"),
    }
    said = {
        "mirror": lambda scene: (scene.banner(scene.link.latest) or ("",))[0],
        "game": lambda scene: scene.no_reading_reason(),
        "rom test": lambda scene: scene.status_line()[0],
    }
    screen = open_headless((640, 360))
    for name, make in scenes.items():
        clock = Clock()
        link = BodyLink(clock)
        app = App(screen, Settings(show_fps=False, max_fps=0), clock=clock, sleep=lambda s: None,
                  services=Services(link), events=lambda: [])
        app.push(BaseScene())
        scene = make(link)
        app.push(scene)
        for _ in range(3):
            link.feed(reference_pose())
            app.frame()                                     # the app's services tick the link
            clock.now_s += 1.0 / 30.0
        assert STOPPED_LINE not in said[name](scene), name
        clock.now_s += STALE_SAMPLE_S - 1.0 / 30.0 - 0.01   # just under the rule since the last sample
        app.frame()
        assert STOPPED_LINE not in said[name](scene), name
        clock.now_s += 0.02
        app.frame()
        assert said[name](scene) == STOPPED_LINE, name
        while len(app.stack) > 1:
            app.pop()
