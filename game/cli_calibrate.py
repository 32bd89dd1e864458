"""``rehab calibrate intrinsics|extrinsics|wand|colour`` and ``rehab simulate-calibration``.

Folders, as a clinic records them and as the simulator writes them (docs/CALIBRATION.md):

- intrinsics: one folder of board images per camera, named after the camera (``cam1/``, ...);
- extrinsics: one folder per camera with the board images taken at the same instants under the
  same file names (``cam1/000.png`` and ``cam2/000.png`` are one view), plus the board lying on
  the floor or seat in every camera that sees it (``cam*/seat.png``);
- wand: a recording folder (one video or image folder per camera and meta.yaml).

Every command writes the calibration as TOML (docs/INTERFACES.md) and, on request, OpenCV YAML.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import Sequence

import numpy as np

from calibration.errors import RehabError
from game.cli_options import COUNT, LENGTH_MM, NOISE, SECONDS, SEED, number

log = logging.getLogger("rehab")

SIM_CHARUCO_SPEC = ("10x7", 40.0, 30.0, "DICT_4X4_50")  # the simulator's ChArUco board: squares, square mm, marker mm
SIM_CHARUCO_EXTRINSICS_SPEC = ("7x5", 100.0, 75.0, "DICT_4X4_50")  # large enough to be read from 2 m at 640x480



def add_commands(sub) -> None:
    """Register the calibration commands on the ``rehab`` sub-parsers."""
    p = sub.add_parser("calibrate", help="calibrate cameras from board images or a wand recording",
                       description="Camera calibration: intrinsics from board images, extrinsics from shared board "
                       "views or a wand. See docs/CALIBRATION.md.")
    cal = p.add_subparsers(dest="calibrate_command", required=True, metavar="STEP")

    q = cal.add_parser("intrinsics", help="lens and focal length of each camera from checkerboard or ChArUco images",
                       description="Calibrate each camera's intrinsics from a folder of board images per "
                       "camera (the folder name is the camera name), or from one folder holding such folders. "
                       "--board charuco uses a ChArUco board (--squares, --marker-mm, --dictionary), which also "
                       "counts views where the board is partly out of the picture.")
    q.add_argument("folders", nargs="*", type=Path, help="one folder of images per camera, or their parent folder")
    _board_options(q)
    q.add_argument("--fit-k3", action="store_true", help="also fit the 3rd radial coefficient (wide-angle lenses)")
    live = q.add_argument_group("live capture (instead of folders)")
    live.add_argument("--live", action="append", default=None, metavar="DEVICE",
                      help="capture board views from a camera (index like 0, URL or video file), once per camera in "
                      "rig order (cam1, cam2, ...); a view is kept when the board is held still in a new place")
    live.add_argument("--views", type=number(1, 1000, integer=True), default=12, help="live: views to keep at least (default: %(default)s)")
    live.add_argument("--coverage", type=number(0.0, 100.0, above=True), default=85.0,
                      help="live: stop when the views cover this %% of the picture (default: %(default)s)")
    live.add_argument("--max-views", type=number(1, 10000, integer=True), default=30, help="live: stop after this many views (default: %(default)s)")
    live.add_argument("--max-seconds", type=SECONDS, default=180.0,
                      help="live: give up on a camera after this long (default: %(default)s)")
    live.add_argument("--save-views", type=Path, default=None,
                      help="live: also save the kept images as DIR/cam1/000.png ... (a folder to calibrate again from)")
    _output_options(q)
    q.set_defaults(func=_cmd_intrinsics)

    q = cal.add_parser("extrinsics", help="camera positions from a board seen by cameras together",
                       description="Calibrate the cameras' positions and orientations from board images taken at "
                       "the same instants (same file name in every camera's folder), then set the world frame "
                       "from the board lying face up on the floor or seat.")
    q.add_argument("views", type=Path, help="folder with one sub-folder of images per camera")
    q.add_argument("--intrinsics", type=Path, required=True, help="calibration file with every camera's intrinsics")
    _board_options(q)
    _floor_options(q)
    q.add_argument("--floor-views", type=Path, default=None,
                   help="folder with one sub-folder per camera holding the floor board's image (named as --floor); "
                   "default: the views folder")
    q.add_argument("--list-skipped", action="store_true", help="name every image without a usable board")
    q.add_argument("--refine-lenses", action=argparse.BooleanOptionalAction, default=None,
                   help="refine the lens data together with the positions, weighted by how exact the lens step found "
                   "them (kept in the intrinsics file by 'rehab calibrate intrinsics'). Default: for the cameras whose "
                   "lens step used 10 or more images; --refine-lenses: every camera the file has that weight for; "
                   "--no-refine-lenses: none (docs/CALIBRATION.md)")
    q.add_argument("--floor-board", default=None, metavar="SPEC",
                   help="another board on the floor or seat than the shared views': 9x6:60 (checkerboard inner "
                   "corners : square mm) or charuco:10x7:40[:30]; --origin and --board-centre then refer to it")
    _output_options(q)
    q.set_defaults(func=_cmd_extrinsics)

    q = cal.add_parser("wand", help="camera positions from a wand (two balls at a known distance) waved through the volume",
                       description="Calibrate the cameras' positions from a recording of a two-ball wand; the world "
                       "frame comes from board images of the board lying on the floor or seat (--floor-views).")
    q.add_argument("recording", type=Path, help="wand recording folder (one video or image folder per camera; meta.yaml "
                   "optional: without it the frame rate comes from the videos)")
    q.add_argument("--intrinsics", type=Path, required=True, help="calibration file with every camera's intrinsics")
    q.add_argument("--length-mm", type=LENGTH_MM, default=None, help="distance between the ball centres (default: meta.yaml wand_length_mm)")
    q.add_argument("--colour", action="append", default=None, metavar="R,G,B",
                   help="ball colours, twice: ball 0 then ball 1; once when both balls have one colour "
                   "(default: meta.yaml wand_colours)")
    q.add_argument("--ball-mm", type=LENGTH_MM, default=40.0, help="ball diameter (default: %(default)s)")
    q.add_argument("--floor-views", type=Path, default=None, help="folder with one sub-folder of board images per camera")
    _board_options(q, required=False)
    _floor_options(q)
    _output_options(q)
    q.set_defaults(func=_cmd_wand)

    q = cal.add_parser("colour", help="learn the marker colours under this room's lighting into the calibration file",
                       description="Identify the markers in the reference pose at the start of a recording, learn each "
                       "marker colour from its balls (and what is not a marker from the rest of the images), and "
                       "save the learnt colours in the calibration file ([metadata.marker_colours]); rehab track and "
                       "the live tracker then use them. Same learning as `rehab colour learn`.")
    q.add_argument("recording", type=Path, help="recording folder that starts in the reference pose")
    q.add_argument("--calibration", type=Path, default=None,
                   help="calibration file to use and to add the colours to (default: RECORDING/calibration.toml)")
    q.add_argument("--out", type=Path, default=None,
                   help="write the calibration with the colours here instead of into --calibration")
    q.add_argument("--markerset", default=None, help="marker set name or YAML file (default: from meta.yaml)")
    q.add_argument("--frames", type=COUNT, default=30, help="frame sets to learn from after identification (default 30)")
    q.set_defaults(func=_cmd_colour)

    q = cal.add_parser("import", help="convert calibration files of other tools (OpenCV, stereo_calib, Caliscope, Qualisys, "
                       "anipose) into this project's TOML",
                       description="Read one rig file, or several files of one camera each (OpenCV's calibration "
                       "sample, stereo_calib's intrinsics.yml), and write them as one TOML calibration. Cameras "
                       "without a position (lens data only) are written at the origin, to be placed with "
                       "'rehab calibrate extrinsics --intrinsics OUT' or 'wand'.")
    q.add_argument("files", nargs="+", type=Path, help="calibration files (.toml, .yaml/.yml/.xml, .qca/.qca.txt)")
    q.add_argument("--out", type=Path, required=True, help="TOML calibration to write")
    q.add_argument("--translation-unit", choices=("m", "mm"), default="m",
                   help="unit of the files' translations (default: %(default)s); mm divides them by 1000")
    q.add_argument("--size", default=None, help="image size WxH for files that do not store it (stereo_calib)")
    q.add_argument("--names", default=None, help="camera names, comma-separated, in order (default: from the files)")
    q.set_defaults(func=_cmd_import)

    p = sub.add_parser("simulate-calibration", help="render calibration material of a virtual rig, with ground truth",
                       description="Render board images (intrinsics, extrinsics, seat board) and a wand recording "
                       "of a virtual camera rig, with the true calibration, so that the calibration commands can be "
                       "tried and checked.")
    p.add_argument("out_dir", type=Path, help="output folder (created)")
    p.add_argument("--rig", default="ring4", help="camera layout: built-in name or YAML file (default: %(default)s)")
    p.add_argument("--size", default="640x480", help="image size WxH (default: %(default)s)")
    p.add_argument("--lens", action="store_true", help="give the cameras a moderate barrel distortion")
    p.add_argument("--images", type=number(1, 1000, integer=True), default=15, help="intrinsics images per camera (default: %(default)s)")
    p.add_argument("--per-pair", type=number(1, 1000, integer=True), default=4, help="extrinsics views per neighbouring camera pair (default: %(default)s)")
    p.add_argument("--wand-seconds", type=number(0.0, 3600.0, above=True), default=20.0, help="length of the wand recording (default: %(default)s)")
    p.add_argument("--noise", type=NOISE, default=1.5, help="sensor noise sigma, 8-bit units (default: %(default)s)")
    p.add_argument("--seed", type=SEED, default=0)
    p.add_argument("--charuco", action="store_true",
                   help="also render ChArUco intrinsics images (10x7 squares of 40 mm), some with the board partly out of view")
    p.add_argument("--check", action="store_true",
                   help="then calibrate from the material, compare with the truth and with tracking on the true calibration")
    p.set_defaults(func=_cmd_simulate_calibration)


# --------------------------------------------------------------------------- options
def _board_options(p, *, required: bool = True) -> None:
    p.add_argument("--board", default="9x6" if not required else None, required=required,
                   help="checkerboard inner corners COLSxROWS, one count even and one odd, e.g. 9x6; "
                   "or 'charuco' for a ChArUco board")
    p.add_argument("--square-mm", type=LENGTH_MM, default=None if required else 60.0, required=required,
                   help="printed square side in mm")
    p.add_argument("--squares", default="10x7", help="ChArUco board: squares COLSxROWS (default: %(default)s)")
    p.add_argument("--marker-mm", type=LENGTH_MM, default=None,
                   help="ChArUco board: printed marker side in mm (default: 0.75 of the square)")
    p.add_argument("--dictionary", default="DICT_4X4_50", help="ChArUco board: OpenCV ArUco dictionary (default: %(default)s)")


def board_from_args(args):
    """The calibration board of the command line: a Checkerboard, or a CharucoBoard for ``--board charuco``."""
    from calibration.board import Checkerboard

    if args.board.lower() == "charuco":
        from calibration.charuco import CharucoBoard

        return CharucoBoard.parse(args.squares, args.square_mm, args.marker_mm, args.dictionary)
    return Checkerboard.parse(args.board, args.square_mm)


def board_from_spec(spec: str):
    """A board from one word: ``9x6:60`` (checkerboard inner corners : square mm) or
    ``charuco:10x7:40[:30]`` (ChArUco squares : square mm [: marker mm], DICT_4X4_50)."""
    from calibration.board import Checkerboard

    parts = spec.lower().split(":")
    try:
        if parts[0] == "charuco" and len(parts) in (3, 4):
            from calibration.charuco import CharucoBoard

            return CharucoBoard.parse(parts[1], float(parts[2]), float(parts[3]) if len(parts) == 4 else None)
        if len(parts) == 2:
            return Checkerboard.parse(parts[0], float(parts[1]))
    except ValueError:
        pass
    raise RehabError(f"board {spec!r}: write COLSxROWS:SQUARE_MM (checkerboard inner corners, e.g. 9x6:60) or "
                     "charuco:COLSxROWS:SQUARE_MM[:MARKER_MM] (ChArUco squares, e.g. charuco:10x7:40)")


def board_name(board) -> str:
    """``9x6 checkerboard`` or ``10x7 ChArUco board`` for messages."""
    if hasattr(board, "squares_x"):
        return f"{board.squares_x}x{board.squares_y}-square ChArUco board"
    return f"{board.cols}x{board.rows} board"


TRIPLE_OPTIONS = ("--origin", "--board-centre")
FLOOR_BOARD_HELP = ("Lay the board face up on the seat (or the floor), its rows of corners running left-right across the "
                    "patient, the black outer corner square at the patient's front left (the corner nearest the front "
                    "cameras on the patient's left); the first inner corner is the one next to that square.")


def _floor_options(p) -> None:
    p.add_argument("--floor", default="seat", type=lambda v: None if v.lower() == "none" else v,
                   help="file name (without extension) of the floor/seat board view; 'none': keep the first "
                   "camera's frame, Y not up (default: %(default)s)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--origin", default=None, metavar="X,Y,Z",
                       help="world position in metres of the floor board's first inner corner (default 0,0,0). "
                       + FLOOR_BOARD_HELP + " Negative numbers are fine: --origin -0.2,0.45,0")
    where.add_argument("--board-centre", default=None, metavar="X,Y,Z",
                       help="world position in metres of the centre of the board's corners instead, e.g. 0,0.45,0: "
                       "the board centred over the origin on a 45 cm seat")
    p.add_argument("--turn-deg", type=number(-360.0, 360.0), default=0.0,
                   help="the board's rows point this many degrees from the patient's right, counter-clockwise from above")
    p.add_argument("--no-world-check", action="store_true",
                   help="accept a world frame with a camera below the floor, facing away from the floor board or on its "
                   "side (refused by default: the usual sign of a wrong floor view)")


def origin_from_args(args, board) -> tuple[float, float, float]:
    """The floor board's corner 0 in the world from --origin or --board-centre."""
    if getattr(args, "board_centre", None):
        from calibration.extrinsics import floor_board_centre_m

        target = np.array(_triple(args.board_centre, "--board-centre"))
        offset = floor_board_centre_m(board, (0.0, 0.0, 0.0), args.turn_deg)
        return tuple(float(v) for v in target - offset)  # type: ignore[return-value]
    return _triple(args.origin or "0,0,0", "--origin")


def join_negative_values(argv: Sequence[str]) -> list[str]:
    """``--origin -0.2,0.45,0`` -> ``--origin=-0.2,0.45,0`` (argparse takes a leading '-' for an option)."""
    out: list[str] = []
    it = iter(argv)
    for a in it:
        if a in TRIPLE_OPTIONS:
            nxt = next(it, None)
            if nxt is None:
                out.append(a)
            elif nxt.startswith("-") and nxt[1:2].isdigit() or nxt.startswith("-."):
                out.append(f"{a}={nxt}")
            else:
                out += [a, nxt]
        else:
            out.append(a)
    return out


def _output_options(p) -> None:
    p.add_argument("--out", type=Path, required=True, help="calibration file to write (.toml)")
    p.add_argument("--opencv", type=Path, default=None, help="also write OpenCV FileStorage (.yaml/.yml/.xml)")


def _triple(text: str, what: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(np.isfinite(vals)):
        raise RehabError(f"{what} {text!r}: give three numbers like 0,0.45,0")
    return vals  # type: ignore[return-value]


def _images_in(folder: Path) -> list[Path]:
    from tracking.io.recording import IMAGE_SUFFIXES

    return sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def _camera_folders(folders: Sequence[Path]) -> list[Path]:
    """The per-camera folders: the given ones, or the sub-folders of a single parent."""
    for f in folders:
        if not f.is_dir():
            raise RehabError(f"{f}: no such folder")
    if len(folders) == 1 and not _images_in(folders[0]):
        subs = sorted(p for p in folders[0].iterdir() if p.is_dir() and _images_in(p))
        if not subs:
            raise RehabError(f"{folders[0]}: holds no images and no folders of images (png, jpg, bmp, tif)")
        return subs
    return list(folders)


def _save(args, cameras, error_px: float) -> None:
    from calibration.files import save_calibration_opencv, save_calibration_toml

    if args.out.suffix.lower() != ".toml":
        raise RehabError(f"--out {args.out}: the calibration file must end in .toml (use --opencv for OpenCV YAML)")
    save_calibration_toml(args.out, cameras, adjusted=False, error=float(error_px))
    if args.opencv:
        save_calibration_opencv(args.opencv, cameras)


SKIPPED_LISTED = 5  # more skipped images than this are summed up in one line


def _report_skipped(skipped: dict[str, str], *, head: str = "", every: bool = False) -> None:
    """Each skipped image with its reason, or past SKIPPED_LISTED one summary line by reason."""
    if every or len(skipped) <= SKIPPED_LISTED:
        if head:
            print(f"{head}:")
        for name, reason in skipped.items():
            print(f"  skipped {name}: {reason}")
        return
    from collections import Counter

    common = Counter(skipped.values()).most_common()
    first, n = common[0]
    rest = f"; {len(skipped) - n} for other reasons" if len(common) > 1 else ""
    print(f"{head or f'  skipped {len(skipped)} images'}: {n} \"{first}\"{rest} (--list-skipped names them)")


# --------------------------------------------------------------------------- intrinsics
def run_intrinsics(folders: Sequence[Path], board, *, fit_k3: bool = False, verbose: bool = True):
    """Calibrate every camera folder; returns the IntrinsicsResults (printing a line per camera)."""
    from calibration.board import detect_in_files
    from calibration.intrinsics import calibrate_intrinsics

    results = []
    for folder in _camera_folders(folders):
        files = _images_in(folder)
        if not files:
            raise RehabError(f"{folder}: no images (png, jpg, bmp, tif) in this folder")
        detections, skipped = detect_in_files(files, board)
        if not detections:
            raise RehabError(f"{folder}: the {board_name(board)} was found in none of its {len(files)} images: "
                             "check --board (inner corners, not squares) and that the board is in view")
        res = calibrate_intrinsics(folder.name, list(detections.values()), board, fix_k3=not fit_k3,
                                   view_names=[Path(k).name for k in detections])
        results.append(res)
        if verbose:
            K = res.camera.K
            print(f"{folder.name}: {len(detections)} of {len(files)} images used, reprojection {res.rms_px:.3f} px, "
                  f"f = {K[0, 0]:.1f}/{K[1, 1]:.1f} px, centre ({K[0, 2]:.1f}, {K[1, 2]:.1f}), "
                  f"coverage {100 * res.coverage:.0f} %")
            _report_skipped({Path(k).name: v for k, v in skipped.items()})
            for w in res.warnings:
                print(f"  warning: {w}")
    return results


def _cmd_intrinsics(args) -> int:
    board = board_from_args(args)
    if args.live and args.folders:
        raise RehabError("give image folders or --live cameras, not both")
    if args.live:
        from tracking.sources.cameras import open_capture

        captures = []
        try:
            for k, device in enumerate(args.live):
                cap = open_capture(device, None, None)
                captures.append((f"cam{k + 1}", cap))
                if not cap.isOpened():
                    raise RehabError(f"--live {device}: cannot open this camera or video (check the index, URL or path)")
            results = run_live_intrinsics(captures, board, fit_k3=args.fit_k3, min_views=args.views,
                                          target_coverage=args.coverage / 100.0, max_views=args.max_views,
                                          max_seconds=args.max_seconds, save_views=args.save_views)
        finally:
            for _, cap in captures:
                cap.release()
    elif args.folders:
        results = run_intrinsics(args.folders, board, fit_k3=args.fit_k3)
    else:
        raise RehabError("give one folder of board images per camera, or --live DEVICE per camera")
    worst = max(r.rms_px for r in results)
    _save(args, [r.camera for r in results], worst)
    from calibration.files import write_lens_information

    write_lens_information(args.out, {r.camera.name: r.information for r in results if r.information is not None},
                           views={r.camera.name: len(r.per_view_rms_px) for r in results})
    print(f"wrote the intrinsics of {len(results)} cameras to {args.out}")
    return 0


def run_live_intrinsics(captures, board, *, fit_k3: bool = False, min_views: int = 12, target_coverage: float = 0.85,
                        max_views: int = 30, max_seconds: float = 180.0, save_views: Path | None = None,
                        clock=None, verbose: bool = True):
    """Calibrate cameras one after the other from their live feeds.

    For each camera the feed is read frame by frame; a :class:`calibration.view_selection.ViewSelector`
    keeps the still, distinct board views, with a progress line per kept view (count, coverage,
    where to move the board), until the views are enough, the feed ends (a video file) or
    ``max_seconds`` pass.

    Args:
        captures: (camera name, capture) pairs; a capture has ``cv2.VideoCapture``'s ``read()``.
        board: a Checkerboard or CharucoBoard.
        save_views: folder to save each camera's kept images in (``save_views/<name>/000.png``).
        clock: seconds, monotonic (default ``time.monotonic``).
    Returns:
        the IntrinsicsResults, in the order of ``captures``.
    Raises:
        RehabError: a camera gave too few views.
    """
    import time

    import cv2

    from calibration.board import detect_board
    from calibration.intrinsics import MIN_VIEWS, calibrate_intrinsics
    from calibration.view_selection import ViewSelector
    from tracking.sources.cameras import FAILED_READS_TO_END

    clock = clock or time.monotonic
    results = []
    for name, cap in captures:
        selector = None
        images: list[np.ndarray] = []
        n_frames = failed = 0
        t0 = clock()
        ended = f"{max_seconds:g} s passed"
        if verbose:
            print(f"{name}: move the board slowly in front of the camera and hold it still in each new place", flush=True)
        while clock() - t0 < max_seconds:
            ok, image = cap.read()
            if not ok or image is None:
                failed += 1
                if failed >= FAILED_READS_TO_END:
                    ended = "the camera stopped delivering frames" if n_frames else "the camera delivered no frame"
                    break
                continue
            failed = 0
            n_frames += 1
            if selector is None:
                selector = ViewSelector((image.shape[1], image.shape[0]), min_views=min_views,
                                        target_coverage=target_coverage, max_views=max_views)
            detection, _ = detect_board(image, board)
            if selector.offer(detection):
                images.append(image)
                prog = selector.progress()
                if verbose:
                    print(f"  {name}: view {prog.n_views} kept, coverage {100 * prog.coverage:.0f} %"
                          + ("" if prog.done else f": {prog.hint}"), flush=True)
                if prog.done:
                    ended = "enough views"
                    break
        n = 0 if selector is None else len(selector.views)
        if n < MIN_VIEWS:
            raise RehabError(f"{name}: {n} board views kept from {n_frames} frames before {ended}: hold the board "
                             f"still in at least {MIN_VIEWS} (better {min_views}) different places")
        if save_views is not None:
            folder = Path(save_views) / name
            folder.mkdir(parents=True, exist_ok=True)
            for k, image in enumerate(images):
                cv2.imwrite(str(folder / f"{k:03d}.png"), image)
        res = calibrate_intrinsics(name, selector.views, board, fix_k3=not fit_k3)
        results.append(res)
        if verbose:
            K = res.camera.K
            print(f"{name}: {n} views kept from {n_frames} frames ({ended}), reprojection {res.rms_px:.3f} px, "
                  f"f = {K[0, 0]:.1f}/{K[1, 1]:.1f} px, centre ({K[0, 2]:.1f}, {K[1, 2]:.1f}), "
                  f"coverage {100 * res.coverage:.0f} %", flush=True)
            for w in res.warnings:
                print(f"  warning: {w}")
    return results


# --------------------------------------------------------------------------- extrinsics
def detect_views(folder: Path, cameras, board, *, only: str | None = None) -> tuple[dict[str, list], dict[str, str]]:
    """Board detections of every view (or of the view named ``only``): {view name: [Detection | None
    per camera]}, and skipped reasons."""
    from calibration.board import detect_board, read_gray

    if not folder.is_dir():
        raise RehabError(f"{folder}: no such folder")
    views: dict[str, list] = {}
    skipped: dict[str, str] = {}
    missing = [c.name for c in cameras if not (folder / c.name).is_dir()]
    if missing:
        raise RehabError(f"{folder}: no image folder for {', '.join(missing)}: give one sub-folder per camera, named as in the intrinsics")
    for c, cam in enumerate(cameras):
        for path in _images_in(folder / cam.name):
            if only is not None and path.stem != only:
                continue
            row = views.setdefault(path.stem, [None] * len(cameras))
            gray, reason = read_gray(path)
            if gray is not None:
                if (gray.shape[1], gray.shape[0]) != tuple(cam.size_px):
                    reason = f"{gray.shape[1]}x{gray.shape[0]} but {cam.name} is calibrated for {cam.size_px[0]}x{cam.size_px[1]}"
                else:
                    det, reason = detect_board(gray, board)
                    row[c] = det
            if row[c] is None:
                skipped[f"{cam.name}/{path.name}"] = reason
    if not views:
        raise RehabError(f"{folder}: no images in the camera folders")
    return views, skipped


def _check_floor_view(folder: Path, cameras, floor: str | None) -> None:
    """Fail early, before any detection, when no camera folder holds the floor board's image."""
    if floor is None:
        return
    if not any((folder / c.name).is_dir() and any(p.stem == floor for p in _images_in(folder / c.name)) for c in cameras):
        raise RehabError(f"{folder}: no image named {floor!r} (the board on the floor or seat) in the camera folders: give --floor NAME")


def run_extrinsics(views_dir: Path, cameras, board, *, floor: str | None, origin_m, turn_deg: float, verbose: bool = True,
                   floor_views: Path | None = None, list_skipped: bool = False, check_world: bool = True,
                   floor_board=None, lens_information=None):
    """Board extrinsics from shared views; the floor board's view from ``floor_views`` when given
    (a folder with one sub-folder per camera), else from ``views_dir``. With ``floor_board`` (another
    board than the shared views', e.g. a checkerboard on the seat after ChArUco views) the rig is
    solved from the shared views alone and then set in the floor board's world frame.
    ``lens_information``: per camera the lens step's information matrix or None
    (:func:`calibration.extrinsics.calibrate_extrinsics`); the lens data are refined with it."""
    from dataclasses import replace

    from calibration.extrinsics import calibrate_extrinsics, world_from_floor_board

    _check_floor_view(floor_views or views_dir, cameras, floor)
    views, skipped = detect_views(views_dir, cameras, board)
    if floor is not None and (floor_views is not None or floor_board is not None):
        floor_rows, floor_skipped = detect_views(floor_views or views_dir, cameras, floor_board or board, only=floor)
        views[floor] = floor_rows.get(floor, [None] * len(cameras))
        where = f"{floor_views.name}/" if floor_views is not None else ""
        skipped.update({f"{where}{k}": v for k, v in floor_skipped.items()})
    if floor_board is not None and floor is not None:
        floor_row = views.pop(floor)
        res = calibrate_extrinsics(cameras, board, views, floor_view=None, lens_information=lens_information)
        placed, _ = world_from_floor_board(res.cameras, floor_row, floor_board, origin_m=origin_m, turn_deg=turn_deg,
                                           check_world=check_world)
        res = replace(res, cameras=placed, world_set=True, warnings=tuple(w for w in res.warnings if "floor" not in w))
    else:
        res = calibrate_extrinsics(cameras, board, views, floor_view=floor, origin_m=origin_m, turn_deg=turn_deg,
                                   check_world=check_world, lens_information=lens_information)
    if verbose:
        for cam, given, rms, n in zip(res.cameras, cameras, res.rms_px, res.n_views):
            print(f"{cam.name}: {n} board views, reprojection {rms:.3f} px, at ({', '.join(f'{v:.3f}' for v in cam.centre_m)}) "
                  f"m{lens_change(cam, given)}")
        if skipped:
            _report_skipped(skipped, every=list_skipped, head=f"  {len(skipped)} camera images without a usable board "
                            "(normal for cameras that do not face it)")
        for w in res.warnings:
            print(f"  warning: {w}")
    return res


def lens_change(cam, given) -> str:
    """", lens refined (...)" when the positions step refined a camera's lens data, else ""."""
    if np.array_equal(cam.K, given.K) and np.array_equal(cam.dist, given.dist):
        return ""
    df = 100 * (cam.K[0, 0] / given.K[0, 0] - 1)
    dc = np.linalg.norm(cam.K[:2, 2] - given.K[:2, 2])
    return f", lens refined (focal {df:+.3f} %, centre moved {dc:.2f} px)"


def _cmd_extrinsics(args) -> int:
    from calibration.files import load_calibration, read_lens_information, read_lens_views
    from calibration.intrinsics import steady_lens_information

    board = board_from_args(args)
    floor_board = board_from_spec(args.floor_board) if args.floor_board else None
    cameras = load_calibration(args.intrinsics)
    info = read_lens_information(args.intrinsics, cameras) if args.refine_lenses is not False else None
    if args.refine_lenses and all(i is None for i in info):
        raise RehabError(f"--refine-lenses: {args.intrinsics} does not say how exact its lens data are: make it with "
                         "'rehab calibrate intrinsics' (or leave the option out)")
    if args.refine_lenses is None:   # the default: the lenses of steady lens steps
        n_views = read_lens_views(args.intrinsics, cameras)
        info = steady_lens_information(info, n_views)
        kept = [c.name for c, i, n in zip(cameras, info, n_views) if i is None and n is not None]
        if kept:
            print(f"lens data kept as they are for {', '.join(kept)} (lens step from fewer than 10 images)")
    res = run_extrinsics(args.views, cameras, board, floor=args.floor, origin_m=origin_from_args(args, floor_board or board),
                         turn_deg=args.turn_deg, floor_views=args.floor_views, list_skipped=args.list_skipped,
                         check_world=not args.no_world_check, floor_board=floor_board, lens_information=info)
    _save(args, res.cameras, float(np.nanmax(res.rms_px)))
    print(f"wrote the calibration of {len(res.cameras)} cameras to {args.out}")
    return 0


# --------------------------------------------------------------------------- wand
def run_wand(recording: Path, intrinsics: Path, *, length_mm: float | None, colours, ball_mm: float,
             floor_views: Path | None, board, floor: str, origin_m, turn_deg: float, verbose: bool = True,
             check_world: bool = True):
    """Wand calibration, world frame from the floor board if given. Returns (WandResult, cameras)."""
    from calibration.extrinsics import world_from_floor_board
    from calibration.wand import calibrate_wand, match_same_colour_balls
    from tracking.markerset import parse_rgb
    from tracking.io.recording import read_meta
    from tracking.drivers.wand_capture import wand_centroids

    if not recording.is_dir():
        raise RehabError(f"{recording}: no such wand recording folder")
    extra = read_meta(recording).extra if (recording / "meta.yaml").is_file() else {}
    if length_mm is None:
        length_mm = extra.get("wand_length_mm")
        if not isinstance(length_mm, (int, float)):
            raise RehabError("give the wand length with --length-mm (distance between the ball centres)")
    if colours:
        if len(colours) not in (1, 2):
            raise RehabError("give --colour twice (ball 0, then ball 1), or once when both balls have one colour")
        rgb = [parse_rgb(c) for c in colours]
        if len(rgb) == 1:
            rgb *= 2
    else:
        rgb = extra.get("wand_colours")
        if not (isinstance(rgb, list) and len(rgb) == 2):
            raise RehabError("give the two ball colours with --colour R,G,B --colour R,G,B")
    cameras, uv = wand_centroids(recording, intrinsics, rgb, ball_mm / 2000.0, progress=verbose)
    if tuple(rgb[0]) == tuple(rgb[1]):
        uv, dropped = match_same_colour_balls(cameras, uv)
        if verbose:
            print(f"balls of one colour told apart by the cameras' geometry ({dropped} camera frames undecided, left out)")
    res = calibrate_wand(cameras, uv, float(length_mm) / 1000.0)
    out = res.cameras
    if floor_views is not None and floor is not None:
        _check_floor_view(floor_views, out, floor)
        views, _ = detect_views(floor_views, out, board, only=floor)
        out, floor_rms = world_from_floor_board(out, views[floor], board, origin_m=origin_m, turn_deg=turn_deg,
                                                check_world=check_world)
        if verbose:
            print(f"world frame from the floor board ({sum(d is not None for d in views[floor])} cameras, {floor_rms:.3f} px)")
    elif verbose:
        print(f"  warning: no floor board: the world frame is {out[res.reference].name}'s own (Y is not up)")
    if verbose:
        for cam, rms, n in zip(out, res.rms_px, np.sum(np.isfinite(uv[..., 0]), axis=(1, 2))):
            print(f"{cam.name}: {n} ball views, reprojection {rms:.3f} px")
        print(f"wand length error {res.length_rmse_mm:.2f} mm RMS over {res.length_error_mm.size} frames")
        for w in res.warnings:
            print(f"  warning: {w}")
    return res, out


def _cmd_wand(args) -> int:
    board = board_from_args(args) if args.floor_views else None
    res, cameras = run_wand(args.recording, args.intrinsics, length_mm=args.length_mm, colours=args.colour,
                            ball_mm=args.ball_mm, floor_views=args.floor_views, board=board, floor=args.floor,
                            origin_m=origin_from_args(args, board) if board is not None else (0.0, 0.0, 0.0),
                            turn_deg=args.turn_deg, check_world=not args.no_world_check)
    _save(args, cameras, float(np.nanmax(res.rms_px)))
    print(f"wrote the calibration of {len(cameras)} cameras to {args.out}")
    return 0


# --------------------------------------------------------------------------- import
def _cmd_import(args) -> int:
    from calibration.camera import Camera
    from calibration.files import read_cameras, save_calibration_toml
    from calibration.foreign import check_units, scaled

    size = None
    if args.size is not None:
        try:
            size = tuple(int(v) for v in args.size.lower().split("x"))
        except ValueError:
            size = ()
        if len(size) != 2 or min(size) < 1:
            raise RehabError(f"--size {args.size!r}: give the image size as WxH, e.g. 1280x720")
    cameras, placed = [], len(args.files) == 1
    for path in args.files:
        cams, ok = read_cameras(path, size_px=size)
        if args.translation_unit == "mm":
            cams = scaled(cams, 0.001)
        elif ok:
            check_units(path, cams, hint=f"rehab calibrate import {path} --translation-unit mm --out {args.out}")
        placed &= ok
        cameras += cams
    if args.names:
        names = [n.strip() for n in args.names.split(",")]
        if len(names) != len(cameras) or not all(names):
            raise RehabError(f"--names: give {len(cameras)} names for the {len(cameras)} cameras read, comma-separated")
        cameras = [Camera(n, c.size_px, c.K, c.dist, c.rvec, c.t_m, c.fisheye) for n, c in zip(names, cameras)]
    seen = [c.name for c in cameras]
    twice = sorted({n for n in seen if seen.count(n) > 1})
    if twice:
        raise RehabError(f"two cameras are named {twice[0]!r}: give --names cam1,cam2,... in the files' order")
    if len(cameras) < 2:
        raise RehabError(f"{args.files[0]} holds one camera: give the files of every camera together, e.g. "
                         f"'rehab calibrate import cam1.yml cam2.yml --out {args.out}'")
    if not placed:
        cameras = [Camera(c.name, c.size_px, c.K, c.dist, np.zeros(3), np.zeros(3), c.fisheye) for c in cameras]
    if args.out.suffix.lower() != ".toml":
        raise RehabError(f"--out {args.out}: the calibration file must end in .toml")
    save_calibration_toml(args.out, cameras)
    lens = ", ".join(f"{c.name} {c.size_px[0]}x{c.size_px[1]} f {c.K[0, 0]:.1f} px{' fisheye' if c.fisheye else ''}"
                     for c in cameras)
    if placed:
        print(f"wrote the calibration of {len(cameras)} cameras to {args.out} ({lens})")
    else:
        print(f"wrote the lens data of {len(cameras)} cameras to {args.out} ({lens}); they are not placed yet: "
              f"next, 'rehab calibrate extrinsics VIEWS --intrinsics {args.out} ...' or 'rehab calibrate wand'")
    return 0


# --------------------------------------------------------------------------- colour
def _cmd_colour(args) -> int:
    import shutil

    from tracking.colour.adapt import learn_colours, save_colours_to_calibration
    from tracking.sources.recording import markerset_for
    from tracking.io.recording import Recording

    if args.frames < 1:
        raise RehabError(f"--frames {args.frames}: give at least 1")
    with Recording(args.recording, args.calibration) as rec:
        source = rec.calibration_path
        target = args.out or source
        if target.suffix.lower() != ".toml" or source.suffix.lower() != ".toml":
            raise RehabError(f"{target if args.out else source}: the colours are saved in TOML calibrations only: "
                             "give --out calibration.toml")
        ms = markerset_for(rec, args.markerset, None)
        adapter = learn_colours(rec, rec.cameras, ms, frames=args.frames)
    if target.resolve() != source.resolve():
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)
    save_colours_to_calibration(target, ms, adapter.models, adapter.builder.label_hs)
    for nominal, m in zip(ms.palette.tolist(), adapter.models):
        print(f"colour {tuple(nominal)}: seen as hue {m.hue_deg:.0f} deg +- {m.hue_tol_deg:.0f}, "
              f"saturation >= {m.sat_floor:.2f} (about {m.rgb})")
    print(f"learned from {adapter.updates} frame sets; saved in {target} [metadata.marker_colours] "
          "(rehab track and the live tracker use them from now on)")
    return 0


# --------------------------------------------------------------------------- simulator
def _cmd_simulate_calibration(args) -> int:
    from calibration.camera import Camera
    from calibration.charuco import CharucoBoard

    charuco = CharucoBoard.parse(*SIM_CHARUCO_SPEC) if args.charuco else None
    charuco_ext = CharucoBoard.parse(*SIM_CHARUCO_EXTRINSICS_SPEC) if args.charuco else None
    from tracking.sim.calibration_material import write_calibration_material
    from tracking.sim.rigs import load_rig

    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        raise RehabError(f"--size {args.size!r} must look like 640x480") from None
    cams = load_rig(args.rig, (w, h))
    if args.lens:
        from tracking.sim.renderer import DEMO_LENS  # lazy: only to run the simulated patient

        cams = tuple(Camera(c.name, c.size_px, c.K, DEMO_LENS, c.rvec, c.t_m) for c in cams)
    print(write_calibration_material(args.out_dir, cams, n_intrinsics=args.images, per_pair=args.per_pair,
                                     wand_seconds=args.wand_seconds, noise_sigma=args.noise, seed=args.seed,
                                     charuco=charuco, charuco_extrinsics=charuco_ext, progress=True))
    if args.check:
        for line in check_material(args.out_dir, seed=args.seed):
            print(line, flush=True)
    return 0


def check_material(folder: Path, *, seed: int = 0, track_seconds: float = 4.0) -> list[str]:
    """Calibrate from simulated material and compare with the truth; returns report lines."""
    import tempfile

    import yaml

    from calibration.board import Checkerboard
    from calibration.extrinsics import rig_errors
    from calibration.files import load_calibration, save_calibration_toml

    folder = Path(folder)
    material = yaml.safe_load((folder / "material.yaml").read_text(encoding="utf-8"))
    board = Checkerboard.parse(material["board"]["pattern"], material["board"]["square_mm"])
    origin = tuple(material["seat_board"]["origin_m"])
    truth = load_calibration(folder / "truth_calibration.toml")
    lines = []
    intr = run_intrinsics([folder / "intrinsics"], board, verbose=False)
    focal = np.array([100.0 * abs(r.camera.K[0, 0] / t.K[0, 0] - 1.0) for r, t in zip(intr, truth)])
    lines.append(f"intrinsics: focal length error max {focal.max():.3f} %, reprojection max {max(r.rms_px for r in intr):.3f} px")
    if "charuco" in material:
        lines += charuco_check(folder, material, truth)
    cams = [r.camera for r in intr]
    ext = run_extrinsics(folder / "extrinsics", cams, board, floor="seat", origin_m=origin, turn_deg=0.0, verbose=False)
    pos, ang = rig_errors(ext.cameras, truth)
    lines.append(f"board extrinsics: position error max {pos.max():.2f} mm, orientation max {ang.max():.3f} deg, "
                 f"reprojection max {np.nanmax(ext.rms_px):.3f} px")
    with tempfile.TemporaryDirectory() as tmp:
        intr_path = Path(tmp) / "intrinsics.toml"
        save_calibration_toml(intr_path, cams)
        wres, wcams = run_wand(folder / "wand", intr_path, length_mm=None, colours=None, ball_mm=40.0,
                               floor_views=folder / "extrinsics", board=board, floor="seat", origin_m=origin,
                               turn_deg=0.0, verbose=False)
        wpos, wang = rig_errors(wcams, truth)
        lines.append(f"wand extrinsics: wand length error {wres.length_rmse_mm:.2f} mm RMS, position error max "
                     f"{wpos.max():.2f} mm, orientation max {wang.max():.3f} deg, reprojection max {np.nanmax(wres.rms_px):.3f} px")
        lines.append(tracking_check(Path(tmp) / "rec", truth, ext.cameras, wcams, seconds=track_seconds, seed=seed))
    return lines


def charuco_check(folder: Path, material: dict, truth) -> list[str]:
    """ChArUco intrinsics from ``intrinsics_charuco/`` (and extrinsics from ``extrinsics_charuco/``
    when the material has them) against the truth: a summary line, then one line per camera."""
    from calibration.charuco import CharucoBoard
    from calibration.extrinsics import rig_errors
    from calibration.intrinsics import steady_lens_information

    spec = material["charuco"]
    board = CharucoBoard.parse(spec["squares"], spec["square_mm"], spec["marker_mm"], spec["dictionary"])
    res = run_intrinsics([folder / "intrinsics_charuco"], board, verbose=False)
    focal = np.array([100.0 * abs(r.camera.K[0, 0] / t.K[0, 0] - 1.0) for r, t in zip(res, truth)])
    centre = np.array([float(np.linalg.norm(r.camera.K[:2, 2] - t.K[:2, 2])) for r, t in zip(res, truth)])
    lines = [f"ChArUco intrinsics: focal length error max {focal.max():.3f} %, reprojection max "
             f"{max(r.rms_px for r in res):.3f} px, coverage min {100 * min(r.coverage for r in res):.0f} %"]
    pos = ang = None
    spec = material.get("charuco_extrinsics")
    if spec is not None and (folder / "extrinsics_charuco").is_dir():
        board = CharucoBoard.parse(spec["squares"], spec["square_mm"], spec["marker_mm"], spec["dictionary"])
        info = steady_lens_information([r.information for r in res], [len(r.per_view_rms_px) for r in res])   # as 'rehab calibrate extrinsics' does
        ext = run_extrinsics(folder / "extrinsics_charuco", [r.camera for r in res], board, floor="seat",
                             origin_m=tuple(spec["seat_origin_m"]), turn_deg=0.0, verbose=False, lens_information=info)
        pos, ang = rig_errors(ext.cameras, truth)
        lines.append(f"ChArUco extrinsics: position error max {pos.max():.2f} mm, orientation max {ang.max():.3f} deg, "
                     f"reprojection max {np.nanmax(ext.rms_px):.3f} px")
        floor_board = material.get("board")
        if floor_board is not None and (folder / "extrinsics").is_dir():   # the world frame from the checkerboard instead
            from calibration.board import Checkerboard

            cb = Checkerboard.parse(floor_board["pattern"], floor_board["square_mm"])
            mixed = run_extrinsics(folder / "extrinsics_charuco", [r.camera for r in res], board, floor="seat",
                                   origin_m=tuple(material["seat_board"]["origin_m"]), turn_deg=0.0, verbose=False,
                                   floor_views=folder / "extrinsics", floor_board=cb, lens_information=info)
            p2, a2 = rig_errors(mixed.cameras, truth)
            lines.append(f"ChArUco extrinsics, checkerboard on the seat: position error max {p2.max():.2f} mm, "
                         f"orientation max {a2.max():.3f} deg")
    for c, t in enumerate(truth):
        extra = "" if pos is None else f", position {pos[c]:.2f} mm, orientation {ang[c]:.3f} deg"
        if pos is not None:   # the lens refined with the positions
            K = ext.cameras[c].K
            extra += (f"; refined lens: focal {100.0 * abs(K[0, 0] / t.K[0, 0] - 1.0):.3f} %, "
                      f"image centre {float(np.linalg.norm(K[:2, 2] - t.K[:2, 2])):.2f} px")
        lines.append(f"  ChArUco {t.name}: focal {focal[c]:.3f} %, image centre {centre[c]:.2f} px{extra}")
    return lines


def tracking_check(rec_dir: Path, truth, board_cams, wand_cams, *, seconds: float, seed: int) -> str:
    """Track a short simulated recording with the true and the recovered calibrations."""
    from tracking.drivers.calibration_check import tracking_difference_mm
    from tracking.markerset import load_markerset
    from tracking.io.recording import RecordingWriter
    from tracking.sim.body import BodyDimensions  # lazy: only to run the simulated patient
    from tracking.sim.motions import load_motion
    from tracking.sim.studio import Studio

    # Rendered with the true cameras (lens included), as simulate_recording would with the rig.
    markerset = load_markerset("upper_limb_seated")
    dims = BodyDimensions.from_percentile(50.0, "female")
    motion = load_motion("shoulder_abduction", dims)
    fps = 10.0
    with Studio(truth, markerset, dims) as studio:
        writer = RecordingWriter(rec_dir, truth, fps)
        try:
            for sf in studio.play(motion, fps, seconds=seconds, noise_sigma=1.5, seed=seed, with_visibility=False):
                writer.write(sf.frames.images)
        finally:
            writer.close()
        writer.write_meta(markerset.name, markerset.rgb, source="simulator: calibration check")
    d_board, n = tracking_difference_mm(rec_dir, board_cams, truth)
    d_wand, _ = tracking_difference_mm(rec_dir, wand_cams, truth)
    return (f"tracking difference against the true calibration over {n} marker positions: "
            f"board {d_board:.2f} mm RMS, wand {d_wand:.2f} mm RMS")
