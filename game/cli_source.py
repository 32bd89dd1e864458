"""What the tracker process measures, as `rehab play` and `rehab stream` both take it: the simulated
studio, real cameras or a recording folder, and the checks that make a missing file or an unknown
motion one line before anything starts."""

from __future__ import annotations

from pathlib import Path

from calibration.errors import RehabError
from game.cli_options import FPS, size_px


def add_tracker_source_options(p) -> None:
    """What the tracker process measures (``rehab play``, ``rehab stream``): the simulated studio
    (``--rig --size --fps --body``), ``--devices`` or ``--recording`` (and ``--calibration``), and
    ``--adapt-colours``; read back by :func:`play_source`."""
    p.add_argument("--rig", default="ring4", help="camera layout of the simulated studio (default: %(default)s)")
    p.add_argument("--size", type=size_px, default=(320, 240), help="camera image size WxH (default: 320x240)")
    p.add_argument("--fps", type=FPS, default=30.0, help="camera frame rate (default: %(default)s)")
    p.add_argument("--body", default="p50_male",
                   help="simulated body as p<percentile>_<sex>, e.g. p5_female (default: %(default)s)")
    p.add_argument("--adapt-colours", action="store_true",
                   help="the tracker's colour table follows lighting drift (learns from the tracked markers)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--devices", default=None, metavar="DEV,DEV,...",
                       help="real cameras instead of the simulated patient: OpenCV device indices, URLs or "
                            "video files, one per camera of --calibration, in its order")
    where.add_argument("--recording", type=Path, default=None, metavar="DIR",
                       help="track a recording folder (rehab record) in real time instead of the simulated patient")
    p.add_argument("--calibration", type=Path, default=None,
                   help="calibration file of the cameras (needed with --devices; replaces a recording's own)")


def check_motion(motion: str | None) -> None:
    """A one-line error for a motion that is neither built in nor a file (None passes)."""
    from tracking.sim.motions import available_motions  # lazy: only to run the simulated patient

    if motion is not None and motion not in available_motions() and not Path(motion).is_file():
        raise RehabError(f"unknown motion {motion!r}: choose one of {', '.join(available_motions())} "
                         "or give a motion YAML file")


def play_source(args) -> dict:
    """The tracker process's source from ``--devices``/``--recording``/``--calibration``
    (nothing: the simulated patient). Missing files are one line here, before anything starts."""
    calibration = args.calibration
    if calibration is not None and not calibration.is_file():
        raise RehabError(f"calibration file {calibration} not found: give the file rehab calibrate wrote")
    if args.devices is not None:
        devices = tuple(d.strip() for d in args.devices.split(",") if d.strip())
        if not devices:
            raise RehabError("--devices: give one camera per calibrated camera, e.g. --devices 0,1,2,3")
        if calibration is None:
            raise RehabError("--devices needs --calibration FILE: the cameras' calibration (rehab calibrate)")
        return {"kind": "cameras", "devices": devices, "calibration": str(calibration)}
    if args.recording is not None:
        if not args.recording.is_dir():
            raise RehabError(f"recording folder {args.recording} not found: give a folder rehab record or "
                             "rehab simulate wrote")
        return {"kind": "recording", "path": str(args.recording),
                "calibration": None if calibration is None else str(calibration)}
    if calibration is not None:
        raise RehabError("--calibration goes with --devices or --recording")
    return {}
