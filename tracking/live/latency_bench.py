"""Latency and pace of the live tracker, measured end to end through the process.

:func:`measure_latency` starts a :class:`~tracking.live.LiveTracker` on the simulated patient,
reads its samples in a tight loop and reports, per sample:

- **latency**: the time from "frame set ready in the tracker process" to "sample visible to the
  game process", minus the tracker's own step time (what the process boundary and the
  publishing add on top of tracking): ``t_seen - t_frame_ready - step``, split into
  ``publish`` (in the tracker process: angles into the record, the record into the ring) and
  ``transport`` (``t_seen - t_published``: shared memory to the reader);
- **pace**: frame sets per second the source kept, against the rate asked for, with the mean
  render and tracker step times (on a shared machine these depend on the load: it is reported).

``python -m tracking.live.latency_bench`` prints the figures for 320x240 and 640x480;
``rehab bench`` calls :func:`measure_latency` as well. ``--kill-both N`` instead times the
restart after the tracker and its warm standby are killed together (:func:`measure_kill_both`).
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import socket
import sys
import time

import numpy as np

from tracking.live.client import LiveTracker, process_cpu_s
from tracking.live.protocol import SourceConfig
from tracking.live.stream import StreamConfig, quiet_lsl

log = logging.getLogger(__name__)

#: Samples of the first second are left out (identification, caches warming up).
SETTLE_S = 1.0


def _percentiles(values_ms: np.ndarray) -> dict[str, float]:
    if len(values_ms) == 0:
        return {"p50": float("nan"), "p99": float("nan"), "max": float("nan")}
    return {"p50": float(np.percentile(values_ms, 50)), "p99": float(np.percentile(values_ms, 99)),
            "max": float(values_ms.max())}


class StreamConsumers:
    """What a lab's receivers do with the streams while the tracker process sends them: an LSL
    inlet per stream pulling, and a UDP socket draining the OSC datagrams."""

    def __init__(self, stream) -> None:
        self.inlets = []
        self.sock = None
        self.received = 0
        if stream.osc is not None:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.bind(stream.osc)
            self.sock.setblocking(False)
        self.stream = stream

    def connect(self, timeout_s: float = 10.0) -> None:
        if self.stream.lsl:
            import pylsl  # lazy: pylsl loads its native liblsl: only when LSL output is on

            quiet_lsl()
            for kind in ("markers", "angles", "status"):
                found = pylsl.resolve_byprop("source_id", f"{self.stream.name}-{kind}", timeout=timeout_s)
                if found:
                    self.inlets.append(pylsl.StreamInlet(found[0]))

    def drain(self) -> None:
        for inlet in self.inlets:
            samples, _ = inlet.pull_chunk(timeout=0.0, max_samples=4096)
            self.received += len(samples)
        while self.sock is not None:
            try:
                self.sock.recv(65536)
                self.received += 1
            except (BlockingIOError, InterruptedError):
                break

    def close(self) -> None:
        for inlet in self.inlets:
            inlet.close_stream()
        self.inlets = []
        if self.sock is not None:
            self.sock.close()


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def measure_latency(seconds: float = 10.0, size: tuple[int, int] = (320, 240), *, fps: float = 30.0,
                    motion: str | None = "shoulder_flexion", rig: str = "ring4", reader: str = "wait",
                    stream=None) -> dict:
    """Run the tracker process for ``seconds`` and measure latency and pace.

    Args:
        seconds: measuring time (after :data:`SETTLE_S`).
        size: camera image (width, height).
        fps: the source's frame rate.
        motion: scripted motion of the simulated patient (None: the interactive patient, still).
        rig: camera layout.
        reader: how the game process reads: ``"wait"`` blocks on the tracker's new-sample pipe
            (:meth:`LiveTracker.wait`) and reads at once; ``"spin"`` polls in a tight loop,
            yielding the CPU between polls (on a loaded machine the scheduler then makes the
            reader wait for its turn); ``"frame"`` polls every 5 ms as a game loop might (the
            latency then includes up to that wait).
        stream: a :class:`tracking.live.stream.StreamConfig`: the tracker process also streams,
            and this process receives (:class:`StreamConsumers`); None: no streaming.

    Returns:
        dict with ``size``, ``fps_asked``, ``fps_kept`` (samples per wall second), ``samples``,
        ``dropped``, ``errors``, ``latency_ms``/``publish_ms``/``transport_ms``/``tracker_ms``
        (each ``p50``, ``p99``, ``max``), ``tracker_ms_mean``, ``render_ms_mean``,
        ``cpu_ms_per_frame`` (CPU time of the tracker process, all threads, per frame set: what
        the figures would be on an idle machine does not depend on the load as wall times do),
        ``load_avg`` (1-minute load average, or NaN).
    """
    if reader not in ("wait", "spin", "frame"):
        raise ValueError(f"reader {reader!r}: use 'wait', 'spin' or 'frame'")
    config = SourceConfig(size=tuple(size), fps=fps, motion=motion, rig=rig)
    latency, publish, transport, step, render = [], [], [], [], []
    consumers = StreamConsumers(stream) if stream is not None else None
    with LiveTracker(config, auto_restart=False, warm_standby=False, stream=stream) as live:
        if consumers is not None:
            consumers.connect()
        t_start = time.perf_counter()
        t_measure = t_start + SETTLE_S
        t_end = t_measure + seconds
        first_number = None
        count = 0
        cpu_start = cpu_end = float("nan")
        while True:
            records = live.poll_records()
            t_seen = time.perf_counter()
            for rec in records:
                ready = float(rec["t_frame_ready_s"])
                if ready < t_measure:
                    continue
                if first_number is None:
                    first_number = int(rec["number"])
                    cpu_start = process_cpu_s(live.pid)
                count += 1
                step_s = float(rec["step_ms"]) / 1000.0
                published = float(rec["t_published_s"])
                latency.append(t_seen - ready - step_s)
                publish.append(published - ready - step_s)
                transport.append(t_seen - published)
                step.append(step_s)
                render.append(float(rec["source_ms"]) / 1000.0)
            if consumers is not None:
                consumers.drain()
            if t_seen >= t_end:
                cpu_end = process_cpu_s(live.pid)
                break
            if reader == "wait":
                live.wait(0.1)
            else:
                time.sleep(0 if reader == "spin" else 0.005)
        if consumers is not None:
            consumers.close()  # before the process stops: no "transmission broke off" from the inlets
        status = live.status()
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = float("nan")
    ms = lambda v: np.asarray(v) * 1000.0  # noqa: E731
    return {
        "size": tuple(size),
        "reader": reader,
        "fps_asked": float(fps),
        "fps_kept": count / seconds,
        "samples": count,
        "dropped": status.dropped,
        "errors": status.errors,
        "latency_ms": _percentiles(ms(latency)),
        "publish_ms": _percentiles(ms(publish)),
        "transport_ms": _percentiles(ms(transport)),
        "tracker_ms": _percentiles(ms(step)),
        "tracker_ms_mean": float(ms(step).mean()) if step else float("nan"),
        "render_ms_mean": float(ms(render).mean()) if render else float("nan"),
        "cpu_ms_per_frame": (cpu_end - cpu_start) * 1000.0 / max(count - 1, 1),
        "load_avg": load,
        "stream_received": consumers.received if consumers is not None else 0,
    }


def compare_streaming(seconds: float, passes: int = 3, size: tuple[int, int] = (320, 240)) -> list[str]:
    """The tracker process with streaming off and on (LSL and OSC, received in this process), in
    alternating passes of ``seconds``: its step time and CPU time per frame set. Lines to print."""
    stream = StreamConfig(lsl=True, osc=("127.0.0.1", free_udp_port()), name="rehab-bench")
    rows = {"off": [], "on": []}
    for _ in range(passes):
        for key in ("off", "on"):
            rows[key].append(measure_latency(seconds, size, stream=stream if key == "on" else None))
    lines = []
    for key, results in rows.items():
        step = [r["tracker_ms_mean"] for r in results]
        cpu = [r["cpu_ms_per_frame"] for r in results]
        kept = [r["fps_kept"] for r in results]
        received = sum(r["stream_received"] for r in results)
        lines.append(f"streaming {key:3s}: tracker step {' / '.join(f'{v:.2f}' for v in step)} ms (median "
                     f"{np.median(step):.2f}), CPU {' / '.join(f'{v:.1f}' for v in cpu)} ms per frame set (median "
                     f"{np.median(cpu):.1f}), kept {' / '.join(f'{v:.1f}' for v in kept)} frame sets/s"
                     + (f", {received} samples and datagrams received" if key == "on" else ""))
    return lines


def format_result(r: dict) -> str:
    """Two lines a person reads."""
    w, h = r["size"]
    lat, tr = r["latency_ms"], r["tracker_ms"]
    return (f"{w}x{h}: kept {r['fps_kept']:.1f} of {r['fps_asked']:.0f} frame sets/s ({r['samples']} samples, "
            f"{r['dropped']} dropped, {r['errors']} errors; render {r['render_ms_mean']:.1f} ms, tracker "
            f"{r['tracker_ms_mean']:.1f} ms mean / {tr['p99']:.1f} p99, CPU {r['cpu_ms_per_frame']:.1f} ms per "
            f"frame set; load average {r['load_avg']:.1f})\n"
            f"  latency beyond tracking ({r['reader']} reader): p50 {lat['p50']:.3f} ms, p99 {lat['p99']:.3f} ms, max {lat['max']:.3f} ms "
            f"(publish p99 {r['publish_ms']['p99']:.3f} ms, transport p99 {r['transport_ms']['p99']:.3f} ms)")


def measure_kill_both(n: int = 10, size: tuple[int, int] = (320, 240), *, log=print) -> list[float]:
    """Kill the running tracker process and its warm standby together (SIGKILL, as the
    out-of-memory killer may) ``n`` times; returns the seconds from the kills to the first new
    sample published (``status()`` and ``poll()`` called every 5 ms, as a game would each frame)."""
    times = []
    with LiveTracker(SourceConfig(size=size, motion="shoulder_flexion")) as live:
        for i in range(n):
            deadline = time.perf_counter() + 120.0
            while not (live.status().alive and live.standby_ready) and time.perf_counter() < deadline:
                live.poll()
                time.sleep(0.02)
            time.sleep(0.5)
            live.poll()
            running, standby = live.pid, live._spare.pid
            t0 = time.perf_counter()
            os.kill(running, signal.SIGKILL)
            os.kill(standby, signal.SIGKILL)
            got = None
            while got is None and time.perf_counter() - t0 < 120.0:
                live.status()
                new = [s for s in live.poll() if s.t_frame_ready_s > t0]
                if new:
                    got = new[0].t_published_s - t0
                time.sleep(0.005)
            if got is None:
                raise RuntimeError(f"no sample within 120 s of kill {i + 1}: {live.status()}")
            times.append(got)
            log(f"  kill {i + 1}: first new sample after {got:.2f} s")
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tracking.live.latency_bench", description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="measuring time per size (default 10)")
    parser.add_argument("--size", action="append", default=None, metavar="WxH",
                        help="camera size; repeat for several (default 320x240 and 640x480)")
    parser.add_argument("--fps", type=float, default=30.0, help="source frame rate (default 30)")
    parser.add_argument("--motion", default="shoulder_flexion", help="scripted motion (default shoulder_flexion)")
    parser.add_argument("--reader", choices=("wait", "spin", "frame"), default="wait",
                        help="how the reader waits for samples (default wait: blocks on the new-sample pipe)")
    parser.add_argument("--kill-both", type=int, default=0, metavar="N",
                        help="instead: kill the tracker and its standby together N times, time the first new sample")
    args = parser.parse_args(argv)
    if args.kill_both > 0:
        t = sorted(measure_kill_both(args.kill_both))
        print(f"tracker and standby killed together, n={len(t)}: median {np.median(t):.2f} s, worst {t[-1]:.2f} s, "
              f"best {t[0]:.2f} s (load average {os.getloadavg()[0]:.1f})")
        return 0
    sizes = args.size or ["320x240", "640x480"]
    for text in sizes:
        try:
            w, h = (int(v) for v in text.lower().split("x"))
        except ValueError:
            print(f"--size {text}: write WIDTHxHEIGHT, e.g. 320x240", file=sys.stderr)
            return 1
        print(format_result(measure_latency(args.seconds, (w, h), fps=args.fps, motion=args.motion, reader=args.reader)),
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
