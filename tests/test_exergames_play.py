"""Each game played headless by the simulated patient in automatic mode through the real pipeline
(the tracker process renders and measures the interactive patient the auto player steers; the
game scores what the tracker measures): targets collected, every target inside the configured
fraction of the stored ROM (from the game's own stored log), the session logged, the screenshot
showing the avatar and the target; the tracker paused mid-game pauses the game, which resumes.
One tracker process serves every game (module fixture) to keep the suite short."""

from __future__ import annotations

import json
import time

import cv2
import numpy as np
import pytest

from game.app import App, Services, Settings
from game.db import Database
from game.exergames.session import Phase
from game.exergames.spec import TherapistLimits, load_game
from game.gfx.screen import GraphicsUnavailable, open_screen
from game.live_link import LiveLink
from game.play import make_avatar
from game.rom.session import RomResult
from game.scenes.game_play import GameScene

pytestmark = pytest.mark.timeout(300)

SIZE = (640, 360)
#: The patient's stored ROM: deliberately unlike the games' defaults, and unlike between the sides.
STORED = {"right": {"shoulder_flexion": 110.0, "shoulder_abduction": 100.0, "elbow_flexion": 130.0,
                    "shoulder_external_rotation": 50.0, "shoulder_internal_rotation": 45.0,
                    "forearm_supination": 70.0, "forearm_pronation": 65.0},
          "left": {"shoulder_flexion": 100.0, "shoulder_abduction": 95.0, "elbow_flexion": 125.0,
                   "shoulder_external_rotation": 44.0, "shoulder_internal_rotation": 52.0,
                   "forearm_supination": 62.0, "forearm_pronation": 72.0}}


def _result(test: str, value: float, side: str) -> RomResult:
    return RomResult(test=test, title=test, side=side, angle=f"{side}_{test}", direction=1, mode="active",
                     position="p", position_words="Seated.", standard="jarm", reference_deg=None, max_deg=value,
                     start_deg=0.0, range_deg=value, max_time_s=1.0, started_s=0.0, ended_s=5.0, compensations=(),
                     estimated_markers=(), n_samples=100)


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    import os

    os.environ["SDL_VIDEODRIVER"] = "dummy"
    os.environ["SDL_AUDIODRIVER"] = "dummy"
    try:
        screen = open_screen(SIZE, "games", headless=True)
    except GraphicsUnavailable as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))
    from tracking.live import LiveTracker, SourceConfig

    db_path = tmp_path_factory.mktemp("games") / "rehab.sqlite3"
    with Database(db_path) as db:
        db.add_patient("P001")
        session = db.start_session("P001", "rom", source="test")
        for side, values in STORED.items():
            for test, value in values.items():
                db.add_rom_result(session, _result(test, value, side))
        db.end_session(session)
    # every frame set tracked whatever the load (docs/LIVE.md, sim_clock): the games' logic, not a
    # tracker dropping frame sets of the patient's moves on a busy machine
    link = LiveLink(lambda: LiveTracker(SourceConfig(motion=None, sim_clock="frames")))
    try:
        link.start()
        assert link.wait_ready(120.0), link.error
        yield screen, link, db_path
    finally:
        link.close()
        screen.close()


def _play(app: App, scene: GameScene, until, budget_s: float) -> bool:
    end = time.perf_counter() + budget_s
    while time.perf_counter() < end:
        app.frame()
        if until(scene):
            return True
    return False


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("name", ["reach", "rotation", "turn_key"])
def test_auto_play_collects_targets_inside_the_stored_rom_and_logs_the_session(rig, name, side, tmp_path):
    screen, link, db_path = rig
    spec = load_game(name)
    app = App(screen, Settings(window_px=SIZE, max_fps=0, show_fps=False), services=Services(link))
    # the left-arm runs play under therapist's limits too: the targets must respect them
    d = spec.difficulty
    therapist = TherapistLimits(max_range=0.8, min_size=round((d.size.easy + d.size.hard) / 2, 3)) \
        if side == "left" else None
    scene = GameScene(link, spec, side, db_path, "P001", make_avatar=make_avatar, auto=True, mute=True, seed=11,
                      therapist=therapist)
    app.push(scene)
    shot = tmp_path / f"{name}.png"
    try:
        assert _play(app, scene, lambda s: s.session.reached >= 2, 40.0), \
            (scene.session.pause_reason, scene.session.log.targets)
        # a target on the screen for a moment: the screenshot shows it
        assert _play(app, scene, lambda s: s.session.target is not None and s.session.target.age_s > 0.3, 10.0)
        assert app.frame(screenshot=shot)
        if scene.river_view is not None:   # the rotation game: the gate on the river, the boat below it
            target_px, boat_px = scene.river_view.gate_px, scene.river_view.boat_px
        else:
            target_px = scene._project(scene.session.target.hand_m)
    finally:
        app.close()   # the scene exits: the session is stored
    assert scene.stored_uid is not None
    with Database(db_path) as db:
        rows = [r for r in db.exercise_results("P001") if r.uid == scene.stored_uid]
    (row,) = rows
    details = json.loads(row.details)
    assert row.game == name and row.repetitions == details["reached"] >= 2 and row.duration_s > 1.0
    assert details["side"] == side
    stored = STORED[side]
    sources = details["limits"]["sources"]
    assert all(v.startswith("stored") for v in sources.values()), sources
    for rec in details["targets"]:
        # the limit is the stored maximum of that direction, the target inside the configured band
        assert rec["limit_deg"] in (details["limits"]["positive_deg"], details["limits"]["negative_deg"]) \
            or spec.kind == "reach"
        assert spec.comfort_fraction - 1e-6 <= rec["fraction"] <= spec.stretch_fraction + 1e-6
        assert abs(rec["value_deg"]) <= spec.stretch_fraction * rec["limit_deg"] + 0.01
        if therapist is not None:
            assert rec["fraction"] <= therapist.max_range + 1e-6 and rec["size"] >= therapist.min_size - 1e-6
    if spec.kind == "reach":
        assert details["limits"]["positive_deg"] == stored["shoulder_flexion"]
        assert details["limits"]["negative_deg"] == stored["shoulder_abduction"]
    elif spec.kind == "rotation":
        assert (details["limits"]["positive_deg"], details["limits"]["negative_deg"]) == \
            (stored["shoulder_external_rotation"], stored["shoulder_internal_rotation"])
    else:
        assert (details["limits"]["positive_deg"], details["limits"]["negative_deg"]) == \
            (stored["forearm_supination"], stored["forearm_pronation"])
    # the screenshot: the avatar's shirt in the view, the target's ring colour around the target
    rgb = cv2.imread(str(shot))[:, :, ::-1].astype(int)
    view_w = round(scene.view.w)
    body = rgb[:, :view_w]
    shirt = (body[..., 2] > body[..., 0] + 50) & (body[..., 2] > 110) & (body[..., 1] < 170)
    assert shirt.sum() > 800
    assert (np.abs(rgb[4, 4] - (204, 222, 240)) <= 3).all()   # the view's gradient (its light top) around it
    x, y = (round(v) for v in target_px)
    if scene.river is None:
        patch = rgb[max(0, y - 45):y + 45, max(0, x - 45):min(view_w, x + 45)]
        colour = np.array(spec.colour)
        near = (np.abs(patch - colour).max(axis=2) < 40).sum()
        assert near > 30, near
    else:
        # the gate's buoys (the game's colour, green while the boat is lined up) and the boat's wooden hull
        patch = rgb[max(0, y - 20):y + 20, max(0, x - 120):x + 120]
        buoys = sum((np.abs(patch - np.array(c)).max(axis=2) < 40).sum() for c in (spec.colour, (120, 220, 120)))
        assert buoys > 30, buoys
        bx, by = (round(v) for v in boat_px)
        hull = rgb[by - 25:by + 25, bx - 20:bx + 20]
        wood = (hull[..., 0] > hull[..., 2] + 40) & (hull[..., 0] > 80)
        assert wood.sum() > 40, wood.sum()
        # the boat sits where the measured rotation puts it on the river, mirrored for the left arm
        river = scene.river
        assert (river.across(river.out_deg) == 1.0) == (side == "right")


def test_a_stopped_tracker_pauses_the_game_with_a_message_and_it_resumes(rig):
    screen, link, db_path = rig
    app = App(screen, Settings(window_px=SIZE, max_fps=0, show_fps=False), services=Services(link))
    scene = GameScene(link, load_game("turn_key"), "right", db_path, "P001", make_avatar=make_avatar, auto=True,
                      mute=True, seed=3)
    app.push(scene)
    try:
        assert _play(app, scene, lambda s: s.session.phase is Phase.PLAYING and not s.session.paused, 40.0)
        link.tracker.pause()
        assert _play(app, scene, lambda s: s.session.pause_reason.startswith("No new images"), 10.0)
        active = scene.session.log.active_s
        _play(app, scene, lambda s: False, 0.5)
        assert scene.session.log.active_s == active          # no play time, no scoring while stopped
        link.tracker.resume()
        assert _play(app, scene, lambda s: not s.session.paused, 20.0), scene.session.pause_reason
    finally:
        app.close()
    assert scene.session.log.paused_s >= 0.5


def test_the_mouse_on_a_target_moves_the_simulated_hand_there_and_collects_it(rig):
    from game.input import Pointer, PointerKind

    screen, link, db_path = rig
    app = App(screen, Settings(window_px=SIZE, max_fps=0, show_fps=False), services=Services(link))
    scene = GameScene(link, load_game("reach"), "right", db_path, "P001", make_avatar=make_avatar, auto=False,
                      mute=True, seed=8)
    app.push(scene)

    def point_at_target(s: GameScene) -> bool:
        if s.session.target is not None and s.proj_m is not None:
            x, y = s._project(s.session.target.hand_m)
            s.handle(Pointer(PointerKind.MOVE, x / SIZE[0], y / SIZE[1]))
        return s.session.reached >= 1

    try:
        assert _play(app, scene, point_at_target, 40.0), scene.session.log.targets
    finally:
        app.close()
    assert scene.session.log.targets[0]["reached"]


@pytest.mark.parametrize("name", ["reach", "rotation", "turn_key"])
def test_the_mouse_alone_brings_the_arm_into_the_start_position_and_the_game_starts(rig, name):
    """No demo key: the pointer moved once into the avatar's view, before the tracker has seen the
    arm, is enough for every game to pass its start check (the rotation games' "elbow at the side,
    bent like an L") and to start playing."""
    from game.input import Pointer, PointerKind

    screen, link, db_path = rig
    app = App(screen, Settings(window_px=SIZE, max_fps=0, show_fps=False), services=Services(link))
    scene = GameScene(link, load_game(name), "right", db_path, "P001", make_avatar=make_avatar, auto=False,
                      mute=True, seed=5)
    app.push(scene)
    try:
        v = scene.view
        scene.handle(Pointer(PointerKind.MOVE, (v.x + 0.4 * v.w) / SIZE[0], (v.y + 0.55 * v.h) / SIZE[1]))
        assert _play(app, scene, lambda s: s.session.phase is Phase.PLAYING, 40.0), scene.session.pause_reason
        assert not scene.auto and scene._hand_target is not None
        assert _play(app, scene, lambda s: s.session.log.active_s > 1.0, 20.0), scene.session.pause_reason
    finally:
        app.close()
