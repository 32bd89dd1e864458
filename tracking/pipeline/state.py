"""What the stages of a frame set share: the rig's constants (:class:`Setup`), each marker's
memory across frame sets (:class:`MarkerMemory`) and one frame set's intermediate results
(:class:`FrameState`, handed from stage to stage)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from calibration.camera import Camera, CameraStack
from tracking.markerset import MarkerSet
from tracking.full_frame import BlobGates, blob_gates
from tracking.reconstruction import RigGeometry
from tracking.marker_status import MarkerStatus
from tracking.triangulation import Triangulator

ONES2 = np.ones(2)  # row sums of (N, 2) and (N, 3) arrays as matrix products
ONES3 = np.ones(3)
MEASURED = np.uint8(MarkerStatus.MEASURED)


@dataclass(frozen=True, eq=False)
class Setup:
    """The cameras and the marker set as the stages use them, derived once per tracker.

    Attributes:
        cameras: the calibrated cameras, in the order of the images.
        stack: all cameras at once (:class:`~calibration.camera.CameraStack`).
        geometry: the rig's projection matrices and extrinsics.
        triangulate: the (compiled or numpy) triangulation of observations with a view mask.
        compiled: the hot loops run compiled (numba) where the images allow.
        radius_m: the balls' radius.
        colour: (M,) each marker's colour index; label: (M,) its label in the colour table.
        gates: each camera's blob gates; min_area_px: (C,) their smallest blob area.
        cam_centres: (C, 3) camera centres; ones_cams: (C,) ones (row sums as a product).
        same_segment: (M, M) pairs of markers whose distance is (nearly) constant.
        colour_pairs_ij: the two index arrays of the pairs of markers of one colour.
        row_s: (C,) seconds per pixel row of each camera's rolling shutter (0: global shutter).
    """

    cameras: tuple[Camera, ...]
    stack: CameraStack
    geometry: RigGeometry
    triangulate: Triangulator
    compiled: bool
    radius_m: float
    colour: np.ndarray
    label: np.ndarray
    gates: tuple[BlobGates, ...]
    min_area_px: np.ndarray
    cam_centres: np.ndarray
    ones_cams: np.ndarray
    same_segment: np.ndarray
    colour_pairs_ij: tuple[np.ndarray, np.ndarray]
    row_s: np.ndarray

    @property
    def rolling(self) -> bool:
        """Any camera with a rolling shutter."""
        return bool(self.row_s.any())

    @classmethod
    def of(cls, cameras: Sequence[Camera], markerset: MarkerSet, geometry: RigGeometry, compiled: bool,
           length_pairs: Sequence[tuple[int, int]]) -> Setup:
        """The setup of ``cameras`` and ``markerset``; ``length_pairs`` the near-rigid pairs across
        a joint that the marker set names (hidden_markers.limits)."""
        cameras = tuple(cameras)
        gates = tuple(blob_gates(c, markerset.radius_m) for c in cameras)
        colour = markerset.colour_index
        m = markerset.n_markers
        # pairs of markers whose distance is (nearly) constant: markers of one segment, and the
        # near-rigid pairs across a joint
        seg = np.array(markerset.segments)
        same_segment = (seg[:, None] == seg[None, :]) & ~np.eye(m, dtype=bool)
        for i, j in length_pairs:
            same_segment[i, j] = same_segment[j, i] = True
        # pairs of markers of one colour: their windows can hold the same ball
        colour_pairs = np.argwhere(np.triu(colour[:, None] == colour[None, :], 1))
        return cls(cameras=cameras, stack=CameraStack(cameras), geometry=geometry,
                   triangulate=Triangulator(geometry.extrinsics, compiled=compiled), compiled=compiled,
                   radius_m=markerset.radius_m, colour=colour, label=(colour + 1).astype(np.uint8), gates=gates,
                   min_area_px=np.array([g.min_area_px for g in gates]),
                   cam_centres=np.array([c.centre_m for c in cameras]), ones_cams=np.ones(len(cameras)),
                   same_segment=same_segment, colour_pairs_ij=tuple(np.ascontiguousarray(colour_pairs.T)),
                   row_s=np.array([c.rolling_shutter_s / c.size_px[1] for c in cameras]))


@dataclass(eq=False)
class MarkerMemory:
    """What the tracker remembers of each marker from one frame set to the next.

    Attributes:
        positions: (M, 3) last positions, world metres (NaN: lost).
        velocity: (M, 3) displacement per frame set.
        status: (M,) uint8 :class:`~tracking.marker_status.MarkerStatus`.
        frames_unmeasured: (M,) frame sets since each marker was last measured.
        seg_length: (M, M) learned distances on segments (NaN until learned).
        last_seen: (M, 3) last measured position of each marker.
        seen_pos: (M, C, 6) images off the frame set's instant: each marker's views as seen in the
            last two frame sets (normalized x, y and the view's instant of the last, then of the one
            before; NaN where not used).
        seen_velocity: (M, 3) the velocity per frame set that brings this set's views to its
            instant, from each view's image motion since then (free of its own correction, which
            fed back into the corrected positions' velocity and oscillated under a rolling shutter).
        lost_streak: frame sets running with more than half the markers lost.
        exchanged_streak: frame sets running in which the self-checks found a pair exchanged.
    """

    positions: np.ndarray
    velocity: np.ndarray
    status: np.ndarray
    frames_unmeasured: np.ndarray
    seg_length: np.ndarray
    last_seen: np.ndarray
    seen_pos: np.ndarray
    seen_velocity: np.ndarray
    lost_streak: int = 0
    exchanged_streak: int = 0

    @classmethod
    def empty(cls, n_markers: int, n_cameras: int) -> MarkerMemory:
        """Nothing known: every marker lost."""
        m = n_markers
        return cls(positions=np.full((m, 3), np.nan), velocity=np.zeros((m, 3)),
                   status=np.full(m, MarkerStatus.LOST, dtype=np.uint8), frames_unmeasured=np.zeros(m, dtype=np.int64),
                   seg_length=np.full((m, m), np.nan), last_seen=np.full((m, 3), np.nan),
                   seen_pos=np.full((m, n_cameras, 6), np.nan), seen_velocity=np.zeros((m, 3)))


@dataclass(eq=False)
class FrameState:
    """One frame set on its way through the stages; each stage fills its own fields.

    Attributes:
        index: frame number; time_s: the set's instant.
        skew_s: (C,) each image's instant minus the set's (None: all at the set's instant and no
            rolling shutter).
        pred, sigma, known: the prediction stage's (M, 3) positions, (M,) uncertainty in metres
            and (M,) markers with a position.
        pred_uv, pred_depth: (M, C, 2), (M, C) the predictions in each image (the windows stage).
        pred_cam, moving_cam: (M, C, 3) camera-frame prediction and velocity (m/s), time-aware only.
        windows_px: (M, C, 3) each search window (u, v, half size) or None.
        used_uv: (M, C, 2) the centroids each position came from, or None.
        seen_views, seen_now: the views as seen with their instants (M, C, 3) and the velocity per
            frame set from their image motion (M, 3), time-aware only.
        n_points: full-frame points measured this frame set.
    """

    index: int
    time_s: float
    skew_s: np.ndarray | None = None
    pred: np.ndarray | None = None
    sigma: np.ndarray | None = None
    known: np.ndarray | None = None
    pred_uv: np.ndarray | None = None
    pred_depth: np.ndarray | None = None
    pred_cam: np.ndarray | None = None
    moving_cam: np.ndarray | None = None
    windows_px: np.ndarray | None = None
    used_uv: np.ndarray | None = None
    seen_views: np.ndarray | None = None
    seen_now: np.ndarray | None = None
    n_points: int = 0
