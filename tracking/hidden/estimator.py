"""The per-frame hidden-marker estimator: statuses, the estimators' order and the gates.

Measured markers pass through and teach the shared state (segment shapes, lengths, the shoulder
pivots, the forearms' angles); hidden markers with a position in the previous frame are estimated
by their marker set's estimator (:mod:`tracking.hidden.registry`), hinges first; estimates that
leave what the body allows are dropped to LOST. docs/HIDDEN_MARKERS.md gives the rules.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Mapping, Sequence

import numpy as np

from tracking.hidden import methods as _builtin  # noqa: F401  (registers the built-in estimators)
from tracking.hidden import registry
from tracking.hidden.arms import ArmTracker
from tracking.hidden.codes import DROP, Method
from tracking.hidden.coasting import coasting
from tracking.hidden.drift import PairRanges
from tracking.hidden.elbows import ElbowState
from tracking.hidden.frame import FrameInputs, SharedState
from tracking.hidden.history import ReferenceHistory
from tracking.hidden.layout import Forearm, Hinge, Layout, weight_matrix
from tracking.hidden.methods.neighbours import neighbour_motion
from tracking.hidden.params import EstimatorParams
from tracking.hidden.pivots import ShoulderPivots
from tracking.hidden.views import ViewRays
from tracking.marker_status import MarkerStatus


class Estimator:
    """Per-frame hidden-marker estimation with the state it needs.

    Args:
        methods: (M,) the estimator of each marker (a registered name, or its code).
        weights: (M, M) equation 6 weights ``S[m, i]`` (row m: the neighbours of marker m), or a
            mapping ``{m: {i: S}}``.
        segments: groups of marker indices treated as rigid; a marker tries the groups that
            contain it in the order given.
        hinges, forearms: the elbow hinges and forearms (:mod:`tracking.hidden.layout`).
        length_pairs: (i, j) marker pairs of near-constant distance, checked for drift.
        trunk: (upper, lower, left, right) marker indices of the trunk frame (None: the world's).
        body_segments: (M,) the body segment of each marker: an estimate whose segment has no
            measured marker for longer than ``max_unsupported_s`` is dropped (None: no check).
        params: the tuning (:class:`~tracking.hidden.params.EstimatorParams`); ``tuning``
            keywords replace single fields of it (``fps=15``).

    After each :meth:`update`: ``used`` (M,) the code of the estimator of each estimate (-1:
    none), ``axis_guessed`` (M,) the estimates whose direction to their pair (the elbow axis,
    the wrist axis), which forearm supination reads, no measurement of this frame pins.
    """

    def __init__(self, methods: Sequence[Method | str | int],
                 weights: np.ndarray | Mapping[int, Mapping[int, float]], segments: Sequence[Sequence[int]] = (),
                 hinges: Sequence[Hinge] = (), forearms: Sequence[Forearm] = (),
                 length_pairs: Sequence[tuple[int, int]] = (), trunk: tuple[int, int, int, int] | None = None,
                 body_segments: Sequence[str] | None = None, *, params: EstimatorParams | None = None,
                 **tuning) -> None:
        prm = dataclasses.replace(params or EstimatorParams(), **tuning)
        m = len(methods)
        fps = float(prm.fps)
        self.n_markers, self.params, self.fps = m, prm, fps
        chosen = [registry.resolve(x) for x in methods]
        self.methods = np.array([x.code for x in chosen], dtype=np.int8)
        self.method_names = tuple(x.name for x in chosen)
        self.weights = weight_matrix(weights, m)
        self.layout = layout = Layout(m, segments, hinges, forearms, length_pairs, trunk, body_segments)
        for i, method in enumerate(chosen):
            method.check(i, layout)
        self._chains = [registry.chain(x) for x in chosen]
        # estimation order: elbows first (the wrists' fits may lean on them), then by rank
        self._rank = np.where(np.isin(np.arange(m), list(layout.hinges)), 10, 0) + np.array(
            [x.rank for x in chosen], dtype=np.int8)
        self.max_unsupported_frames = (math.ceil(prm.max_unsupported_s * fps) if np.isfinite(prm.max_unsupported_s)
                                       else np.inf)
        max_s = np.broadcast_to(np.asarray(prm.max_hidden_s, dtype=np.float64), (m,))
        self.max_hidden_frames = np.ceil(max_s * fps)  # float: inf allowed
        finite = self.max_hidden_frames[np.isfinite(self.max_hidden_frames)]
        self._hist_len = int(max(2, min(finite.max() if finite.size else 0.5 * prm.history_max_s * fps,
                                        prm.history_max_s * fps) + 1))
        # velocity carried into a free rotation decays to 1/e in ``velocity_decay_s``
        tau = np.broadcast_to(np.asarray(prm.velocity_decay_s, dtype=np.float64), (m,))
        with np.errstate(divide="ignore"):
            self._decay = np.where(tau > 0, np.exp(-1.0 / (fps * tau)), 0.0)[:, None]
        self.marker_sigma_m = np.full(m, float(prm.marker_sigma_m))
        self.pivots = ShoulderPivots(layout, prm)
        self.elbows = ElbowState(layout, prm)
        self.views = ViewRays(prm)
        self.arms = ArmTracker(layout, prm, self.pivots, self.views)
        self.drift = PairRanges(layout.pairs, prm.tolerance_m)
        self.reset()

    def reset(self) -> None:
        """Forget everything (after re-identification)."""
        m = self.n_markers
        self.positions = np.full((m, 3), np.nan)     # last output, the base of the next frame
        self.velocity = np.full((m, 3), np.nan)      # last output step
        self.velocity_before = np.full((m, 3), np.nan)  # the step before it
        self.measured = np.zeros(m, dtype=bool)      # measured in the last frame
        self.status = np.full(m, MarkerStatus.LOST, dtype=np.uint8)
        self.hidden_frames = np.zeros(m, dtype=np.int64)
        self.unsupported_frames = np.zeros(m, dtype=np.int64)  # hidden with the whole segment
        self.used = np.full(m, -1, dtype=np.int8)
        self.axis_guessed = np.zeros(m, dtype=bool)
        self.frame = -1
        self.chain_coast = np.zeros(len(self.layout.arms), dtype=np.int64)  # frames in a row the chain coasted
        self.history = ReferenceHistory(self._hist_len, m)
        for part in (self.pivots, self.elbows, self.arms, self.drift):
            part.reset()
        self.views.clear()
        self.state = SharedState(self.layout, self.params, self.history, self.pivots, self.elbows, self.arms,
                                 self.views)

    def pivot_offset(self, shoulder: int, elbow_m: np.ndarray | None = None,
                     shoulder_m: np.ndarray | None = None) -> np.ndarray:
        """(3,) learned shoulder pivot minus the shoulder marker, trunk frame (see
        :meth:`~tracking.hidden.pivots.ShoulderPivots.pivot_offset`)."""
        return self.pivots.pivot_offset(shoulder, elbow_m, shoulder_m)

    def observe_views(self, markers: np.ndarray, origins_m: np.ndarray, directions: np.ndarray,
                      sigma_rad: np.ndarray) -> None:
        """Single camera views of markers that the next :meth:`update` will not have measured
        (seen by one camera, or by views that do not agree), used by that update only.

        Args:
            markers: (K,) marker index of each view (a marker may have several).
            origins_m: (K, 3) camera centres, world metres.
            directions: (K, 3) unit ray directions, world frame.
            sigma_rad: (K,) angular uncertainty of each view (centroid error over focal length).
        """
        self.views.observe(markers, origins_m, directions, sigma_rad)

    def _learn(self, p: np.ndarray, ok: np.ndarray) -> None:
        self.history.store(self.frame, p, ok)
        self.drift.learn(p, ok)
        self.pivots.learn_trunk(p, ok)
        self.arms.begin_frame(self.positions, self.marker_sigma_m)
        layout = self.layout
        if len(layout.arms) or len(layout.f_idx) or len(layout.h_idx):
            pl, okl = p.tolist(), ok.tolist()
            self.arms.learn(pl, okl)
            self.elbows.learn(pl, okl, self.pivots)

    def update(self, positions_m: np.ndarray, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One frame: pass measured markers through, estimate the hidden ones.

        Args:
            positions_m: (M, 3) float64 world metres; rows of unmeasured markers are ignored (NaN).
            measured: (M,) bool, the marker was measured in this frame.

        Returns:
            positions: (M, 3) measured or estimated positions, NaN where LOST (a new array).
            status: (M,) uint8 :class:`~tracking.marker_status.MarkerStatus` values.
        """
        ok = np.asarray(measured, dtype=bool) & np.isfinite(positions_m).all(axis=1)
        p = np.where(ok[:, None], positions_m, np.nan)
        self.frame += 1
        self._learn(p, ok)
        prev = self.positions
        has_base = self._has_base(ok, np.isfinite(prev).all(axis=1))
        hidden_frames = np.where(ok, 0, self.hidden_frames + 1)
        alone = self.layout.has_partner & ~(self.layout.partners & ok[None, :]).any(axis=1)
        unsupported_frames = np.where(~ok & alone, self.unsupported_frames + 1, 0)
        hidden = (~ok & has_base & (hidden_frames <= self.max_hidden_frames)
                  & (unsupported_frames <= self.max_unsupported_frames))
        used = np.full(self.n_markers, -1, dtype=np.int8)
        guessed = np.zeros(self.n_markers, dtype=bool)
        if hidden.any():
            self._estimate_hidden(p, ok, prev, hidden, used, guessed)
        else:
            p[~ok] = np.nan
        self.elbows.end_frame()
        if self.layout.arms:
            self.arms.update(p, ok)
            if len(self.layout.chain):
                few = ok[self.layout.chain].sum(axis=1) < 2
                self.chain_coast = np.where(few, self.chain_coast + 1, 0)
        known = ok | hidden
        # a reappearing marker keeps the velocity of its estimate (its measured jump is estimate error)
        keep_v = ok & ~self.measured & has_base
        self.velocity_before = self.velocity
        self.velocity = np.where(keep_v[:, None], self.velocity, np.where(known[:, None], p - prev, np.nan))
        self.positions, self.measured = p, ok
        self.hidden_frames, self.unsupported_frames = hidden_frames, unsupported_frames
        self.used = used
        self.axis_guessed = guessed & hidden & ~ok
        self.status = np.where(ok, MarkerStatus.MEASURED,
                               np.where(hidden, MarkerStatus.ESTIMATED, MarkerStatus.LOST)).astype(np.uint8)
        self.views.clear()
        return p.copy(), self.status.copy()

    def _has_base(self, ok: np.ndarray, has_base: np.ndarray) -> np.ndarray:
        """Markers with a place to estimate from: last frame's output, or where the body pins a
        LOST marker from measured ones (a styloid whose partner is measured while the forearm's
        angles are recent; an epicondyle whose partner, shoulder and styloids are measured)."""
        arms = self.arms
        stale = self.params.max_forearm_stale_s * self.fps
        for r, (wa, wb, _, _, _) in enumerate(self.layout.arms):
            if ok[wa] != ok[wb] and arms.age[r] <= stale and arms.shape[r] is not None:
                has_base[wb if ok[wa] else wa] = True
        for mk, pa, sh, wa, wb in self.layout.h_idx.tolist():
            if not ok[mk] and ok[pa] and ok[sh] and ok[wa] and ok[wb] and self.methods[mk] == Method.HINGE:
                has_base[mk] = True
        return has_base

    def _estimate_hidden(self, p: np.ndarray, ok: np.ndarray, prev: np.ndarray, hidden: np.ndarray,
                         used: np.ndarray, guessed: np.ndarray) -> None:
        """Estimate the ``hidden`` markers into p (in order: hinges first, then by rank), drop the
        ones their estimator or the drift check gives up (``hidden`` cleared)."""
        d_ok = ok & self.measured
        d_now = np.where(d_ok[:, None], p - prev, 0.0)
        eq6, eq6_ok = neighbour_motion(prev, self.velocity, d_now, d_ok, self.weights,
                                       own_velocity=self.params.own_velocity)
        # what a rigid fit's free rotation follows: the neighbours' motion plus the marker's own
        # velocity relative to them, decaying (equation 6 with a damped equation 5 term)
        step6 = np.where(eq6_ok[:, None], eq6 - prev, 0.0)
        prior = prev + step6 + self._decay * np.nan_to_num(self.velocity - step6)
        frame = FrameInputs(p, ok, ok.astype(np.float64), prior, prev, self.velocity, eq6, eq6_ok, self.state)
        order = np.flatnonzero(hidden)
        order = order[np.argsort(-self._rank[order], kind="stable")]
        coast = coasting(self.layout, self.params, ok, self.chain_coast, self.positions, self.velocity,
                         self.velocity_before)
        for k in order:
            if int(k) in coast:
                est, how = coast[int(k)], Method.CONSTANT_VELOCITY
                guessed[k] = k in self.layout.arm_of or k in self.layout.hinges
            else:
                est, how = self._estimate_one(frame, k)
                if est is DROP or not np.all(np.isfinite(est)):
                    hidden[k] = False
                    continue
                guessed[k] = self._guessed(k, how, ok)
            used[k] = how
            p[k] = est
            frame.weight[k] = self.params.estimate_weight
        hidden[self.drift.outside(p, hidden, ok)] = False
        p[~ok & ~hidden] = np.nan
        used[~hidden] = -1

    def _estimate_one(self, frame: FrameInputs, k: int) -> tuple[np.ndarray, int]:
        """Marker k by its estimator's chain: the first that places it; a result that is not
        finite (or degenerate geometry) goes to the chain's last; where that has nothing, the
        marker's own velocity, decaying (a seated body mostly rests)."""
        chain = self._chains[k]
        est, how = None, -1
        with np.errstate(invalid="ignore", divide="ignore"):
            try:
                for method in chain[:-1]:
                    est = method.estimate(frame, k)
                    if est is not None:
                        how = method.code
                        break
            except np.linalg.LinAlgError:  # degenerate geometry (coincident markers)
                est = None
        if est is DROP:
            return DROP, how
        if est is None or not np.all(np.isfinite(est)):
            est, how = chain[-1].estimate(frame, k), chain[-1].code
            if est is None:
                est, how = frame.prior[k], Method.CONSTANT_VELOCITY
        return est, how

    def _guessed(self, k: int, how: int, ok: np.ndarray) -> bool:
        """Whether estimate k's direction to its pair is a guess (see ``axis_guessed``)."""
        layout, elbows = self.layout, self.elbows
        if self.methods[k] == Method.HINGE:
            # the elbow axis' turn about the arm: pinned by the hinge (elbow bent, or the
            # wrists measured) or by a view of the marker; else extrapolated, a rigid fit's
            # guess or a weak condition's mean with it (a straight elbow while the forearm
            # turns: supination unknown)
            r = layout.h_row[k]
            return not (k in elbows.viewed_now or (how == Method.HINGE and r not in elbows.free_now
                                                    and r not in elbows.weak_now))
        if k in layout.arm_of:
            # the wrist's turn: a styloid marker of the arm measured, or views that pin the
            # forearm's angles; else the angles extrapolated from earlier frames
            r = layout.arm_of[k][0]
            wa, wb = layout.arms[r][:2]
            return not (ok[wa] or ok[wb] or r in self.arms.pinned)
        return False
