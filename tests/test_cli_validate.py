"""`rehab validate --tracker --seed`: the sensor noise's seed reaches the simulated studio."""

import re

from game.cli import main


def _measured_rmse(capsys, seed):
    assert main(["validate", "--tracker", "--motion", "reference", "--size", "320x240", "--fps", "15",
                 "--seconds", "1", "--seed", str(seed)]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("reference") and "0 swaps" in line
    return float(re.search(r"measured [\d.]+ % \(RMSE ([\d.]+) mm\)", line).group(1))


def test_the_seed_changes_the_noise_and_only_the_noise(capsys):
    first, again, other = (_measured_rmse(capsys, s) for s in (0, 0, 7))
    assert first == again  # the same seed: the same figures
    assert other != first and abs(other - first) < 1.0  # another draw of the same noise
