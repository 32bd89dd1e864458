"""The soak test: a long headless ``rehab play`` session, its memory over time, and what it leaves.

``python -m game.soak --minutes 60`` runs ``rehab play --headless`` (the live avatar on the
simulated patient, a scripted motion in a loop) as a child process for that long, samples the
resident memory (RSS) of the game and of each of its processes (the tracker, its warm standby,
multiprocessing's helpers) from ``/proc``, and at the end checks that the session left no shared
memory block (``/dev/shm``) and no process behind. It prints the figures and exits 1 if memory
grew by more than ``--max-growth-mb`` after the warm-up, a block or a process was left, or the
session failed. Linux only (``/proc``, ``/dev/shm``). The figures of past runs are in docs/LIVE.md.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from game.cli_options import OneLineParser, number

_PAGE_KB = os.sysconf("SC_PAGE_SIZE") // 1024 if hasattr(os, "sysconf") else 4


@dataclass(frozen=True, slots=True)
class ProcInfo:
    """One process as /proc shows it: id, parent, start time (clock ticks: tells a reused id), name."""

    pid: int
    ppid: int
    start_ticks: int
    name: str


def read_proc(pid: int) -> ProcInfo | None:
    """The process ``pid`` (None if it is gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            text = f.read()
    except OSError:
        return None
    name = text[text.index("(") + 1:text.rindex(")")]
    fields = text[text.rindex(")") + 2:].split()
    if fields[0] == "Z":   # a zombie is gone but for its exit status
        return None
    return ProcInfo(pid, int(fields[1]), int(fields[19]), name)


def descendants(root: int) -> list[ProcInfo]:
    """Every living process below ``root`` (children, their children...)."""
    procs = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            info = read_proc(int(entry))
            if info is not None:
                procs.append(info)
    children: dict[int, list[ProcInfo]] = {}
    for p in procs:
        children.setdefault(p.ppid, []).append(p)
    out, todo = [], [root]
    while todo:
        for child in children.get(todo.pop(), []):
            out.append(child)
            todo.append(child.pid)
    return out


def rss_kb(pid: int) -> int | None:
    """Resident memory of ``pid`` in KiB (None if it is gone)."""
    try:
        with open(f"/proc/{pid}/statm") as f:
            return int(f.read().split()[1]) * _PAGE_KB
    except (OSError, IndexError, ValueError):
        return None


def shm_blocks(pid: int) -> set[str]:
    """Names of the /dev/shm blocks ``pid`` has mapped."""
    try:
        with open(f"/proc/{pid}/maps") as f:
            return {line.split("/dev/shm/", 1)[1].split()[0] for line in f if "/dev/shm/" in line}
    except OSError:
        return set()


@dataclass(slots=True)
class Sample:
    """Memory at one moment: seconds since the start, the game's RSS and each child's (KiB)."""

    t_s: float
    game_kb: int
    children_kb: dict[int, int] = field(default_factory=dict)

    @property
    def total_kb(self) -> int:
        return self.game_kb + sum(self.children_kb.values())


@dataclass(slots=True)
class SoakResult:
    """What a soak run measured (memory in KiB, times in seconds)."""

    seconds: float
    exit_code: int
    samples: list[Sample]
    warmup_s: float
    processes_seen: dict[int, ProcInfo]
    processes_left: list[ProcInfo]
    blocks_seen: set[str]
    blocks_left: set[str]
    output_tail: str = ""

    @property
    def running(self) -> list[Sample]:
        """The samples of the session proper: from the first one with every process up (the tracker
        and its standby started) to the last one before they were stopped."""
        most = max((len(s.children_kb) for s in self.samples), default=0)
        idx = [i for i, s in enumerate(self.samples) if len(s.children_kb) >= most]
        return self.samples[idx[0]:idx[-1] + 1] if idx else self.samples

    def warm(self) -> Sample:
        """The first running sample ``warmup_s`` after the processes were up (the last if none)."""
        run = self.running
        return next((s for s in run if s.t_s >= run[0].t_s + self.warmup_s), run[-1])

    def slope_mb_per_h(self, which: str = "total") -> float:
        """Least-squares growth of RSS after the warm-up, MB per hour."""
        warm = self.warm()
        pts = [(s.t_s, (s.total_kb if which == "total" else s.game_kb) / 1024) for s in self.running
               if s.t_s >= warm.t_s]
        if len(pts) < 3:
            return float("nan")
        n = len(pts)
        mt = sum(t for t, _ in pts) / n
        mv = sum(v for _, v in pts) / n
        den = sum((t - mt) ** 2 for t, _ in pts)
        return float("nan") if den == 0 else sum((t - mt) * (v - mv) for t, v in pts) / den * 3600.0


def run_soak(seconds: float, *, sample_every_s: float = 10.0, warmup_s: float | None = None,
             play_args: list[str] | None = None, log=print) -> SoakResult:
    """Run ``rehab play --headless`` for ``seconds`` and watch it (see the module docstring)."""
    if warmup_s is None:
        warmup_s = min(120.0, max(10.0, 0.1 * seconds))
    env = dict(os.environ, SDL_VIDEODRIVER="dummy", SDL_AUDIODRIVER="dummy", PYGAME_HIDE_SUPPORT_PROMPT="1")
    with tempfile.TemporaryDirectory(prefix="rehab-soak-") as tmp:
        cmd = [sys.executable, "-m", "game", "play", "--headless", "--seconds", f"{seconds:g}", "--scene", "live",
               "--motion", "shoulder_abduction", "--db", str(Path(tmp) / "soak.db"),
               "--screenshot", str(Path(tmp) / "last.png"), *(play_args or [])]
        out_path = Path(tmp) / "play.log"
        with open(out_path, "w") as out:
            t0 = time.perf_counter()
            proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env)
            try:
                samples, seen, blocks = _watch(proc, t0, sample_every_s, log)
            except BaseException:   # interrupted (Ctrl+C, SIGTERM): the session ends too, as it would on quit
                proc.terminate()
                proc.wait(30)
                raise
            code = proc.wait()
            elapsed = time.perf_counter() - t0
        time.sleep(0.5)   # let the kernel finish reaping what the game killed on its way out
        left = [p for p in seen.values() if (now_p := read_proc(p.pid)) is not None and now_p.start_ticks == p.start_ticks]
        blocks_left = {b for b in blocks if (Path("/dev/shm") / b).exists()}
        tail = "\n".join(out_path.read_text(errors="replace").splitlines()[-15:])
    return SoakResult(elapsed, code, samples, warmup_s, seen, left, blocks, blocks_left, tail)


def _watch(proc: subprocess.Popen, t0: float, sample_every_s: float, log):
    """Sample the memory of ``proc`` and its processes, and the blocks they map, until it ends."""
    samples: list[Sample] = []
    seen: dict[int, ProcInfo] = {}
    blocks: set[str] = set()
    next_at = 0.0
    while proc.poll() is None:
        now = time.perf_counter() - t0
        if now >= next_at:
            kids = descendants(proc.pid)
            game_kb = rss_kb(proc.pid)
            if game_kb is None:
                break
            s = Sample(now, game_kb)
            for k in kids:
                seen.setdefault(k.pid, k)
                kb = rss_kb(k.pid)
                if kb is not None:
                    s.children_kb[k.pid] = kb
                blocks |= shm_blocks(k.pid)
            blocks |= shm_blocks(proc.pid)
            samples.append(s)
            if len(samples) % max(1, int(300 / sample_every_s)) == 1:
                log(f"  {now / 60:5.1f} min: game {s.game_kb / 1024:7.1f} MB, "
                    f"{len(s.children_kb)} child processes {sum(s.children_kb.values()) / 1024:7.1f} MB")
            next_at += sample_every_s
        time.sleep(min(0.5, max(0.01, next_at - (time.perf_counter() - t0))))
    return samples, seen, blocks


def report(r: SoakResult, max_growth_mb: float) -> tuple[list[str], bool]:
    """The lines to print and whether the run passed."""
    if not r.samples:
        return [f"soak: the session ended at once (exit {r.exit_code}):", r.output_tail], False
    run = r.running
    first, warm, last = run[0], r.warm(), run[-1]
    mb = lambda kb: kb / 1024   # noqa: E731
    growth_mb = mb(last.total_kb - warm.total_kb)
    lines = [
        f"soak: {r.seconds / 60:.1f} min of rehab play --headless, {len(r.samples)} samples, exit code {r.exit_code}",
        f"  the tracker and its standby up after {first.t_s:.0f} s; measured from then to {last.t_s / 60:.1f} min",
        f"  RSS game + tracker processes: start {mb(first.total_kb):.1f} MB, after a {r.warmup_s:.0f} s warm-up "
        f"{mb(warm.total_kb):.1f} MB, end {mb(last.total_kb):.1f} MB",
        f"  growth after the warm-up: {growth_mb:+.1f} MB (limit {max_growth_mb:g}); trend "
        f"{r.slope_mb_per_h('total'):+.2f} MB/h (game alone {r.slope_mb_per_h('game'):+.2f} MB/h)",
        f"  game alone: start {mb(first.game_kb):.1f}, warm {mb(warm.game_kb):.1f}, end {mb(last.game_kb):.1f} MB; "
        f"child processes: warm {mb(sum(warm.children_kb.values())):.1f}, end "
        f"{mb(sum(last.children_kb.values())):.1f} MB ({len(last.children_kb)} at the end)",
        f"  max total {max(mb(s.total_kb) for s in run):.1f} MB while running "
        f"({max(mb(s.total_kb) for s in r.samples):.1f} MB with the start-up's compilation)",
        f"  shared memory: {len(r.blocks_seen)} blocks used, {len(r.blocks_left)} left behind"
        + (f" ({', '.join(sorted(r.blocks_left))})" if r.blocks_left else ""),
        f"  processes: {len(r.processes_seen)} started under the game, {len(r.processes_left)} left behind"
        + (f" ({', '.join(f'{p.pid} {p.name}' for p in r.processes_left)})" if r.processes_left else ""),
    ]
    said = [line for line in r.output_tail.splitlines() if line.startswith("rehab play:")]
    if said:   # its frames, frame rate and stalls
        lines.append(f"  the session: {said[-1][len('rehab play: '):]}")
    ok = r.exit_code == 0 and growth_mb < max_growth_mb and not r.blocks_left and not r.processes_left
    if r.exit_code != 0:
        lines.append("  the session failed; its last lines:\n" + r.output_tail)
    lines.append("soak: " + ("passed" if ok else "FAILED"))
    return lines, ok


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="python -m game.soak", description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=number(0.1, 24 * 60.0), default=60.0, help="length of the session")
    parser.add_argument("--sample-every", type=number(0.5, 600.0), default=10.0, metavar="S",
                        help="seconds between memory samples (default: %(default)s)")
    parser.add_argument("--warmup", type=number(0.0, 3600.0), default=None, metavar="S",
                        help="seconds after the processes are up before growth counts (default: 10 %% of the run, "
                        "10-120 s)")
    parser.add_argument("--max-growth-mb", type=number(0.0, 100_000.0), default=10.0,
                        help="RSS growth after the warm-up that fails the run (default: %(default)s)")
    parser.add_argument("play_args", nargs="*", help="more rehab play options after --, e.g. -- --rig ring6")
    args = parser.parse_args(argv)
    if not Path("/proc/self/stat").exists():
        print("soak: needs Linux (/proc)")
        return 2

    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))   # a kill ends the session it runs too
    print(f"soak: {args.minutes:g} min of rehab play --headless ...", flush=True)
    result = run_soak(args.minutes * 60.0, sample_every_s=args.sample_every, warmup_s=args.warmup,
                      play_args=args.play_args, log=lambda line: print(line, flush=True))
    lines, ok = report(result, args.max_growth_mb)
    print("\n".join(lines))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
