"""``rehab play``: the application put together (screen, tracker, scenes) and run.

Window mode opens on the home screen; headless mode (offscreen, no window) opens the live avatar
directly, plays a scripted motion on the simulated patient for a given time and saves the last
frame, which is how tests and reviewers see the whole application work.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable

from calibration.errors import RehabError
from game.app import App, RunSummary, Services, Settings
from game.gfx.screen import open_screen
from game.live_link import LiveLink
from game.scenes.home import HomeScene, MenuEntry
from game.scenes.live import LiveScene

if TYPE_CHECKING:
    from tracking.live import SourceConfig

log = logging.getLogger(__name__)

#: What headless runs play when no motion is named.
DEFAULT_HEADLESS_MOTION = "shoulder_abduction"
SCENES = ("home", "live", "cameras", "rom", "progress", "game", "calibrate")
#: The test ``--scene rom`` opens when none is named.
DEFAULT_ROM_TEST = "shoulder_flexion"
#: The game ``--scene game`` opens when none is named.
DEFAULT_GAME = "reach"


@dataclass(frozen=True, slots=True)
class PlayOptions:
    """What ``rehab play`` was asked for.

    Attributes:
        settings: window size, update rate, frame-rate cap.
        source: what the tracker process measures (None: the simulated patient's defaults).
        headless: draw offscreen for ``seconds`` and stop.
        seconds: run time (None: until quit).
        screenshot: save the last frame there (PNG).
        scene: the first scene: ``home``, ``live``, ``cameras``, ``rom`` (the ROM test of ``patient``,
            ``test``, ``side``, playing its demo motion) or ``progress`` (of ``patient``).
        motion: the scripted motion playing at the start (None: the patient follows the mouse).
        start_timeout_s: how long the tracker may take to start.
        db_path: the database of patients and results (None: the user's data directory).
        patient, test, side, standard: what ``rom`` and ``progress`` open on.
        game: the exercise game to open (``content/games`` name) on ``patient`` and ``side``.
        auto: the simulated patient plays the game by itself (the automatic demo).
        mute: no sound.
        max_level: the therapist's highest level of the games, 1..10 (None: each game's own limit).
        calibration_path: where the calibration scene saves (None: ``calibration.toml`` in the
            user's data directory).
        calibrate_devices: cameras (OpenCV indices, URLs or video files) the calibration scene
            shows, named cam1, cam2, ...; () : the simulated studio's.
        calibration_board: the board held up in the calibration scene (a Checkerboard or
            CharucoBoard; None: the simulator's 9 x 6 checkerboard of 60 mm squares).
        calibration_lenses: a calibration file whose lens data the calibration scene reuses
            (it opens at step 2; None: the lens step first).
        wait_for_tracker: the run's ``seconds`` begin once the tracker is ready, in a window too
            (headless runs always wait; ``rehab bench`` measures the window with the avatar moving).
        stream: a :class:`tracking.live.stream.StreamConfig`: the tracker process also streams
            over LSL and/or OSC (None: no streaming).
    """

    settings: Settings = field(default_factory=Settings)
    source: "SourceConfig | None" = None
    headless: bool = False
    seconds: float | None = None
    screenshot: Path | None = None
    scene: str = "home"
    motion: str | None = None
    start_timeout_s: float = 60.0
    db_path: str | Path | None = None
    patient: str | None = None
    test: str | None = None
    side: str = "right"
    standard: str = "jarm"
    game: str | None = None
    auto: bool = False
    mute: bool = False
    max_level: int | None = None
    calibration_path: Path | None = None
    calibrate_devices: tuple[str, ...] = ()
    calibration_board: object = None
    calibration_lenses: Path | None = None
    wait_for_tracker: bool = False
    stream: object = None
    user: str | None = None   # the signed-in account (check_account), audited with accepted ROM results
    sign_in: bool = False     # open on the sign-in screen (accounts, and no account or PIN given: needs_sign_in)


def make_avatar(ctx, marker_names, roles=None):
    """The patient's avatar on ``ctx`` for a marker set's names and roles (:mod:`game.avatar`)."""
    from game.avatar.live import LiveAvatar

    return LiveAvatar(ctx, marker_names, roles=roles)


def build_app(screen, options: PlayOptions, link: LiveLink, *, clock: Callable[[], float] = time.perf_counter,
              sleep: Callable[[float], None] = time.sleep) -> App:
    """The application with its scenes on ``screen``, reading ``link``."""
    from tracking.sim.motions import available_motions  # lazy: only to run the simulated patient

    app = App(screen, options.settings, clock=clock, sleep=sleep, services=Services(link))
    motions = [None, *available_motions()]

    def open_monitor():
        from game.scenes.monitor import MonitorScene

        return MonitorScene(link)

    def open_live():
        return LiveScene(link, motions=motions, motion=options.motion, open_monitor=open_monitor,
                         make_avatar=make_avatar, source_kind=getattr(options.source, "kind", "sim") or "sim")

    from game.db import db_location
    from game.scenes.patients import PatientsScene
    from game.scenes.progress import ProgressScene
    from game.rom.visit import RomVisit
    from game.scenes.rom_test import ChooseTestScene, RomTestScene

    db_path = db_location(options.db_path)
    source_kind = getattr(options.source, "kind", "sim") or "sim"

    def open_test(visit, test, side, demo=False):
        return RomTestScene(link, visit, test, side, make_avatar=make_avatar, demo=demo)

    def open_rom():
        def visit(pid):
            return RomVisit(db_path, pid, options.standard, source_kind, accepted_by=options.user or "")

        return PatientsScene(db_path, lambda pid: ChooseTestScene(visit(pid), open_test),
                             title="ROM test: choose the patient")

    def open_progress():
        return PatientsScene(db_path, lambda pid: ProgressScene(db_path, pid, standard=options.standard),
                             title="Progress: choose the patient", allow_new=False)

    def open_game(spec, patient_id, side=options.side, auto=options.auto, limits=None):
        from game.exergames.limits import load_limits
        from game.scenes.game_play import GameScene, level_from_shown

        if limits is None:   # straight from the command line: the patient's stored limits, --max-level on top
            limits = load_limits(db_path, patient_id, [spec])[spec.name]
            if options.max_level is not None:
                limits = limits.model_copy(update={"max_level": level_from_shown(options.max_level)})
        return GameScene(link, spec, side, db_path, patient_id, make_avatar=make_avatar, auto=auto,
                         mute=options.mute, source=source_kind, therapist=limits)

    def open_games():
        from game.scenes.game_menu import ChooseGameScene

        return PatientsScene(db_path, lambda pid: ChooseGameScene(pid, open_game, side=options.side,
                                                                  max_level=options.max_level, db_path=db_path,
                                                                  account=options.user or ""),
                             title="Games: choose the patient")

    def open_calibrate():
        from game.scenes.calibrate import CalibrateScene, camera_feeds, lenses_for_feeds, sim_feeds
        from tracking.sim.calibration_material import DEFAULT_BOARD  # lazy: only to run the simulated patient

        board = options.calibration_board or DEFAULT_BOARD
        if options.calibrate_devices:
            feeds = camera_feeds(options.calibrate_devices)
        else:
            rig = getattr(options.source, "rig", "ring4") or "ring4"
            feeds = sim_feeds(rig, (640, 480), board, ctx=app.screen.ctx)
        lenses = None
        if options.calibration_lenses is not None:
            try:
                lenses = lenses_for_feeds(options.calibration_lenses, feeds)
            except Exception:
                for feed in feeds:   # real cameras are released before the one-line error
                    getattr(feed, "close", lambda: None)()
                raise
        return CalibrateScene(feeds, board, out_path=options.calibration_path, auto=options.headless, lenses=lenses)

    home = HomeScene([
        MenuEntry("Live avatar", "See yourself move, with your joint angles", open_live),
        MenuEntry("Games", "Exercise inside the measured range", open_games),
        MenuEntry("ROM test", "Measure a range of motion", open_rom),
        MenuEntry("Progress", "Results over the sessions", open_progress),
        MenuEntry("Camera check", "What each camera sees, and the markers it finds", open_monitor),
        MenuEntry("Calibrate cameras", "Lenses, camera positions and the floor, step by step", open_calibrate),
        MenuEntry("Quit", "", None),
    ], status=link.summary)
    def open_start():
        """The home screen and the first screen asked for (``--scene``, ``--game``)."""
        app.push(home)
        if options.scene == "live":
            app.push(open_live())
        elif options.scene == "cameras":
            app.push(open_monitor())
        elif options.scene == "calibrate":
            app.push(open_calibrate())
        elif options.scene == "game" or options.game:
            from game.exergames.spec import load_game

            spec = load_game(options.game or DEFAULT_GAME)
            check_scene_options(replace(options, scene="game"))
            app.push(open_game(spec, options.patient))
        elif options.scene in ("rom", "progress"):
            check_scene_options(options)
            if options.scene == "progress":
                app.push(ProgressScene(db_path, options.patient, standard=options.standard))
            else:
                from game.rom.spec import load_rom_test

                test = load_rom_test(options.test or DEFAULT_ROM_TEST)
                visit = RomVisit(db_path, options.patient, options.standard, source_kind, accepted_by=options.user or "")
                app.push(ChooseTestScene(visit, open_test, side=options.side))
                app.push(open_test(visit, test, options.side, demo=True))

    def signed_in(account):
        """After the sign-in screen: what ``account`` may open (as :func:`check_account`), audited as it."""
        nonlocal options
        own_games = account.role == "patient" and (options.game or options.scene in (None, "home", "game"))
        account.require("play" if own_games else SCENE_ACTIONS.get(options.scene, "patients"), options.patient)
        options = replace(options, user=account.name)
        if account.role == "therapist":
            return open_start()
        from game.scenes.game_menu import ChooseGameScene

        own = account.patient_id
        app.push(ChooseGameScene(own, open_game, side=options.side, max_level=options.max_level, db_path=db_path,
                                 account=account.name, may_change_limits=False))
        if options.game or options.scene == "game":
            from game.exergames.spec import load_game

            app.push(open_game(load_game(options.game or DEFAULT_GAME), own))

    if options.sign_in:
        from game.scenes.sign_in import SignInScene

        app.push(SignInScene(db_path, signed_in, name=options.user or ""))
    else:
        open_start()
    return app


#: the first screen -> what the account must be allowed (game.db.accounts.PERMISSIONS)
SCENE_ACTIONS = {"game": "play", "rom": "rom_test", "progress": "progress"}


def needs_sign_in(options: PlayOptions) -> bool:
    """Whether the application opens on its sign-in screen: the database has accounts, and no account
    was given (``--user``, ``REHAB_USER``) or no secret for it (``REHAB_PIN``) without a terminal to ask
    it on (a desktop launcher). ``--user`` with ``REHAB_PIN``, or on a terminal, signs in as before."""
    import os
    import sys

    from game.db import Database, DatabaseError, DatabaseUnreachable, db_location
    from game.db.accounts import accounts_in_use

    location = db_location(options.db_path)
    if isinstance(location, Path) and not location.is_file():
        return False
    try:
        with Database(location) as db:
            if not accounts_in_use(db):
                return False
    except (DatabaseUnreachable, DatabaseError):
        return False
    if not (options.user or os.environ.get("REHAB_USER", "").strip()):
        return True
    return os.environ.get("REHAB_PIN") is None and not sys.stdin.isatty()


def check_account(options: PlayOptions):
    """Where the database has accounts: the signed-in account may open the first screen (None: no accounts).

    A patient account may only play its own patient's games (``--game``); every other screen is
    the therapist's (the patient list, ROM tests, progress, limits, cameras, calibration).

    Raises:
        AccessDenied: no or a wrong account, or one that may not open this screen (one line).
    """
    from game.cli_clinic import signed_in
    from game.db import Database, DatabaseError, DatabaseUnreachable, db_location

    location = db_location(options.db_path)
    if isinstance(location, Path) and not location.is_file():
        return None   # no database yet: no accounts
    try:
        with Database(location) as db:
            return signed_in(options.user, db, SCENE_ACTIONS.get(options.scene, "patients"), options.patient)
    except (DatabaseUnreachable, DatabaseError):
        return None   # the screens that read the database say what is wrong with it (check_scene_options)


def check_scene_options(options: PlayOptions) -> None:
    """The ``rom``, ``progress`` and ``game`` scenes open on an existing patient (and a test for the side).

    Raises:
        RehabError: one line saying what to give or fix.
    """
    from game.db import Database, DatabaseUnreachable

    if not options.patient:
        what = "--game" if options.scene == "game" else f"--scene {options.scene}"
        raise RehabError(f"give --patient ID with {what} (see rehab patients)")
    if options.scene == "rom":
        from game.rom.spec import check_side, load_rom_test

        check_side(load_rom_test(options.test or DEFAULT_ROM_TEST), options.side)
    try:
        with Database(options.db_path, check_integrity=True) as db:   # the full check: at start-up
            db.require_patient(options.patient)
    except DatabaseUnreachable as exc:
        raise RehabError(f"{str(exc).split('): ')[0]}): a visit needs the patient's stored ROM and the therapist's "
                         f"limits from the server: start it again when the server is back") from None


def run_play(options: PlayOptions, *, clock: Callable[[], float] = time.perf_counter,
             sleep: Callable[[float], None] = time.sleep) -> RunSummary:
    """Open the screen, start the tracker, run the scenes; everything is closed on the way out.

    Raises:
        game.gfx.screen.NoDisplayError: no display and not headless.
        RehabError: the tracker cannot start (headless), unwritable screenshot, bad options.
    """
    from tracking.live import LiveTracker, SourceConfig

    source = options.source or SourceConfig()
    source.check()
    screen = open_screen(options.settings.window_px, options.settings.title, headless=options.headless,
                         vsync=options.settings.max_fps > 0)
    link = LiveLink(lambda: LiveTracker(source, stream=options.stream), start_timeout_s=options.start_timeout_s)
    app = None
    try:
        link.start()
        if options.headless or options.wait_for_tracker:
            # Offscreen there is nobody to watch "Starting...": the run's seconds begin with the tracker.
            if not link.wait_ready(options.start_timeout_s):
                raise RehabError(link.error or "the tracker did not start")
        app = build_app(screen, options, link, clock=clock, sleep=sleep)
        summary = app.run(seconds=options.seconds, screenshot=options.screenshot)
        link.tick()
        return replace(summary, problem=link.run_problem())
    finally:
        if app is not None:
            app.close()
        link.close()
        screen.close()
