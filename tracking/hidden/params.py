"""The tuned numbers of hidden-marker estimation, each named with its reason.

One frozen dataclass: :class:`~tracking.hidden.Estimator` takes it (or its fields as keywords);
the marker set's ``hidden_markers:`` section sets the per-marker limits
(:func:`~tracking.hidden.estimator_config`). docs/HIDDEN_MARKERS.md has the measurements behind
the values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence


@dataclass(frozen=True)
class EstimatorParams:
    """Tuning of :class:`~tracking.hidden.Estimator` (times in seconds, lengths in metres).

    Attributes:
        own_velocity: equation 6 adds the marker's own last displacement (the paper's formula;
            with the estimate fed back it runs away, so off).
        tolerance_m: an estimate whose distance to a measured near-rigid partner leaves the range
            learned while both were measured by more than this is dropped (skin and marker noise:
            30 mm).
        max_hidden_s: an estimate older than this is dropped (a scalar or one per marker; the
            marker set gives one per estimator).
        max_unsupported_s: an estimate whose body segment has no measured marker for longer than
            this is dropped (a whole forearm hidden: its turning is guesswork).
        fps: frame rate; the times above and the learning memories are converted with it.
        prior_weight: weight of the predicted position in rigid fits that leave a rotation free
            (two supports): weak, it only picks the free turn.
        min_spread_m: support markers nearer than this (RMS) to one line leave a rotation free.
        pivot_prior_m: the shoulder pivot (glenohumeral centre) relative to the acromion marker in
            the trunk frame before anything is learned (x right, y up, z back): 6 cm below it.
        pivot_memory_s: forgetting time of the pivot's least squares (it follows slow changes).
        min_singular: hinge constraints weaker than this leave the elbow axis to the prediction.
        weak_singular: a second hinge constraint between this and ``min_singular`` (a straight
            elbow with the wrists measured: about 0.28 for any body) is averaged with the
            prediction instead of being ignored.
        estimate_weight: weight of a marker estimated earlier in the same frame as support of a
            rigid fit (measured markers weigh 1).
        velocity_decay_s: where a fit leaves a direction free, the marker's own velocity relative
            to its neighbours decays with this time constant (0: none; scalar or per marker).
        max_rigid_residual_m: a styloid marker takes the rigid forearm fit while its supports fit
            within this (RMS); beyond, the forearm turned and the wrist circle places it.
        forearm_sigma_rad: uncertainty of the predicted flexion and supination in a forearm fit.
        forearm_decay_s: with both styloid markers hidden the forearm's angular velocities decay
            with this time constant (a seated patient's forearm mostly stops).
        scapular_rhythm: upward rotation of the scapula per degree of humerus elevation within
            ``rhythm_deg`` (the 2:1 scapulohumeral rhythm): the learned pivot turns with it.
        rhythm_deg: the elevation range (degrees) over which the scapula turns.
        forearm_accel_deg_s2: the unknown angular acceleration of an extrapolated forearm (its
            uncertainty grows as that plus 30 % of the angular speed).
        max_forearm_sigma_deg: past this extrapolation uncertainty both styloid estimates are
            dropped.
        forearm_reversal: a forearm fit's prior is also uncertain by this times ``|v| age``: the
            turn may reverse within the frames it was extrapolated (2: a full reversal).
        max_hinge_sigma_deg: an elbow axis whose turn the hinge's conditions do not pin is
            extrapolated and dropped past this uncertainty.
        max_forearm_stale_s: a LOST styloid marker is estimated again from the other, measured,
            while its forearm's angles are at most this old.
        view_gate_m: a single camera view of a hidden marker counts when its ray passes this near
            the predicted marker (farther: another ball of the colour).
        drop_unpinned: a styloid whose measured partner has not pinned both forearm angles for
            longer than the extrapolation allows is LOST (palm up or down: flexion and
            supination confounded).
        view_estimate_sigma_m: uncertainty of an elbow hinge's estimate across a view's ray.
        axis_square: share of the forearm model's flexion axis component along the humerus taken
            out (1: perpendicular to the humerus; 0: as measured); None: per frame, the markers'
            noise against ``axis_model_sigma_deg`` decides.
        axis_model_sigma_deg: how far the hinge's axis strays from perpendicular to the humerus
            through the learned pivot (the pivot's error, the arm's own geometry).
        marker_sigma_m: position noise of a measured marker until the caller sets
            ``Estimator.marker_sigma_m`` per frame (the tracker does, from the pixel size).
        limb_accel_m_s2: the unknown acceleration of a coasting arm chain.
        max_extrapolation_m: a hidden arm chain coasts on its velocity while ``0.5 a t^2`` stays
            within this.
        speed_share: share of an extrapolated turn's angular speed counted as its uncertainty
            (the turn may slow down or speed up), beside the unknown acceleration.
        forearm_prediction_frames: a forearm's predicted angles carry its angular velocities over
            at most this many frames since they were last known.
        forearm_fit_sigma_m: noise of a measured styloid marker in the forearm fit.
        bend_min_sine: the side the elbow bends is learned where the elbow is clearly flexed (the
            sine of its angle above this; near straight the side is noise).
        bend_sense_min: the learned side picks between the hinge's mirror images once its running
            mean passes this (before: the previous axis' side).
        arm_velocity_memory_s: memory of the forearm's angular velocities (0.1 s: a few frames).
        shape_memory_s: memory of the learned hinge lengths and forearm shapes (0.3 s).
        history_max_s: the longest stored past in which a rigid fit looks for its reference frame
            (where no marker has a finite ``max_hidden_s``: half of it).
    """

    own_velocity: bool = False
    tolerance_m: float = 0.03
    max_hidden_s: float | Sequence[float] = 5.0
    max_unsupported_s: float = 0.5
    fps: float = 30.0
    prior_weight: float = 0.1
    min_spread_m: float = 0.015
    pivot_prior_m: Sequence[float] = (0.0, -0.06, 0.0)
    pivot_memory_s: float = 3.0
    min_singular: float = 0.3
    weak_singular: float = 0.25
    estimate_weight: float = 0.3
    velocity_decay_s: float | Sequence[float] = 0.15
    max_rigid_residual_m: float = 0.004
    forearm_sigma_rad: float = 0.06
    forearm_decay_s: float = 0.3
    scapular_rhythm: float = 0.5
    rhythm_deg: tuple[float, float] = (30.0, 150.0)
    forearm_accel_deg_s2: float = 150.0
    max_forearm_sigma_deg: float = 3.0
    forearm_reversal: float = 2.0
    max_hinge_sigma_deg: float = 10.0
    max_forearm_stale_s: float = 0.5
    view_gate_m: float = 0.025
    drop_unpinned: bool = True
    view_estimate_sigma_m: float = 0.01
    axis_square: float | None = None
    axis_model_sigma_deg: float = 0.5
    marker_sigma_m: float = 0.0015
    limb_accel_m_s2: float = 3.0
    max_extrapolation_m: float = 0.015
    speed_share: float = 0.3
    forearm_prediction_frames: int = 2
    forearm_fit_sigma_m: float = 0.002
    bend_min_sine: float = 0.3
    bend_sense_min: float = 0.5
    arm_velocity_memory_s: float = 0.1
    shape_memory_s: float = 0.3
    history_max_s: float = 20.0

    def rate(self, memory_s: float) -> float:
        """Per-frame rate of an exponential average with this memory."""
        return 1.0 - math.exp(-1.0 / (float(self.fps) * memory_s))

    def decay(self, tau_s: float) -> float:
        """Per-frame factor of a decay with this time constant (0: none kept)."""
        return math.exp(-1.0 / (float(self.fps) * tau_s)) if tau_s > 0 else 0.0
