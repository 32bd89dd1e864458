"""The whole foundation pipeline as a user runs it: simulate a recording, track it, compare."""

import csv

import numpy as np

from game.cli import main
from tracking.drivers.evaluate import evaluate_points
from tracking.markerset import load_markerset
from tracking.sim.studio import read_visibility_csv
from tracking.io.csv_tables import read_angles_csv
from tracking.io.trc import read_trc


def test_simulate_then_track_recovers_the_markers(tmp_path):
    rec = tmp_path / "rec"
    assert main(["simulate", str(rec), "--motion", "shoulder_abduction", "--size", "320x240",
                 "--fps", "10", "--seconds", "6"]) == 0
    for name in ("calibration.toml", "cam1.avi", "cam4.avi", "truth.trc", "truth_angles.csv", "meta.yaml"):
        assert (rec / name).is_file(), name
    truth = read_trc(rec / "truth.trc")
    assert truth.names == load_markerset().names and truth.n_frames == 61
    angles = read_angles_csv(rec / "truth_angles.csv")
    assert np.nanmax(angles.angles["right_shoulder_abduction"]) > 60  # the arm really goes up

    assert main(["track", str(rec), "--points", str(tmp_path / "points.csv")]) == 0
    rows = list(csv.DictReader(open(tmp_path / "points.csv")))
    assert set(rows[0]) == {"frame", "time", "x_mm", "y_mm", "z_mm", "n_cameras", "reproj_px"}
    pts = [[] for _ in range(truth.n_frames)]
    for r in rows:
        pts[int(r["frame"])].append([float(r["x_mm"]), float(r["y_mm"]), float(r["z_mm"])])
    pts = [np.array(p).reshape(-1, 3) / 1000 for p in pts]
    vis = read_visibility_csv(rec / "truth_visibility.csv", truth.names)
    acc = evaluate_points(pts, truth.positions_mm / 1000, vis)
    assert acc.completeness > 0.97
    assert acc.rmse_mm < 4.0
    assert acc.ghost_points == 0
