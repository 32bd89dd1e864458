"""A station that records results in a loop, for the multi-station tests and the soak.

``python tests/pg_station.py DB PATIENT [--count N] [--session UID] [--resend] [--pause S]``
stores ROM and game results (alternating) for PATIENT through :func:`game.db.pending.store_durably`
(so an unreachable server queues them on the station) and prints ``<uid> stored`` or
``<uid> pending`` once each result is accepted (in the database or in its pending file). A
shared ``--session`` makes every station write into the same session; ``--resend`` stores each
record twice (a station that did not hear the server's answer): neither may duplicate anything.
SIGTERM stops it after the result in hand (SIGKILL is the tests' crash).
"""

from __future__ import annotations

import argparse
import logging
import random
import signal
import sys
import time
from pathlib import Path
from types import SimpleNamespace

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from game.db import exercise_record, rom_record  # noqa: E402
from game.db.pending import store_durably  # noqa: E402


def make_record(patient: str, k: int, rng: random.Random, session: str | None):
    if k % 2:
        return exercise_record(patient, "reach", rng.randint(1, 30), rng.uniform(10, 120), rng.uniform(0, 100),
                               source="station")
    top = rng.uniform(90.0, 170.0)
    r = SimpleNamespace(test="shoulder_flexion", side=rng.choice(("right", "left")), mode="active",
                        position="seated_arm_at_side", standard="jarm", reference_deg=180.0, max_deg=top,
                        start_deg=-5.0, range_deg=top + 5.0, started_s=0.0, ended_s=rng.uniform(3, 8),
                        compensations=(), estimated_markers=())
    r.angle = f"{r.side}_shoulder_flexion"
    return rom_record(patient, r, session_uid=session, source="station")


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("db")
    p.add_argument("patient")
    p.add_argument("--count", type=int, default=0, help="results to record (0: until killed)")
    p.add_argument("--session", default=None, help="store every ROM result in this session uid")
    p.add_argument("--resend", action="store_true", help="store every record twice")
    p.add_argument("--pause", type=float, default=0.0, help="seconds between results")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--wait", type=float, default=2.0, help="seconds to wait out a lock before queueing")
    a = p.parse_args()
    logging.basicConfig(level=logging.ERROR)   # the queue's warnings are the test's to count, not to print
    rng = random.Random(a.seed)
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))   # finish the result in hand, then stop
    k = 0
    while (a.count == 0 or k < a.count) and not stop:
        record = make_record(a.patient, k, rng, a.session)
        outcome = store_durably(a.db, record, wait_s=a.wait)
        if a.resend:
            store_durably(a.db, record, wait_s=a.wait)
        print(f"{record.uid} {'stored' if outcome.stored else 'pending'}", flush=True)
        k += 1
        if a.pause:
            time.sleep(a.pause)
    return 0


if __name__ == "__main__":
    sys.exit(main())
