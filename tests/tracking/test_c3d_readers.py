"""The project's C3D read by independent readers: the ``c3d`` package (follows the C3D standard
to the byte, refuses inconsistent headers) and ezc3d (what kineticstoolkit and pyomeca read with)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from tracking.io.c3d import C3dEvent, read_c3d_points, write_c3d
from tracking.marker_status import MarkerStatus

c3d = pytest.importorskip("c3d")  # the test extra installs it
ezc3d = pytest.importorskip("ezc3d")

NAMES = ("MB", "MP", "MRS", "MRE1")


def sample(n_frames: int = 30, seed: int = 0):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1500, 1500, size=(n_frames, len(NAMES), 3))
    status = rng.choice([MarkerStatus.MEASURED, MarkerStatus.ESTIMATED, MarkerStatus.LOST], p=[0.7, 0.2, 0.1],
                        size=(n_frames, len(NAMES))).astype(np.uint8)
    p[status == MarkerStatus.LOST] = np.nan
    residuals = rng.uniform(0.0, 3.0, size=status.shape)
    seen = rng.random((n_frames, len(NAMES), 4)) < 0.6
    angles = {"right_elbow_flexion": rng.uniform(0, 140, n_frames), "trunk_forward_lean": rng.uniform(-10, 30, n_frames)}
    angles["right_elbow_flexion"][3] = np.nan
    return p, status, residuals, seen, angles


def read_with_c3d_package(path):
    """(labels, (T, P, 3) positions, (T, P) residuals, (T, P) camera bytes) with the `c3d` package."""
    with open(path, "rb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "No analog data found in file."
        reader = c3d.Reader(fh)
        labels = [s.strip() for s in reader.point_labels]
        frames = [points.copy() for _, points, _ in reader.read_frames()]
        params = {key: reader.get(key) for key in ("POINT:ANGLES", "SUBJECTS:NAMES", "SUBJECTS:MARKER_SETS",
                                                   "EVENT:LABELS", "EVENT:TIMES", "POINT:ANGLE_UNITS")}
        rate, scale = reader.point_rate, reader.point_scale
    data = np.stack(frames)
    return labels, data[:, :, :3], data[:, :, 3], data[:, :, 4], params, rate, scale


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_c3d_package_reads_positions_residuals_masks_angles(tmp_path, seed):
    path = tmp_path / "m.c3d"
    p, status, residuals, seen, angles = sample(seed=seed)
    write_c3d(path, NAMES, p, 29.97, residuals=residuals, status=status, camera_masks=seen, angles_deg=angles,
              subject="P007", markerset="upper_limb_seated",
              events=[C3dEvent("Identified", 0.0), C3dEvent("Identified", 0.5, description="again")])
    labels, q, res, cams, params, rate, scale = read_with_c3d_package(path)
    assert labels == [*NAMES, *angles]
    assert rate == pytest.approx(29.97, abs=1e-4) and scale == pytest.approx(-0.1)

    measured = status == MarkerStatus.MEASURED
    estimated = status == MarkerStatus.ESTIMATED
    lost = status == MarkerStatus.LOST
    m = len(NAMES)
    # positions: exact (float32) where present
    np.testing.assert_allclose(q[:, :m][~lost], p[~lost], rtol=1e-6, atol=1e-3)
    # residual: > 0 measured (0.1 mm steps, at least 0.1), 0 estimated, -1 lost
    np.testing.assert_allclose(res[:, :m][measured], np.maximum(np.round(residuals[measured], 1), 0.1), atol=1e-5)
    assert (res[:, :m][estimated] == 0).all() and (res[:, :m][lost] == -1).all()
    # camera masks: bit k = camera k+1 saw it; none for estimated points
    bits = (seen.astype(int) * (1 << np.arange(4))).sum(axis=2)
    np.testing.assert_array_equal(cams[:, :m][measured], bits[measured])
    assert (cams[:, :m][estimated] == 0).all()
    # joint angles: POINT:ANGLES points, the angle in X, invalid where undefined
    assert [s.strip() for s in params["POINT:ANGLES"].string_array] == list(angles)
    assert params["POINT:ANGLE_UNITS"].string_value.strip() == "deg"
    for k, (name, values) in enumerate(angles.items()):
        defined = np.isfinite(values)
        np.testing.assert_allclose(q[defined, m + k, 0], values[defined], atol=1e-4)
        assert (res[~defined, m + k] == -1).all() and (res[defined, m + k] == 0).all()
    assert [s.strip() for s in params["SUBJECTS:NAMES"].string_array] == ["P007"]
    assert [s.strip() for s in params["SUBJECTS:MARKER_SETS"].string_array] == ["upper_limb_seated"]
    assert [s.strip() for s in params["EVENT:LABELS"].string_array] == ["Identified", "Identified"]
    np.testing.assert_allclose(params["EVENT:TIMES"].float_array, [[0.0, 0.0], [0.0, 0.5]])


def test_ezc3d_reads_the_same_positions_and_which_samples_are_estimated(tmp_path):
    path = tmp_path / "m.c3d"
    p, status, residuals, seen, angles = sample(seed=4)
    write_c3d(path, NAMES, p, 60.0, residuals=residuals, status=status, camera_masks=seen, angles_deg=angles)
    e = ezc3d.c3d(str(path))
    points = np.asarray(e["data"]["points"])[:3].transpose(2, 1, 0)  # (T, P, 3)
    _, q, _, _, _, _, _ = read_with_c3d_package(path)
    lost = status == MarkerStatus.LOST
    m = len(NAMES)
    assert np.isnan(points[:, :m][lost]).all()
    np.testing.assert_array_equal(points[:, :m][~lost], q[:, :m][~lost])  # the same numbers in both readers
    # ezc3d 1.7 decodes the floating-point residual word with its bytes swapped (its issue 386),
    # so its "residual" is the camera byte; an estimated sample still reads 0 and a lost one -1
    res = np.asarray(e["data"]["meta_points"]["residuals"])[0].T
    assert (res[:, :m][status == MarkerStatus.ESTIMATED] == 0).all()
    assert (res[:, :m][lost] < 0).all()
    # and the project's own reader (ezc3d underneath) gives the markers, not the angles
    names, ours, rate = read_c3d_points(path)
    assert names == NAMES and rate == 60.0
    np.testing.assert_allclose(ours[~lost], p[~lost], rtol=1e-6, atol=1e-3)


def test_defaults_every_present_point_measured(tmp_path):
    path = tmp_path / "m.c3d"
    p = np.arange(2 * 4 * 3, dtype=float).reshape(2, 4, 3)
    p[1, 2] = np.nan
    write_c3d(path, NAMES, p, 100.0)
    _, q, res, cams, _, rate, _ = read_with_c3d_package(path)
    assert rate == 100.0
    np.testing.assert_allclose(res, [[0.1, 0.1, 0.1, 0.1], [0.1, 0.1, -1, 0.1]], atol=1e-6)
    np.testing.assert_allclose(q[0], p[0], atol=1e-5)


@pytest.mark.parametrize("reader", ["kineticstoolkit", "pyomeca"])
def test_gait_lab_toolkits_read_the_same_positions(tmp_path, reader):
    """kineticstoolkit and pyomeca (both on ezc3d; not dependencies: skipped where not installed)."""
    path = tmp_path / "m.c3d"
    p, status, residuals, seen, angles = sample(seed=5)
    write_c3d(path, NAMES, p, 30.0, residuals=residuals, status=status, camera_masks=seen, angles_deg=angles)
    lost = status == MarkerStatus.LOST
    if reader == "kineticstoolkit":
        ktk = pytest.importorskip("kineticstoolkit", reason="kineticstoolkit not installed (not a dependency: it "
                                  "brings PyQt5, scikit-learn and pandas, ~340 MB)")
        points = ktk.read_c3d(str(path), convert_point_unit=True)["Points"]
        q = np.stack([points.data[n][:, :3] for n in NAMES], axis=1) * 1000.0  # it converts to metres
        assert set(angles) <= set(points.data)
    else:
        pytest.importorskip("pyomeca", reason="pyomeca not installed (not a dependency: it brings xarray and pandas, "
                                        "~110 MB)")
        from pyomeca import Markers

        markers = Markers.from_c3d(str(path))
        assert markers.attrs["units"] == "mm"
        q = np.asarray(markers.sel(channel=list(NAMES)).values)[:3].transpose(2, 1, 0)
    assert (np.isnan(q).any(axis=2) == lost).all()
    np.testing.assert_allclose(q[~lost], p[~lost], rtol=1e-6, atol=1e-3)


def estimated_from_ranges(ranges: np.ndarray, n_frames: int, n_points: int) -> np.ndarray:
    """(3, R) point, first, last frame (all from 1) -> (T, P) bool."""
    out = np.zeros((n_frames, n_points), dtype=bool)
    for point, first, last in np.asarray(ranges, dtype=int).T.tolist():
        out[first - 1:last, point - 1] = True
    return out


@pytest.mark.parametrize("seed", [6, 7, 8])
def test_estimated_samples_identifiable_in_every_reader(tmp_path, seed):
    """The ESTIMATED group's runs give the estimated samples exactly in ezc3d, the `c3d` package and
    kineticstoolkit (parameters: every reader has them); and with every measured sample naming its
    cameras (as the tracker's do), ezc3d's byte-swapped residual still tells the three kinds apart
    (> 0 measured, 0 estimated, -1 lost), as the `c3d` package's does."""
    path = tmp_path / "m.c3d"
    p, status, residuals, seen, angles = sample(n_frames=600, seed=seed)
    rng = np.random.default_rng(seed)
    pair = np.argsort(rng.random(seen.shape), axis=2)[..., :2]  # two cameras at least for each sample
    np.put_along_axis(seen, pair, True, axis=2)
    write_c3d(path, NAMES, p, 30.0, residuals=residuals, status=status, camera_masks=seen, angles_deg=angles)
    estimated = status == MarkerStatus.ESTIMATED
    m = len(NAMES)
    n_points = m + len(angles)

    e = ezc3d.c3d(str(path))
    group = e["parameters"]["ESTIMATED"]
    assert int(group["USED"]["value"][0]) == sum(np.asarray(group[k]["value"]).shape[1] for k in group
                                                 if k.startswith("RANGES"))
    ranges = np.concatenate([np.asarray(group[k]["value"]) for k in sorted(group) if k.startswith("RANGES")], axis=1)
    np.testing.assert_array_equal(estimated_from_ranges(ranges, 600, n_points)[:, :m], estimated)
    assert not estimated_from_ranges(ranges, 600, n_points)[:, m:].any()  # angles are never "estimated"
    word = np.asarray(e["data"]["meta_points"]["residuals"])[0].T[:, :m]  # (T, M)
    kind = np.select([word > 0, word == 0], [MarkerStatus.MEASURED, MarkerStatus.ESTIMATED], MarkerStatus.LOST)
    np.testing.assert_array_equal(kind, status)

    with open(path, "rb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = c3d.Reader(fh)
        used = reader.get("ESTIMATED:USED").int16_value
        arrays = [reader.get(f"ESTIMATED:{name}").float_array.T for name in ("RANGES", "RANGES2", "RANGES3")
                  if reader.get(f"ESTIMATED:{name}") is not None]
    assert used == sum(a.shape[1] for a in arrays) and len(arrays) >= 2  # more than one parameter's 255 runs
    np.testing.assert_array_equal(estimated_from_ranges(np.concatenate(arrays, axis=1), 600, n_points)[:, :m],
                                  estimated)
    _, _, res, _, _, _, _ = read_with_c3d_package(path)
    kind = np.select([res[:, :m] > 0, res[:, :m] == 0], [MarkerStatus.MEASURED, MarkerStatus.ESTIMATED],
                     MarkerStatus.LOST)
    np.testing.assert_array_equal(kind, status)


def test_kineticstoolkit_shows_the_estimated_runs(tmp_path):
    """kineticstoolkit hands the C3D parameters over (``C3DParameters``), the ESTIMATED group too."""
    ktk = pytest.importorskip("kineticstoolkit", reason="kineticstoolkit not installed (not a dependency: it brings "
                              "PyQt5, scikit-learn and pandas, ~340 MB)")
    path = tmp_path / "m.c3d"
    p, status, residuals, seen, angles = sample(n_frames=600, seed=9)
    write_c3d(path, NAMES, p, 30.0, residuals=residuals, status=status, camera_masks=seen, angles_deg=angles)
    params = ktk.read_c3d(str(path), convert_point_unit=False)["C3DParameters"]["ESTIMATED"]
    ranges = np.concatenate([np.asarray(params[k]) for k in ("RANGES", "RANGES2", "RANGES3") if k in params], axis=1)
    estimated = estimated_from_ranges(ranges, 600, len(NAMES) + len(angles))[:, :len(NAMES)]
    np.testing.assert_array_equal(estimated, status == MarkerStatus.ESTIMATED)


def test_estimated_runs_too_many_for_the_parameters_leave_the_residuals(tmp_path, caplog):
    """More runs than the parameter section holds: no ESTIMATED group, a warning; the residuals
    still say it (0 where estimated)."""
    path = tmp_path / "m.c3d"
    n = 4200
    p = np.zeros((n, len(NAMES), 3))
    status = np.full((n, len(NAMES)), MarkerStatus.MEASURED, dtype=np.uint8)
    status[::2] = MarkerStatus.ESTIMATED  # 2100 runs per marker, 8400 in all
    with caplog.at_level("WARNING", logger="tracking.io.c3d"):
        write_c3d(path, NAMES, p, 30.0, status=status)
    assert "8400 runs of estimated samples do not fit" in caplog.text
    assert "ESTIMATED" not in ezc3d.c3d(str(path))["parameters"]
    _, _, res, _, _, _, _ = read_with_c3d_package(path)
    np.testing.assert_array_equal(res == 0, status == MarkerStatus.ESTIMATED)


def test_no_estimated_samples_is_said_too(tmp_path):
    path = tmp_path / "m.c3d"
    write_c3d(path, NAMES, np.zeros((3, len(NAMES), 3)), 30.0)
    group = ezc3d.c3d(str(path))["parameters"]["ESTIMATED"]
    assert int(group["USED"]["value"][0]) == 0 and "RANGES" not in group


def test_qualisys_file_shows_which_byte_is_the_residual():
    """A real QTM file (content/captures, from ezc3d's test data): by the C3D standard's layout
    (residual in the low byte, camera mask in the high byte) its residuals are 64 distinct
    multiples of |POINT:SCALE| up to ~5 mm, masks none, as QTM writes them; ezc3d 1.7 reads the
    bytes the other way (all residuals 0, the residual bytes as camera masks). The project writes
    the standard's layout."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "content" / "captures" / "ezc3d_qualisys_walk.c3d"
    _, _, res, cams, _, _, scale = read_with_c3d_package(path)
    valid = res >= 0
    assert scale == pytest.approx(-0.0762, abs=1e-4)
    assert len(np.unique(res[valid])) == 64 and 3.0 < res[valid].max() < 6.0 and (cams[valid] == 0).all()
    from importlib.metadata import version

    if tuple(int(v) for v in version("ezc3d").split(".")[:2]) < (1, 7):
        return   # older ezc3d releases decode the fourth word otherwise; the swap checked is 1.7's
    e = ezc3d.c3d(str(path))
    swapped = np.asarray(e["data"]["meta_points"]["residuals"])[0].T
    masks = np.asarray(e["data"]["meta_points"]["camera_masks"]).transpose(2, 1, 0) @ (1 << np.arange(7))
    assert (swapped[valid] == 0).all()
    np.testing.assert_array_equal(masks[valid], np.round(res[valid] / abs(scale)).astype(int) & 0x7F)
