"""Unlabelled 3D points from the marker centroids of N >= 2 cameras.

For each marker colour separately: every pair of centroids from two cameras that agrees with the
epipolar geometry proposes a point; the proposal collects the centroids of the other cameras that
lie near its projection; proposals are ranked (more cameras first, then smaller reprojection
error) and accepted greedily so that a centroid serves one point only. Two checks reject the
*ghost* points that wrong pairings create:

- reprojection: every observation must lie within ``gate_px`` of the point's projection; with three
  or more cameras an observation that disagrees (a partly hidden ball has a shifted centroid) is
  dropped and the point triangulated again;
- size: markers are balls of known radius, so a blob's radius in pixels says how far the ball is
  (``r_px = f R / depth``). A wrong pairing puts the point at the wrong depth, where the observed
  blob sizes do not fit. A two-camera point is accepted only if it is size-consistent and
  unambiguous (no competing pairing for either centroid).

Pure numpy; camera geometry enters as arrays prepared once in :class:`RigGeometry`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from calibration.camera import Camera
from tracking.triangulation import reprojection_errors_px, triangulate


@dataclass(frozen=True, slots=True)
class CameraObservations:
    """Centroids of one camera in one frame.

    Attributes:
        uv_px: (N, 2) float64 distorted pixel centroids.
        colour: (N,) int palette index of each centroid.
        radius_px: (N,) float64 equivalent radius sqrt(area / pi) of each blob (NaN if unknown).
        roundness: (N,) float64 in 0..1 (1 = a full disc), or None if unknown (taken as round).
    """

    uv_px: np.ndarray
    colour: np.ndarray
    radius_px: np.ndarray
    roundness: np.ndarray | None = None

    @staticmethod
    def empty() -> "CameraObservations":
        return CameraObservations(np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))


@dataclass(frozen=True, slots=True)
class Points3D:
    """Unlabelled 3D points of one frame.

    Attributes:
        p_world_m: (P, 3) float64 world metres.
        colour: (P,) int palette index.
        n_cameras: (P,) int number of cameras used.
        reproj_px: (P,) float64 RMS reprojection error over the cameras used, pixels.
        obs_index: (P, C) int index of the centroid used in each camera, -1 if none.
    """

    p_world_m: np.ndarray
    colour: np.ndarray
    n_cameras: np.ndarray
    reproj_px: np.ndarray
    obs_index: np.ndarray

    def __len__(self) -> int:
        return int(self.p_world_m.shape[0])


@dataclass(frozen=True, slots=True)
class RigGeometry:
    """Camera arrays prepared once for the per-frame reconstruction.

    Attributes:
        cameras: the calibrated cameras, in order.
        extrinsics: (C, 3, 4) ``[R | t]`` world -> camera.
        focal_px: (C,) mean focal length in pixels.
        essential: (C, C, 3, 3) essential matrices with ``x_j^T E[i, j] x_i = 0`` (normalized coords).
    """

    cameras: tuple[Camera, ...]
    extrinsics: np.ndarray
    focal_px: np.ndarray
    essential: np.ndarray

    @staticmethod
    def from_cameras(cameras: Sequence[Camera]) -> "RigGeometry":
        cams = tuple(cameras)
        ext = np.stack([c.extrinsic for c in cams])
        focal = np.array([(c.K[0, 0] + c.K[1, 1]) / 2.0 for c in cams])
        n = len(cams)
        E = np.zeros((n, n, 3, 3))
        for i in range(n):
            for j in range(n):
                if i == j:
                    continue
                R_ji = cams[j].R @ cams[i].R.T  # camera i -> camera j
                t_ji = cams[j].t_m - R_ji @ cams[i].t_m
                tx = np.array([[0, -t_ji[2], t_ji[1]], [t_ji[2], 0, -t_ji[0]], [-t_ji[1], t_ji[0], 0]])
                E[i, j] = tx @ R_ji
        return RigGeometry(cams, ext, focal, E)

    @property
    def n_cameras(self) -> int:
        return len(self.cameras)


@dataclass(frozen=True, slots=True)
class ReconstructionParams:
    """Gates of the reconstruction.

    Attributes:
        gate_px: largest epipolar distance of a proposed pair, and distance of a supporting
            centroid to the proposal's projection (twice this), pixels.
        drop_px: an observation of a point seen by three or more cameras that misses the point's
            projection by more than this is dropped (a partly hidden ball, or another ball).
        max_rms_px: largest RMS reprojection error of an accepted point, pixels.
        max_rms_px_two_view: the same for a point seen by two cameras only: with sub-pixel
            centroids a true pair fits within a few tenths of a pixel, while a chance pairing of
            two different balls usually misses by more.
        marker_radius_m: radius of the marker balls (for the size check).
        size_ratio_range: accepted (observed radius / expected radius) per observation of a point
            seen by three or more cameras (one view may miss it: a partly hidden ball).
        size_ratio_range_two_view: the tighter range both views of a two-camera point must meet;
            with no third camera to vouch for it, the blob sizes are what tells a true point
            from a mirror-image pairing (symmetric rigs pair a left marker in one camera with its
            right twin in the mirrored camera, consistently with the epipolar geometry).
        roundness_two_view: (every view, best view) roundness of a two-camera point: at least one
            view must show a whole ball and none a thin crescent. Two crescents of partly hidden
            balls (shifted centroids) can line up with each other by chance.
        min_depth_m, max_depth_m: plausible distance of a marker from a camera.
        ambiguity_ratio: a two-camera pairing is taken over a rival pairing sharing one of its
            centroids only if its reprojection error is below this fraction of the rival's.
    """

    gate_px: float = 3.0
    drop_px: float = 2.0
    max_rms_px: float = 1.5
    max_rms_px_two_view: float = 0.7
    marker_radius_m: float = 0.02
    size_ratio_range: tuple[float, float] = (0.6, 1.5)
    size_ratio_range_two_view: tuple[float, float] = (0.85, 1.15)
    roundness_two_view: tuple[float, float] = (0.6, 0.8)
    min_depth_m: float = 0.3
    max_depth_m: float = 8.0
    ambiguity_ratio: float = 0.35


def _epipolar_distance_px(geo: RigGeometry, i: int, j: int, xi: np.ndarray, xj: np.ndarray) -> np.ndarray:
    """(Ni, 2), (Nj, 2) normalized -> (Ni, Nj) symmetric epipolar distance in pixels."""
    E = geo.essential[i, j]
    hi = np.hstack([xi, np.ones((len(xi), 1))])
    hj = np.hstack([xj, np.ones((len(xj), 1))])
    lines_j = hi @ E.T  # epipolar lines in camera j of points in i: l = E x_i
    lines_i = hj @ E  # lines in camera i of points in j: l = E^T x_j
    num = hj @ lines_j.T  # (Nj, Ni): x_j . (E x_i)
    num = np.abs(num.T)  # (Ni, Nj)
    nj = np.hypot(lines_j[:, 0], lines_j[:, 1])[:, None]  # distance in camera j
    ni = np.hypot(lines_i[:, 0], lines_i[:, 1])[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        d_j = num / nj * geo.focal_px[j]
        d_i = num / ni * geo.focal_px[i]
    return np.maximum(d_i, d_j)


def _depths(geo: RigGeometry, p: np.ndarray) -> np.ndarray:
    """(N, 3) -> (N, C) depth of each point in each camera."""
    return np.einsum("cj,nj->nc", geo.extrinsics[:, 2, :3], p) + geo.extrinsics[None, :, 2, 3]


def reconstruct(
    geo: RigGeometry,
    observations: Sequence[CameraObservations],
    params: ReconstructionParams = ReconstructionParams(),
) -> Points3D:
    """Match centroids across cameras and triangulate them.

    Args:
        geo: the rig's prepared geometry.
        observations: one :class:`CameraObservations` per camera, in rig order.
        params: gates.
    Returns:
        The accepted points (unlabelled), sorted by colour.
    """
    n_cams = geo.n_cameras
    if len(observations) != n_cams:
        raise ValueError(f"expected observations for {n_cams} cameras, got {len(observations)}")
    xn_all = [geo.cameras[c].undistort_points(o.uv_px) for c, o in enumerate(observations)]
    colours = np.unique(np.concatenate([o.colour for o in observations])) if n_cams else np.zeros(0)
    pts, cols, ncs, errs, idxs = [], [], [], [], []
    for colour in colours:
        sel = [np.flatnonzero(o.colour == colour) for o in observations]
        xn = [xn_all[c][sel[c]] for c in range(n_cams)]
        rad = [observations[c].radius_px[sel[c]] for c in range(n_cams)]
        rnd = [
            np.ones(len(sel[c])) if observations[c].roundness is None else observations[c].roundness[sel[c]]
            for c in range(n_cams)
        ]
        for p, obs_local, err in _reconstruct_colour(geo, xn, rad, rnd, params):
            obs_global = np.array([sel[c][k] if k >= 0 else -1 for c, k in enumerate(obs_local)])
            pts.append(p)
            cols.append(int(colour))
            ncs.append(int((obs_local >= 0).sum()))
            errs.append(err)
            idxs.append(obs_global)
    if not pts:
        return Points3D(np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, n_cams), np.int64))
    return Points3D(np.array(pts), np.array(cols), np.array(ncs), np.array(errs), np.array(idxs))


def _refine(geo: RigGeometry, xn_obs: np.ndarray, seen: np.ndarray, params: ReconstructionParams):
    """Triangulate candidates and drop their worst observation while it breaks the gate.

    Args:
        xn_obs: (K, C, 2) normalized observations of K candidates; seen: (K, C) bool (modified).
    Returns:
        p (K, 3), err (K, C) pixel errors, seen (K, C).
    """
    seen = seen.copy()
    for _ in range(geo.n_cameras):
        p = triangulate(geo.extrinsics, xn_obs, seen)
        err = reprojection_errors_px(geo.extrinsics, geo.focal_px, p, xn_obs, seen)
        worst = np.nanargmax(np.where(seen, err, -1.0), axis=1)
        worst_err = err[np.arange(len(p)), worst]
        fix = (worst_err > params.drop_px) & (seen.sum(axis=1) >= 3)
        if not fix.any():
            break
        seen[np.flatnonzero(fix), worst[fix]] = False
    return p, err, seen


def _size_ratio(geo: RigGeometry, p: np.ndarray, r_obs: np.ndarray, params: ReconstructionParams) -> np.ndarray:
    """(K, C) observed blob radius / radius expected for a ball at the point's depth (f R / z)."""
    depth = _depths(geo, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        return r_obs / (geo.focal_px[None, :] * params.marker_radius_m / depth)


def _reconstruct_colour(geo: RigGeometry, xn: list[np.ndarray], rad: list[np.ndarray], rnd: list[np.ndarray],
                        params: ReconstructionParams):
    """Yield (point, obs index per camera (C,) with -1, rms px) for one colour: proposals from
    every epipolar-consistent pair (1), support from the other cameras (2), triangulated with the
    disagreeing and partial views dropped (3), checked (:func:`_valid`) and accepted greedily (4, 5)."""
    counts = [len(x) for x in xn]
    proposed = _proposals(geo, xn, counts, params)
    if proposed is None:
        return
    xn_obs, seen, obs, gather = proposed
    p2 = triangulate(geo.extrinsics, xn_obs, seen)
    _gather_support(geo, xn, counts, p2, xn_obs, seen, obs, gather, params)
    # 3. triangulate with everything, dropping disagreeing views
    p, err, seen = _refine(geo, xn_obs, seen, params)
    p, err, seen, ratio, belongs = _drop_partial_views(geo, rad, counts, xn_obs, seen, obs, p, err, params)
    obs = np.where(seen, obs, -1)
    depth = _depths(geo, p)
    _partial_elsewhere(geo, xn, rad, counts, p, depth, seen, belongs, params)
    valid, n_used, rms, round_obs = _valid(rnd, counts, seen, obs, err, depth, ratio, belongs, params)
    yield from _accept(counts, p, seen, obs, belongs, valid, n_used, rms, round_obs, params)


def _proposals(geo: RigGeometry, xn: list[np.ndarray], counts: list[int], params: ReconstructionParams):
    """1. Proposals from every epipolar-consistent pair: (K, C, 2) normalized observations, (K, C)
    seen, (K, C) observation index (-1), (K,) whether the proposal gathers support (the first
    half; the second half is every pair again as a bare two-camera candidate), or None."""
    n_cams = geo.n_cameras
    props = []  # (cam_i, k_i, cam_j, k_j)
    for i in range(n_cams):
        for j in range(i + 1, n_cams):
            if counts[i] == 0 or counts[j] == 0:
                continue
            d = _epipolar_distance_px(geo, i, j, xn[i], xn[j])
            ki, kj = np.nonzero(d < params.gate_px)
            for a, b in zip(ki, kj):
                props.append((i, a, j, b))
    if not props:
        return None
    K = len(props)
    xn_obs = np.full((K, n_cams, 2), np.nan)
    seen = np.zeros((K, n_cams), dtype=bool)
    obs = np.full((K, n_cams), -1, dtype=np.int64)
    for r, (i, a, j, b) in enumerate(props):
        xn_obs[r, i], xn_obs[r, j] = xn[i][a], xn[j][b]
        seen[r, i] = seen[r, j] = True
        obs[r, i], obs[r, j] = a, b
    # every pair also stays a bare two-camera candidate: if the support gathered below holds a
    # centroid that another point owns, the clean pair is still there to be taken
    xn_obs, seen, obs = (np.concatenate([a, a]) for a in (xn_obs, seen, obs))
    gather = np.arange(2 * K) < K
    return xn_obs, seen, obs, gather


def _gather_support(geo: RigGeometry, xn: list[np.ndarray], counts: list[int], p2: np.ndarray, xn_obs: np.ndarray,
                    seen: np.ndarray, obs: np.ndarray, gather: np.ndarray, params: ReconstructionParams) -> None:
    """2. Support from the other cameras: each gathering proposal (its pair's point ``p2``) takes
    the nearest centroid of every camera it does not use within twice the gate (in place)."""
    K = len(p2)
    for c in range(geo.n_cameras):
        if counts[c] == 0:
            continue
        free = ~seen[:, c] & gather
        if not free.any():
            continue
        cam = geo.extrinsics[c]
        pc = p2 @ cam[:, :3].T + cam[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            proj = pc[:, :2] / pc[:, 2:3]
        dist = np.linalg.norm(proj[:, None, :] - xn[c][None, :, :], axis=-1) * geo.focal_px[c]
        best = np.argmin(dist, axis=1)
        ok = free & (dist[np.arange(K), best] < 2.0 * params.gate_px) & (pc[:, 2] > 0)
        xn_obs[ok, c] = xn[c][best[ok]]
        seen[ok, c] = True
        obs[ok, c] = best[ok]


def _drop_partial_views(geo: RigGeometry, rad: list[np.ndarray], counts: list[int], xn_obs: np.ndarray,
                        seen: np.ndarray, obs: np.ndarray, p: np.ndarray, err: np.ndarray,
                        params: ReconstructionParams):
    """A partly hidden ball shows a smaller blob whose centroid is shifted: such views are left
    out of points that keep two or more full-size views, and the points triangulated again.
    Returns (points, errors, seen, (K, C) size ratios, (K, C) the dropped views that still
    belong to each point, -1 elsewhere)."""
    K, n_cams = seen.shape
    r_obs = np.full((K, n_cams), np.nan)
    for c in range(n_cams):
        if counts[c]:
            r_obs[:, c] = np.where(obs[:, c] >= 0, rad[c][np.maximum(obs[:, c], 0)], np.nan)
    ratio = _size_ratio(geo, p, r_obs, params)
    partial = seen & (ratio < params.size_ratio_range_two_view[0])
    redo = partial.any(axis=1) & ((seen & ~partial).sum(axis=1) >= 2)
    # a dropped partial view still belongs to the point: it is consumed with it, so that it
    # cannot pair by chance with another marker's view later
    belongs = np.where(partial & redo[:, None], obs, -1)
    if redo.any():
        seen[redo] &= ~partial[redo]
        p_r, err_r, seen_r = _refine(geo, xn_obs[redo], seen[redo], params)
        p[redo], err[redo], seen[redo] = p_r, err_r, seen_r
        ratio[redo] = _size_ratio(geo, p_r, r_obs[redo], params)
    return p, err, seen, ratio, belongs


def _partial_elsewhere(geo: RigGeometry, xn: list[np.ndarray], rad: list[np.ndarray], counts: list[int],
                       p: np.ndarray, depth: np.ndarray, seen: np.ndarray, belongs: np.ndarray,
                       params: ReconstructionParams) -> None:
    """Any undersized blob at the point's projection in a camera the point does not use is the
    same ball, partly hidden there (dropped above, or never gathered): it belongs to the point
    too (``belongs``, in place)."""
    K = len(p)
    for c in range(geo.n_cameras):
        if counts[c] == 0:
            continue
        cam = geo.extrinsics[c]
        pc = p @ cam[:, :3].T + cam[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            proj = pc[:, :2] / pc[:, 2:3]
        dist = np.linalg.norm(proj[:, None, :] - xn[c][None, :, :], axis=-1) * geo.focal_px[c]
        near = np.nan_to_num(dist, nan=np.inf).argmin(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            small = rad[c][near] / (geo.focal_px[c] * params.marker_radius_m / depth[:, c])
        hit = ~seen[:, c] & (dist[np.arange(K), near] < 2.0 * params.gate_px) & (small < params.size_ratio_range_two_view[0])
        belongs[hit, c] = near[hit]


def _valid(rnd: list[np.ndarray], counts: list[int], seen: np.ndarray, obs: np.ndarray,
           err: np.ndarray, depth: np.ndarray, ratio: np.ndarray, belongs: np.ndarray, params: ReconstructionParams):
    """The candidates that may be accepted: one of each set of centroids, seen by two cameras or
    more, within the reprojection and depth gates, their blob sizes fitting the depth (two-camera
    points: every view round and of the right size). Returns (valid, views used, rms px, (K, C)
    each view's roundness)."""
    K, n_cams = seen.shape
    # proposals that ended with the same centroids are one candidate
    # (the one that carries dropped partial views is kept)
    pref = np.argsort(~(belongs >= 0).any(axis=1), kind="stable")
    _, first = np.unique(obs[pref], axis=0, return_index=True)
    unique = np.zeros(K, dtype=bool)
    unique[pref[first]] = True
    n_used = seen.sum(axis=1)
    rms = np.sqrt(np.nanmean(np.where(seen, err, np.nan) ** 2, axis=1))
    valid = unique & (n_used >= 2) & np.isfinite(rms) & (rms <= params.max_rms_px)
    valid &= np.all(~seen | ((depth > params.min_depth_m) & (depth < params.max_depth_m)), axis=1)
    # size consistency: observed radius vs. f R / depth
    lo, hi = params.size_ratio_range
    size_ok = np.where(seen & np.isfinite(ratio), (ratio > lo) & (ratio < hi), True)
    # a ball may be partly hidden in one view (smaller blob); require most views to fit
    size_fit = size_ok.sum(axis=1) >= np.maximum(2, n_used - 1)
    lo2, hi2 = params.size_ratio_range_two_view
    round_obs = np.ones((K, n_cams))
    for c in range(n_cams):
        if counts[c]:
            round_obs[:, c] = np.where(obs[:, c] >= 0, rnd[c][np.maximum(obs[:, c], 0)], 1.0)
    r_min, r_best = params.roundness_two_view
    two_view_fit = np.all(~seen | ((ratio > lo2) & (ratio < hi2) & (round_obs >= r_min)), axis=1)
    two_view_fit &= np.where(seen, round_obs, 0.0).max(axis=1) >= r_best
    two_view_fit &= rms <= params.max_rms_px_two_view
    valid &= size_fit & ((n_used > 2) | two_view_fit)
    return valid, n_used, rms, round_obs


def _accept(counts: list[int], p: np.ndarray, seen: np.ndarray, obs: np.ndarray, belongs: np.ndarray,
            valid: np.ndarray, n_used: np.ndarray, rms: np.ndarray, round_obs: np.ndarray,
            params: ReconstructionParams):
    """Yield the accepted candidates (point, obs index per camera, rms px), each centroid serving
    one point: 4. points seen by 3+ cameras first, 5. then the unambiguous two-camera ones."""
    _, r_best = params.roundness_two_view
    # 4. greedy acceptance, points seen by 3+ cameras first (more cameras, then smaller error);
    #    each centroid serves one point
    order = np.lexsort((rms, -n_used))
    used = [np.zeros(n, dtype=bool) for n in counts]

    def free(r: int) -> bool:
        return not any(used[c][obs[r, c]] for c in np.flatnonzero(seen[r]))

    def take(r: int):
        for c in np.flatnonzero(seen[r]):
            used[c][obs[r, c]] = True
        for c in np.flatnonzero(belongs[r] >= 0):
            used[c][belongs[r, c]] = True
        return p[r], obs[r].copy(), float(rms[r])

    for r in order:
        if valid[r] and n_used[r] >= 3 and free(r):
            yield take(r)
    # 5. two-camera points: a centroid may have several plausible partners in the other camera
    #    (markers near one epipolar plane). Take a pairing only when it is clearly the best for
    #    both of its centroids: its reprojection error is below ``ambiguity_ratio`` times that of
    #    every rival pairing that shares a centroid. Otherwise two views cannot tell, and no
    #    point is better than a ghost.
    # Candidates whose two views are both whole balls go first (then by error), so that they
    # consume the partial views that belong to them before a chance pairing can use those.
    whole = np.where(seen, round_obs, 1.0).min(axis=1) >= r_best
    pending = [r for r in order if valid[r] and n_used[r] == 2 and free(r)]
    pending.sort(key=lambda r: (not whole[r], rms[r]))
    for r in pending:  # ``order`` sorts by error, so the first free one is the best
        if not free(r):
            continue
        cams_r = np.flatnonzero(seen[r])
        rivals = [
            q for q in pending
            if q != r and free(q) and any(obs[q, c] == obs[r, c] for c in cams_r if seen[q, c])
            and whole[q] >= whole[r]
        ]
        if all(rms[r] < params.ambiguity_ratio * rms[q] for q in rivals):
            yield take(r)
