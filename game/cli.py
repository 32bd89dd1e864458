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

log = logging.getLogger("rehab")


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = text.lower().split("x")
        size = (int(w), int(h))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r} must look like 640x480") from None
    if min(size) < 16 or max(size) > 8192:
        raise argparse.ArgumentTypeError(f"size {text!r} is out of range (16..8192 pixels)")
    return size


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be positive")
    return value


def _add_studio_options(p, *, size=(640, 480), fps=30.0) -> None:
    """Options shared by the commands that run the simulated studio."""
    p.add_argument("--rig", default="ring4", help="camera layout: built-in name or YAML file (default: %(default)s)")
    p.add_argument("--cameras", type=int, default=None, help="use the first N cameras of the rig")
    p.add_argument("--size", type=_size, default=size, help=f"image size WxH (default: {size[0]}x{size[1]})")
    p.add_argument("--fps", type=_positive_float, default=fps, help="frame rate (default: %(default)s)")
    p.add_argument("--seconds", type=_positive_float, default=None, help="cut the motion(s) to this length")
    p.add_argument("--percentile", type=float, default=50.0, help="body size percentile 5..95 (default: %(default)s)")
    p.add_argument("--sex", choices=("female", "male"), default="female")
    p.add_argument("--noise", type=float, default=1.5, help="sensor noise sigma in 8-bit units (default: %(default)s)")


# --------------------------------------------------------------------------- simulate
def _add_simulate(sub) -> None:
    p = sub.add_parser(
        "simulate",
        help="render a synthetic recording of the simulated patient, with ground truth",
        description="Render a recording folder (spec/INTERFACES.md) of the simulated patient seen by "
        "virtual cameras, with truth.trc and truth_angles.csv.",
    )
    p.add_argument("out_dir", type=Path, help="output recording folder (created)")
    p.add_argument("--motion", default="right_external_rotation",
                   help="built-in motion name, or a motion YAML file (default: %(default)s)")
    _add_studio_options(p)
    p.add_argument("--drift", type=float, default=0.0,
                   help="brightness drop over the recording as a fraction, e.g. 0.4 (default: none)")
    p.add_argument("--cast", default=None, help="colour cast as R,G,B gains reached at the end, e.g. 1.1,1.0,0.85")
    p.add_argument("--images", action="store_true", help="write PNG folders instead of lossless AVI videos")
    p.add_argument("--markerset", default="upper_limb_seated", help="marker set name or YAML file")
    p.add_argument("--seed", type=int, default=0, help="random seed of the sensor noise")
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
    settings = SimulationSettings(
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
    p.add_argument("recording", type=Path, help="recording folder (spec/INTERFACES.md)")
    p.add_argument("--calibration", type=Path, default=None, help="calibration file (default: RECORDING/calibration.toml)")
    p.add_argument("--markerset", default=None, help="marker set name or YAML file (default: from meta.yaml)")
    p.add_argument("--marker-color", action="append", default=None, metavar="R,G,B",
                   help="override marker colours: once for all markers, or once per marker in marker-set order")
    p.add_argument("--points", type=Path, default=None,
                   help="write unlabelled 3D points: frame,time,x_mm,y_mm,z_mm,n_cameras,reproj_px")
    p.add_argument("--out", type=Path, default=None, help="labelled markers as an OpenSim TRC file (mm)")
    p.add_argument("--status", type=Path, default=None,
                   help="per-marker status CSV: frame,time,marker,x_mm,y_mm,z_mm,status")
    p.add_argument("--angles", type=Path, default=None, help="joint angles CSV (spec/JOINT_ANGLES.md)")
    p.add_argument("--c3d", type=Path, default=None, help="labelled markers as a C3D file")
    p.add_argument("--colours", type=Path, default=None, help="learned colour file from `rehab colour learn`")
    p.add_argument("--adapt-colours", action="store_true", help="adapt the colour table as the lighting drifts")
    p.set_defaults(func=_cmd_track)


def _cmd_track(args) -> int:
    from tracking.offline import track_recording

    labelled = args.out or args.status or args.angles or args.c3d
    if args.points and labelled:
        raise RehabError("--points (unlabelled full-frame points) cannot be combined with the labelled outputs: run them separately")
    if not (args.points or labelled):
        raise RehabError("nothing to write: give --out markers.trc (and/or --status, --angles, --c3d, --points)")
    report = track_recording(
        args.recording,
        calibration=args.calibration,
        markerset=args.markerset,
        marker_colours=args.marker_color,
        points_csv=args.points,
        trc=args.out,
        status_csv=args.status,
        angles_csv=args.angles,
        c3d=args.c3d,
        colours=args.colours,
        adapt_colours=args.adapt_colours,
        progress=True,
    )
    print(report)
    return 0


# --------------------------------------------------------------------------- angles
def _add_angles(sub) -> None:
    p = sub.add_parser("angles", help="joint angles from a TRC marker file (spec/JOINT_ANGLES.md)")
    p.add_argument("trc", type=Path, help="marker file with the marker set's names (mm)")
    p.add_argument("--out", type=Path, required=True, help="angles CSV to write")
    p.set_defaults(func=_cmd_angles)


def _cmd_angles(args) -> int:
    from tracking.tables import angles_csv_from_trc

    n = angles_csv_from_trc(args.trc, args.out)
    print(f"wrote {n} frames of joint angles to {args.out}")
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
    p.set_defaults(func=_cmd_validate)


def _cmd_validate(args) -> int:
    from dataclasses import replace

    from tracking.sim.studio import SimulationSettings
    from tracking.sim.validate import combine, validate

    base = SimulationSettings(rig=args.rig, n_cameras=args.cameras, size_px=args.size, fps=args.fps,
                              seconds=args.seconds, noise_sigma=args.noise, percentile=args.percentile,
                              sex=args.sex)
    if args.tracker:
        from tracking.sim.motions import available_motions
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


# --------------------------------------------------------------------------- play
def _add_play(sub) -> None:
    p = sub.add_parser(
        "play",
        help="watch the simulated patient being measured live (interim viewer)",
        description="Render the simulated patient from the virtual cameras, measure the markers live and "
        "show the camera images with the detected markers, a front and side view of the measured points "
        "and the speed. Keys: Space pause, Right arrow next motion, R restart, Esc/Q quit.",
    )
    p.add_argument("--motion", default="right_external_rotation",
                   help="built-in motion name, or a motion YAML file (default: %(default)s)")
    p.add_argument("--rig", default="ring4", help="camera layout: built-in name or YAML file (default: %(default)s)")
    p.add_argument("--size", type=_size, default=(320, 240), help="camera image size WxH (default: 320x240)")
    p.add_argument("--fps", type=_positive_float, default=15.0, help="camera frame rate (default: %(default)s)")
    p.add_argument("--headless", action="store_true",
                   help="render offscreen without a window, one frame set per 1/fps of motion")
    p.add_argument("--seconds", type=_positive_float, default=None,
                   help="stop after this much motion time (default: until quit; 5 with --headless)")
    p.add_argument("--screenshot", type=Path, default=None, help="save the last frame shown as a PNG")
    p.set_defaults(func=_cmd_play)


def _cmd_play(args) -> int:
    import os

    # pygame greets on import; keep the command's output to its one summary line.
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    from game.viewer import PlayOptions, run_viewer

    seconds = args.seconds if args.seconds is not None or not args.headless else 5.0
    options = PlayOptions(motion=args.motion, rig=args.rig, size_px=args.size, fps=args.fps,
                          headless=args.headless, seconds=seconds, screenshot=args.screenshot)
    summary = run_viewer(options)
    print(f"rehab play: {summary.line()}")
    return 0


# --------------------------------------------------------------------------- bench
def _add_bench(sub) -> None:
    p = sub.add_parser("bench", help="measure speed: colour table, centroids, triangulation, simulator")
    p.add_argument("--frames", type=int, default=60, help="frame sets per measurement (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="fewer frames, for a smoke run")
    p.set_defaults(func=_cmd_bench)


def _cmd_bench(args) -> int:
    from tracking.bench import run_benchmarks

    n = 10 if args.quick else args.frames
    for line in run_benchmarks(n_frames=n):
        print(line, flush=True)
    return 0


# --------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
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
    from game import cli_colour  # rehab colour learn|drift-check

    cli_colour.add_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="rehab: %(levelname)s: %(message)s",
        stream=sys.stderr,
    )
    try:
        return int(args.func(args) or 0)
    except RehabError as exc:
        print(f"rehab: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("rehab: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
