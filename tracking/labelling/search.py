"""The rules' search: the naming of the points whose worst rule margin is largest (branch and bound).

Markers are the variables; a marker's domain is the points of its colour. A depth-first search
assigns the marker with the fewest candidates left (colour classes of one point first), and after
each assignment removes from every constrained neighbour's domain the points that would break a
constraint with it (forward checking on bitsets). It is a branch and bound on the worst margin:
after each complete assignment the bar rises to its worst margin, so the result is the assignment
whose worst rule margin is largest. Rows of NaN are stand-ins for unseen markers; a ray is one
candidate point, its markers placed at the samples that keep the rules best. Timings:
docs/TRACKING.md, "Identification".
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from tracking.labelling.body_frame import patient_axes, yaw_from_pairs
from tracking.labelling.constraints import Blocks, Constraints, RayRows
from tracking.labelling.rays import RAY_STEP_M

log = logging.getLogger(__name__)

REFINE_TOL_DEG = 1.0
MAX_REFINE = 3
# every rule holds (up to rounding)
SATISFIED = -1e-12
# markers on rays that share a rule are placed together up to this many sample combinations
MAX_JOINT = 200_000


def bitsets(ok: np.ndarray) -> list[list[int]]:
    """(..., P) bool -> nested lists of ints with bit q set where ``ok[..., q]``."""
    n = ok.shape[-1]
    if n <= 62:
        return (ok.astype(np.int64) @ (np.int64(1) << np.arange(n, dtype=np.int64))).tolist()
    packed = np.packbits(ok, axis=-1, bitorder="little")
    return [[int.from_bytes(row.tobytes(), "little") for row in m] for m in packed]


@dataclass(frozen=True, slots=True)
class Pools:
    """Groups of points of which a naming may take at most so many (for :func:`branch_and_bound`).

    Attributes:
        mask: per pool, the bitset of its points.
        size: per pool, how many of its points may be taken.
        of_point: point -> the pools it belongs to.
    """

    mask: tuple[int, ...]
    size: tuple[int, ...]
    of_point: dict[int, tuple[int, ...]]

    @staticmethod
    def of(groups: Iterable[tuple[np.ndarray, int]]) -> "Pools":
        """From (point indices, how many may be taken) per pool."""
        mask, size, of_point = [], [], {}
        for k, (rows, n) in enumerate(groups):
            mask.append(sum(1 << int(q) for q in rows))
            size.append(int(n))
            for q in rows:
                of_point[int(q)] = of_point.get(int(q), ()) + (k,)
        return Pools(tuple(mask), tuple(size), of_point)


@dataclass(frozen=True, slots=True)
class Found:
    index: np.ndarray
    slack_m: np.ndarray  # (K,) per constraint
    yaw: float
    nodes: int


class RuleSearch:
    """Searches of one frame's points under the compiled constraints (the last frame's pair
    slacks kept: the uniqueness checks search the same frame many times).

    Args:
        constraints: the marker set's compiled rules.
        names: the marker names (for the log).
        max_nodes: search-node budget per search.
    """

    def __init__(self, constraints: Constraints, names: tuple[str, ...], max_nodes: int):
        self.constraints = constraints
        self.names = names
        self.max_nodes = max_nodes
        self._last_slack: tuple[object, tuple | None] = (None, None)  # (frame key, pair slacks)
        self.inexact = False  # a search placed markers on rays without trying every combination

    def search(self, p_world_m: np.ndarray, colour: np.ndarray, yaw: float, bars_m: Iterable[float],
                hard_distances: bool = False, exclude: tuple[int, int] | None = None,
                pools: Pools | None = None, rays: RayRows | None = None) -> Found | None:
        """The assignment with the largest worst slack, in the frame of ``yaw``.

        ``bars_m`` are lower and lower bars on the worst slack: the search stops at the first
        bar above which an assignment exists, so a good bar keeps the tree small. Rows of NaN are
        stand-ins for unseen markers (they satisfy every constraint), or with ``rays`` the rays
        from ``rays.first`` on. ``exclude`` = (marker, point) forbids that one naming. ``pools``:
        see :func:`branch_and_bound`.

        A ray is one point of the search whose pair slacks are the best over its samples (a bound);
        a complete naming places its markers on rays at the samples that make its worst slack
        largest (:meth:`place_on_rays`), so the result is exact on the samples.
        """
        cons = self.constraints
        if rays is not None and hard_distances:
            raise ValueError("rays are searched with soft distances only")
        centre = np.nanmean(p_world_m, axis=0)
        axes = patient_axes(yaw)
        c_pat = (p_world_m - centre) @ axes
        key = (p_world_m.tobytes(), yaw, hard_distances, None if rays is None else rays.key)
        if self._last_slack[0] != key:  # the uniqueness checks search the same frame many times
            if rays is None:
                self._last_slack = (key, (cons.pair_slack(p_world_m, c_pat, hard_distances), None))
            else:
                ext_p = np.vstack([p_world_m[:rays.first], *rays.samples])
                ext_pat = (ext_p - centre) @ axes
                ext_col = np.concatenate([colour[:rays.first]]
                                         + [np.full(len(p), colour[rays.first + k]) for k, p in enumerate(rays.samples)])
                blocks = cons.pair_blocks(ext_p, ext_pat, ext_col)
                self._last_slack = (key, (cons.compact(blocks, colour, ext_col, rays), (ext_p, ext_pat, blocks)))
        slack, ext = self._last_slack[1]
        domains = [0] * len(cons.colour)
        for m, c in enumerate(cons.colour):
            for q in np.flatnonzero(colour == c):
                domains[m] |= 1 << int(q)
        if exclude is not None:
            domains[exclude[0]] &= ~(1 << exclude[1])

        def slack_of(index: np.ndarray, hard: bool = hard_distances) -> np.ndarray:
            if ext is None or not np.any(index >= rays.first):
                return cons.slack(p_world_m, c_pat, index[cons.c_a], index[cons.c_b], hard)
            ext_index = self.place_on_rays(index, rays, ext[2])
            return cons.slack(ext[0], ext[1], ext_index[cons.c_a], ext_index[cons.c_b], hard)

        nodes = 0
        for bar in bars_m:
            best, nodes_used = branch_and_bound(slack, domains, cons.neighbours, bar, slack_of, self.max_nodes,
                                                 pools)
            nodes += nodes_used
            if nodes_used > self.max_nodes:
                log.warning("identification search stopped after %d nodes; the result may not be the best", nodes_used)
            if best is not None:
                return Found(best, slack_of(best, False), yaw, nodes)
        return None

    def place_on_rays(self, index: np.ndarray, rays: RayRows, s_ext: Blocks) -> np.ndarray:
        """Each marker named to a ray at the sample that makes the naming's worst slack largest.

        The markers on rays that share a constraint are placed together (every combination of
        their samples: up to ``MAX_JOINT``; beyond, each alone and the search is marked inexact).

        Args:
            index: (M,) a complete naming; rows from ``rays.first`` on are rays.
            rays: the rays' samples (rows of the extended points after ``rays.first``).
            s_ext: pair slacks over the extended points (seen, stand-ins, samples).

        Returns:
            (M,) the naming in rows of the extended points.
        """
        cons = self.constraints
        ext_index = index.copy()
        on_ray = np.flatnonzero(index >= rays.first)
        rows = {int(m): rays.rows(int(index[m])) for m in on_ray}
        unary = {m: np.full(len(r), np.inf) for m, r in rows.items()}
        links: list[tuple[int, int, np.ndarray]] = []
        for m, r in rows.items():
            for j, k, forward in cons.neighbours[m]:
                if j in rows:
                    if m < j:
                        mat = s_ext.get(k, r[:, None], rows[j][None, :])
                        links.append((m, j, mat if forward else mat.T))
                else:
                    q = int(index[j])
                    unary[m] = np.minimum(unary[m], s_ext.get(k, r, q) if forward else s_ext.get(k, q, r))
        group = {m: m for m in rows}  # union-find over the links: markers placed together

        def root(m: int) -> int:
            while group[m] != m:
                m = group[m]
            return m

        for a, b, _ in links:
            group[root(a)] = root(b)
        for g in {root(m) for m in rows}:
            members = [m for m in rows if root(m) == g]
            sizes = [len(rows[m]) for m in members]
            if math.prod(sizes) > MAX_JOINT:
                self.inexact = True
                for m in members:
                    ext_index[m] = rows[m][int(np.argmax(unary[m]))]
                continue
            axis = {m: a for a, m in enumerate(members)}
            total = np.full(sizes, np.inf)
            for m in members:
                shape = [1] * len(members)
                shape[axis[m]] = sizes[axis[m]]
                total = np.minimum(total, unary[m].reshape(shape))
            for a, b, mat in links:
                if a in axis:
                    if axis[a] > axis[b]:
                        a, b, mat = b, a, mat.T
                    shape = [1] * len(members)
                    shape[axis[a]], shape[axis[b]] = mat.shape
                    total = np.minimum(total, mat.reshape(shape))
            best = np.unravel_index(int(np.argmax(total)), total.shape)
            for m in members:
                ext_index[m] = rows[m][best[axis[m]]]
        return ext_index

    def settle(self, pts: np.ndarray, colour: np.ndarray, yaw: float, pools: Pools | None = None,
                rays: RayRows | None = None) -> Found | None:
        """Search in the frame of ``yaw``, then in the frame of the identified left-right pairs."""
        cons = self.constraints
        found = self.search(pts, colour, yaw, [SATISFIED], pools=pools, rays=rays)
        for _ in range(MAX_REFINE):
            if found is None:
                break
            new_yaw = yaw_from_pairs(pts, found.index[cons.lr_pairs], found.yaw)
            if abs(math.degrees(new_yaw - found.yaw)) < REFINE_TOL_DEG:
                break
            again = self.search(pts, colour, new_yaw, [SATISFIED], pools=pools, rays=rays)
            if again is None:
                break
            found = again
        return found

    def certain(self, pts: np.ndarray, col: np.ndarray, found: Found, n_seen: int, pools: Pools | None = None,
                 rays: RayRows | None = None) -> bool:
        """Whether the names of the seen points (rows below ``n_seen``) of ``found`` are beyond doubt.

        Every rule must hold by twice its margin: a rule with an unseen marker checks nothing, so
        the others must hold clearly (a wrong pose, hands on the thighs with the inner wrist
        markers hidden, kept every rule within 4 mm with the elbow and wrist markers swapped).
        And no naming that gives a seen point another name may come within half a margin of
        satisfying the rules (with ``rays``, within half a margin and a sampling step).
        """
        cons = self.constraints
        if cons.rule_margins(found.slack_m).min() < cons.min_order_margin_m:
            return False
        bar = -0.5 * cons.min_order_margin_m
        if rays is not None:
            # a naming is scored at its best samples, up to half a step from the best place on
            # each of two rays: another naming may fit better than its samples say
            bar -= RAY_STEP_M
        for m, q in enumerate(found.index):
            if q < n_seen and self.search(pts, col, found.yaw, [bar], exclude=(m, int(q)), pools=pools,
                                           rays=rays) is not None:
                log.debug("identification with unseen markers is ambiguous for %s", self.names[m])
                return False
        return True


def seen_names(found: Found, n_seen: int) -> np.ndarray:
    """(M,) the point each marker is named to, -1 where it is not one of the first ``n_seen``."""
    return np.where(found.index < n_seen, found.index, -1)


def branch_and_bound(slack: np.ndarray, domains: list[int], neighbours: list[list[tuple[int, int, bool]]],
                      bar_m: float, slack_of, max_nodes: int, pools: Pools | None = None
                      ) -> tuple[np.ndarray | None, int]:
    """Depth-first search for the assignment with the largest worst slack above ``bar_m``.

    Args:
        slack: (pairs, P, P) worst slack of each constrained marker pair, [first at p, second at q].
        domains: per marker, a bitset of the points it may take (its colour).
        neighbours: per marker, (other marker, pair, marker is the pair's first) of its pairs.
        bar_m: only assignments whose every pair slack exceeds this are considered.
        slack_of: (M,) assignment -> (K,) slack of every constraint.
        max_nodes: node budget; the best so far is returned when it is spent.
        pools: groups of points of which at most so many may be taken (the points sampled along
            one ray: one; the points that are not seen of one colour: its unseen markers).

    Returns:
        (the best assignment or None, nodes visited).
    """
    masks: list[tuple[list[int], list[int]]] = []

    def set_bar(bar: float) -> None:
        ok = slack > bar
        masks[:] = list(zip(bitsets(ok), bitsets(ok.transpose(0, 2, 1))))

    state = {"bar": bar_m, "best": None, "nodes": 0}
    set_bar(bar_m)

    pool_of = pools.of_point if pools is not None else {}

    def descend(dom: list[int], free: list[int], left: tuple[int, ...]) -> bool:
        """False stops the search (budget spent, or nothing left to improve); ``left``: what each
        pool may still give."""
        if not free:
            index = np.array([d.bit_length() - 1 for d in dom], np.int64)
            s = slack_of(index)
            worst = float(s.min()) if s.size else math.inf
            if worst > state["bar"]:
                state["best"], state["bar"] = index, worst
                if math.isinf(worst):
                    return False
                set_bar(worst)  # from now on only better assignments pass the forward checks
            return True
        v = min(free, key=lambda u: dom[u].bit_count())  # fewest candidates first
        rest = [u for u in free if u != v]
        d = dom[v]
        while d:
            low = d & -d
            d ^= low
            state["nodes"] += 1
            if state["nodes"] > max_nodes:
                return False
            q = low.bit_length() - 1
            new = dom.copy()
            new[v] = low
            used, now = low, left
            if q in pool_of:
                now = list(left)
                for k in pool_of[q]:
                    now[k] -= 1
                    if now[k] == 0:
                        used |= pools.mask[k]
                now = tuple(now)
            used = ~used
            for u in rest:
                new[u] &= used
            for u, k, forward in neighbours[v]:
                new[u] &= masks[k][0 if forward else 1][q]
            # assigned neighbours too: after the bar rose, an earlier pair may no longer pass
            if not all(new):
                continue
            if not descend(new, rest, now):
                return False
        return True

    descend(domains, list(range(len(domains))), tuple(pools.size) if pools is not None else ())
    return state["best"], state["nodes"]
