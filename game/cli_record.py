"""``rehab record``: save synchronized raw camera images as a recording folder.

Registered on the ``rehab`` parser by :func:`add_commands`. ``rehab record OUT --cameras 0,1,2
--calibration calib.toml --seconds 30`` records live cameras; ``rehab record OUT --source sim
--motion NAME`` records the simulated cameras (same files, plus truth.trc). ``rehab track OUT``
tracks the result offline.
"""

from __future__ import annotations

import math
from pathlib import Path

from calibration.errors import RehabError
from game.cli_options import FPS, NOISE, SECONDS, SEED, size_px


def add_commands(sub) -> None:
    """Add ``record`` to the sub-command parsers ``sub``."""
    p = sub.add_parser(
        "record",
        help="save synchronized camera images as a recording folder, for offline tracking",
        description="Record live cameras (one OpenCV reader thread per camera, frames grouped by time stamp) or "
        "the simulated cameras into a recording folder (docs/INTERFACES.md): calibration.toml, one lossless "
        "video per camera, meta.yaml, timestamps.csv. A camera that stops or drops frames is reported; its "
        "missing images are written black so that the cameras stay in step. Ctrl-C stops and keeps what was "
        "recorded.",
    )
    p.add_argument("out_dir", type=Path, help="new recording folder (must not exist or be empty)")
    p.add_argument("--source", choices=("cameras", "sim"), default="cameras",
                   help="live cameras (default) or the simulated patient")
    p.add_argument("--cameras", default=None, metavar="DEV,DEV,...",
                   help="camera devices in calibration order: indices (0,1,2), URLs or video files")
    p.add_argument("--calibration", type=Path, default=None, help="calibration file of the cameras (TOML or OpenCV YAML)")
    p.add_argument("--seconds", type=SECONDS, default=10.0, help="length of the recording (default: %(default)s)")
    p.add_argument("--fps", type=FPS, default=30.0, help="frame rate (default: %(default)s)")
    p.add_argument("--size", type=size_px, default=None,
                   help="image size WxH (cameras: must match the calibration; sim: default 640x480)")
    p.add_argument("--images", action="store_true", help="write PNG folders instead of lossless AVI videos")
    p.add_argument("--markerset", default="upper_limb_seated", help="marker set worn: name or YAML file")
    p.add_argument("--motion", default="right_external_rotation", help="sim: built-in motion name or motion file")
    p.add_argument("--rig", default="ring4", help="sim: camera layout (default: %(default)s)")
    p.add_argument("--noise", type=NOISE, default=1.5, help="sim: sensor noise sigma, 8-bit units (default: %(default)s)")
    p.add_argument("--seed", type=SEED, default=0, help="sim: sensor-noise seed")
    p.set_defaults(func=_cmd_record)


def _cmd_record(args) -> int:
    from tracking.markerset import load_markerset
    from tracking.sources.record import check_new_folder, record

    check_new_folder(args.out_dir)
    n_frames = max(1, int(math.floor(args.seconds * args.fps + 1e-9)))
    if args.source == "sim":
        from tracking.live.protocol import SourceConfig
        from tracking.sources.sim import SimulatedSource

        if args.cameras or args.calibration:
            raise RehabError("--cameras and --calibration are for live cameras: drop them with --source sim")
        config = SourceConfig(kind="sim", rig=args.rig, size=tuple(args.size or (640, 480)), fps=args.fps,
                              motion=args.motion, body="p50_female", markerset=args.markerset, seed=args.seed,
                              noise_sigma=args.noise, sim_clock="frames")
        source = SimulatedSource(config, seconds=args.seconds)
        markerset = source.markerset
        meta = {"source": "rehab record (simulated cameras)", "motion": args.motion, "rig": args.rig}
    else:
        from calibration.files import check_camera_count, load_calibration
        from tracking.sources.cameras import CameraSource

        if not args.cameras or not args.calibration:
            raise RehabError("give --cameras 0,1,2 (one device per calibrated camera) and --calibration FILE, "
                             "or --source sim")
        devices = [d.strip() for d in args.cameras.split(",") if d.strip()]
        cameras = load_calibration(args.calibration)
        check_camera_count(cameras, len(devices), "--cameras", kind="devices", calibration_name=args.calibration.name)
        for cam in cameras if args.size is not None else ():
            if tuple(cam.size_px) != tuple(args.size):
                w, h = cam.size_px
                raise RehabError(f"--size {args.size[0]}x{args.size[1]} but the calibration of {cam.name} is for "
                                 f"{w}x{h}: record at the calibrated size (leave out --size) or recalibrate")
        markerset = load_markerset(args.markerset)
        source = CameraSource(cameras, devices, args.fps, markerset=markerset)
        meta = {"source": "rehab record (live cameras)", "devices": devices}
    try:
        summary = record(source, args.out_dir, n_frames, markerset, images=args.images, progress=True, meta=meta)
    finally:
        source.close()
    print(summary.line())
    return 0
