"""Killing the process at any moment never corrupts the database or loses an accepted result.

A child process stores ROM results in a loop and prints each uid once ``add_rom_result`` has
returned; the parent kills it with SIGKILL at random moments (seeded), reopens the file (which
runs ``PRAGMA integrity_check``) and checks that every printed uid is there.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from game.db import Database

ROOT = Path(__file__).resolve().parents[1]

CHILD = """
import sys
from types import SimpleNamespace
from game.db import Database
db = Database(sys.argv[1])
if not db.has_patient("P001"):
    db.add_patient("P001")
print("ready", flush=True)
k = 0
while True:
    s = db.start_session("P001", "rom", "kill-test")
    for _ in range(3):
        k += 1
        r = SimpleNamespace(test="shoulder_flexion", side="right", angle="right_shoulder_flexion", mode="active",
                            position="seated_arm_at_side", standard="jarm", reference_deg=180.0, max_deg=100.0 + k % 50,
                            start_deg=-10.0, range_deg=110.0 + k % 50, started_s=1.0, ended_s=4.0, compensations=(),
                            estimated_markers=())
        print(db.add_rom_result(s, r), flush=True)
    db.end_session(s)
"""


@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs SIGKILL")
def test_sigkill_during_writes_loses_no_committed_result(tmp_path):
    path = tmp_path / "kill.sqlite3"
    rng = random.Random(5)
    committed: set[str] = set()
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for _ in range(6):
        child = subprocess.Popen([sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE, cwd=ROOT, env=env,
                                 text=True)
        assert child.stdout.readline().strip() == "ready"
        time.sleep(rng.uniform(0.05, 0.4))
        child.send_signal(signal.SIGKILL)
        out, _ = child.communicate(timeout=30)
        committed.update(line.strip() for line in out.splitlines() if len(line.strip()) == 32)
        with Database(path) as db:  # integrity check on open
            stored = {r.uid for r in db.rom_results("P001")}
            assert db.conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert committed <= stored, f"lost {len(committed - stored)} committed results"
    assert len(committed) >= 6  # the child did write between the kills
