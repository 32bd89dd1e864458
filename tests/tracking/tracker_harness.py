"""Behaviour harness of the per-frame tracker: a fixed set of tracked runs, every frame's output.

A renovation of ``tracking/tracker.py`` and ``tracking/pipeline/`` must leave every sample the
tracker gives unchanged. This script tracks a fixed set of simulated runs (several motions and rigs
at 320x240, one colour and four colours, free-running cameras with their stamps and rolling
shutters, markers hidden, cameras blacked out so that markers are lost and found again, the hold
of the reference pose before the names, the numpy paths beside the compiled ones, and a recording
folder with its time stamps through ``rehab track``'s driver) and writes every frame's state,
positions, statuses, angles, windows, centroids, suspects, messages and point counts.

    python tests/tracking/tracker_harness.py record [OUT.npz]    # the baseline (default below)
    python tests/tracking/tracker_harness.py compare [BASE.npz]  # identical to 1e-9, or the first difference

The rendered images are cached in ``$REHAB_HARNESS_CACHE`` (default: the system's temporary
folder), so a compare after the first takes the tracking time only (20-30 s on an idle machine;
the first renders the runs, about a minute).
The baseline belongs to the code it was recorded on: record it again on main after a change that
is meant to change the tracker's results (e.g. the blobs' centroids).
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from tracking.markerset import load_markerset
from tracking.drivers.offline import track_frames_of
from tracking.sim.body import BodyDimensions
from tracking.sim.clocks import CameraClocks
from tracking.sim.motions import load_motion
from tracking.sim.population import ONE_COLOUR_RGB
from tracking.sim.rigs import load_rig
from tracking.sim.studio import SimulationSettings, Studio, simulate_recording
from tracking.tracker import Tracker, TrackerParams

BASELINE = Path(__file__).with_name("data") / "tracker_harness_baseline.npz"
SIZE_PX = (320, 240)
TOL = 1e-9


@dataclasses.dataclass(frozen=True)
class Run:
    """One tracked run: what is rendered and how it is tracked."""

    name: str
    motion: str
    rig: str
    fps: float = 30.0
    seconds: float = 2.0
    one_colour: bool = False
    clocks: str | None = None  # "free" (drawn offsets and drift, with stamps) or "rolling" (25 ms readout)
    blackout: tuple[int, int] | None = None  # frames [a, b) whose images are black (all markers lost)
    params: dict = dataclasses.field(default_factory=dict)
    compiled: bool = True
    seed: int = 0


RUNS = (
    Run("seed_experiment_hidden", "right_external_rotation", "ring4", fps=15.0, seconds=6.0),
    Run("abduction_front3", "shoulder_abduction", "front3", seconds=2.0),
    Run("trunk_lean_numpy", "trunk_lean_compensation", "corners4", seconds=1.5, compiled=False),
    Run("reach_one_colour", "reach", "tri3", seconds=2.0, one_colour=True),
    Run("rotation_one_colour", "right_internal_rotation", "ring4", seconds=2.0, one_colour=True),
    Run("supination_free_clocks", "elbow_flexion_supination", "ring4", seconds=1.5, clocks="free", seed=3),
    Run("flexion_rolling", "shoulder_flexion", "wall3", seconds=1.5, clocks="rolling", seed=1),
    Run("blackout_reacquire", "right_internal_rotation", "ring4", seconds=2.0, blackout=(12, 20),
        params={"reidentify_after": 30}),
    Run("blackout_reidentify", "reach", "front4", fps=15.0, seconds=2.5, blackout=(5, 30),
        params={"reidentify_after": 4}, compiled=False),
    Run("hold_then_identify", "reference", "ring4", seconds=1.0, params={"identify_hold_s": 0.2}),
)


def _cache_dir() -> Path:
    d = Path(os.environ.get("REHAB_HARNESS_CACHE", Path(tempfile.gettempdir()) / "rehab-tracker-harness"))
    d.mkdir(parents=True, exist_ok=True)
    return d


def _rig(run: Run):
    cams = load_rig(run.rig, SIZE_PX)
    if run.clocks == "rolling":
        cams = tuple(dataclasses.replace(c, rolling_shutter_s=0.025) for c in cams)
    return cams


def _markerset(run: Run):
    ms = load_markerset()
    return ms.with_colours([ONE_COLOUR_RGB]) if run.one_colour else ms


def _frames(run: Run) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(T, C, H, W, 3) images, (T,) times, (T, C) stamps or None: rendered once, then cached."""
    key = hashlib.sha1(repr((run.motion, run.rig, run.fps, run.seconds, run.one_colour, run.clocks, run.seed,
                             SIZE_PX)).encode()).hexdigest()[:12]
    path = _cache_dir() / f"{run.name}-{key}.npz"
    if path.exists():
        with np.load(path) as z:
            return z["images"], z["times"], (z["stamps"] if "stamps" in z.files else None)
    cams = _rig(run)
    n = len(cams)
    clocks = None
    if run.clocks == "free":
        clocks = CameraClocks.drawn(n, run.seed, drift=0.001)
    elif run.clocks == "rolling":
        clocks = CameraClocks((0.0,) * n, (0.0,) * n, (0.025,) * n)
    dims = BodyDimensions.from_percentile(50.0, "female")
    images, times, stamps = [], [], []
    with Studio(cams, _markerset(run), dims) as studio:
        for sf in studio.play(load_motion(run.motion, dims), run.fps, seconds=run.seconds, noise_sigma=1.5,
                              seed=run.seed, with_visibility=False, clocks=clocks):
            images.append(np.stack(sf.frames.images))
            times.append(sf.frames.time_s)
            stamps.append(sf.stamps_s if sf.stamps_s is not None else np.full(n, np.nan))
    out = {"images": np.stack(images), "times": np.array(times)}
    if run.clocks == "free":
        out["stamps"] = np.stack(stamps)
    np.savez_compressed(path, **out)
    return out["images"], out["times"], out.get("stamps")


def track(run: Run) -> dict[str, np.ndarray]:
    """Every frame's output of the tracker on ``run``, as arrays (prefixed by the run's name)."""
    images, times, stamps = _frames(run)
    tracker = Tracker(_rig(run), _markerset(run), params=TrackerParams(**run.params), fps=run.fps,
                      compiled=run.compiled)
    n_cams = images.shape[1]
    m = tracker.markerset.n_markers
    cols: dict[str, list] = {k: [] for k in ("state", "positions", "status", "windows", "uv", "suspect", "n_points")}
    angles: dict[str, list[float]] = {}
    messages = []
    for k in range(len(times)):
        imgs = list(images[k])
        if run.blackout and run.blackout[0] <= k < run.blackout[1]:
            imgs = [np.zeros_like(i) for i in imgs]
        s = tracker.step(imgs, float(times[k]), None if stamps is None else stamps[k])
        cols["state"].append(int(s.state))
        cols["positions"].append(s.positions_m)
        cols["status"].append(s.status)
        cols["windows"].append(s.windows_px if s.windows_px is not None else np.full((m, n_cams, 3), np.inf))
        cols["uv"].append(s.uv_px if s.uv_px is not None else np.full((m, n_cams, 2), np.inf))
        cols["suspect"].append(s.suspect if s.suspect is not None else np.full(m, 2, np.int8))
        cols["n_points"].append(s.n_points)
        for name in set(angles) | set(s.angles_deg):
            angles.setdefault(name, [np.inf] * k).append(s.angles_deg.get(name, np.inf))
        messages.append(s.message)
    out = {f"{run.name}/{k}": np.asarray(v, dtype=np.float64) for k, v in cols.items()}
    for name, v in angles.items():
        out[f"{run.name}/angle/{name}"] = np.asarray(v, dtype=np.float64)
    out[f"{run.name}/message"] = np.array(messages, dtype=str)
    return out


#: a recording folder written by ``rehab simulate`` with its cameras' time stamps, tracked by the
#: offline driver (``rehab track``'s) through the recording reader
RECORDED = SimulationSettings(motion="right_forearm_supination", size_px=SIZE_PX, fps=15.0, seconds=2.0, seed=5,
                              images=True, camera_offsets=(0.0, 0.3, -0.2, 0.1))


def track_recorded() -> dict[str, np.ndarray]:
    """The recorded run's positions, statuses, angles and centroids (the folder written once, then cached)."""
    key = hashlib.sha1(repr(RECORDED).encode()).hexdigest()[:12]
    folder = _cache_dir() / f"recorded-{key}"
    if not (folder / "meta.yaml").exists():
        simulate_recording(folder, RECORDED)
    rec = track_frames_of(folder)
    out = {"recorded/positions_mm": rec.positions_mm, "recorded/status": rec.status.astype(np.float64),
           "recorded/uv": rec.uv_px, "recorded/frames": rec.frames.astype(np.float64),
           "recorded/timing": np.array([rec.timing], dtype=str)}
    for name, v in rec.angles_deg.items():
        out[f"recorded/angle/{name}"] = np.asarray(v, dtype=np.float64)
    return out


def track_all() -> dict[str, np.ndarray]:
    out = {}
    t0 = time.perf_counter()
    out.update(track_recorded())
    print(f"  recorded folder: {len(out['recorded/frames'])} frame sets, {time.perf_counter() - t0:.1f} s",
          file=sys.stderr)
    for run in RUNS:
        t0 = time.perf_counter()
        res = track(run)
        print(f"  {run.name}: {len(res[f'{run.name}/state'])} frame sets, {time.perf_counter() - t0:.1f} s",
              file=sys.stderr)
        out.update(res)
    return out


def first_difference(base: dict[str, np.ndarray], now: dict[str, np.ndarray], tol: float = TOL) -> str | None:
    """None when ``now`` equals ``base`` (numbers within ``tol``, NaN where NaN, text exactly); else
    a line naming the first run, field and frame set that differs."""
    for key in sorted(set(base) | set(now)):
        if key not in base or key not in now:
            return f"{key}: only in the {'baseline' if key in base else 'new run'}"
        a, b = base[key], now[key]
        if a.shape != b.shape:
            return f"{key}: shape {a.shape} in the baseline, {b.shape} now"
        if a.dtype.kind in "US":
            bad = np.flatnonzero(a != b)
            if bad.size:
                f = int(bad[0])
                return f"{key}: frame set {f}: {a[f]!r} in the baseline, {b[f]!r} now"
            continue
        with np.errstate(invalid="ignore"):  # (inf - inf where both have no value: equal below)
            same = (np.abs(a - b) <= tol) | (np.isnan(a) & np.isnan(b)) | (a == b)
        if not same.all():
            f = int(np.argwhere(~same)[0][0])
            where = np.argwhere(~same[f])
            return (f"{key}: frame set {f}: {int((~same).reshape(len(a), -1).any(axis=1).sum())} frame sets differ; "
                    f"first at {where[0].tolist() if where.size else ''}: {a[f][tuple(where[0])] if where.size else a[f]}"
                    f" in the baseline, {b[f][tuple(where[0])] if where.size else b[f]} now")
    return None


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in ("record", "compare"):
        print(__doc__)
        return 2
    path = Path(argv[1]) if len(argv) > 1 else BASELINE
    t0 = time.perf_counter()
    now = track_all()
    if argv[0] == "record":
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, **now)
        print(f"recorded {len(RUNS) + 1} runs to {path} ({time.perf_counter() - t0:.0f} s)")
        return 0
    with np.load(path) as z:
        base = {k: z[k] for k in z.files}
    diff = first_difference(base, now)
    if diff is None:
        n_sets = sum(len(v) for k, v in now.items() if k.endswith(("/state", "/frames")))
        print(f"identical to {TOL:g}: {len(RUNS) + 1} runs, {n_sets} frame sets ({time.perf_counter() - t0:.0f} s)")
        return 0
    print(f"DIFFERENT: {diff}")
    return 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
