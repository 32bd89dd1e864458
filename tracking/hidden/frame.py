"""What an estimator sees of one frame: positions so far, the predictions, and the shared state."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracking.hidden.arms import ArmTracker
from tracking.hidden.elbows import ElbowState
from tracking.hidden.history import ReferenceHistory
from tracking.hidden.layout import Layout
from tracking.hidden.params import EstimatorParams
from tracking.hidden.pivots import ShoulderPivots
from tracking.hidden.views import ViewRays


@dataclass(frozen=True)
class SharedState:
    """The learned state every estimator may read (and the hinge and forearm update)."""

    layout: Layout
    params: EstimatorParams
    history: ReferenceHistory
    pivots: ShoulderPivots
    elbows: ElbowState
    arms: ArmTracker
    views: ViewRays


@dataclass(frozen=True)
class FrameInputs:
    """One frame's inputs of the estimators (arrays shared, not copied).

    Attributes:
        p: (M, 3) positions: measured rows, and the rows estimated earlier in this frame.
        ok: (M,) measured in this frame.
        weight: (M,) weight of each marker as support of a fit (1 measured, ``estimate_weight``
            estimated earlier in this frame, 0 no position yet).
        prior: (M, 3) predictions: the neighbours' motion (equation 6) plus the marker's own
            velocity relative to them, decaying.
        base: (M, 3) the last frame's output.
        velocity: (M, 3) the last frame's output step.
        eq6: (M, 3) equation 6; ``eq6_ok`` (M,): a weighted neighbour's motion is known.
        state: the shared learned state.
    """

    p: np.ndarray
    ok: np.ndarray
    weight: np.ndarray
    prior: np.ndarray
    base: np.ndarray
    velocity: np.ndarray
    eq6: np.ndarray
    eq6_ok: np.ndarray
    state: SharedState
