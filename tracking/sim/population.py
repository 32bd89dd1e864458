"""A population of simulated patients for judging the labelling on bodies it was never tuned on.

Each draw (one integer seed) is a patient and a reference pose: body size (stature percentile
5-95, woman or man), every marker moved up to 15 mm along the skin off its landmark, the
reference pose varied within its tolerances (each arm 5-40 degrees from the body, flexed or
extended up to 10 degrees, the upper arm turned from 60 degrees in to 15 degrees out, the elbow
flexed up to 30 degrees, the thumb within 30 degrees of forward; the trunk leaning forward,
sideways and turned up to 15 degrees each; the chair turned up to 20 degrees), one colour for
all markers or the marker set's four, and 0-2 markers seen by fewer than two cameras.

Seeds below :data:`REPORTED_SEEDS_FROM` are for tuning (the tests use them); reported figures
come from seeds from there on only, so that nothing reported was looked at while tuning.

:func:`label_draws` runs the labelling on the markers' points (measurement noise added): the
labelling's own figures (rate, swaps, margins, time) without rendering. The rendered check of
the same draws through the tracker is :func:`tracking.sim.validate.validate_population`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from tracking.markerset import MarkerSet, load_markerset
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose, axis_angle_matrix

#: seeds from here on are reported; below are for tuning
REPORTED_SEEDS_FROM = 100_000
#: colour of all markers in the one-colour scheme (the seed paper's set-up)
ONE_COLOUR_RGB = (255, 214, 0)


@dataclass(frozen=True, slots=True)
class Draw:
    """One patient in one reference pose.

    Attributes:
        seed: the draw's seed.
        dims: the body.
        pose: the reference pose as varied.
        yaw_deg: the chair's turn about the vertical (+: towards the patient's left).
        offsets_m: (M, 3) each marker's placement error (along the skin), world metres.
        one_colour: one colour for all markers (else the marker set's colours).
        unseen: markers seen by fewer than two cameras (no 3D point).
    """

    seed: int
    dims: BodyDimensions
    pose: Pose
    yaw_deg: float
    offsets_m: np.ndarray
    one_colour: bool
    unseen: tuple[int, ...]


def draw(seed: int, markerset: MarkerSet, *, one_colour: bool | None = None, max_unseen: int = 2) -> Draw:
    """The draw of ``seed`` (``one_colour`` None: drawn too, half and half).

    A pose the body cannot take is drawn again (from the same generator): an elbow inside the
    trunk, two balls overlapping, a ball inside the chair seat.
    """
    rng = np.random.default_rng(seed)
    for _ in range(100):
        d = _draw_once(seed, rng, markerset, one_colour, max_unseen)
        if _possible(d, markerset):
            return d
    raise RuntimeError(f"no possible pose in 100 draws of seed {seed}")


def _possible(d: Draw, markerset: MarkerSet) -> bool:
    from tracking.sim.identify_sweep import seat_clash

    body = BodyModel(d.dims, markerset)
    if any(body.trunk_gap_m(d.pose, side) < 0.0 for side in ("right", "left")):
        return False
    if seat_clash(body, d.pose, markerset):
        return False
    p = body.markers_m(d.pose) + d.offsets_m
    gap = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.eye(len(p))
    return bool(gap.min() > 2.0 * markerset.radius_m + 0.005)


def _draw_once(seed: int, rng: np.random.Generator, markerset: MarkerSet, one_colour: bool | None, max_unseen: int
               ) -> Draw:
    sex = "female" if rng.random() < 0.5 else "male"
    dims = BodyDimensions.from_percentile(float(rng.uniform(5, 95)), sex)
    arms = []
    for _ in range(2):
        er = float(rng.uniform(-60, 15))
        sup = float(np.clip(-er + rng.uniform(-30, 30), -85, 85))
        arms.append(ArmPose.clinical(flexion_deg=float(rng.uniform(-10, 10)), abduction_deg=float(rng.uniform(5, 40)),
                                     external_rotation_deg=er, elbow_flexion_deg=float(rng.uniform(0, 30)),
                                     forearm_supination_deg=sup, shoulder_shrug_m=float(rng.uniform(-0.01, 0.02))))
    pose = Pose(trunk_forward_lean_deg=float(rng.uniform(-15, 15)), trunk_lateral_lean_deg=float(rng.uniform(-15, 15)),
                trunk_axial_rotation_deg=float(rng.uniform(-15, 15)), right=arms[0], left=arms[1])
    yaw = float(rng.uniform(-20, 20))
    body = BodyModel(dims, markerset)
    _, normal = body.landmarks_m(pose)
    # a random direction along the skin (perpendicular to the normal), up to 15 mm
    v = rng.normal(size=normal.shape)
    v -= np.sum(v * normal, axis=1, keepdims=True) * normal
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    offsets = v * rng.uniform(0, 0.015, size=(len(v), 1))
    if one_colour is None:
        one_colour = bool(rng.random() < 0.5)
    n_unseen = int(rng.integers(0, max_unseen + 1))
    unseen = tuple(sorted(int(k) for k in rng.choice(markerset.n_markers, n_unseen, replace=False)))
    return Draw(seed, dims, pose, yaw, offsets, one_colour, unseen)


def draw_markerset(d: Draw, markerset: MarkerSet) -> MarkerSet:
    """The marker set with the draw's colours."""
    return markerset.with_colours([ONE_COLOUR_RGB]) if d.one_colour else markerset


def markers_m(d: Draw, markerset: MarkerSet) -> np.ndarray:
    """(M, 3) the draw's marker centres, world metres (placement error and chair turn applied)."""
    p = BodyModel(d.dims, markerset).markers_m(d.pose) + d.offsets_m
    rot = axis_angle_matrix(np.array([0.0, 1.0, 0.0]), math.radians(d.yaw_deg))
    centre = np.array([0.0, p[:, 1].mean(), 0.0])
    return centre + (p - centre) @ rot.T


@dataclass(frozen=True, slots=True)
class LabelResult:
    """The labelling of one draw's points."""

    seed: int
    one_colour: bool
    n_unseen: int
    confident: bool
    wrong: int          # markers given another marker's point, among the confident ones (a swap)
    score: float
    margin: float
    time_s: float
    worst: str


def label_draws(seeds: Iterable[int], *, noise_m: float = 0.0015, one_colour: bool | None = None,
                markerset: MarkerSet | None = None) -> list[LabelResult]:
    """Label each draw's points (shuffled, with ``noise_m`` of measurement noise per axis)."""
    from tracking.labelling import Labeller

    base = markerset or load_markerset()
    out = []
    for seed in seeds:
        d = draw(seed, base, one_colour=one_colour)
        ms = draw_markerset(d, base)
        rng = np.random.default_rng(seed + 7919)
        p = markers_m(d, ms) + rng.normal(scale=noise_m, size=(ms.n_markers, 3))
        seen = np.setdiff1d(np.arange(ms.n_markers), d.unseen)
        order = rng.permutation(seen)
        labeller = Labeller.for_markerset(ms)
        t0 = time.perf_counter()
        lab = labeller.label(p[order], ms.colour_index[order])
        dt = time.perf_counter() - t0
        wrong = 0
        if lab.confident:
            truth = np.full(ms.n_markers, -1)
            truth[order] = np.arange(len(order))
            wrong = int(np.sum((lab.index != truth) & (lab.index >= 0)))
        worst = "" if lab.worst is None else f"{lab.worst[0]} {lab.worst[1]:.3g}"
        out.append(LabelResult(seed, d.one_colour, len(d.unseen), lab.confident, wrong, lab.score, lab.margin, dt,
                               worst))
    return out
