"""The tracker's tuned numbers, each named once with the reason for its value (docs/TRACKING.md)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, slots=True)
class TrackerParams:
    """Knobs of the tracker.

    Attributes:
        base_sigma_m: position uncertainty of a prediction for a marker measured last frame.
        accel_sigma_m: added uncertainty per frame without a measurement (unmodelled motion).
        max_sigma_frames: the uncertainty stops growing after this many frames (the hidden-marker
            estimate, not the extrapolation, is the prediction then).
        speed_sigma: added uncertainty as a fraction of the marker's displacement per frame (a fast
            swing changes velocity more between frames than a slow one).
        window_sigmas: search-window half size in prediction standard deviations (plus the ball).
        max_window_px: cap on the window half size.
        window_ball_factor: the window's half size holds this many ball radii (a ball's blob reaches
            a little past its projected radius: blur, rounding)...
        window_margin_px: ...plus this many pixels (a ball of a few pixels: its rounding and noise).
        min_depth_m: depths below this are clamped when sizing windows (a prediction at a camera's
            centre would divide by zero).
        gate_sigmas: a candidate farther than this many sigmas from the prediction is rejected.
        gate_slack_m: added to the gate's distance (the ball's own size: a sharp prediction must
            not reject its ball for a few millimetres).
        same_ball_m: two markers whose candidates are nearer than this hold the same ball: only one
            keeps it.
        segment_tol_m: largest change of a learned distance to a neighbour on the same segment.
        returning_tol_factor: a marker found again is checked against the neighbours known only by
            their last estimate with this many times ``segment_tol_m`` (an estimate is less sure).
        length_learning_rate: each measured frame set moves a learned segment length by this
            share towards the measured distance (slow: one wrong ball must not teach a length).
        reacquire_every: full-frame search for lost markers every this many frames.
        reacquire_radius_m: a lost marker with no measured neighbour on its segment takes a free
            point of its colour this near to where it was last seen.
        taken_radius_m: a full-frame point this near a marker measured in its windows is that
            marker's ball and free for no other (about a ball's diameter).
        stale_after: an estimated marker unmeasured for this many frames is searched for in the
            full frame too (its estimate may have drifted off its ball, e.g. after the cameras
            were blocked while the arm moved: its windows then miss it for good), every
            ``reacquire_stale_every`` frames.
        reidentify_after: identify again when more than half the markers are lost this many frames.
        identify_hold_s: the markers are named only once the patient has held still this long
            (:class:`tracking.labelling.still.Stillness`; 0.2 s in ``rehab validate
            --population``); 0 (the default for now): on any frame set, moving or not.
        rejudge_every: while the patient holds still and no labelling is confident, the labelling
            is judged again every this many frame sets (a judgement costs tens of milliseconds).
        exchange_after: a pair of markers that the self-checks find exchanged this many frame sets
            running is named back (one frame set can be a passing crossing).
        max_reproj_px: largest RMS reprojection error of a candidate.
        max_reproj_px_two_view: the same for a candidate seen by two cameras only (which must also
            show a ball of the right size in both).
        two_view_min_ratio: ...the right size: a blob radius at least this fraction of the ball's
            projected radius (and at most ``oversize_ratio``).
        max_loo_px: of three or more views, the worst is dropped when the point triangulated
            from the others misses it by more than this (a wrong ball in one view).
        view_choice_margin_m: of three or more views, the worst is dropped unless another view's
            removal leaves a fitting point this much nearer the prediction (then that view goes).
        partial_ratio, oversize_ratio: a view whose blob radius is below / above these fractions
            of the ball's projected radius is left out while two other views remain (a partly
            hidden ball: centroid shifted by ~1 px at 0.8-0.9; a blob holding another ball of the
            colour: 0.8 of those above 1.1 were > 2 px off in the simulated motions); a
            two-view candidate needs both views at most ``oversize_ratio``.
        sliver_area_ratio: a window's blob under this fraction of the ball's projected area is a
            ball mostly hidden in that camera: no view.
        simple_max_area_ratio, simple_min_roundness: a window's mask up to this many balls' area
            and at least this round is one ball, its centroid taken from the moments; otherwise
            the window holds several balls (or clutter) and its regions are separated.
        shared_view_ratio: two markers' window centroids nearer than this fraction of the smaller
            projected radius are one ball's (the same blob): one marker keeps that view.
        marker_sigma_px: position noise of a measured marker, in pixels of the camera nearest to it
            (its pixel's size there), for the hidden-marker estimator's weights
            (:attr:`~tracking.hidden.Estimator.marker_sigma_m`).
        view_sigma_px: centroid uncertainty of a single full view of a marker that is not
            measured; such views go to the hidden-marker estimator as rays
            (:meth:`~tracking.hidden.Estimator.observe_views`).
        arc_fit_ratio, arc_fit_roundness: a window region whose equivalent radius is below
            ``arc_fit_ratio`` times the ball's (projected radius less ``ARC_EDGE_SHRINK_PX``), or
            whose roundness is below ``arc_fit_roundness``, is taken for a partly hidden ball: its
            centre is fitted to the visible arc of its outline (:func:`~tracking.blobs.arc_centres`)
            instead of its centroid. In the simulated motions at 640x480 this takes 99.8 % of the
            views of balls 10-50 % hidden and 0.2 % of the whole ones (at 320x240 a third of the
            whole ones too: balls of 2.5-3.5 px are seldom round); all 0 turn it off.
        arc_fit_all_below_px: every region (not larger than the whole ball) of a ball whose
            radius (less ``ARC_EDGE_SHRINK_PX``) is below this is fitted: on balls of a few pixels
            neither size nor roundness tells a partly hidden ball, and the fit leaves a whole
            ball's centre where its centroid is (0.168 px RMS either way on the 5661 whole views
            of trunk_lean_compensation at 320x240).
        arc_subpixel: fit those arcs a second time on edges placed by the pixels' coverage
            (``colours`` of :func:`~tracking.blobs.arc_centres`): a binary region reaches into a
            dark background and stops short of a bright one, which moved the centres of partly
            hidden balls 0.2-0.4 px (docs/TRACKING.md, "Partly hidden balls: edges placed by
            coverage"). False: the binary fit alone.
        window_luma: a window holding one whole ball (``simple``, not fitted to its arc, its area
            within the camera's blob gates) has its centroid checked against a fit of the ball in
            the luma (:func:`~tracking.blobs.luma_centre`, as the full-frame detection does) and
            takes the fit's centre where it is sure and differs by more than
            ``window_luma_confirm_px``: webcams send colour at half resolution (MJPEG 4:2:0,
            4:2:2), which moves the colour mask's edge; the luma is at full resolution
            (docs/TRACKING.md, "Luma centres in the search windows"). False: the colour centroids
            alone.
        window_luma_confirm_px: the fit's centre replaces the window's centroid only where they
            differ by more than this, as the full frame keeps its colour centre within
            ``tracking.blobs.LUMA_CONFIRM_PX`` of the fit. On the population's tuning draws 1-20
            (webcams, 7 draws named) 0.2 px made the measured RMSE of all 7 smaller (median ratio
            0.984), 0 of 6 (0.985, one 3 % worse); 0: every sure fit is taken.
    """

    base_sigma_m: float = 0.008
    accel_sigma_m: float = 0.006
    max_sigma_frames: int = 5
    speed_sigma: float = 0.35
    window_sigmas: float = 2.5
    max_window_px: float = 80.0
    gate_sigmas: float = 3.0
    same_ball_m: float = 0.025
    segment_tol_m: float = 0.03
    reacquire_every: int = 3
    reacquire_radius_m: float = 0.08
    stale_after: int = 3
    reacquire_stale_every: int = 6
    reidentify_after: int = 30
    identify_hold_s: float = 0.0
    max_reproj_px: float = 2.5
    max_reproj_px_two_view: float = 1.2
    max_loo_px: float = 3.0
    partial_ratio: float = 0.88
    view_choice_margin_m: float = 0.02
    oversize_ratio: float = 1.1
    view_sigma_px: float = 0.5
    marker_sigma_px: float = 0.25
    arc_fit_ratio: float = 0.95
    arc_fit_roundness: float = 0.9
    arc_fit_all_below_px: float = 4.0
    arc_subpixel: bool = True
    window_luma: bool = False
    window_luma_confirm_px: float = 0.2
    window_ball_factor: float = 1.2
    window_margin_px: float = 2.0
    min_depth_m: float = 1e-3
    gate_slack_m: float = 0.01
    returning_tol_factor: float = 2.0
    length_learning_rate: float = 0.05
    taken_radius_m: float = 0.02
    rejudge_every: int = 3
    exchange_after: int = 2
    two_view_min_ratio: float = 0.65
    sliver_area_ratio: float = 0.4
    simple_max_area_ratio: float = 1.6
    simple_min_roundness: float = 0.6
    shared_view_ratio: float = 0.5

    def full_view(self, ratio: np.ndarray) -> np.ndarray:
        """Views whose blob radius over the ball's projected radius (``ratio``) shows the whole
        ball: neither partly hidden nor holding more than the ball (False for NaN)."""
        return (ratio >= self.partial_ratio) & (ratio <= self.oversize_ratio)
