"""Online estimation of hidden markers (docs/HIDDEN_MARKERS.md), without look-ahead.

A marker that no camera pair measures in a frame is *estimated* from the past and from this
frame's other markers, or reported *lost*. :class:`Estimator` keeps the state and runs every frame;
each marker's estimator is named in the marker set (``hidden_markers:``, :func:`estimator_config`)
and found in :mod:`~tracking.hidden.registry`. Layout of the package:

- ``estimator.py``: statuses, order and gates; ``params.py``: the tuned numbers;
  ``config.py``: the marker set's section as the estimator's arguments;
- ``methods/``: one module per estimator (equation 5, equation 6, rigid, hinge, forearm); a new
  estimator is a new file there;
- shared state: ``history.py`` (rigid references), ``pivots.py`` (trunk frame, shoulder pivots),
  ``elbows.py`` (hinge and wrist-circle constants), ``arms.py`` (forearm angles), ``views.py``
  (single camera rays), ``drift.py``, ``coasting.py``;
- pure math: ``geometry.py``, ``forearm_model.py``.
"""

from tracking.hidden.codes import DROP, Method
from tracking.hidden.config import estimator_config
from tracking.hidden.estimator import Estimator
from tracking.hidden.forearm_model import (
    ElbowFrame,
    ForearmShape,
    elbow_frame,
    fit_forearm,
    forearm_angles,
    forearm_markers,
    wrist_centre,
)
from tracking.hidden.frame import FrameInputs, SharedState
from tracking.hidden.geometry import hinge_axis, kabsch, spread_m, trunk_rotation
from tracking.hidden.layout import Forearm, Hinge
from tracking.hidden.methods.constant_velocity import constant_velocity
from tracking.hidden.methods.neighbours import neighbour_motion
from tracking.hidden.methods.rigid import rigid_estimate
from tracking.hidden.params import EstimatorParams
from tracking.hidden.registry import HiddenMethod, register

__all__ = [
    "DROP", "ElbowFrame", "Estimator", "EstimatorParams", "Forearm", "ForearmShape", "FrameInputs", "HiddenMethod",
    "Hinge", "Method", "SharedState", "constant_velocity", "elbow_frame", "estimator_config", "fit_forearm",
    "forearm_angles", "forearm_markers", "hinge_axis", "kabsch", "neighbour_motion", "register", "rigid_estimate",
    "spread_m", "trunk_rotation", "wrist_centre",
]
