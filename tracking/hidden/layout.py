"""Which markers the hidden-marker estimators relate: hinges, forearms, arms, rigid groups, pairs.

Built once from the marker indices (:func:`~tracking.hidden.estimator_config` gives them from the
marker set) and checked there; the per-frame code reads only these index arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np


@dataclass(frozen=True, slots=True)
class Hinge:
    """An elbow hinge for estimating ``marker`` (indices into the marker set).

    Attributes:
        marker: the epicondyle marker to estimate.
        partner: the other epicondyle marker of that elbow (the axis runs partner -> marker).
        shoulder: the acromion marker of that arm (the shoulder pivot is learned relative to it).
        wrists: the two styloid markers of that forearm (their midpoint gives the forearm's axis).
    """

    marker: int
    partner: int
    shoulder: int
    wrists: tuple[int, int]


@dataclass(frozen=True, slots=True)
class Forearm:
    """A forearm for estimating the styloid marker ``marker`` when its rigid fit does not hold.

    Attributes:
        marker: the styloid marker to estimate.
        partner: the other styloid marker of that wrist.
        elbow: the two epicondyle markers of that arm (the flexion axis).
    """

    marker: int
    partner: int
    elbow: tuple[int, int]


def weight_matrix(weights: np.ndarray | Mapping[int, Mapping[int, float]], m: int) -> np.ndarray:
    """(M, M) equation 6 weights from an array or ``{m: {i: S}}``, checked, diagonal zeroed."""
    if isinstance(weights, Mapping):
        w = np.zeros((m, m))
        for i, row in weights.items():
            for j, v in row.items():
                w[i, j] = v
    else:
        w = np.array(weights, dtype=np.float64)
    if w.shape != (m, m) or np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError(f"weights must be a non-negative ({m}, {m}) array, got shape {w.shape}")
    np.fill_diagonal(w, 0.0)
    return w


class Layout:
    """The index structure of one marker set's estimation (read-only after construction).

    Attributes:
        n_markers: M.
        segments: rigid groups (index arrays); ``segments_of[i]``: the groups holding marker i.
        hinges, forearms: marker -> its :class:`Hinge` / :class:`Forearm`.
        h_idx: (H, 5) per hinge: marker, partner, shoulder, wrist a, wrist b; ``h_row``: marker ->
            row; ``shoulder_slot``: shoulder marker -> slot; ``h_shoulder_slot``: (H,) slots.
        f_idx: (F, 4) per forearm: marker, partner, elbow a, elbow b; ``f_row``: marker -> row.
        arms: (styloid a, styloid b, epicondyle a, epicondyle b, shoulder) of each arm whose
            flexion and supination are tracked (a forearm whose elbow has hinges);
            ``arm_of``: styloid -> (arm, slot); ``arm_of_elbow``: epicondyle -> arm.
        chain: (A, 4) each arm's epicondyle and styloid markers.
        pairs: (P, 2) near-rigid pairs checked for drift.
        trunk: (4,) upper, lower, left, right trunk markers, or None.
        partners: (M, M) bool, same body segment; ``has_partner``: (M,).
    """

    def __init__(self, m: int, segments: Sequence[Sequence[int]], hinges: Sequence[Hinge],
                 forearms: Sequence[Forearm], length_pairs: Sequence[tuple[int, int]],
                 trunk: tuple[int, int, int, int] | None, body_segments: Sequence[str] | None) -> None:
        self.n_markers = m
        self.segments = tuple(np.array(g, dtype=np.intp) for g in segments)
        for g in self.segments:
            if len(g) < 2 or g.min() < 0 or g.max() >= m or len(set(g.tolist())) != len(g):
                raise ValueError(f"segment {g.tolist()} must list at least 2 distinct marker indices 0..{m - 1}")
        self.segments_of = [[k for k, g in enumerate(self.segments) if i in g] for i in range(m)]
        self.hinges = {h.marker: h for h in hinges}
        self.forearms = {f.marker: f for f in forearms}
        self.f_idx = np.array([[f.marker, f.partner, *f.elbow] for f in forearms], dtype=np.intp).reshape(-1, 4)
        self.f_row = {f.marker: r for r, f in enumerate(forearms)}
        self.h_idx = np.array([[h.marker, h.partner, h.shoulder, *h.wrists] for h in hinges],
                              dtype=np.intp).reshape(-1, 5)
        self.h_row = {h.marker: r for r, h in enumerate(hinges)}
        self.shoulder_slot = {sh: i for i, sh in enumerate(sorted({h.shoulder for h in hinges}))}
        self.h_shoulder_slot = np.array([self.shoulder_slot[h.shoulder] for h in hinges], dtype=np.intp)
        self._build_arms(hinges, forearms)
        pairs = np.array(length_pairs, dtype=np.intp).reshape(-1, 2)
        pair_mask = np.zeros((m, m), dtype=bool)
        pair_mask[pairs[:, 0], pairs[:, 1]] = True
        pair_mask[pairs[:, 1], pairs[:, 0]] = True
        self.pairs = np.argwhere(np.triu(pair_mask))
        self.trunk = None if trunk is None else np.array(trunk, dtype=np.intp)
        if body_segments is None:
            self.partners = np.zeros((m, m), dtype=bool)
        else:
            labels = np.asarray(body_segments)
            if labels.shape != (m,):
                raise ValueError(f"body_segments must name one segment per marker ({m}), got {labels.shape}")
            self.partners = (labels[:, None] == labels[None, :]) & ~np.eye(m, dtype=bool)
        self.has_partner = self.partners.any(axis=1)

    def _build_arms(self, hinges: Sequence[Hinge], forearms: Sequence[Forearm]) -> None:
        # forearms as arms: flexion and supination are tracked per arm when the arm's shoulder is
        # known from a hinge
        shoulder_of = {m_: h.shoulder for h in hinges for m_ in (h.marker, h.partner)}
        self.arms: list[tuple[int, int, int, int, int]] = []
        self.arm_of: dict[int, tuple[int, int]] = {}
        for f in forearms:
            wa, wb = sorted((f.marker, f.partner))
            ea, eb = f.elbow
            sh = shoulder_of.get(ea, -1)
            if sh < 0 or shoulder_of.get(eb) != sh:
                continue
            arm = (wa, wb, ea, eb, sh)
            if arm not in self.arms:
                self.arms.append(arm)
            self.arm_of[f.marker] = (self.arms.index(arm), 0 if f.marker == wa else 1)
        self.arm_of_elbow = {e: r for r, (_, _, ea, eb, _) in enumerate(self.arms) for e in (ea, eb)}
        # each arm's chain (epicondyle and styloid markers): too few of them measured, the hinge
        # and the forearm have nothing to turn about, and the chain's markers keep their velocity
        self.chain = np.array([[ea, eb, wa, wb] for wa, wb, ea, eb, _ in self.arms], dtype=np.intp).reshape(-1, 4)
