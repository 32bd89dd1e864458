"""ROM tests on the simulated patient through the real pipeline (renderer -> tracker -> session).

Kept few and small (15 frames/s, 320x240); ``rehab rom-accuracy`` runs every test (docs/ROM.md).
"""

from __future__ import annotations

import pytest

from game.rom.simulated import run_simulated_test
from game.rom.spec import load_rom_test


def test_external_rotation_maximum_is_within_3_degrees_of_the_truth():
    run = run_simulated_test(load_rom_test("shoulder_external_rotation"), "right", "jarm", fps=15.0)
    (attempt,) = run.attempts
    assert attempt.accepted and not attempt.result.compensated
    assert attempt.true_max_deg == pytest.approx(65.3, abs=0.5)  # the motion's 65 degrees, from the true markers
    assert abs(attempt.error_deg) <= 3.0
    assert attempt.result.rounded_deg == 65 and attempt.result.reference_deg == 60
    # the run stops once the test is done, well before the end of the 12.5 s motion
    assert run.motion_s < 10.0


def test_trunk_lean_compensation_is_flagged_and_the_clean_repetition_is_not():
    # the motion repeats shoulder flexion: clean, then leaning back and hiking the shoulder; the
    # therapist discards both so that the session measures the second repetition too
    run = run_simulated_test(load_rom_test("shoulder_flexion"), "right", "jarm", motion="trunk_lean_compensation",
                             fps=15.0, max_attempts=2, decide=lambda r: False)
    clean, leaning = run.attempts
    assert clean.result.compensations == () and abs(clean.error_deg) <= 3.0
    assert any("trunk leaned" in c for c in leaning.result.compensations)
    assert any("shoulder hiked" in c for c in leaning.result.compensations)
    assert not clean.accepted and not leaning.accepted
