"""Acceptance soak: several stations on one PostgreSQL database for a few minutes, with a server restart.

    python tests/soak_postgres.py [--minutes 4] [--outage 15] [--game-seconds 20]

Starts a throwaway cluster (tests/pg_cluster.py), then concurrently: two headless application
instances (``rehab -v play --headless --game reach --auto``, each a station with its own queue
folder, run again and again, each run storing one game session) and a ``rehab rom-test`` loop (a
third station). Part-way through, the server is stopped for ``--outage`` seconds and started again.
Every result a station accepted (its uid from the output: stored, or kept in the station's queue)
must be in the database exactly once at the end, after each station has opened the database once
more (as it does on its next use, which sends its queue); ``rehab db check`` must pass. Prints the
figures and exits 1 on any loss or duplicate. Not part of the test suite (it takes minutes).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from game.db import Database  # noqa: E402
from game.db.copy import integrity_problems  # noqa: E402
from pg_cluster import TempCluster, why_not  # noqa: E402

REHAB = [sys.executable, "-m", "game.cli"]
_GAME_UID = re.compile(r"stored reach session ([0-9a-f]{32}) for")
_ROM_UID = re.compile(r"(?:stored|kept) result ([0-9a-f]{32})")
_STATION_UID = re.compile(r"^([0-9a-f]{32}) (?:stored|pending)$", re.MULTILINE)
_QUEUED = re.compile(r"kept result [0-9a-f]{32}")


class Station(threading.Thread):
    """Runs one command again and again until ``stop_at``; collects accepted uids and outcomes."""

    def __init__(self, name: str, cmd: list[str], pattern: re.Pattern, stop_at: float, home: Path):
        super().__init__(daemon=True)
        self.name, self.cmd, self.pattern, self.stop_at = name, cmd, pattern, stop_at
        self.env = {**os.environ, "XDG_DATA_HOME": str(home), "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy",
                    "PYTHONPATH": str(ROOT)}
        self.uids: list[str] = []
        self.queued = 0
        self.runs = Counter()
        self.failures: list[str] = []
        self.timeout = None   # seconds: one long process stopped then (SIGTERM), instead of runs again and again

    def run(self) -> None:
        while time.monotonic() < self.stop_at:
            if self.timeout is None:
                r = subprocess.run(self.cmd, capture_output=True, text=True, env=self.env, timeout=600)
            else:
                proc = subprocess.Popen(self.cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                        env=self.env)
                try:
                    proc.wait(self.timeout)
                except subprocess.TimeoutExpired:
                    proc.terminate()   # between two results or during one: its printed ones are what counts
                out, err = proc.communicate()
                r = subprocess.CompletedProcess(self.cmd, 0 if proc.returncode in (0, -15) else proc.returncode,
                                                out, err)
            out = r.stdout + r.stderr
            found = list(dict.fromkeys(self.pattern.findall(out)))   # a run names its result on stdout and stderr
            self.uids += found
            self.queued += len(set(_QUEUED.findall(out))) + r.stdout.count(" pending\n")
            self.runs["ok" if r.returncode == 0 else f"exit {r.returncode}"] += 1
            if r.returncode != 0:
                self.failures.append(out.strip().splitlines()[-1] if out.strip() else "(no output)")
                time.sleep(3.0)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=4.0)
    p.add_argument("--outage", type=float, default=15.0, help="seconds the server is down")
    p.add_argument("--game-seconds", type=float, default=20.0, help="length of each application run")
    p.add_argument("--fast-pause", type=float, default=0.2, help="seconds between the fast station's results")
    a = p.parse_args()
    reason = why_not()
    if reason:
        print(f"soak skipped: {reason}")
        return 2
    work = Path(tempfile.mkdtemp(prefix="rehab-soak-"))
    cluster = TempCluster()
    try:
        url = cluster.create_db("clinic")
        with Database(url) as db:
            for pid in ("APP1", "APP2", "ROM1"):
                db.add_patient(pid)
        t0 = time.monotonic()
        stop_at = t0 + a.minutes * 60.0
        stations = [
            Station(f"app{i}", [*REHAB, "-v", "play", "--headless", "--mute", "--db", url, "--game", "reach", "--auto",
                                "--patient", f"APP{i}", "--seconds", str(a.game_seconds)], _GAME_UID, stop_at,
                    work / f"station-app{i}")
            for i in (1, 2)
        ]
        stations.append(Station("rom", [*REHAB, "rom-test", "--db", url, "--patient", "ROM1", "--test",
                                        "shoulder_flexion", "--side", "right"], _ROM_UID, stop_at, work / "station-rom"))
        # a fourth station writing fast into the same patient as the ROM loop, one process throughout
        fast = Station("fast", [sys.executable, str(ROOT / "tests" / "pg_station.py"), url, "ROM1", "--pause",
                                str(a.fast_pause), "--wait", "1", "--seed", "1"], _STATION_UID, stop_at,
                       work / "station-fast")
        fast.timeout = a.minutes * 60.0
        stations.append(fast)
        for s in stations:
            s.start()
        time.sleep(a.minutes * 60.0 * 0.4)
        down_at = time.monotonic() - t0
        cluster.stop()
        time.sleep(a.outage)
        cluster.start()
        up_at = time.monotonic() - t0
        for s in stations:
            s.join()
        wall = time.monotonic() - t0
        # each station's next use sends what it queued
        for s in stations:
            env_home = s.env["XDG_DATA_HOME"]
            os.environ["XDG_DATA_HOME"] = env_home
            with Database(url):
                pass
        with Database(url) as db:
            problems = integrity_problems(db)
            stored = {pid: [r.uid for r in db.exercise_results(pid)] for pid in ("APP1", "APP2")}
            stored["ROM1"] = [r.uid for r in db.rom_results("ROM1")] + [r.uid for r in db.exercise_results("ROM1")]
        check = subprocess.run([*REHAB, "db", "check", "--db", url], capture_output=True, text=True)
        ok = True
        print(f"soak: {wall:.0f} s, server down from {down_at:.0f} s to {up_at:.0f} s")
        print("| station | runs | accepted | queued while down | in database | missing | extra | duplicates |")
        print("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        rom_loop = set(stations[2].uids)
        for s, pid in zip(stations, ("APP1", "APP2", "ROM1", "ROM1")):
            have = stored[pid]
            if pid == "ROM1":   # two stations write this patient: each is checked against its own results
                theirs = rom_loop if s.name == "rom" else set(stations[3].uids)
                have = [u for u in have if u in theirs] + [u for u in have if u not in rom_loop | set(stations[3].uids)
                                                            and s.name == "rom"]
            missing = len(set(s.uids) - set(have))
            extra = len(set(have) - set(s.uids))
            dup = len(have) - len(set(have))
            ok &= missing == 0 and extra == 0 and dup == 0 and len(s.uids) == len(set(s.uids))
            runs = ", ".join(f"{n} {k}" for k, n in sorted(s.runs.items()))
            print(f"| {s.name} | {runs} | {len(s.uids)} | {s.queued} | {len(have)} | {missing} | {extra} | {dup} |")
            for f in s.failures[:3]:
                print(f"  {s.name} failed run: {f}")
        print(f"integrity: {'pass' if not problems else '; '.join(problems)}; rehab db check: "
              f"{check.stdout.strip() or check.stderr.strip()}")
        ok &= not problems and check.returncode == 0
        print("RESULT:", "every accepted result present exactly once" if ok else "FAILED")
        return 0 if ok else 1
    finally:
        cluster.close()


if __name__ == "__main__":
    sys.exit(main())
