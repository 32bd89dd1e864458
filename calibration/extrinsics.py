"""Extrinsic calibration of a camera rig from a checkerboard seen by cameras together.

Steps (:func:`calibrate_extrinsics`):

1. The board's pose in every camera that sees it (``solvePnP``: IPPE, then iterative refinement).
2. Relative poses of camera pairs that saw the same board at the same instant; of a pair's shared
   views, the one whose relative pose reprojects all shared views best is kept.
3. A spanning tree over the cameras, the pairs with the most shared views first, chains the
   relative poses to every camera, so no single view needs all cameras (a ring of cameras around
   the patient sees a board only two by two).
4. Bundle adjustment (``scipy.optimize.least_squares``, sparse Jacobian pattern, soft-L1 loss with
   a 1 px scale) over all camera poses but the first and all board poses; intrinsics stay as
   calibrated. Then again with each camera's view of each board weighed by its own corner
   scatter (:func:`view_sigmas_px`): an oblique board's corners in one camera can be several
   times as scattered as in another, and the seat board alone sets the world frame. Given the
   lens step's information matrices, this second pass also refines the lens data, the lens
   step's estimate a prior of that weight (:class:`LensPrior`; an adjustment that does not
   settle keeps the lens step's data).
5. The world frame of docs/INTERFACES.md from one board lying face up on the floor or the seat
   (:func:`world_from_floor_board`): +Y is up out of the board, +X along the board's rows of
   corners (the patient's right), corner 0 at ``origin_m``.

Poses are (R, t) pairs mapping the second frame to the first: ``T_a_b`` takes b coordinates to a
coordinates, ``x_a = R @ x_b + t``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Mapping, Sequence

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import bmat, lil_matrix

from calibration.board import Detection
from calibration.camera import Camera, rotation_from_rvec, rvec_from_rotation
from calibration.errors import CalibrationError

log = logging.getLogger(__name__)

Pose = tuple[np.ndarray, np.ndarray]  # (R (3, 3), t (3,))

# World axes (columns: X, Y, Z) in the frame of a board lying face up: X along the board's x,
# Y up = against the board's z (which points into the printed face), Z = X cross Y = board y.
_WORLD_AXES_IN_BOARD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True, slots=True)
class ExtrinsicsResult:
    """A calibrated rig.

    Attributes:
        cameras: the cameras with their extrinsics, world -> camera, in the order given.
        rms_px: (C,) RMS reprojection error of each camera over its board corners after the
            bundle adjustment, pixels (NaN for a camera that saw no board).
        n_views: (C,) number of board views each camera contributed.
        world_set: True when the world frame comes from a floor board, False when it is the
            first camera's frame.
        warnings: one-line warnings.
    """

    cameras: tuple[Camera, ...]
    rms_px: np.ndarray
    n_views: np.ndarray
    world_set: bool
    warnings: tuple[str, ...]


def compose(a: Pose, b: Pose) -> Pose:
    """T_x_y composed with T_y_z -> T_x_z."""
    return a[0] @ b[0], a[0] @ b[1] + a[1]


def invert(a: Pose) -> Pose:
    return a[0].T, -a[0].T @ a[1]


def board_pose_in_camera(camera: Camera, det: Detection, board) -> Pose:
    """T_cam_board from one detection (PnP with the camera's intrinsics and distortion)."""
    obj = det.object_points(board)
    uv = det.uv_px.reshape(-1, 1, 2)
    K, dist = camera.K, camera.dist
    if camera.fisheye:  # PnP on the undistorted normalized points: OpenCV's PnP knows the pinhole model only
        uv, K, dist = camera.undistort_points(uv).reshape(-1, 1, 2), np.eye(3), None
    ok, rvec, tvec = cv2.solvePnP(obj, uv, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        ok, rvec, tvec = cv2.solvePnP(obj, uv, K, dist)
    rvec, tvec = cv2.solvePnPRefineLM(obj, uv, K, dist, rvec, tvec)
    return rotation_from_rvec(rvec.ravel()), tvec.ravel().astype(np.float64)


def _reprojection(camera: Camera, T_cam_board: Pose, det: Detection, obj: np.ndarray) -> np.ndarray:
    """(N, 2) projected minus detected corners, pixels."""
    p_cam = obj @ T_cam_board[0].T + T_cam_board[1]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = camera.distort_normalized(p_cam[:, :2] / p_cam[:, 2:3])
    return uv - det.uv_px


def _rms(res: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(res**2, axis=-1))))


def _initial_camera_poses(cameras: Sequence[Camera], board, views: Mapping[str, Sequence[Detection | None]],
                          pnp: dict[tuple[str, int], Pose]) -> list[Pose]:
    """T_cam_ref for every camera (ref = camera 0) by chaining pair poses over a spanning tree."""
    n = len(cameras)
    shared: dict[tuple[int, int], list[str]] = {}
    for name, dets in views.items():
        seen = [c for c in range(n) if dets[c] is not None]
        for i in seen:
            for j in seen:
                if i < j:
                    shared.setdefault((i, j), []).append(name)
    rel: dict[tuple[int, int], Pose] = {}  # rel[i, j] = T_j_i
    for (i, j), names in shared.items():
        best, best_err = None, np.inf
        for cand in names:  # T_j_i = T_j_board T_board_i
            T_ji = compose(pnp[cand, j], invert(pnp[cand, i]))
            err = sum(_rms(_reprojection(cameras[j], compose(T_ji, pnp[v, i]), views[v][j], views[v][j].object_points(board)))
                      for v in names)
            if err < best_err:
                best, best_err = T_ji, err
        rel[i, j] = best
        rel[j, i] = invert(best)
    poses: list[Pose | None] = [None] * n
    poses[0] = (np.eye(3), np.zeros(3))
    while True:  # Prim: attach the unplaced camera with the most views shared with a placed one
        best_edge, best_count = None, 0
        for (i, j), names in shared.items():
            for a, b in ((i, j), (j, i)):
                if poses[a] is not None and poses[b] is None and len(names) > best_count:
                    best_edge, best_count = (a, b), len(names)
        if best_edge is None:
            break
        a, b = best_edge
        poses[b] = compose(rel[a, b], poses[a])  # rel[a, b] = T_b_a
    missing = [cameras[c].name for c in range(n) if poses[c] is None]
    if missing:
        raise CalibrationError(
            f"{', '.join(missing)} shares no board view with {cameras[0].name} or the cameras linked to it: "
            "take images where the board is seen by that camera and a neighbour at the same time"
        )
    return poses  # type: ignore[return-value]


def _pack(poses: Sequence[Pose]) -> np.ndarray:
    return np.concatenate([np.concatenate([rvec_from_rotation(R), t]) for R, t in poses])


def _unpack(x: np.ndarray, n: int) -> list[Pose]:
    x = x.reshape(n, 6)
    return [(rotation_from_rvec(r[:3]), r[3:].copy()) for r in x]


def calibrate_extrinsics(
    cameras: Sequence[Camera],
    board,
    views: Mapping[str, Sequence[Detection | None]],
    *,
    floor_view: str | None = None,
    origin_m=(0.0, 0.0, 0.0),
    turn_deg: float = 0.0,
    check_world: bool = True,
    weigh_views: bool = True,
    lens_information: Sequence[np.ndarray | None] | None = None,
) -> ExtrinsicsResult:
    """Calibrate the cameras' poses from board views.

    Args:
        cameras: cameras with calibrated intrinsics (their extrinsics are ignored), in rig order.
        board: the board (a Checkerboard, or a CharucoBoard whose detections may hold part of
            its corners).
        views: view name -> one detection per camera (None where that camera did not find the
            board); one view is one instant, seen by several cameras.
        floor_view: the view of the board lying face up on the floor or seat, x along the
            patient's right; sets the world frame. None: the world frame is the first camera's.
        origin_m: world coordinates of the floor board's corner 0 (metres), e.g. (0, 0.45, 0)
            for a corner on a seat 0.45 m high.
        turn_deg: the floor board's x axis points this many degrees from +X towards -Z (turned
            counter-clockwise seen from above) instead of along +X.
        check_world: refuse a world frame no room has (:func:`check_world_frame`).
        weigh_views: weigh each camera's view of a board by its own corner scatter (see
            :func:`view_sigmas_px`); False: every corner alike.
        lens_information: per camera, the information matrix of its lens step's estimate
            (:attr:`calibration.intrinsics.IntrinsicsResult.information`) or None. Cameras with
            one get their focal lengths, principal point and distortion refined together with
            the poses, the lens step's estimate a prior of that weight; the others keep theirs.
    Raises:
        CalibrationError: a camera shares no view with the others, the floor view is missing, or
            the world frame it gives is not a room's.
    """
    n = len(cameras)
    if n < 2:
        raise CalibrationError("extrinsic calibration needs at least two cameras")
    for name, dets in views.items():
        if len(dets) != n:
            raise CalibrationError(f"view {name!r}: {len(dets)} detections for {n} cameras")
    views = {name: dets for name, dets in views.items() if sum(d is not None for d in dets) >= 1}
    if floor_view is not None and floor_view not in views:
        raise CalibrationError(f"the floor board view {floor_view!r} was not found by any camera: check that image")
    pnp = {(name, c): board_pose_in_camera(cameras[c], d, board) for name, dets in views.items() for c, d in enumerate(dets) if d is not None}
    cam_poses = _initial_camera_poses(cameras, board, views, pnp)
    view_names = list(views)
    board_poses = []
    for name in view_names:  # from the camera that sees the board largest
        dets = views[name]
        c = max((c for c in range(n) if dets[c] is not None), key=lambda c: np.ptp(dets[c].uv_px, axis=0).prod())
        board_poses.append(compose(invert(cam_poses[c]), pnp[name, c]))
    obs = [(c, v) for v, name in enumerate(view_names) for c in range(n) if views[name][c] is not None]
    objs = [views[view_names[v]][c].object_points(board) for c, v in obs]
    starts = np.concatenate([[0], np.cumsum([2 * len(o) for o in objs])])  # residual rows of each observation

    weights = np.ones(starts[-1])
    warnings_pre: list[str] = []
    n_pose = 6 * (n - 1) + 6 * len(view_names)
    prior = lens_prior(cameras, lens_information, sorted({c for c, _ in obs}), n_pose)

    def residuals(x: np.ndarray) -> np.ndarray:
        cams = [(np.eye(3), np.zeros(3))] + _unpack(x[: 6 * (n - 1)], n - 1)
        boards = _unpack(x[6 * (n - 1) : n_pose], len(view_names))
        lens = prior.cameras(cameras, x) if x.size > n_pose else cameras
        out = np.empty(starts[-1])
        for k, (c, v) in enumerate(obs):
            out[starts[k] : starts[k + 1]] = _reprojection(lens[c], compose(cams[c], boards[v]),
                                                           views[view_names[v]][c], objs[k]).ravel()
        out *= weights
        return out if x.size == n_pose else np.concatenate([out, prior.residuals(x)])

    sparsity = lil_matrix((int(starts[-1]), n_pose), dtype=int)
    for k, (c, v) in enumerate(obs):
        rows = slice(int(starts[k]), int(starts[k + 1]))
        if c > 0:
            sparsity[rows, 6 * (c - 1) : 6 * c] = 1
        sparsity[rows, 6 * (n - 1) + 6 * v : 6 * (n - 1) + 6 * v + 6] = 1
    x0 = np.concatenate([_pack(cam_poses[1:]), _pack(board_poses)])
    sol = least_squares(residuals, x0, jac_sparsity=sparsity, loss="soft_l1", f_scale=1.0, x_scale="jac", method="trf",
                        xtol=1e-8, ftol=1e-8, gtol=1e-8, max_nfev=100)
    if weigh_views or prior.lens_cams:  # again, each view weighed by its own scatter (in units of it: the loss scale 3 sigma)
        sigma = view_sigmas_px([sol.fun[starts[k] : starts[k + 1]] for k in range(len(obs))])
        if not weigh_views:  # every view alike, in units of the pooled scatter (the lens prior's units)
            sigma = np.full_like(sigma, np.sqrt(np.mean(sol.fun**2)))
        weights = np.repeat(1.0 / sigma, np.diff(starts))
        x0, jac = sol.x, sparsity
        if prior.lens_cams:
            x0 = np.concatenate([sol.x, prior.x0])
            jac = prior.extend_sparsity(sparsity, [np.arange(starts[k], starts[k + 1]) for k in range(len(obs))],
                                        [c for c, _ in obs])
        first = sol
        # the lens columns are strongly correlated (focal length with distortion): LSMR's default
        # tolerances left each step inexact and the adjustment crawled (155 evaluations, 28 s, on
        # the test's rig) where tight ones settle it in 5 (1 s)
        tight = {"tr_options": {"atol": 1e-12, "btol": 1e-12, "maxiter": 2000}} if prior.lens_cams else {}
        sol = least_squares(residuals, x0, jac_sparsity=jac, loss="soft_l1", f_scale=3.0, x_scale="jac",
                            method="trf", xtol=1e-8, ftol=1e-8, gtol=1e-8, max_nfev=100, **tight)
        if prior.lens_cams and sol.status == 0:   # not converged: the lens data stay as the lens step found them
            warnings_pre.append("the lens data were not refined (the adjustment did not settle): they stay as the lens step found them")
            sol = least_squares(residuals, first.x, jac_sparsity=sparsity, loss="soft_l1", f_scale=3.0, x_scale="jac",
                                method="trf", xtol=1e-8, ftol=1e-8, gtol=1e-8, max_nfev=100)
        elif prior.lens_cams:
            cameras = prior.cameras(cameras, sol.x)
        sol.fun = sol.fun[: int(starts[-1])] / weights   # back to pixels for the report
    cam_poses = [(np.eye(3), np.zeros(3))] + _unpack(sol.x[: 6 * (n - 1)], n - 1)
    board_poses = _unpack(sol.x[6 * (n - 1) : n_pose], len(view_names))
    rms = np.full(n, np.nan)
    n_views = np.zeros(n, int)
    for c in range(n):
        mine = [k for k, (cc, _) in enumerate(obs) if cc == c]
        n_views[c] = len(mine)
        if mine:
            rms[c] = _rms(np.concatenate([sol.fun[starts[k] : starts[k + 1]] for k in mine]).reshape(-1, 2))
    warnings = warnings_pre
    if floor_view is not None:
        T_ref_world = compose(board_poses[view_names.index(floor_view)], board_from_world(origin_m, turn_deg))
    else:
        T_ref_world = (np.eye(3), np.zeros(3))
        warnings.append(f"no floor board view: the world frame is {cameras[0].name}'s own (Y is not up)")
    out = tuple(
        Camera.from_rotation(cam.name, cam.size_px, cam.K, cam.dist, *compose(T, T_ref_world), fisheye=cam.fisheye)
        for cam, T in zip(cameras, cam_poses)
    )
    if floor_view is not None and check_world:
        centre = floor_board_centre_m(board, origin_m, turn_deg)
        check_world_frame(out, centre, min(0.0, float(centre[1])))
    for c in range(n):
        if rms[c] > 1.0:
            warnings.append(f"{cameras[c].name}: board corners fit to {rms[c]:.2f} px only: check its intrinsics and blurred images")
    for w in warnings:  # returned for the caller to show; logged for the record
        log.info(w)
    return ExtrinsicsResult(out, rms, n_views, floor_view is not None, tuple(warnings))


@dataclass(frozen=True)
class LensPrior:
    """Lens data refined in a bundle adjustment, the lens step's estimate a prior of its own weight.

    The lens parameters (fx, fy, cx, cy, distortions) of ``lens_cams`` follow the adjustment's
    ``n_base`` other parameters; the prior's residuals ``L.T @ (p - p0)`` (``L L.T`` = the lens
    step's information matrix) follow its data residuals, which must then be in units of their
    scatter: the sum of squares is the lens step's and the rig's evidence together.
    Freeing the lens without the prior let the principal points wander 3-7 px on ``corners4``
    (the held views do not pin them down, docs/CALIBRATION.md).
    """

    lens_cams: tuple[int, ...]
    cols: dict
    roots: dict
    x0: np.ndarray
    n_base: int

    def cameras(self, cameras: Sequence[Camera], x: np.ndarray) -> list[Camera]:
        """The cameras with the lens parameters of ``x``."""
        out = list(cameras)
        for c in self.lens_cams:
            p = x[self.cols[c]]
            cam = cameras[c]
            K = np.array([[p[0], cam.K[0, 1], p[2]], [0.0, p[1], p[3]], [0.0, 0.0, 1.0]])
            out[c] = Camera(cam.name, cam.size_px, K, p[4:], cam.rvec, cam.t_m, cam.fisheye, cam.rolling_shutter_s)
        return out

    def residuals(self, x: np.ndarray) -> np.ndarray:
        p0 = self.x0
        off = self.n_base
        return np.concatenate([self.roots[c].T @ (x[self.cols[c]] - p0[self.cols[c].start - off : self.cols[c].stop - off])
                               for c in self.lens_cams])

    def extend_sparsity(self, sparsity, row_groups: Sequence[np.ndarray], group_cams: Sequence[int]):
        """The adjustment's Jacobian pattern with the lens columns and the prior's rows added:
        ``row_groups[k]`` are data rows of camera ``group_cams[k]``."""
        n_lens = self.x0.size
        lens = lil_matrix((sparsity.shape[0], n_lens), dtype=int)
        for rows, c in zip(row_groups, group_cams):
            if c in self.cols:
                sl = self.cols[c]
                lens[np.asarray(rows)[:, None], np.arange(sl.start, sl.stop)[None, :] - self.n_base] = 1
        own = lil_matrix((n_lens, n_lens), dtype=int)
        for c in self.lens_cams:
            sl = slice(self.cols[c].start - self.n_base, self.cols[c].stop - self.n_base)
            own[sl, sl] = 1
        return bmat([[sparsity, lens], [None, own]]).tocsr()


def lens_prior(cameras: Sequence[Camera], information: Sequence[np.ndarray | None] | None, seen: Sequence[int],
               n_base: int) -> LensPrior:
    """The :class:`LensPrior` of the cameras in ``seen`` with an information matrix (fisheye lenses
    keep theirs).

    Raises:
        CalibrationError: an information matrix that does not fit its camera's lens.
    """
    cols, roots, x0 = {}, {}, []
    col = n_base
    lens_cams = tuple(c for c in seen if information is not None and information[c] is not None and not cameras[c].fisheye)
    for c in lens_cams:
        K = cameras[c].K
        p0 = np.concatenate([[K[0, 0], K[1, 1], K[0, 2], K[1, 2]], cameras[c].dist])
        info = np.asarray(information[c], float)
        if info.shape != (p0.size, p0.size):
            raise CalibrationError(f"{cameras[c].name}: lens information for {info.shape} parameters, "
                                   f"the lens has {p0.size}: calibrate its lens again")
        w, V = np.linalg.eigh(0.5 * (info + info.T))   # L L.T = info; directions of no information get none
        roots[c] = V * np.sqrt(np.clip(w, 0.0, None))
        cols[c] = slice(col, col + p0.size)
        col += p0.size
        x0.append(p0)
    return LensPrior(lens_cams, cols, roots, np.concatenate(x0) if x0 else np.zeros(0), n_base)


def view_sigmas_px(residuals: Sequence[np.ndarray]) -> np.ndarray:
    """Each observation's corner scatter, pixels: one camera's view of one board, from its residuals.

    Corners are not equally exact: a board seen obliquely or from afar by one camera gives corners
    several times as scattered as another camera's (ChArUco on the seat of ``corners4``: 0.3-0.5 px
    RMS from the truth in the front cameras, 0.1-0.15 px in the back ones; docs/CALIBRATION.md), and
    the board lying on the seat alone sets the world frame. Each observation's variance is its mean
    squared residual, shrunk towards the pooled one with the weight of one corner (so a view of few
    corners cannot claim to be exact by chance): weighing by the inverse gives the least-squares
    estimate for unequal scatter (variance components, as in photogrammetric adjustment).
    """
    sq = [float(np.sum(np.asarray(r, float) ** 2)) for r in residuals]
    m = [np.asarray(r).size for r in residuals]
    pooled = sum(sq) / max(sum(m), 1)
    return np.sqrt((np.array(sq) + 2.0 * pooled) / (np.array(m) + 2.0))


def board_from_world(origin_m=(0.0, 0.0, 0.0), turn_deg: float = 0.0) -> Pose:
    """T_board_world of a board lying face up with corner 0 at ``origin_m`` (see calibrate_extrinsics)."""
    a = np.radians(turn_deg)
    # The board's x in the world: +X turned by turn_deg about +Y (counter-clockwise from above: towards -Z).
    Ry = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    R_world_board = Ry @ _WORLD_AXES_IN_BOARD.T
    R_bw = R_world_board.T
    return R_bw, -R_bw @ np.asarray(origin_m, float)


def world_from_floor_board(cameras: Sequence[Camera], detections: Sequence[Detection | None], board, *,
                           origin_m=(0.0, 0.0, 0.0), turn_deg: float = 0.0,
                           check_world: bool = True) -> tuple[tuple[Camera, ...], float]:
    """Move a rig calibrated in any frame into the world frame of a floor board.

    The board's pose is fitted to its corners in every camera that found it (the cameras' poses
    kept fixed), then every camera is re-expressed in the board's world frame.

    Args:
        cameras: the calibrated rig (any common frame, metric).
        detections: one per camera, None where the board was not found.
    Returns:
        the cameras in the world frame, and the RMS reprojection error of the board in pixels.
    Raises:
        CalibrationError: no camera found the board.
    """
    seen = [c for c, d in enumerate(detections) if d is not None]
    if not seen:
        raise CalibrationError("no camera found the floor board: check that it lies fully in view of at least one camera")
    c0 = max(seen, key=lambda c: np.ptp(detections[c].uv_px, axis=0).prod())
    cam_T = [(cam.R, cam.t_m) for cam in cameras]
    T_frame_board = compose(invert(cam_T[c0]), board_pose_in_camera(cameras[c0], detections[c0], board))

    def residuals(x: np.ndarray) -> np.ndarray:
        T = _unpack(x, 1)[0]
        return np.concatenate([_reprojection(cameras[c], compose(cam_T[c], T), detections[c],
                                             detections[c].object_points(board)).ravel() for c in seen])

    sol = least_squares(residuals, _pack([T_frame_board]), loss="soft_l1", f_scale=1.0, x_scale="jac", xtol=1e-12, ftol=1e-12)
    T_frame_world = compose(_unpack(sol.x, 1)[0], board_from_world(origin_m, turn_deg))
    out = tuple(
        Camera.from_rotation(cam.name, cam.size_px, cam.K, cam.dist, *compose(T, T_frame_world), fisheye=cam.fisheye)
        for cam, T in zip(cameras, cam_T)
    )
    if check_world:
        centre = floor_board_centre_m(board, origin_m, turn_deg)
        check_world_frame(out, centre, min(0.0, float(centre[1])))
    return out, _rms(sol.fun.reshape(-1, 2))


FACING_MARGIN_DEG = 15.0  # how far outside its picture a camera may aim and still count as facing the board
MAX_ROLL_DEG = 25.0  # a camera's picture turned further from the world's vertical is taken for a wrong frame
_NEAR_VERTICAL_DEG = 20.0  # cameras looking this close to straight up or down have no meaningful roll
_WRONG_FLOOR = ("the floor view is not the board lying face up on the seat or floor (check --floor / --floor-views "
                "and --origin; a camera mounted on its side: --no-world-check)")


def check_world_frame(cameras: Sequence[Camera], board_centre_m, floor_y_m: float = 0.0) -> None:
    """Refuse a world frame that cannot be a room's.

    Every camera must stand above the floor (Y above ``floor_y_m``), have the floor board's centre
    within its picture's diagonal field of view plus ``FACING_MARGIN_DEG``, and stand upright:
    the world's vertical within ``MAX_ROLL_DEG`` of its picture's (cameras looking nearly straight
    up or down excepted). A board held up by hand taken for the floor board turns the world's
    vertical sideways and breaks at least one of these on the simulated rigs
    (tests/calibration/test_calib_extrinsics.py).
    Raises:
        CalibrationError: one line naming the camera and what to check.
    """
    target = np.asarray(board_centre_m, float)
    for cam in cameras:
        if cam.centre_m[1] <= floor_y_m:
            raise CalibrationError(f"the world frame puts {cam.name} {floor_y_m - cam.centre_m[1]:.2f} m below the floor: "
                                   + _WRONG_FLOOR)
        w, h = cam.size_px
        half_diag = np.degrees(np.arctan(0.5 * np.hypot(w / cam.K[0, 0], h / cam.K[1, 1])))
        to_board = cam.R @ (target - cam.centre_m)
        angle = np.degrees(np.arccos(np.clip(to_board[2] / np.linalg.norm(to_board), -1.0, 1.0)))
        if angle > half_diag + FACING_MARGIN_DEG:
            raise CalibrationError(f"the world frame turns {cam.name} {angle:.0f} degrees away from the floor board: "
                                   + _WRONG_FLOOR)
        up = cam.R[:, 1]  # the world's +Y in camera coordinates (image y points down)
        if abs(up[2]) < np.cos(np.radians(_NEAR_VERTICAL_DEG)):
            roll = float(np.degrees(np.arctan2(up[0], -up[1])))
            if abs(roll) > MAX_ROLL_DEG:
                raise CalibrationError(f"the world frame tips {cam.name} {abs(roll):.0f} degrees on its side: " + _WRONG_FLOOR)


def floor_board_centre_m(board, origin_m=(0.0, 0.0, 0.0), turn_deg: float = 0.0) -> np.ndarray:
    """World position of the centre of a floor board's inner corners (corner 0 at ``origin_m``)."""
    R_bw, t_bw = board_from_world(origin_m, turn_deg)
    centre_board = board.object_points().mean(axis=0)
    return R_bw.T @ (centre_board - t_bw)


def rig_errors(cameras: Sequence[Camera], truth: Sequence[Camera]) -> tuple[np.ndarray, np.ndarray]:
    """Per camera: optical-centre distance (mm) and rotation angle (degrees) from the truth."""
    pos = np.array([1000.0 * np.linalg.norm(a.centre_m - b.centre_m) for a, b in zip(cameras, truth)])
    ang = []
    for a, b in zip(cameras, truth):
        c = (np.trace(a.R @ b.R.T) - 1.0) / 2.0
        ang.append(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
    return pos, np.array(ang)
