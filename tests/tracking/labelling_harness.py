"""Behaviour harness of the labelling: the rules' naming and the body-model fit on fixed draws.

A renovation of ``tracking/labelling/`` must leave every naming unchanged. This script labels the
points of a fixed population of simulated patients (:mod:`tracking.sim.population`: bodies, poses,
one colour and four, markers without a point, some seen by one camera) three ways: the rules with
every marker (:meth:`Identifier.identify`), the rules with markers unseen and on single-camera
rays (:meth:`Identifier.identify_with_unseen`), and the body-model fit (:class:`Labeller`), and
writes each result's names, margins, yaw and message.

    python tests/tracking/labelling_harness.py record [OUT.npz]    # the baseline (default below)
    python tests/tracking/labelling_harness.py compare [BASE.npz]  # identical to 1e-9, or the differences

60 draws take about a minute on an idle machine.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from calibration.errors import RehabError
from tracking.labelling import Labeller
from tracking.labelling.rules import Identifier
from tracking.markerset import load_markerset
from tracking.sim.population import draw, draw_markerset, markers_m, single_camera_rays

BASELINE = Path(__file__).parent / "data" / "labelling_harness_baseline.npz"
SEEDS = range(60)
NOISE_M = 0.0015


def _naming(prefix: str, call) -> dict[str, np.ndarray]:
    """The result of one naming as arrays: names, margins and yaw, or the error's message."""
    try:
        result = call()
    except RehabError as err:
        return {f"{prefix}/message": np.array(str(err))}
    if result is None:
        return {f"{prefix}/none": np.array(True)}
    out = {}
    for name in ("index", "margin_m", "rule_margins_m", "yaw_deg", "score", "margin", "confident", "ambiguous"):
        if getattr(result, name, None) is not None:
            out[f"{prefix}/{name}"] = np.asarray(getattr(result, name))
    if getattr(result, "worst", None) is not None:
        out[f"{prefix}/worst"] = np.array(repr(result.worst))
    return out


def run() -> dict[str, np.ndarray]:
    """Every draw's namings, keyed ``seed/way/field``."""
    base = load_markerset()
    out: dict[str, np.ndarray] = {}
    for seed in SEEDS:
        d = draw(seed, base)
        ms = draw_markerset(d, base)
        rng = np.random.default_rng(seed + 7919)
        p = markers_m(d, ms) + rng.normal(scale=NOISE_M, size=(ms.n_markers, 3))
        seen = np.setdiff1d(np.arange(ms.n_markers), d.unseen)
        order = rng.permutation(seen)
        unseen = list(d.unseen)
        rays = single_camera_rays(p[unseen], ms.colour_index[unseen], rng) if unseen else None
        identifier, labeller = Identifier(ms), Labeller.for_markerset(ms)
        every = rng.permutation(ms.n_markers)
        out.update(_naming(f"{seed}/all", lambda: identifier.identify(p[every], ms.colour_index[every])))
        pts, col = p[order], ms.colour_index[order]
        out.update(_naming(f"{seed}/unseen", lambda: identifier.identify_with_unseen(pts, col)))
        if rays is not None:
            out.update(_naming(f"{seed}/rays", lambda: identifier.identify_with_unseen(pts, col, rays)))
        out.update(_naming(f"{seed}/fit", lambda: labeller.label(pts, col, rays)))
    return out


def compare(base: dict[str, np.ndarray], now: dict[str, np.ndarray]) -> list[str]:
    """The keys that differ (missing, added, or values beyond 1e-9)."""
    diffs = [f"missing {k}" for k in sorted(set(base) - set(now))] + [f"added {k}" for k in sorted(set(now) - set(base))]
    for k in sorted(set(base) & set(now)):
        a, b = base[k], now[k]
        if a.dtype.kind in "fc":
            same = a.shape == b.shape and np.allclose(a, b, rtol=0.0, atol=1e-9, equal_nan=True)
        else:
            same = a.shape == b.shape and bool(np.all(a == b))
        if not same:
            diffs.append(f"{k}: {a!r} -> {b!r}")
    return diffs


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in ("record", "compare"):
        print(__doc__)
        return 2
    path = Path(argv[1]) if len(argv) > 1 else BASELINE
    t0 = time.perf_counter()
    now = run()
    print(f"labelled {len(SEEDS)} draws in {time.perf_counter() - t0:.1f} s ({len(now)} values)")
    if argv[0] == "record":
        np.savez_compressed(path, **now)
        print(f"recorded {path}")
        return 0
    with np.load(path) as f:
        base = {k: f[k] for k in f.files}
    diffs = compare(base, now)
    for line in diffs[:20]:
        print(line)
    print("identical" if not diffs else f"{len(diffs)} differences")
    return 0 if not diffs else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
