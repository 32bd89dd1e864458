"""``rehab stream``: the tracker process alone, streaming over LSL and/or OSC (docs/STREAMING.md).

Registered on the ``rehab`` parser by :func:`add_commands`; :func:`add_stream_options` and
:func:`stream_config` give ``rehab play`` the same ``--lsl``/``--osc`` flags.
"""

from __future__ import annotations

import time

from calibration.errors import RehabError
from game.cli_options import SECONDS
from game.cli_source import add_tracker_source_options, check_motion, play_source

#: Seconds between the progress lines of ``rehab stream``.
REPORT_EVERY_S = 5.0
#: A recording whose samples stopped this long ago has ended.
ENDED_AFTER_S = 2.0


def add_stream_options(p) -> None:
    """``--lsl``, ``--osc HOST:PORT`` and ``--stream-name`` on a sub-command parser."""
    p.add_argument("--lsl", action="store_true",
                   help="publish Lab Streaming Layer streams: markers (3 x N, mm), joint angles, status")
    p.add_argument("--osc", default=None, metavar="HOST:PORT",
                   help="send OSC messages (markers, angles) and VMC bones to HOST:PORT (VMC tools listen on 39539)")
    p.add_argument("--stream-name", default="rehab-mocap", help="name prefix of the streams (default: %(default)s)")


def stream_config(args):
    """The :class:`~tracking.live.stream.StreamConfig` of the parsed flags, or None when all are off."""
    from tracking.live.stream import StreamConfig, parse_osc_target

    if not (args.lsl or args.osc):
        return None
    name = args.stream_name.strip()
    if not name or any(c in name for c in "\r\n\t"):
        raise RehabError(f"--stream-name {args.stream_name!r}: give a one-line name, e.g. rehab-mocap")
    config = StreamConfig(lsl=args.lsl, osc=parse_osc_target(args.osc) if args.osc else None, name=name)
    config.check()
    return config


def add_commands(sub) -> None:
    """Add ``stream`` to the sub-command parsers ``sub``."""
    p = sub.add_parser(
        "stream",
        help="stream markers and joint angles live over LSL and/or OSC (no window)",
        description="Run the tracker on the simulated patient (a scripted motion), a recording (played in real "
        "time) or live cameras, and stream every frame set: --lsl publishes Lab Streaming Layer streams "
        "(markers, joint angles, status; time stamps are the frame sets' instants), --osc sends OSC messages "
        "and VMC bones. Runs until --seconds, the end of a recording, or Ctrl-C.",
    )
    add_stream_options(p)
    p.add_argument("--motion", default="shoulder_flexion",
                   help="scripted motion of the simulated patient (built-in name or motion YAML; default: %(default)s)")
    p.add_argument("--seconds", type=SECONDS, default=None, help="stop after this many seconds")
    add_tracker_source_options(p)
    p.set_defaults(func=_cmd_stream)


def _cmd_stream(args) -> int:
    from tracking.live import LiveTracker, SourceConfig

    stream = stream_config(args)
    if stream is None:
        raise RehabError("nothing to stream: give --lsl and/or --osc HOST:PORT")
    where = play_source(args)
    motion = None if where else args.motion
    check_motion(motion)
    source = SourceConfig(rig=args.rig, size=args.size, fps=args.fps, motion=motion, body=args.body,
                          adapt_colours=args.adapt_colours, **where)
    source.check()
    outputs = " and ".join(filter(None, ["LSL" if stream.lsl else "", f"OSC to {stream.osc[0]}:{stream.osc[1]}"
                                         if stream.osc else ""]))
    with LiveTracker(source, stream=stream) as live:
        print(f"rehab stream: streaming {outputs} as {stream.name!r} at {source.fps:g} frame sets/s; "
              "Ctrl-C stops", flush=True)
        start = last_report = last_change = time.monotonic()
        samples = 0
        try:
            while args.seconds is None or time.monotonic() - start < args.seconds:
                time.sleep(0.1)
                status = live.status()
                live.poll_records()  # keep the ring read: nobody else does here
                now = time.monotonic()
                if status.samples != samples:
                    samples, last_change = status.samples, now
                elif source.kind == "recording" and samples and now - last_change > ENDED_AFTER_S:
                    print(f"rehab stream: {status.warning or 'the recording ended'}", flush=True)
                    break
                if now - last_report >= REPORT_EVERY_S:
                    last_report = now
                    problems = "; ".join(filter(None, [status.warning, status.last_error]))
                    print(f"rehab stream: {status.samples} frame sets, {status.source_fps:.1f}/s, tracker "
                          f"{status.tracker_ms:.1f} ms" + (f" ({problems})" if problems else ""), flush=True)
        except KeyboardInterrupt:
            pass
        status = live.status()
    print(f"rehab stream: {status.samples} frame sets streamed in {time.monotonic() - start:.0f} s", flush=True)
    return 0

