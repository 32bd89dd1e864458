"""Tracking accuracy with free-running cameras and rolling shutters against synchronized global
shutters (docs/TRACKING.md, "Cameras on their own clocks"): the same motion rendered with the
cameras in step and on their own clocks, tracked with and without the images' instants, and
(``--auto FOLDER``) with the clocks estimated from the motion (``rehab track --sync auto``)."""

from __future__ import annotations

import argparse
import dataclasses
import json
import shutil
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from tracking.drivers.offline import estimated_skews, track_frames_of
from tracking.io.recording import read_timestamps
from tracking.io.trc import read_trc
from tracking.sim.clocks import CameraClocks
from tracking.sim.studio import SimulationSettings, simulate_recording, studio_from_settings
from tracking.marker_status import MarkerStatus
from tracking.tracker import Tracker


def measured_rmse_mm(cameras, markerset, frames, fps: float, *, stamps: bool) -> tuple[float, float, int]:
    """Track rendered frame sets (list of (images, time, stamps or None, truth)); (RMSE mm, share
    measured, count) of the measured markers."""
    tracker = Tracker(cameras, markerset, fps=fps)
    err, n_meas, n_all = [], 0, 0
    for images, t, st, truth in frames:
        s = tracker.step(images, t, st if stamps else None)
        meas = s.status == MarkerStatus.MEASURED
        n_meas += int(meas.sum())
        n_all += meas.size
        err.append(np.linalg.norm(s.positions_m[meas] - truth[meas], axis=1))
    e = np.concatenate(err) * 1000.0
    return float(np.sqrt(np.mean(e**2))) if e.size else float("nan"), n_meas / max(n_all, 1), int(e.size)


def render(settings: SimulationSettings, clocks: CameraClocks | None):
    studio, motion = studio_from_settings(settings)
    with studio:
        frames = [(sf.frames.images, sf.frames.time_s, sf.stamps_s, sf.markers_m)
                  for sf in studio.play(motion, settings.fps, seconds=settings.seconds, noise_sigma=settings.noise_sigma,
                                        seed=settings.seed, with_visibility=False, clocks=clocks)]
        return studio.cameras, studio.markerset, frames


def evaluate(motion: str, seed: int, *, size=(640, 480), seconds: float = 8.0, fps: float = 30.0,
             drift: float = 0.001, readout_s: float = 0.025) -> dict:
    """One motion and seed: measured-marker RMSE of synchronized global shutters, free-running
    cameras (offsets drawn in +-0.5 frame, rate differences in +-``drift``) with and without their
    stamps, and synchronized rolling shutters with and without the readout in the calibration."""
    base = SimulationSettings(motion=motion, size_px=tuple(size), fps=fps, seconds=seconds, seed=seed)
    cams, ms, sync = render(base, None)
    n = len(cams)
    out = {"motion": motion, "seed": seed}
    out["sync"] = measured_rmse_mm(cams, ms, sync, fps, stamps=False)
    free = CameraClocks.drawn(n, seed, drift=drift)
    out["offsets_frames"] = list(free.offsets_frames)
    _, _, frames = render(base, free)
    out["free_none"] = measured_rmse_mm(cams, ms, frames, fps, stamps=False)
    out["free_stamps"] = measured_rmse_mm(cams, ms, frames, fps, stamps=True)
    rolling = CameraClocks((0.0,) * n, (0.0,) * n, (readout_s,) * n)
    _, _, frames = render(base, rolling)
    rs_cams = [dataclasses.replace(c, rolling_shutter_s=readout_s) for c in cams]
    out["rolling_off"] = measured_rmse_mm(cams, ms, frames, fps, stamps=False)
    out["rolling_on"] = measured_rmse_mm(rs_cams, ms, frames, fps, stamps=True)
    return out


def evaluate_auto(motion: str, seed: int, folder: Path, *, size=(320, 240), seconds: float = 8.0,
                  fps: float = 30.0, drift: float = 0.001, keep: bool = False) -> dict:
    """``--sync auto`` on a recording without time stamps: the first camera at offset 0, the others'
    drawn in +-0.5 frame period (from ``seed``), every camera's drift in +-``drift``; measured-marker
    RMSE with the estimate, with the stamps, as synchronized, and of the synchronized recording;
    the recovered skews' errors against the first camera (modulo the period). Writes the
    recordings into ``folder`` and removes them (``keep``: keeps them, and uses those already
    there: the same motion, seed and size rendered once for several runs)."""

    def rmse(run, truth_mm):
        meas = run.status == MarkerStatus.MEASURED
        e = np.linalg.norm(run.positions_mm - truth_mm[: len(run.positions_mm)], axis=-1)[meas]
        return float(np.sqrt(np.mean(e**2)))

    rng = np.random.default_rng([seed, 99])
    offsets = (0.0, *(round(float(v), 3) for v in rng.uniform(-0.5, 0.5, 3)))
    base = SimulationSettings(motion=motion, size_px=tuple(size), fps=fps, seconds=seconds, seed=seed, images=True)
    tag = f"{motion}_{seed}_{size[0]}x{size[1]}_{seconds:g}s"
    sync_dir, free_dir = folder / f"{tag}_sync", folder / f"{tag}_free"
    stamps_file = free_dir / "timestamps.truth.csv"  # (the stamps, kept aside while --sync auto runs)
    try:
        if not (sync_dir / "meta.yaml").exists():
            simulate_recording(sync_dir, base)
        if not stamps_file.exists():
            simulate_recording(free_dir, dataclasses.replace(base, camera_offsets=offsets, clock_drift=drift))
            shutil.copy(free_dir / "timestamps.csv", stamps_file)
        shutil.copy(stamps_file, free_dir / "timestamps.csv")
        names = [f"cam{k + 1}" for k in range(4)]
        _, stamps = read_timestamps(free_dir, names)
        studio, mo = studio_from_settings(base)
        with studio:  # the truth at the first camera's instants (the frame sets' instants of --sync auto)
            truth_first = np.stack([studio.body.markers_m(mo.pose_at(float(t))) for t in stamps[:, 0]]) * 1000.0
        out = {"motion": motion, "seed": seed, "offsets_frames": list(offsets)}
        out["sync"] = rmse(track_frames_of(sync_dir, sync="none"), read_trc(sync_dir / "truth.trc").positions_mm)
        out["stamps"] = rmse(track_frames_of(free_dir, sync="stamps"), read_trc(free_dir / "truth.trc").positions_mm)
        (free_dir / "timestamps.csv").unlink()
        skews, out["line"] = estimated_skews(free_dir, len(stamps), fps)
        true_rel = stamps - stamps[:, :1]
        d = np.abs((np.zeros_like(true_rel) if skews is None else skews) - true_rel)
        d = np.minimum(d, 1.0 / fps - d)[:, 1:] * 1000.0
        out["skew_error_ms"] = [float(np.median(d)), float(np.percentile(d, 95))]
        out["skew_error_median_ms_per_camera"] = [round(float(v), 2) for v in np.median(d, axis=0)]
        out["auto"] = rmse(track_frames_of(free_dir), truth_first)
        out["none"] = rmse(track_frames_of(free_dir, sync="none"), truth_first)
        return out
    finally:
        if not keep:
            shutil.rmtree(sync_dir, ignore_errors=True)
            shutil.rmtree(free_dir, ignore_errors=True)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--motions", default="right_external_rotation,vicon_upper_limb")
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--size", default="640x480")
    p.add_argument("--seconds", type=float, default=8.0)
    p.add_argument("--auto", type=Path, default=None, metavar="FOLDER",
                   help="evaluate --sync auto instead (recordings written to FOLDER and removed)")
    p.add_argument("--keep", action="store_true", help="with --auto: keep the recordings in FOLDER and use those "
                   "already there")
    args = p.parse_args(argv)
    size = tuple(int(v) for v in args.size.split("x"))
    for motion in args.motions.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            t0 = time.perf_counter()
            if args.auto is not None:
                args.auto.mkdir(parents=True, exist_ok=True)
                r = evaluate_auto(motion, seed, args.auto, size=size, seconds=args.seconds, keep=args.keep)
            else:
                r = evaluate(motion, seed, size=size, seconds=args.seconds)
            r["seconds"] = round(time.perf_counter() - t0, 1)
            print(json.dumps(r), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
