"""Behaviour record of the hidden-marker estimators, for changes that must not change them.

Runs every estimator of :data:`tracking.sim.hidden_eval.ESTIMATORS` (with and without the gates
that drop estimates to LOST), at 30 and 15 frames/s, on simulated motions whose occlusions come
from rendering the studio (:func:`tracking.sim.hidden_eval.occlusion_data`), and the recommended
estimator once more with single camera views of its hidden markers (rays from fixed camera
centres to the noisy truth, with per-marker position noise set as the tracker sets it). Every
frame's positions, statuses, estimator used and ``axis_guessed`` are written to one ``.npz``.

    python -m tracking.sim.hidden_regression record before.npz --cache /tmp/occl
    python -m tracking.sim.hidden_regression compare before.npz --cache /tmp/occl

``compare`` runs the same again and reports the largest difference per run (positions to 1e-9 m,
the rest exactly); it exits non-zero where a run differs.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from tracking.hidden import Estimator, estimator_config
from tracking.markerset import MarkerSet, load_markerset
from tracking.sim.hidden_eval import ESTIMATORS, OcclusionData, make_estimator, occlusion_data

log = logging.getLogger(__name__)

#: Motions of the record: the seed's experiment, a capture replay with swinging arms, and scripted
#: motions that hide the elbow and wrist markers.
MOTIONS: tuple[str, ...] = ("right_external_rotation", "qualisys_walk", "elbow_flexion_supination", "reach")

#: Camera centres of the synthetic single views (world metres), around the seated patient.
VIEW_ORIGINS_M = np.array([[2.0, 1.2, 0.5], [-2.0, 1.4, 0.3], [0.3, 1.6, 2.2]])


def _frames(data: OcclusionData, step: int) -> tuple[np.ndarray, np.ndarray]:
    return data.truth_m[::step], data.measured[::step]


def _run(est: Estimator, truth_m: np.ndarray, measured: np.ndarray, *, seed: int,
         views: bool) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    noisy = truth_m + rng.normal(0.0, 0.001, truth_m.shape)
    t_frames, m = measured.shape
    out = {"positions": np.empty((t_frames, m, 3)), "status": np.empty((t_frames, m), np.uint8),
           "used": np.empty((t_frames, m), np.int8), "guessed": np.empty((t_frames, m), bool)}
    for t in range(t_frames):
        ok = measured[t]
        if views:
            est.marker_sigma_m = 0.001 + 0.001 * rng.random(m)
            hidden = np.flatnonzero(~ok & (rng.random(m) < 0.6))
            if hidden.size:
                cams = rng.integers(0, len(VIEW_ORIGINS_M), hidden.size)
                origins = VIEW_ORIGINS_M[cams]
                target = noisy[t, hidden] + rng.normal(0.0, 0.002, (hidden.size, 3))
                d = target - origins
                d /= np.linalg.norm(d, axis=1, keepdims=True)
                est.observe_views(hidden, origins, d, np.full(hidden.size, 0.0015))
        p, st = est.update(np.where(ok[:, None], noisy[t], np.nan), ok)
        out["positions"][t], out["status"][t] = p, st
        out["used"][t], out["guessed"][t] = est.used, est.axis_guessed
    return out


def runs(markerset: MarkerSet, motions: Sequence[str], cache: Path | None) -> Iterator[tuple[str, dict]]:
    """(name, arrays) of every run of the record."""
    for motion in motions:
        data = occlusion_data(motion, fps=30.0, cache_dir=cache)
        for step, fps in ((1, 30.0), (2, 15.0)):
            truth, measured = _frames(data, step)
            for label in ESTIMATORS:
                for gates in (False, True):
                    est = make_estimator(markerset, label, fps, gates=gates)
                    yield (f"{motion}/{fps:g}/{label}/gates={gates}",
                           _run(est, truth, measured, seed=step, views=False))
            est = Estimator(**estimator_config(markerset), fps=fps)
            yield f"{motion}/{fps:g}/recommended/views", _run(est, truth, measured, seed=10 + step, views=True)


def _compare(before: dict[str, np.ndarray], name: str, arrays: dict[str, np.ndarray]) -> bool:
    same = True
    for key, now in arrays.items():
        old = before.get(f"{name}|{key}")
        if old is None or old.shape != now.shape:
            print(f"DIFF {name} {key}: missing or shape changed")
            return False
        if key == "positions":
            if not np.array_equal(np.isnan(old), np.isnan(now)):
                n = int((np.isnan(old) != np.isnan(now)).sum())
                print(f"DIFF {name} positions: NaN pattern differs in {n} values")
                same = False
                continue
            diff = float(np.nanmax(np.abs(old - now))) if np.isfinite(old).any() else 0.0
            if diff > 1e-9:
                print(f"DIFF {name} positions: max {diff:.3g} m")
                same = False
        elif not np.array_equal(old, now):
            print(f"DIFF {name} {key}: {int((old != now).sum())} values differ")
            same = False
    return same


def main(argv: Sequence[str] | None = None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mode", choices=("record", "compare"))
    ap.add_argument("file", type=Path)
    ap.add_argument("--cache", type=Path, default=None, help="folder keeping the rendered visibility")
    ap.add_argument("--motions", nargs="*", default=list(MOTIONS))
    args = ap.parse_args(argv)
    ms = load_markerset()
    t0 = time.perf_counter()
    if args.mode == "record":
        store = {f"{name}|{k}": v for name, arrays in runs(ms, args.motions, args.cache) for k, v in arrays.items()}
        np.savez_compressed(args.file, **store)
        print(f"recorded {len(store) // 4} runs in {time.perf_counter() - t0:.0f} s")
        return
    with np.load(args.file) as f:
        before = dict(f)
    n = bad = 0
    for name, arrays in runs(ms, args.motions, args.cache):
        n += 1
        bad += not _compare(before, name, arrays)
    print(f"{n - bad} of {n} runs identical ({time.perf_counter() - t0:.0f} s)")
    sys.exit(1 if bad or n * 4 != len(before) else 0)


if __name__ == "__main__":
    main()
