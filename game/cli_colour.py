"""``rehab colour learn|drift-check``: learned marker colours (tracking/colour/adapt.py, docs/COLOUR.md)."""

from __future__ import annotations

from pathlib import Path

from calibration.errors import RehabError
from game.cli_options import COUNT, SEED, number


def add_commands(sub) -> None:
    """Register the ``colour`` command and its subcommands on the top-level subparsers."""
    p = sub.add_parser("colour", help="learn the marker colours from a recording; check them under lighting drift",
                       description="Marker colours learned from the images (docs/COLOUR.md).")
    csub = p.add_subparsers(dest="colour_command", required=True, metavar="SUBCOMMAND")

    q = csub.add_parser("learn", help="learn the marker colours from the first frames (reference pose) of a recording",
                        description="Identify the markers in the reference pose at the start of a recording, learn "
                        "each marker colour from the pixels of its balls and the background from the rest of "
                        "the images, and write the learned colour file for `rehab track --colours`.")
    q.add_argument("recording", type=Path, help="recording folder that starts in the reference pose")
    q.add_argument("--out", type=Path, required=True, help="learned colour file to write, e.g. colours.toml")
    q.add_argument("--calibration", type=Path, default=None, help="calibration file (default: RECORDING/calibration.toml)")
    q.add_argument("--markerset", default=None, help="marker set name or YAML file (default: from meta.yaml)")
    q.add_argument("--frames", type=COUNT, default=30, help="frame sets to learn from after identification (default 30)")
    q.set_defaults(func=_cmd_learn)

    q = csub.add_parser("drift-check", help="simulate a lighting drift and compare the fixed and the adapted table",
                        description="Render a simulated recording whose lighting drifts (darker, colour cast) and "
                        "track it with the fixed nominal colour table and with the adapted one; print both, per marker.")
    q.add_argument("--motion", default="shoulder_abduction", help="simulated motion (default shoulder_abduction)")
    q.add_argument("--rig", default="ring4", help="camera rig (default ring4)")
    q.add_argument("--size", default="320x240", help="image size WxH (default 320x240)")
    q.add_argument("--seconds", type=number(0.0, 3600.0, above=True), default=10.0, help="length of the recording (default 10)")
    q.add_argument("--drop", type=number(0.0, 0.95), default=0.4, help="brightness drop reached (default 0.4 = 40 %% darker)")
    q.add_argument("--cast", default="1.3,1.0,0.7", help="R,G,B gains reached (default 1.3,1.0,0.7: warm)")
    q.add_argument("--drift-start", type=number(0.0, 3600.0), default=1.0, help="drift starts at this time, s (default 1)")
    q.add_argument("--drift-seconds", type=number(0.0, 3600.0, above=True), default=6.0, help="drift lasts this long, s (default 6)")
    q.add_argument("--every", type=COUNT, default=60, help="learn from every this many frame sets (default 60)")
    q.add_argument("--seed", type=SEED, default=0, help="noise seed")
    q.set_defaults(func=_cmd_drift_check)


def _cmd_learn(args) -> int:
    from tracking.colour.adapt import learn_colours
    from tracking.sources.recording import markerset_for
    from tracking.io.recording import Recording

    if args.frames < 1:
        raise RehabError(f"--frames {args.frames}: give at least 1")
    with Recording(args.recording, args.calibration) as rec:
        ms = markerset_for(rec, args.markerset, None)
        adapter = learn_colours(rec, rec.cameras, ms, frames=args.frames)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    adapter.save(args.out)
    for nominal, m in zip(ms.palette.tolist(), adapter.models):
        print(f"colour {tuple(nominal)}: seen as hue {m.hue_deg:.0f} deg +- {m.hue_tol_deg:.0f}, "
              f"saturation >= {m.sat_floor:.2f} (about {m.rgb})")
    print(f"learned from {adapter.updates} frame sets; wrote {args.out} (use: rehab track ... --colours {args.out})")
    return 0


def _cmd_drift_check(args) -> int:
    from dataclasses import replace

    from tracking.sim.colour_drift import DRIFT_SETTINGS, run_drift  # lazy: only to run the simulated patient

    try:
        w, h = (int(v) for v in args.size.lower().split("x"))
        cast = tuple(float(v) for v in args.cast.split(","))
        assert len(cast) == 3 and all(0.2 < v < 5 for v in cast) and 0 <= args.drop < 1
    except (ValueError, AssertionError):
        raise RehabError("--size WxH (e.g. 320x240), --cast R,G,B gains (e.g. 1.3,1.0,0.7) and --drop 0..1 "
                         f"(got {args.size!r}, {args.cast!r}, {args.drop})") from None
    settings = replace(DRIFT_SETTINGS, motion=args.motion, rig=args.rig, size_px=(w, h), seconds=args.seconds,
                       brightness_drop=args.drop, colour_cast=cast, drift_start_s=args.drift_start,
                       drift_s=args.drift_seconds, seed=args.seed)
    result = run_drift(settings, every=args.every, progress=True)
    print(f"{args.motion}, {args.rig} at {w}x{h}, {args.seconds:g} s: {100 * args.drop:.0f} % darker and cast "
          f"{cast} from {args.drift_start:g} s over {args.drift_seconds:g} s")
    print(result.table())
    return 0
