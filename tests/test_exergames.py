"""Exercise-game logic on arrays: content, target placement inside the stored ROM (and moving with
it), the forward kinematics against the joint-angle definitions, difficulty adaptation, the
pauses (tracker stopped, markers lost, posture, compensation) and the stored log."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from game.db import Database
from game.exergames.session import READY_S, Cue, GameSession, LevelAdapter, Phase, Reading, read_sample
from game.exergames.spec import available_games, load_game
from game.exergames.visit import store_log
from game.exergames.kinds import place_target, target_hand_m
from game.exergames.targets import (ArmFrame, RomLimits, elbow_at_side_hand_m, elevation_direction,
                                    flexion_abduction_deg, rom_limits_from_rows)
from tracking.errors import ContentError

DT = 1.0 / 30.0


def frame(side: str = "right") -> ArmFrame:
    """An upright seated patient's arm: trunk axes = world axes (x right, y up, z back)."""
    x = 0.19 if side == "right" else -0.19
    return ArmFrame(np.array([x, 1.05, 0.0]), np.eye(3), 0.30, 0.26, side)


def reading(hand, *, lean=0.0, hiking=0.10, elbow=90.0, elevation=5.0, er=0.0, sup=0.0, side="right") -> Reading:
    angles = {"shoulder_flexion": 0.0, "shoulder_abduction": elevation, "shoulder_elevation": elevation,
              "elbow_flexion": elbow, "shoulder_external_rotation": er, "forearm_supination": sup,
              "trunk_forward_lean": lean, "trunk_lateral_lean": 0.0}
    return Reading(np.asarray(hand, dtype=np.float64), angles, hiking, frame(side))


def rom_row(test, value, side="right", day="2026-11-01"):
    from game.db.database import RomRow

    return RomRow("u", "s", "P001", f"{day}T10:00:00Z", test, side, f"{side}_{test}", "active", "p", "jarm", None,
                  value, 0.0, value, "", "", 5.0, day)


# ----------------------------------------------------------------------------- content
@pytest.mark.parametrize("name", available_games())
def test_every_game_loads(name):
    spec = load_game(name)
    assert spec.name == name and spec.comfort_fraction < spec.stretch_fraction


def test_there_are_three_games_for_different_motions():
    kinds = {load_game(n).kind for n in available_games()}
    assert kinds == {"reach", "rotation", "forearm"}


def test_a_misspelt_key_is_one_line_naming_file_and_key(tmp_path):
    text = (load_game("reach").model_dump_json())
    data = json.loads(text)
    data["hold_time"] = 3
    path = tmp_path / "bad.yaml"
    import yaml

    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ContentError, match=r"bad.yaml: hold_time: unknown key"):
        load_game(str(path))


# ----------------------------------------------------------------------------- ROM limits
def test_latest_stored_result_of_each_test_wins_and_defaults_fill_the_rest():
    spec = load_game("reach")
    rows = [rom_row("shoulder_flexion", 100.0, day="2026-10-01"), rom_row("shoulder_flexion", 130.0),
            rom_row("shoulder_abduction", 150.0, side="left")]
    limits = rom_limits_from_rows(spec, rows, "right")
    assert limits.positive_deg == 130.0
    assert limits.negative_deg == spec.rom["frontal"].default_deg   # only the left side was stored
    assert dict(limits.sources)["shoulder_flexion"].startswith("stored")
    assert dict(limits.sources)["shoulder_abduction"] == "default"


# ----------------------------------------------------------------------------- forward kinematics
@pytest.mark.parametrize("theta", [20.0, 45.0, 80.0])
def test_elevation_directions_read_back_as_flexion_and_abduction(theta):
    f = frame()
    flex, abd = flexion_abduction_deg(elevation_direction(f, theta, 0.0), f)
    assert flex == pytest.approx(theta) and abd == pytest.approx(0.0, abs=1e-9)
    flex, abd = flexion_abduction_deg(elevation_direction(f, theta, 90.0), f)
    assert abd == pytest.approx(theta) and flex == pytest.approx(0.0, abs=1e-9)
    left = frame("left")
    assert flexion_abduction_deg(elevation_direction(left, theta, 90.0), left)[1] == pytest.approx(theta)


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("rotation", [-40.0, 0.0, 35.0])
def test_elbow_at_side_hand_gives_the_external_rotation_of_the_spec(side, rotation):
    """docs/JOINT_ANGLES.md: signed angle from -z_T to the forearm about u (about -u on the left)."""
    f = frame(side)
    hand = elbow_at_side_hand_m(f, rotation)
    elbow = f.shoulder_m - f.upper_arm_m * f.trunk[:, 1]
    u = (elbow - f.shoulder_m) / f.upper_arm_m
    axis = u if side == "right" else -u
    fore = hand - elbow
    ref = np.array([0.0, 0.0, -1.0])
    measured = math.degrees(math.atan2(np.cross(ref, fore) @ axis, ref @ fore))
    assert measured == pytest.approx(rotation, abs=1e-6)
    assert np.linalg.norm(fore) == pytest.approx(f.forearm_m)


# ----------------------------------------------------------------------------- placement
@pytest.mark.parametrize("name", ["reach", "rotation", "turn_key"])
def test_targets_lie_between_the_comfort_fraction_and_the_top_of_the_stored_maximum(name):
    spec = load_game(name)
    limits = RomLimits(120.0, 100.0, 140.0)
    rng = np.random.default_rng(3)
    for top in (spec.difficulty.top_fraction.easy, spec.stretch_fraction):
        for k in range(200):
            t = place_target(spec.kind, limits, spec.comfort_fraction, top, rng, direction=1 if k % 2 else -1,
                             planes_deg=spec.planes_deg, elbow_range_deg=spec.elbow_flexion_deg)
            assert spec.comfort_fraction <= t.fraction <= top
            assert abs(t.value_deg) == pytest.approx(t.fraction * t.limit_deg)
            assert min(limits.positive_deg, limits.negative_deg) <= t.limit_deg <= max(limits.positive_deg,
                                                                                        limits.negative_deg)
            if spec.kind != "reach":
                assert t.limit_deg == (limits.positive_deg if t.value_deg > 0 else limits.negative_deg)
            else:
                assert t.elbow_deg <= limits.elbow_deg


def test_changing_the_stored_rom_moves_the_targets():
    spec = load_game("reach")
    f = frame()
    small, large = RomLimits(60.0, 60.0, 140.0), RomLimits(150.0, 150.0, 140.0)
    heights = {}
    for name, limits in (("small", small), ("large", large)):
        rng = np.random.default_rng(7)
        ts = [place_target("reach", limits, spec.comfort_fraction, spec.stretch_fraction, rng,
                           planes_deg=spec.planes_deg, elbow_range_deg=spec.elbow_flexion_deg) for _ in range(30)]
        heights[name] = np.array([target_hand_m("reach", t, f)[1] for t in ts])
        assert all(t.value_deg <= spec.stretch_fraction * limits.positive_deg + 1e-9 for t in ts)
    # same draws, larger range: every target higher (the arm rises further)
    assert (heights["large"] > heights["small"] + 0.05).all()
    rot = load_game("rotation")
    a = place_target("rotation", RomLimits(30.0, 30.0), rot.comfort_fraction, 1.0, np.random.default_rng(1))
    b = place_target("rotation", RomLimits(70.0, 30.0), rot.comfort_fraction, 1.0, np.random.default_rng(1))
    assert b.value_deg == pytest.approx(a.value_deg * 70.0 / 30.0)
    assert np.linalg.norm(target_hand_m("rotation", a, f) - target_hand_m("rotation", b, f)) > 0.05


# ----------------------------------------------------------------------------- difficulty
def test_level_rises_with_success_falls_with_failure_within_the_therapists_limits():
    spec = load_game("reach").difficulty
    a = LevelAdapter(spec, start=0.3, low=0.2, high=0.6)
    sizes = [a.size]
    for _ in range(5 * spec.window):
        a.record(True)
        sizes.append(a.size)
    assert a.level == pytest.approx(0.6)                 # capped by the therapist
    assert sizes[-1] < sizes[0]                          # smaller targets
    assert a.hold_s > spec.hold_s.at(0.3) and a.time_limit_s < spec.time_limit_s.at(0.3)
    assert a.top_fraction > spec.top_fraction.at(0.3)    # further out
    for _ in range(10 * spec.window):
        a.record(False)
    assert a.level == pytest.approx(0.2)
    b = LevelAdapter(spec, start=0.5)
    for ok in (True, False, True, False):                # 50 %: between the thresholds, stays
        b.record(ok)
    assert b.level == 0.5


# ----------------------------------------------------------------------------- the session
def _ready(session: GameSession, t0: float = 0.0, **kw) -> float:
    """Feed still readings until the game plays; returns the time."""
    t = t0
    rest = elbow_at_side_hand_m(frame(), 0.0)
    while session.phase is Phase.GET_READY:
        session.update(t, reading(rest, **kw))
        t += DT
        assert t < t0 + READY_S + 1.0
    return t


def _until_target(session: GameSession, t: float, hand=None) -> float:
    rest = elbow_at_side_hand_m(frame(), 0.0)
    while session.target is None:
        session.update(t, reading(rest if hand is None else hand))
        t += DT
    return t


def test_holding_the_hand_on_a_target_collects_it_and_leaving_it_misses_it():
    spec = load_game("reach")
    s = GameSession(spec, RomLimits(120.0, 110.0, 140.0), seed=1)
    t = _until_target(s, _ready(s))
    target = s.target
    t0 = t
    while s.log.reached == 0:
        s.update(t, reading(target.hand_m + 0.3 * target.size))
        t += DT
        assert t - t0 < target.hold_s + 0.2
    assert t - t0 >= target.hold_s - DT
    assert Cue.COLLECTED in s.take_cues()
    rec = s.log.targets[0]
    assert rec["reached"] and rec["value_deg"] == pytest.approx(target.target.value_deg, abs=0.01)
    # the next target: the hand stays away, the time limit runs out
    t = _until_target(s, t)
    limit = s.target.time_limit_s
    far = s.target.hand_m + np.array([0.0, -0.4, 0.2])
    t1 = t
    while s.log.missed == 0:
        s.update(t, reading(far))
        t += DT
    assert t - t1 == pytest.approx(limit, abs=2 * DT)
    assert s.log.range_used["elbow_flexion"] == (90.0, 90.0)


def test_tracker_stopped_or_markers_lost_pause_the_game_and_it_resumes():
    spec = load_game("rotation")
    s = GameSession(spec, RomLimits(60.0, 60.0), seed=2)
    t = _until_target(s, _ready(s))
    age = s.target.age_s
    for _ in range(60):   # two seconds without a reading
        s.update(t, None, "The tracker stopped: restarting...")
        t += DT
    assert s.paused and s.pause_reason.startswith("The tracker stopped")
    assert s.target.age_s == age and s.log.paused_s == pytest.approx(2.0, abs=1e-6)
    assert Cue.PAUSED in s.take_cues()
    goal = s.target.target.value_deg
    s.update(t, reading(elbow_at_side_hand_m(frame(), goal), er=goal))
    assert not s.paused and Cue.RESUMED in s.take_cues()
    # the elbow leaves the side: a posture pause, nothing scored
    held = s.target.held_s
    for _ in range(30):
        t += DT
        s.update(t, reading(elbow_at_side_hand_m(frame(), goal), er=goal, elevation=60.0))
    assert s.pause_reason == "Keep your elbow at your side" and s.target.held_s == held


def test_read_sample_says_why_there_is_no_reading():
    from tracking.markerset import load_markerset
    from tracking.sim.body import BodyDimensions, BodyModel, reference_pose
    from tracking.angles import ANGLE_COLUMNS, joint_angles

    ms = load_markerset("upper_limb_seated")
    p = BodyModel(BodyDimensions.from_percentile(50, "male"), ms).markers_m(reference_pose())
    angles = joint_angles(p, ms.names)
    names = tuple(ANGLE_COLUMNS)

    class S:
        state = 1
        message = ""
        positions_m = p
        status = np.ones(len(ms.names), np.uint8)
        angles_deg = np.array([float(angles[n]) for n in names])

    r, why = read_sample(S, ms.names, names, "right")
    assert why == "" and r is not None
    assert np.linalg.norm(r.hand_m - (p[ms.names.index("MRW1")] + p[ms.names.index("MRW2")]) / 2) < 1e-12
    assert r.angles["elbow_flexion"] == pytest.approx(float(angles["right_elbow_flexion"]))
    S.status = S.status.copy()
    S.status[ms.names.index("MRW1")] = 0
    r, why = read_sample(S, ms.names, names, "right")
    assert r is None and "MRW1" in why
    S.state = 0
    S.message = "identifying the markers"
    r, why = read_sample(S, ms.names, names, "right")
    assert r is None and "identifying" in why


def test_compensation_pauses_scoring_and_its_time_is_logged():
    spec = load_game("reach")
    s = GameSession(spec, RomLimits(120.0, 110.0, 140.0), seed=4)
    t = _until_target(s, _ready(s))
    on = s.target.hand_m
    for _ in range(45):   # leaning 15 degrees forward while on the target: nothing collected
        s.update(t, reading(on, lean=15.0))
        t += DT
    assert s.compensation.startswith("Sit up straight") and s.log.reached == 0
    assert s.log.compensation_s == pytest.approx(45 * DT, abs=1e-6)
    for _ in range(10):   # hiking the shoulder 3 cm at a low elevation
        s.update(t, reading(on, hiking=0.13))
        t += DT
    assert s.compensation.startswith("Relax your shoulder")
    while s.log.reached == 0:
        s.update(t, reading(on))
        t += DT
    assert not s.compensation


def test_the_log_is_stored_and_read_back(tmp_path):
    spec = load_game("turn_key")
    s = GameSession(spec, RomLimits(70.0, 60.0), seed=5)
    t = _ready(s)
    for _ in range(3):
        t = _until_target(s, t)
        goal = s.target.target.value_deg
        n = s.log.reached
        while s.log.reached == n:
            s.update(t, reading(elbow_at_side_hand_m(frame(), 0.0), sup=goal))
            t += DT
    log = s.finish()
    path = tmp_path / "db.sqlite3"
    with Database(path) as db:
        db.add_patient("P001")
    uid = store_log(path, "P001", log, source="sim")
    with Database(path) as db:
        (row,) = db.exercise_results("P001")
        (session,) = db.sessions("P001")
    assert row.uid == uid and row.game == "turn_key" and row.repetitions == 3 and session.kind == "exercise"
    assert row.duration_s == pytest.approx(t - DT, abs=1e-6) and row.score == 1.0
    details = json.loads(row.details)
    assert details["reached"] == 3 and len(details["targets"]) == 3
    assert all(spec.comfort_fraction <= d["fraction"] <= spec.stretch_fraction for d in details["targets"])
    lo, hi = details["range_used"]["forearm_supination"]
    assert lo < 0 < hi   # targets alternate pronation and supination
    assert details["limits"]["positive_deg"] == 70.0


def test_a_stored_session_spans_its_duration_and_the_demo_is_logged_apart(tmp_path):
    """The session's ended_utc is its duration after started_utc (they were equal); the demo's
    play time and the targets it collected are logged, and a session the demo played from start
    to end is stored with the source "demo"."""
    from datetime import datetime

    spec = load_game("turn_key")
    path = tmp_path / "db.sqlite3"
    with Database(path) as db:
        db.add_patient("P001")
    rest = elbow_at_side_hand_m(frame(), 0.0)
    for demo_from in (2, 0):               # the patient plays, M hands over to the demo after 2 targets; the demo alone
        s = GameSession(spec, RomLimits(70.0, 60.0), seed=5)
        t = 0.0
        for k in range(4):
            demo = k >= demo_from
            while s.target is None:        # getting ready, the rest between targets
                s.update(t, reading(rest), demo=demo)
                t += DT
            goal = s.target.target.value_deg
            n = s.log.reached
            while s.log.reached == n:
                s.update(t, reading(elbow_at_side_hand_m(frame(), 0.0), sup=goal), demo=demo)
                t += DT
        log = s.finish()
        store_log(path, "P001", log, source="sim")
        by_demo = [d["demo"] for d in json.loads(log.details_json())["targets"]]
        assert by_demo == ([False, False, True, True] if demo_from == 2 else [True] * 4)
        assert 0.0 < log.demo_s <= log.active_s
    with Database(path) as db:
        rows = db.exercise_results("P001")
        sessions = db.sessions("P001")
    assert [x.source for x in sessions] == ["sim", "demo"]
    for row, session in zip(rows, sessions):
        span = (datetime.fromisoformat(session.ended_utc.rstrip("Z"))
                - datetime.fromisoformat(session.started_utc.rstrip("Z"))).total_seconds()
        assert row.duration_s > 5.0 and abs(span - row.duration_s) <= 1.0
    from game.report import demo_part, score_words

    mixed, alone = demo_part(rows[0]), demo_part(rows[1])
    assert mixed.repetitions == 2 and mixed.words.startswith("patient + demo")
    assert alone.repetitions == 4 and alone.words == "demo"
    assert score_words(rows[0]) == "100 %"


def test_play_game_options_are_checked_in_one_line(tmp_path, capsys):
    from game.cli import main

    db = tmp_path / "db.sqlite3"
    with Database(db) as d:
        d.add_patient("P001")
    for argv, words in ((["--game", "nosuch", "--patient", "P001"], "unknown game 'nosuch'"),
                        (["--game", "reach", "--patient", "NOPE"], "no patient 'NOPE'"),
                        (["--game", "reach"], "give --patient ID with --game"),
                        (["--auto"], "--auto plays a game")):
        assert main(["play", "--headless", "--db", str(db), *argv]) != 0
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1


def test_sound_cues_are_generated_tones_and_silence_never_fails(monkeypatch):
    from game.exergames.audio import NOTES, RATE_HZ, Sounds, tone

    samples = tone(NOTES[Cue.COLLECTED])
    duration = sum(d for _, d in NOTES[Cue.COLLECTED])
    assert samples.dtype == np.int16 and samples.shape[1] == 2
    assert abs(len(samples) - duration * RATE_HZ) <= len(NOTES[Cue.COLLECTED])
    assert 0.2 * 32767 < np.abs(samples).max() < 32767
    # the first note's pitch: 659 Hz from the zero crossings
    first = samples[: int(0.08 * RATE_HZ), 0].astype(float)
    crossings = np.count_nonzero(np.diff(np.sign(first)) != 0)
    assert crossings / 2 / 0.08 == pytest.approx(659.3, rel=0.2)
    monkeypatch.setenv("SDL_AUDIODRIVER", "dummy")
    for sounds in (Sounds(), Sounds(mute=True)):
        assert not sounds.enabled
        sounds.play(Cue.COLLECTED)   # silent, no error


def test_game_menu_passes_side_demo_and_the_therapists_highest_level():
    from game.input import Action, Press
    from game.scenes.game_menu import ChooseGameScene
    from game.scenes.game_play import level_from_shown, level_shown

    opened = []

    class FakeApp:
        def push(self, scene):
            opened.append(scene)

    menu = ChooseGameScene("P001", lambda spec, pid, **kw: (spec.name, pid, kw))
    menu.app = FakeApp()
    for action in (Action.DOWN, Action.RIGHT, Action.NEXT_MOTION, Action.ROTATE_IN, Action.ROTATE_IN,
                   Action.ROTATE_IN, Action.SELECT):
        menu.handle(Press(action, True))
    assert not opened and menu.column == 0     # Enter on a game: to its Play button and limits
    menu.handle(Press(Action.SELECT, True))
    (name, pid, kw), = opened
    assert name == menu.games[1].name and pid == "P001"
    assert kw["side"] == "left" and kw["auto"] is True
    assert level_shown(kw["limits"].max_level) == 7 and menu.max_level == 7   # 10 is no limit: 9, 8, 7
    menu.change_max_level(+5)
    assert menu.max_level is None          # above 10: no limit
    assert [level_shown(level_from_shown(k)) for k in range(1, 11)] == list(range(1, 11))
    spec = load_game("reach").difficulty
    a = LevelAdapter(spec, start=0.9, high=level_from_shown(3))
    assert a.level == pytest.approx(2 / 9)


def test_limits_step_within_the_games_bounds_and_unset_past_the_games_own():
    from game.exergames.limits import LIMIT_KEYS, describe, free_value, step_limit, whose
    from game.exergames.spec import TherapistLimits, check_limits, limit_bounds

    for name in available_games():
        spec = load_game(name)
        for key in LIMIT_KEYS:
            lim = TherapistLimits()
            lo, hi = limit_bounds(spec)[key]
            values = []
            for direction in (1, -1):
                lim = TherapistLimits()
                for _ in range(40):
                    lim = step_limit(spec, lim, key, direction)
                    check_limits(spec, lim)          # never outside the game's bounds
                    values.append(getattr(lim, key))
            assert None in values and any(v is not None for v in values), (name, key)
            assert all(v is None or lo - 1e-9 <= v <= hi + 1e-9 for v in values)
            assert whose(TherapistLimits(), key) == "the game's own" and describe(spec, TherapistLimits(), key)
        # one step stricter than the game's own from unset
        rot = load_game("rotation")
        assert step_limit(rot, TherapistLimits(), "min_size", 1).min_size == free_value(rot, "min_size") + 1
        assert step_limit(rot, TherapistLimits(), "min_size", -1).min_size is None
    reach = load_game("reach")
    lim = step_limit(reach, TherapistLimits(), "max_range", -1)
    assert lim.max_range == pytest.approx(1.0) and describe(reach, lim, "max_range") == "100 % of the measured range"
    assert whose(lim, "max_range") == "set for this patient"


def _menu_for(db_path):
    """The game menu of patient P001 whose Play records (spec, keywords) in the returned list."""
    from game.scenes.game_menu import ChooseGameScene

    opened = []

    class FakeApp:
        def push(self, scene):
            opened.append(scene)

    menu = ChooseGameScene("P001", lambda spec, pid, **kw: (spec, kw), db_path=db_path)
    menu.app = FakeApp()
    return menu, opened


def test_the_menu_stores_a_patients_limits_and_the_next_menu_and_the_game_use_them(tmp_path):
    from game.exergames.limits import LIMIT_KEYS, load_limits
    from game.input import Action, Press
    from game.scenes.game_menu import ChooseGameScene

    db_path = tmp_path / "rehab.sqlite3"
    with Database(db_path) as db:
        db.add_patient("P001")
        db.add_patient("P002")
    menu, opened = _menu_for(db_path)
    rot = [g.name for g in menu.games].index("rotation")
    for _ in range(rot):
        menu.handle(Press(Action.DOWN, True))
    menu.handle(Press(Action.SELECT, True))                      # the rotation game's column
    for _ in range(1 + LIMIT_KEYS.index("max_range")):           # down from Play to the range limit
        menu.handle(Press(Action.DOWN, True))
    assert menu.game.name == "rotation" and menu.column == 1 + LIMIT_KEYS.index("max_range")
    for _ in range(3):
        menu.handle(Press(Action.LEFT, True))                    # 105 % -> 90 %
    menu.handle(Press(Action.SELECT, True))                      # Enter plays
    (spec, kw), = opened
    assert spec.name == "rotation" and kw["limits"].max_range == pytest.approx(0.9)
    again = load_limits(db_path, "P001", [spec])["rotation"]
    assert again.max_range == pytest.approx(0.9)                 # stored for the patient
    assert load_limits(db_path, "P002", [spec])["rotation"] == spec.limits   # not for another
    menu2 = ChooseGameScene("P001", lambda spec, pid, **kw: None, db_path=db_path)
    assert menu2.limits["rotation"].max_range == pytest.approx(0.9)
    # a stored value the game no longer allows is ignored
    with Database(db_path) as db:
        db.set_game_limits("P001", "rotation", '{"max_range": 0.1}')
    assert load_limits(db_path, "P001", [spec])["rotation"] == spec.limits


def test_the_lowest_level_is_set_on_the_menu_stored_and_the_session_starts_and_stays_there(tmp_path):
    from game.exergames.limits import LIMIT_KEYS, describe, load_limits, whose
    from game.exergames.spec import TherapistLimits
    from game.input import Action, Press
    from game.scenes.game_play import level_shown

    db_path = tmp_path / "rehab.sqlite3"
    with Database(db_path) as db:
        db.add_patient("P001")
    menu, opened = _menu_for(db_path)
    menu.handle(Press(Action.SELECT, True))                      # the first game's column
    for _ in range(1 + LIMIT_KEYS.index("min_level")):           # down from Play to the lowest level
        menu.handle(Press(Action.DOWN, True))
    spec0 = menu.game
    assert whose(menu.limits[spec0.name], "min_level") == "the game's own"
    for _ in range(4):
        menu.handle(Press(Action.RIGHT, True))                   # level 1 -> level 5
    lim = menu.limits[spec0.name]
    assert level_shown(lim.min_level) == 5 and describe(spec0, lim, "min_level") == "level 5"
    assert load_limits(db_path, "P001", [spec0])[spec0.name].min_level == pytest.approx(lim.min_level)  # stored
    menu.handle(Press(Action.SELECT, True))                      # Enter plays with it
    (spec, kw), = opened
    assert kw["limits"].min_level == pytest.approx(4 / 9, abs=1e-3)
    # the session starts at the lowest level at least and failing never takes it below
    a = LevelAdapter(spec.difficulty, start=0.0, limits=kw["limits"])
    assert a.level == pytest.approx(4 / 9, abs=1e-3)
    for _ in range(5 * spec.difficulty.window):
        a.record(False)
    assert a.level == pytest.approx(4 / 9, abs=1e-3)
    # the highest level wins when the two cross
    b = LevelAdapter(spec.difficulty, start=0.0, limits=TherapistLimits(min_level=0.8, max_level=0.5))
    assert b.level == pytest.approx(0.5) and b.low == pytest.approx(0.5)


# ----------------------------------------------------------------------------- the rotation game's river
@pytest.mark.parametrize("side", ["right", "left"])
def test_the_river_spans_the_measured_range_and_mirrors_the_left_arm(side):
    from game.exergames.river import MARGIN_DEG, river_for

    spec = load_game("rotation")
    river = river_for(RomLimits(50.0, 40.0), spec.stretch_fraction, side)
    assert river.out_deg == pytest.approx(50.0 * spec.stretch_fraction + MARGIN_DEG)
    assert river.in_deg == pytest.approx(-(40.0 * spec.stretch_fraction + MARGIN_DEG))
    out, inward = river.across(river.out_deg), river.across(river.in_deg)
    # a mirror: the right arm turning out goes right on the screen, the left arm's goes left
    assert (out, inward) == ((1.0, 0.0) if side == "right" else (0.0, 1.0))
    assert river.across(500.0) == out                       # the boat stops at the bank
    for v in (-30.0, 0.0, 12.5, 49.0):
        assert river.rotation_at(river.across(v)) == pytest.approx(v)
    assert river.width(river.span_deg / 4) == pytest.approx(0.25)


def test_a_gate_drifts_down_to_the_boat_and_cannot_be_passed_before_it_arrives():
    from game.exergames.river import gate_distance

    spec = load_game("rotation")
    s = GameSession(spec, RomLimits(60.0, 60.0), seed=4)
    t = _until_target(s, _ready(s))
    gate = s.target
    assert gate.approach_s == pytest.approx(spec.difficulty.approach_share * gate.time_limit_s)
    goal = gate.target.value_deg
    on_goal = reading(elbow_at_side_hand_m(frame(), goal), er=goal)
    distances, t0 = [], t
    while s.log.reached == 0:        # the boat lined up from the start
        s.update(t, on_goal)
        if s.target is gate:
            distances.append(gate_distance(gate))
            if not gate.arrived:
                assert gate.held_s == 0.0          # not before it reaches the boat
        t += DT
        assert t - t0 < gate.approach_s + gate.hold_s + 0.3
    assert t - t0 >= gate.approach_s + gate.hold_s - 2 * DT
    assert distances[0] == pytest.approx(1.0, abs=0.05) and min(distances) <= -0.9
    assert all(b <= a + 1e-9 for a, b in zip(distances, distances[1:]))   # always towards and through the boat
    assert s.log.targets[0]["reached"]


def test_therapist_limits_bound_what_the_adaptation_asks_at_every_level():
    from game.exergames.spec import TherapistLimits

    for name in ("reach", "rotation", "turn_key"):
        d = load_game(name).difficulty
        limits = TherapistLimits(max_level=0.8, max_range=0.9, min_size=(d.size.easy + d.size.hard) / 2,
                                 max_hold_s=(d.hold_s.easy + d.hold_s.hard) / 2,
                                 min_time_s=(d.time_limit_s.easy + d.time_limit_s.hard) / 2)
        a = LevelAdapter(d, start=0.0, limits=limits)
        seen = []
        for _ in range(12 * d.window):     # always successful: the level climbs as far as allowed
            a.record(True)
            seen.append((a.level, a.top_fraction, a.size, a.hold_s, a.time_limit_s, a.approach_s))
        levels, tops, sizes, holds, times, approaches = map(np.array, zip(*seen))
        assert levels.max() == pytest.approx(0.8)
        assert (tops <= 0.9 + 1e-9).all() and tops.max() == pytest.approx(0.9)
        assert (sizes >= limits.min_size - 1e-9).all() and (holds <= limits.max_hold_s + 1e-9).all()
        assert (times >= limits.min_time_s - 1e-9).all()
        assert (approaches >= d.approach_share * limits.min_time_s - 1e-9).all()
        free = LevelAdapter(d, start=0.8)
        assert free.size < limits.min_size and free.hold_s > limits.max_hold_s   # the limits did bind
    # the session places its targets under the limited top
    spec = load_game("rotation")
    s = GameSession(spec, RomLimits(60.0, 60.0), seed=5, level=1.0, therapist=TherapistLimits(max_range=0.7))
    _until_target(s, _ready(s))
    assert s.target.target.fraction <= 0.7 and s.log.therapist == {"max_range": 0.7}


def test_limits_out_of_a_games_bounds_are_one_line_naming_the_key(tmp_path):
    text = (load_game("rotation").model_dump_json())
    data = json.loads(text)
    data["limits"] = {"max_range": 2.0}
    path = tmp_path / "bad.yaml"
    import yaml

    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ContentError, match=r"bad.yaml: limits.max_range"):
        load_game(path)
    data["limits"] = {"min_size": 40.0}
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ContentError, match=r"limits.min_size 40 must lie in 6..24"):
        load_game(path)
    data["limits"] = {}
    data["difficulty"]["approach_share"] = 0.0
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ContentError, match="approach_share"):
        load_game(path)


def test_no_sound_card_is_silence_without_messages_on_the_terminal():
    """Without a sound card the mixer fails once, quietly: ALSA's lines (eight per try, twice for
    two games) go to the debug log, and a second game does not try again."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "SDL_AUDIODRIVER"}
    code = ("import logging, sys\n"
            "logging.basicConfig(level=logging.DEBUG, stream=sys.stdout)\n"
            "from game.exergames.audio import Sounds\n"
            "a, b = Sounds(), Sounds()\n"
            "print('enabled', a.enabled, b.enabled)\n")
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "ALSA" not in run.stderr and run.stderr.strip() == "", run.stderr
    enabled = run.stdout.split("enabled ")[-1].split()
    assert enabled[0] == enabled[1]
    if enabled[0] == "False":
        assert run.stdout.count("no sound:") == 1          # tried once
