"""The ``rehab`` command line.

Each sub-command imports what it needs when it runs, so ``rehab track`` never loads pygame or
OpenGL. Errors the user can fix (:class:`calibration.errors.RehabError`) are printed as one line on
stderr with exit code 1; nothing else is caught, so a real bug still shows its traceback.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from calibration.errors import RehabError
from game.cli_options import (COUNT, FPS, NOISE, SECONDS, SEED, OneLineParser, check_outputs, handle_broken_pipe,
                              number, size_px)
from game.cli_source import add_tracker_source_options, check_motion, play_source
from tracking import exports  # rehab track's output options are made from the export formats (no pygame, no GL)

log = logging.getLogger("rehab")


def _add_studio_options(p, *, size=(640, 480), fps=30.0) -> None:
    """Options shared by the commands that run the simulated studio."""
    p.add_argument("--rig", default="ring4", help="camera layout: built-in name or YAML file (default: %(default)s)")
    p.add_argument("--cameras", type=number(1, 64, integer=True), default=None, help="use the first N cameras of the rig")
    p.add_argument("--size", type=size_px, default=size, help=f"image size WxH (default: {size[0]}x{size[1]})")
    p.add_argument("--fps", type=FPS, default=fps, help="frame rate (default: %(default)s)")
    p.add_argument("--seconds", type=SECONDS, default=None, help="cut the motion(s) to this length")
    p.add_argument("--percentile", type=number(5.0, 95.0), default=50.0, help="body size percentile 5..95 (default: %(default)s)")
    p.add_argument("--sex", choices=("female", "male"), default="female")
    p.add_argument("--noise", type=NOISE, default=1.5, help="sensor noise sigma in 8-bit units (default: %(default)s)")


# --------------------------------------------------------------------------- simulate
def _add_simulate(sub) -> None:
    p = sub.add_parser(
        "simulate",
        help="render a synthetic recording of the simulated patient, with ground truth",
        description="Render a recording folder (docs/INTERFACES.md) of the simulated patient seen by "
        "virtual cameras, with truth.trc and truth_angles.csv.",
    )
    p.add_argument("out_dir", type=Path, help="output recording folder (created)")
    p.add_argument("--motion", default="right_external_rotation",
                   help="built-in motion name, or a motion YAML file (default: %(default)s)")
    _add_studio_options(p)
    p.add_argument("--drift", type=number(0.0, 0.95), default=0.0,
                   help="brightness drop over the recording as a fraction, e.g. 0.4 (default: none)")
    p.add_argument("--cast", default=None, help="colour cast as R,G,B gains reached at the end, e.g. 1.1,1.0,0.85")
    p.add_argument("--images", action="store_true", help="write PNG folders instead of lossless AVI videos")
    p.add_argument("--markerset", default="upper_limb_seated", help="marker set name or YAML file")
    p.add_argument("--seed", type=SEED, default=0, help="random seed of the sensor noise (and of drawn camera clocks)")
    p.add_argument("--camera-offsets", default=None, metavar="F,F,...|random",
                   help="free-running cameras: each camera's phase in frame periods (one per camera, -0.5..0.5), or "
                        "'random' (drawn from --seed); their instants go to timestamps.csv (default: in step)")
    p.add_argument("--clock-drift", type=number(0.0, 0.05), default=0.0, metavar="FRACTION",
                   help="largest rate difference of a camera's clock, e.g. 0.001 (0.1 %%); each camera's is drawn "
                        "from --seed (default: 0)")
    p.add_argument("--rolling-shutter-ms", type=number(0.0, 200.0), default=0.0, metavar="MS",
                   help="rolling-shutter readout, first row to last, e.g. 25; written to calibration.toml "
                        "(default: 0, global shutter)")
    p.add_argument("--jpeg-quality", type=number(1, 100, integer=True), default=None, metavar="Q",
                   help="MJPEG: each image JPEG-compressed at quality Q (1..100), as webcams send it; the videos stay "
                        "lossless (default: none)")
    p.add_argument("--jpeg-chroma", choices=("422", "420", "444"), default="422",
                   help="with --jpeg-quality: chroma subsampling, 4:2:2 as most webcams' MJPEG (default), 4:2:0 or 4:4:4")
    p.add_argument("--exposure-ms", type=number(0.0, 1000.0), default=0.0, metavar="MS",
                   help="shutter time: a moving ball is smeared along its image motion over MS ms, e.g. 20 "
                        "(default: 0, no motion blur)")
    p.add_argument("--auto-exposure", action="store_true",
                   help="each camera keeps its image's mean brightness with a lagging control loop that hunts when "
                        "the patient moves or the light drifts; its gains go to truth_camera_gains.csv")
    p.add_argument("--auto-white-balance", action="store_true",
                   help="the same loop for the colour balance (grey world)")
    p.set_defaults(func=_cmd_simulate)


def _cmd_simulate(args) -> int:
    from tracking.sim.studio import SimulationSettings, simulate_recording

    cast = None
    if args.cast:
        try:
            cast = tuple(float(v) for v in args.cast.split(","))
            assert len(cast) == 3 and all(0.2 < v < 5 for v in cast)
        except (ValueError, AssertionError):
            raise RehabError(f"--cast {args.cast!r}: give three gains like 1.1,1.0,0.85") from None
    offsets = args.camera_offsets
    if offsets is not None and offsets.strip().lower() != "random":
        try:
            offsets = tuple(float(v) for v in offsets.split(","))
            assert all(-0.5 <= v <= 0.5 for v in offsets)
        except (ValueError, AssertionError):
            raise RehabError(f"--camera-offsets {args.camera_offsets!r}: give one phase per camera in frame "
                             f"periods, -0.5..0.5, like 0,0.4,-0.3,0.2, or 'random'") from None
    elif offsets is not None:
        offsets = "random"
    settings = SimulationSettings(
        camera_offsets=offsets,
        clock_drift=args.clock_drift,
        rolling_shutter_s=args.rolling_shutter_ms / 1000.0,
        jpeg_quality=args.jpeg_quality,
        jpeg_chroma=args.jpeg_chroma,
        exposure_s=args.exposure_ms / 1000.0,
        auto_exposure=args.auto_exposure,
        auto_white_balance=args.auto_white_balance,
        motion=args.motion,
        rig=args.rig,
        n_cameras=args.cameras,
        size_px=args.size,
        fps=args.fps,
        seconds=args.seconds,
        percentile=args.percentile,
        sex=args.sex,
        noise_sigma=args.noise,
        brightness_drop=args.drift,
        colour_cast=cast,
        markerset=args.markerset,
        seed=args.seed,
        images=args.images,
    )
    summary = simulate_recording(args.out_dir, settings, progress=True)
    print(summary)
    return 0


# --------------------------------------------------------------------------- track
def _add_track(sub) -> None:
    p = sub.add_parser(
        "track",
        help="track a recording folder offline with the online algorithm",
        description="Track a recording folder frame by frame (no look-ahead) and write the results.",
    )
    # (optional for argparse only: a recording written after --marker-color's colours is taken back below)
    p.add_argument("recording", type=Path, nargs="?", default=None, help="recording folder (docs/INTERFACES.md)")
    p.add_argument("--calibration", type=Path, default=None, help="calibration file (default: RECORDING/calibration.toml)")
    p.add_argument("--markerset", default=None, help="marker set name or YAML file (default: from meta.yaml)")
    p.add_argument("--marker-color", action="extend", nargs="+", default=None, metavar="R,G,B",
                   help="override marker colours: one for all markers, or one per marker in marker-set order "
                        "(--marker-color R,G,B R,G,B ... or the flag repeated)")
    p.add_argument("--points", type=Path, default=None,
                   help="write unlabelled 3D points: frame,time,x_mm,y_mm,z_mm,n_cameras,reproj_px")
    for fmt in exports.formats():   # one option per export format (tracking/exports/formats/)
        p.add_argument(*fmt.options, dest=fmt.dest, type=Path, default=None, help=fmt.help)
    p.add_argument("--colours", type=Path, default=None, help="learned colour file from `rehab colour learn`")
    p.add_argument("--adapt-colours", action="store_true", help="adapt the colour table as the lighting drifts")
    p.add_argument("--sync", choices=("auto", "stamps", "none"), default="auto",
                   help="the cameras' image instants: auto (timestamps.csv when the recording has it, else each "
                        "camera's clock offset and drift estimated from the markers' motion in the first 10 s), "
                        "stamps (timestamps.csv, required), none (taken as synchronized) (default: %(default)s)")
    p.set_defaults(func=_cmd_track)


def _track_folder(args) -> Path:
    """The recording folder; a folder written right after --marker-color's colours (which take
    every value up to the next option) is the last of those values that is not a colour."""
    if args.recording is not None:
        return args.recording
    colours = args.marker_color or []
    if colours and "," not in colours[-1]:
        args.marker_color = colours[:-1] or None
        return Path(colours[-1])
    first = exports.formats()[0]
    raise RehabError(f"give the recording folder: rehab track RECORDING {first.option} {first.example}")


def _cmd_track(args) -> int:
    from tracking.drivers.offline import track_recording

    args.recording = _track_folder(args)

    formats = exports.formats()
    outputs = {fmt.name: getattr(args, fmt.dest) for fmt in formats}
    labelled = any(outputs.values())
    if args.points and labelled:
        raise RehabError("--points (unlabelled full-frame points) cannot be combined with the labelled outputs: run them separately")
    if not (args.points or labelled):
        others = ", ".join([fmt.option for fmt in formats[1:]] + ["--points"])
        raise RehabError(f"nothing to write: give {formats[0].option} {formats[0].example} (and/or {others})")
    # before the work, not after minutes of tracking
    check_outputs({**{fmt.option: outputs[fmt.name] for fmt in formats}, "--points": args.points},
                  {**{fmt.option: fmt.example for fmt in formats}, "--points": "points.csv"})
    report = _writing(track_recording, "the results")(
        args.recording,
        calibration=args.calibration,
        markerset=args.markerset,
        marker_colours=args.marker_color,
        points_csv=args.points,
        **outputs,
        colours=args.colours,
        adapt_colours=args.adapt_colours,
        progress=True,
        sync=args.sync,
    )
    print(report)
    return 0


def _writing(work, what: str):
    """``work`` with an OSError while writing its outputs (full disk, a folder gone) as one line."""

    def run(*args, **kwargs):
        try:
            return work(*args, **kwargs)
        except OSError as exc:
            where = f" {exc.filename}" if getattr(exc, "filename", None) else ""
            raise RehabError(f"cannot write {what}{where} ({exc.strerror or exc}): check the folder and the free "
                             f"space") from None

    return run


# --------------------------------------------------------------------------- angles
def _add_angles(sub) -> None:
    p = sub.add_parser("angles", help="joint angles from a TRC marker file (docs/JOINT_ANGLES.md)")
    p.add_argument("trc", type=Path, help="marker file with the marker set's names (mm)")
    p.add_argument("--out", type=Path, required=True, help="angles CSV to write")
    p.add_argument("--map", type=Path, default=None, metavar="FILE.yaml",
                   help="the file's names for the angles' markers, one 'MB: STER' line each (TRCs of other marker sets)")
    p.add_argument("--markerset", default=None, metavar="NAME|FILE",
                   help="the marker set the file was made with: the angles take their markers from its roles "
                        "(those it has no markers for are left empty)")
    p.set_defaults(func=_cmd_angles)


def _cmd_angles(args) -> int:
    from tracking.angles import withheld_angles
    from tracking.markerset import load_markerset
    from tracking.io.csv_tables import angles_csv_from_trc, read_marker_map

    check_outputs({"--out": args.out})
    if args.map is not None and args.markerset is not None:
        raise RehabError("give --map (names mapped to upper_limb_seated's) or --markerset (the file's marker set), not both")
    marker_map = read_marker_map(args.map) if args.map is not None else None
    roles = load_markerset(args.markerset).roles if args.markerset is not None else None
    n = _writing(angles_csv_from_trc, "the angles")(args.trc, args.out, marker_map, roles)
    print(f"wrote {n} frames of joint angles to {args.out}")
    withheld = withheld_angles(roles) if roles is not None else {}
    if withheld:
        print(f"left empty: {', '.join(withheld)} (the marker set has no markers for them)")
    return 0


# --------------------------------------------------------------------------- validate
def _add_validate(sub) -> None:
    p = sub.add_parser(
        "validate",
        help="measurement accuracy on the simulated patient, motion by motion",
        description="Render each motion of the simulated patient and compare the measured 3D points "
        "with the truth: completeness, RMSE, ghost points.",
    )
    p.add_argument("--motion", action="append", default=None, help="motion name (repeat; default: all)")
    p.add_argument("--tracker", action="store_true",
                   help="run the tracker (labels, windows, hidden markers) instead of full-frame measurement")
    _add_studio_options(p, fps=15.0)
    p.add_argument("--seed", type=SEED, default=0,
                   help="random seed of the sensor noise (the figures in docs/ are for 0; other seeds show the spread)")
    p.add_argument("--population", type=COUNT, default=None, metavar="N",
                   help="the labelling on N simulated patients (body size, marker placement, reference-pose "
                        "variation, one or four colours), and a fifth of them rendered and tracked in layouts "
                        "of 2-4 cameras; reported seeds only (docs/TRACKING.md)")
    p.add_argument("--rendered", type=number(0, 1_000_000, integer=True), default=None, metavar="M",
                   help="with --population: how many draws are rendered and tracked (default N/5)")
    p.set_defaults(func=_cmd_validate)


def _cmd_validate(args) -> int:
    from dataclasses import replace

    from tracking.sim.studio import SimulationSettings  # lazy: only to run the simulated patient
    from tracking.sim.validate import combine, validate

    if args.population is not None:
        return _validate_population(args)
    base = SimulationSettings(rig=args.rig, n_cameras=args.cameras, size_px=args.size, fps=args.fps,
                              seconds=args.seconds, noise_sigma=args.noise, percentile=args.percentile,
                              sex=args.sex, seed=args.seed)
    if args.tracker:
        from tracking.sim.motions import available_motions  # lazy: only to run the simulated patient
        from tracking.sim.validate import validate_tracking

        for name in args.motion or available_motions():
            acc = validate_tracking(replace(base, motion=name), progress=True)
            print(f"{name:26s} {acc.summary()}", flush=True)
        return 0
    results, whole = [], []
    for name, acc, acc_whole in validate(base, args.motion, progress=True):
        results.append(acc)
        whole.append(acc_whole)
        print(f"{name:26s} {acc.summary()}; whole-ball views: {100 * acc_whole.completeness:.2f} %", flush=True)
    if len(results) > 1:
        print(f"{'all':26s} {combine(results).summary()}; whole-ball views: "
              f"{100 * combine(whole).completeness:.2f} %")
    return 0


def _validate_population(args) -> int:
    from tracking.sim.population import REPORTED_SEEDS_FROM, label_draws, population_report, track_draws

    n = args.population
    rendered = n // 5 if args.rendered is None else args.rendered
    if n < 1 or rendered < 0:
        raise RehabError("--population needs a number of draws >= 1 (and --rendered >= 0)")
    first = REPORTED_SEEDS_FROM + 1000 * args.seed  # (--seed: another set of reported seeds)
    labelled = label_draws(range(first, first + n), rays=None)
    tracked = track_draws(range(first, first + rendered), size_px=args.size, fps=args.fps, progress=True)
    print(population_report(labelled, tracked))
    return 0


# --------------------------------------------------------------------------- play
def _render_scale(text: str) -> float | None:
    """``--render-scale``: ``auto`` (None: dynamic) or a fixed scale."""
    return None if text.strip().lower() == "auto" else number(0.25, 1.0)(text)


def _add_play(sub) -> None:
    p = sub.add_parser(
        "play",
        help="start the application: the live avatar of the (simulated) patient",
        description="Open the application window: the home screen, the live avatar mirroring the patient "
        "with joint angles, the camera check. With no cameras configured the tracker runs on the simulated "
        "patient, whom the mouse and keys move (mouse: the hand; Tab: other arm; Q/E: forearm; arrows: lean; "
        "M: scripted motions). --headless runs offscreen for --seconds and saves --screenshot.",
    )
    p.add_argument("--motion", default=None,
                   help="scripted motion to play (built-in name or motion YAML); default: the mouse moves the "
                   f"patient (headless: {_HEADLESS_MOTION})")
    p.add_argument("--window", type=size_px, default=(1280, 720), help="window size WxH (default: 1280x720)")
    p.add_argument("--max-fps", type=number(0.0, 1000.0), default=60.0,
                   help="frames drawn per second at most; 0 = as many as possible; while a busy machine makes "
                   "frames skip refreshes, half of it (tried again every few seconds; docs/APP.md) "
                   "(default: %(default)s)")
    p.add_argument("--fixed-rate", action="store_true",
                   help="keep --max-fps even when frames miss it, instead of halving it on a busy machine")
    p.add_argument("--render-scale", type=_render_scale, default=1.0, metavar="auto|0.25..1",
                   help="share of the window's pixels (each axis) the 3D views render, upscaled; auto: from 1.0 "
                   "down to 0.5 while frames take longer than 1/--max-fps, then back up (for a GPU: on the software "
                   "rasterizer the upscale costs more than it saves, docs/APP.md); the text stays at full "
                   "resolution (default: 1.0)")
    p.add_argument("--game", default=None,
                   help="open this exercise game (content/games name or YAML) for --patient on --side")
    p.add_argument("--auto", action="store_true",
                   help="with --game: the simulated patient plays by itself (the automatic demo)")
    p.add_argument("--mute", action="store_true", help="no sound")
    p.add_argument("--max-level", type=int, choices=range(1, 11), default=None, metavar="1..10",
                   help="the therapist's highest level of the games (default: each game's own limit)")
    p.add_argument("--scene", choices=("home", "live", "cameras", "rom", "progress", "game", "calibrate"), default=None,
                   help="first screen (default: home; live with --headless); rom: the ROM test of --patient and "
                   "--test playing its demo motion; progress: the progress review of --patient; calibrate: the "
                   "camera calibration on the simulated board")
    from game.cli_clinic import DB_HELP, USER_HELP

    p.add_argument("--db", default=None, metavar="PATH_OR_URL", help=DB_HELP)
    p.add_argument("--user", default=None, metavar="NAME", help=USER_HELP)
    p.add_argument("--patient", default=None, help="pseudonymous patient ID for --scene rom or progress, or --game")
    p.add_argument("--test", default=None, help="ROM test for --scene rom (default: shoulder_flexion)")
    p.add_argument("--side", choices=("right", "left"), default="right", help="side for --scene rom or --game")
    p.add_argument("--standard", choices=("jarm", "aaos"), default="jarm",
                   help="reference standard of the ROM tests and the progress band (default: %(default)s)")
    p.add_argument("--calibrate-cameras", default=None, metavar="DEV,DEV,...",
                   help="the calibration scene shows these cameras (OpenCV indices, URLs or video files) instead of the "
                   "simulated studio")
    p.add_argument("--calibration-board", default=None, metavar="SPEC",
                   help="board of the calibration scene: COLSxROWS:SQUARE_MM (inner corners), or "
                   "charuco:COLSxROWS:SQUARE_MM[:MARKER_MM] (squares); default 9x6:60")
    p.add_argument("--calibration-lenses", type=Path, default=None, metavar="FILE",
                   help="the calibration scene reuses the lens data of this file (from 'rehab calibrate intrinsics' or "
                   "an earlier calibration, cameras by name) and opens at step 2, where the cameras stand")
    p.add_argument("--headless", action="store_true", help="run offscreen without a window (tests, screenshots)")
    p.add_argument("--seconds", type=SECONDS, default=None,
                   help="stop after this many seconds (default: until quit; 5 with --headless)")
    p.add_argument("--screenshot", type=Path, default=None, help="save the last frame as a PNG")
    add_tracker_source_options(p)
    from game.cli_stream import add_stream_options

    add_stream_options(p)
    p.set_defaults(func=_cmd_play)


_HEADLESS_MOTION = "shoulder_abduction"


def _cmd_play(args) -> int:
    import os

    # pygame greets on import; keep the command's output to its one summary line.
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    from game.app import Settings
    from game.play import PlayOptions, run_play
    from tracking.live import SourceConfig

    motion = args.motion if args.motion is not None or not args.headless else _HEADLESS_MOTION
    if args.game is not None or args.scene == "game":
        from game.exergames.spec import load_game

        load_game(args.game or "reach")   # an unknown game is one line, before anything starts
        motion = None   # games drive the interactive patient (the mouse or the auto player)
    elif args.auto:
        raise RehabError("--auto plays a game: give --game NAME")
    if args.scene == "rom" and args.motion is None:
        from game.play import DEFAULT_ROM_TEST
        from game.rom.spec import load_rom_test

        # the ROM scene plays the test's own motion (its demo); start the tracker on it
        motion = load_rom_test(args.test or DEFAULT_ROM_TEST).simulated_motion.get(args.side)
    check_motion(motion)
    if args.devices is not None or args.recording is not None:
        if args.motion is not None:
            raise RehabError("--motion plays on the simulated patient: leave it out with --devices or --recording")
        motion = None  # the cameras or the recording show the patient
    seconds = args.seconds if args.seconds is not None or not args.headless else 5.0
    source = SourceConfig(rig=args.rig, size=args.size, fps=args.fps, motion=motion, body=args.body,
                          adapt_colours=args.adapt_colours, **play_source(args))
    from game.cli_calibrate import board_from_spec
    from game.cli_stream import stream_config

    options = PlayOptions(
        # the frame rate is the engineer's (F shows it): in the corner it covered the scenes' own text
        settings=Settings(window_px=args.window, max_fps=args.max_fps, show_fps=False,
                          render_scale=args.render_scale, adaptive_pace=not args.fixed_rate),
        source=source,
        headless=args.headless,
        seconds=seconds,
        screenshot=args.screenshot,
        scene=args.scene or ("game" if args.game else "live" if args.headless else "home"),
        motion=motion,
        db_path=args.db,
        patient=args.patient,
        test=args.test,
        side=args.side,
        standard=args.standard,
        game=args.game,
        auto=args.auto,
        mute=args.mute,
        max_level=args.max_level,
        calibrate_devices=tuple(d.strip() for d in (args.calibrate_cameras or "").split(",") if d.strip()),
        calibration_board=board_from_spec(args.calibration_board) if args.calibration_board else None,
        calibration_lenses=args.calibration_lenses,
        stream=stream_config(args),
        user=args.user,
    )
    from dataclasses import replace

    from game.play import check_account, needs_sign_in

    if needs_sign_in(options):   # accounts, and no account or PIN given: the application's sign-in screen
        options = replace(options, sign_in=True, user=options.user or os.environ.get("REHAB_USER", "").strip() or None)
    else:
        account = check_account(options)   # where the database has accounts: may this account open this screen
        options = replace(options, user=account.name if account else None)
    if options.scene in ("rom", "progress", "game") and not (options.sign_in and not options.patient):
        from game.play import check_scene_options

        check_scene_options(options)   # one line before anything starts
    summary = run_play(options)
    print(f"rehab play: {summary.line()}")
    if options.headless and summary.problem:
        # nobody watched the window: a source that ended early or failed must not pass as a good run
        raise RehabError(summary.problem)
    return 0


# --------------------------------------------------------------------------- bench
def _add_bench(sub) -> None:
    p = sub.add_parser("bench", help="measure speed: colour table, centroids, triangulation, simulator")
    p.add_argument("--frames", type=COUNT, default=60, help="frame sets per measurement (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="fewer frames and one pass, for a smoke run")
    p.add_argument("--passes", type=number(1, 1000, integer=True), default=5,
                   help="alternating passes of full-frame measurement and tracking (default: %(default)s)")
    p.add_argument("--seconds", type=number(0.0, 3600.0, above=True), default=10.0,
                   help="measuring time of the live-process and application figures (default: %(default)s)")
    p.add_argument("--skip-live", action="store_true",
                   help="only the per-frame pipeline (no tracker process, no application)")
    p.add_argument("--streaming", action="store_true",
                   help="also compare the tracker process with LSL + OSC streaming off and on (alternating passes)")
    p.set_defaults(func=_cmd_bench)


def _cmd_bench(args) -> int:
    from tracking.drivers.bench import run_benchmarks

    n = 10 if args.quick else args.frames
    for line in run_benchmarks(n_frames=n, passes=1 if args.quick else max(1, args.passes)):
        print(line, flush=True)
    if args.skip_live:
        return 0
    seconds = 2.0 if args.quick else args.seconds
    app_measured = _bench_live(seconds)
    if args.streaming:
        from tracking.live.latency_bench import compare_streaming

        print(f"\nTracker process (320x240, 30 frame sets/s) with streaming off and on, alternating passes of "
              f"{seconds:g} s, {1 if args.quick else 3} of each (LSL inlets and an OSC socket receive in this process):",
              flush=True)
        for line in compare_streaming(seconds, passes=1 if args.quick else 3):
            print("  " + line, flush=True)
    return 0 if app_measured else 1


def _bench_live(seconds: float) -> bool:
    """The tracker process (latency, pace) and the application (frame rate) with it running;
    False when the application could not be measured."""
    from tracking.live.latency_bench import format_result, measure_latency

    print("\nTracker process (simulated patient, 30 frame sets/s): frame ready -> sample seen by the game "
          "process, minus the tracker's own step time", flush=True)
    for size in ((320, 240), (640, 480)):
        print("  " + format_result(measure_latency(seconds, size)).replace("\n", "\n  "), flush=True)
    import os
    import sys

    from game.gfx.screen import has_display

    # In a window where there is a display (e.g. under xvfb-run), as the application runs;
    # otherwise offscreen (EGL), as the tests run.
    window = has_display(os.environ, sys.platform)
    where = "in a window" if window else "headless EGL"
    print(f"\nApplication (live avatar scene, 1280x720, {where}, uncapped) while the tracker process "
          "measures the simulated patient at 320x240, 30 frame sets/s:", flush=True)
    try:
        summary = bench_app(seconds, window)
    except RehabError as exc:
        print(f"  not measured: {exc}", flush=True)
        return False
    print(f"  {summary.line()}", flush=True)
    print(f"  target 60 frames/s: {'met' if summary.fps >= 60.0 else 'NOT met'} on this machine", flush=True)
    return True


def bench_app(seconds: float, window: bool):
    """The application's frame rate (a :class:`game.app.RunSummary`), measured in a process of its own.

    A fresh process, as the application runs: the figures before it render the simulated cameras
    on EGL contexts in this process, and once a thread has made an EGL context current, GLX
    refuses it the window's context (X error BadAccess on X_GLXMakeCurrent, which ends the process).

    Raises:
        RehabError: the application could not run (its one-line reason).
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        try:
            return pool.submit(_app_figure, seconds, window).result()
        except BrokenProcessPool:
            raise RehabError("the application's process ended abruptly (see the messages above)") from None
        except Exception as exc:  # NoDisplayError, GraphicsUnavailable, RehabError from the child
            raise RehabError(str(exc).splitlines()[0] if str(exc) else type(exc).__name__) from None


def _app_figure(seconds: float, window: bool):
    """:func:`bench_app`'s child: the live avatar scene uncapped for ``seconds``."""
    from game.app import Settings
    from game.play import PlayOptions, run_play

    return run_play(PlayOptions(settings=Settings(window_px=(1280, 720), max_fps=0.0, show_fps=False),
                                headless=not window, seconds=seconds, scene="live", motion="shoulder_abduction",
                                wait_for_tracker=True))


# --------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="rehab",
        description="Colour-marker motion capture for rehabilitation: tracking, ROM tests and games.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log more detail")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_simulate(sub)
    _add_track(sub)
    _add_angles(sub)
    _add_validate(sub)
    _add_bench(sub)
    _add_play(sub)
    from game import cli_calibrate  # calibrate, simulate-calibration
    from game import cli_clinic  # rom-test, rom-accuracy, patients, export, import, backup, report
    from game import cli_colour  # colour learn|drift-check
    from game import cli_record  # record
    from game import cli_stream  # stream

    cli_calibrate.add_commands(sub)
    cli_clinic.add_commands(sub)
    cli_colour.add_commands(sub)
    cli_record.add_commands(sub)
    cli_stream.add_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    from game.cli_calibrate import join_negative_values  # --origin -0.2,0.45,0

    parser = build_parser()
    args = parser.parse_args(join_negative_values(sys.argv[1:] if argv is None else argv))
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="rehab: %(levelname)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        code = int(args.func(args) or 0)
        sys.stdout.flush()   # a closed pipe shows here, inside the handler, not at exit
        return code
    except RehabError as exc:
        print(f"rehab: error: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:   # rehab ... | head
        return handle_broken_pipe()
    except KeyboardInterrupt:
        print("rehab: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
