"""Each arm's forearm flexion and supination, tracked from frame to frame.

While an arm's four chain markers are measured its forearm shape and angles are learned; with one
styloid marker hidden the angles are fitted to the measured one (and to single camera views of
the hidden one) near their prediction; with both hidden they are extrapolated until their
uncertainty passes ``max_forearm_sigma_deg``. docs/HIDDEN_MARKERS.md ("Forearm") has the model.
"""

from __future__ import annotations

import math

import numpy as np

from tracking.hidden.codes import DROP
from tracking.hidden.forearm_model import (
    ElbowFrame,
    ForearmShape,
    elbow_frame,
    fit_forearm,
    forearm_angles,
    forearm_angles_floats,
    forearm_markers,
)
from tracking.hidden.layout import Layout
from tracking.hidden.params import EstimatorParams
from tracking.hidden.pivots import ShoulderPivots
from tracking.hidden.views import ViewRays


class ArmTracker:
    """Per arm (:attr:`Layout.arms`): learned shape, flexion and supination (rad) and their
    speeds (rad per frame), and how long since the data pinned them."""

    def __init__(self, layout: Layout, params: EstimatorParams, pivots: ShoulderPivots, views: ViewRays) -> None:
        self.layout, self.params, self.pivots, self.views = layout, params, pivots, views
        self.arms = layout.arms
        self.fps = float(params.fps)
        self.accel_rad_s2 = math.radians(params.forearm_accel_deg_s2)
        self.max_sigma_rad = math.radians(params.max_forearm_sigma_deg)
        self.axis_model_sigma_rad = math.radians(params.axis_model_sigma_deg)
        self.beta = params.rate(params.arm_velocity_memory_s)
        self.decay = params.decay(params.forearm_decay_s)
        self.shape_rate = params.rate(params.shape_memory_s)
        self.last_m = np.full((layout.n_markers, 3), np.nan)  # the estimator's last output
        self.marker_sigma_m = np.full(layout.n_markers, float(params.marker_sigma_m))
        self.reset()

    def reset(self) -> None:
        a = len(self.arms)
        self.shape: list[ForearmShape | None] = [None] * a
        self.angles = np.full((a, 2), np.nan)
        self.velocity = np.full((a, 2), np.nan)
        self.age = np.zeros(a, dtype=np.int64)         # frames since the angles were known
        self.unmeasured = np.zeros(a, dtype=np.int64)  # frames with neither styloid measured
        self.unpinned = np.zeros(a, dtype=np.int64)    # frames since the data last pinned both angles
        self.begin_frame(self.last_m, self.marker_sigma_m)

    def begin_frame(self, last_m: np.ndarray, marker_sigma_m: np.ndarray) -> None:
        """Start a frame: the estimator's last output (a hidden shoulder marker's place) and the
        markers' noise now."""
        self.last_m, self.marker_sigma_m = last_m, marker_sigma_m
        self.seen: dict[int, tuple[float, float, bool]] = {}  # arm -> (theta, psi, measured)
        self.var: dict[int, tuple[float, float]] = {}  # arm -> the fit's data variances (rad^2)
        self.points: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.pinned: set[int] = set()

    def learn(self, pl: list, okl: list) -> None:
        """Shape and angles of every arm with its four chain markers measured (lists of floats)."""
        for r, (wa, wb, ea, eb, sh) in enumerate(self.arms):
            if not (okl[wa] and okl[wb] and okl[ea] and okl[eb]):
                continue
            angles = self.forearm_angles_f(r, pl, okl)
            if angles is None:
                continue
            theta, psi, shape = angles
            old = self.shape[r]
            if old is None:
                self.shape[r] = shape
            else:
                self.shape[r] = ForearmShape(*(o + self.shape_rate * (s - o) for o, s in zip(
                    (old.along, old.radius, old.half, old.tilt), (shape.along, shape.radius, shape.half, shape.tilt))))
            self.seen[r] = (theta, psi, True)

    def forearm_angles_f(self, r: int, pl: list, okl: list) -> tuple[float, float, ForearmShape] | None:
        """``forearm_angles(self.elbow_frame(r, p, ok, square=0), p[wa], p[wb])`` in plain floats.
        The learned angles and shape are about the markers' own axis, as the reported supination
        reads it (not squared to the humerus: that measured better on the simulated walk)."""
        wa, wb, ea, eb, sh = self.arms[r]
        shoulder = pl[sh] if okl[sh] else self.last_m[sh].tolist()
        if not all(math.isfinite(x) for x in shoulder):
            return None
        a, b = pl[ea], pl[eb]
        centre = [0.5 * (a[i] + b[i]) for i in range(3)]
        rt = self.pivots.trunk_rot.tolist()
        g = self.pivots.offset_f(self.pivots.shoulder_slot[sh], shoulder, centre)
        pivot = [shoulder[i] + rt[i][0] * g[0] + rt[i][1] * g[1] + rt[i][2] * g[2] for i in range(3)]
        return forearm_angles_floats(a, b, centre, pivot, pl[wa], pl[wb])

    def elbow_frame(self, r: int, p: np.ndarray, ok: np.ndarray, square: float | None = None) -> ElbowFrame | None:
        """Arm r's elbow frame now (the shoulder marker measured, else its last output), its axis
        squared to the humerus by ``square`` (default: ``axis_square``, or per frame the markers'
        noise against the model's)."""
        _, _, ea, eb, sh = self.arms[r]
        shoulder = p[sh] if ok[sh] else self.last_m[sh]
        if not np.all(np.isfinite(shoulder)):
            return None
        pivot = self.pivots.pivot_m(sh, shoulder, 0.5 * (p[ea] + p[eb]))
        if square is None:
            square = self.params.axis_square
        if square is None:
            e = p[eb] - p[ea]
            noise = (self.marker_sigma_m[ea] ** 2 + self.marker_sigma_m[eb] ** 2) / max(float(e @ e), 1e-6)
            square = noise / (noise + self.axis_model_sigma_rad ** 2) if noise > 0 else 0.0
        return elbow_frame(p[ea], p[eb], pivot, square)

    def sigma(self, r: int, frames: float, speed_share: float | None = None) -> np.ndarray:
        """(2,) uncertainty (rad) of arm r's flexion and supination extrapolated ``frames`` ahead:
        an unknown angular acceleration up to ``forearm_accel`` plus ``speed_share`` (default:
        the parameter's) of the speed."""
        if speed_share is None:
            speed_share = self.params.speed_share
        t = frames / self.fps
        speed = np.abs(np.nan_to_num(self.velocity[r])) * self.fps
        return 0.5 * self.accel_rad_s2 * t * t + speed_share * speed * t

    def estimate(self, k: int, p: np.ndarray, ok: np.ndarray, weight: np.ndarray):
        """Styloid marker k from its arm's flexion and supination: fitted to the arm's measured
        styloid marker near their prediction, or (both hidden) the prediction alone, its angular
        velocities decaying, until the extrapolation's uncertainty passes the limit (then
        :data:`~tracking.hidden.codes.DROP`). None where the arm has no state."""
        r, slot = self.layout.arm_of[k]
        if r in self.points:
            return self.points[r][slot]
        wa, wb, ea, eb, _ = self.arms[r]
        shape = self.shape[r]
        angles, vel = self.angles[r], self.velocity[r]
        if shape is None or not np.all(np.isfinite(angles)) or not (weight[ea] > 0 and weight[eb] > 0):
            return None
        frame = self.elbow_frame(r, p, ok)
        if frame is None:
            return None
        measured = [(s, p[w]) for s, w in ((0, wa), (1, wb)) if ok[w]]
        age = int(self.age[r]) + 1  # frames since the angles were last known
        pred = angles + np.nan_to_num(vel) * min(age, self.params.forearm_prediction_frames)
        rays = self.views.nearest((wa, wb), ok, lambda: forearm_markers(frame, shape, float(pred[0]), float(pred[1])))
        evidence = bool(measured)
        theta = psi = math.nan
        if measured or rays:
            fitted = self._fit(r, frame, shape, measured, pred, age, rays)
            if fitted is DROP:
                return DROP
            theta, psi, pinned = fitted
            evidence = evidence or pinned
        if not evidence:  # neither styloid measured, and no view that pins the angles
            if np.any(self.sigma(r, int(self.unmeasured[r]) + 1) > self.max_sigma_rad):
                self.points[r] = (DROP, DROP)
                return DROP
            theta, psi = (float(x) for x in angles + np.nan_to_num(vel) * self.decay)
        self.seen[r] = (theta, psi, evidence)
        pts = forearm_markers(frame, shape, theta, psi)
        self.points[r] = pts
        return pts[slot]

    def _fit(self, r: int, frame: ElbowFrame, shape: ForearmShape, measured: list, pred: np.ndarray,
             age: int, rays: list):
        """Arm r's angles fitted to its measured styloid and views: (theta, psi, pinned), or DROP
        where one styloid has not pinned both angles for longer than the extrapolation allows."""
        prm = self.params
        # the prediction carries the velocity over ``age`` frames, in which the turn may
        # reverse: a change of up to twice the velocity (the walking capture's supination
        # reverses at up to 4000 degrees/s^2, the median being 130)
        sigma = prm.forearm_sigma_rad + self.sigma(r, age, prm.forearm_reversal)
        pinned = [False]
        info = [0.0, 0.0, 0.0]
        theta, psi = fit_forearm(frame, shape, measured, float(pred[0]), float(pred[1]),
                                 float(sigma[0]), float(sigma[1]), sigma_m=prm.forearm_fit_sigma_m, pinned=pinned,
                                 rays=rays, pin_sigma=prm.forearm_sigma_rad, info=info)
        # the data's own variance of each angle (the other one free): how far this fit's step
        # is evidence of the angle's speed (update)
        da, ab, db = info[0] - float(sigma[0]) ** -2, info[1], info[2] - float(sigma[1]) ** -2
        self.var[r] = (1.0 / (da - ab * ab / db) if da > 0 and db > 0 and da * db > ab * ab else math.inf,
                       1.0 / (db - ab * ab / da) if da > 0 and db > 0 and da * db > ab * ab else math.inf)
        if pinned[0]:
            self.pinned.add(r)
        elif measured and prm.drop_unpinned and np.any(
                self.sigma(r, int(self.unpinned[r]) + 1) > self.max_sigma_rad):
            # one styloid measured, but for a while it has not pinned both angles (palm up or
            # down: flexion and supination confounded): the hidden one is a guess, dropped;
            # the fit stays the arm's state, so the marker returns once the data pin it again
            self.seen[r] = (theta, psi, False)
            self.points[r] = (DROP, DROP)
            return DROP
        return theta, psi, pinned[0]

    def update(self, p: np.ndarray, ok: np.ndarray) -> None:
        """Carry the arms' flexion and supination to the next frame."""
        for r, (wa, wb, ea, eb, _) in enumerate(self.arms):
            seen = self.seen.get(r)
            if seen is None and ok[wa] and ok[wb] and np.all(np.isfinite(p[[ea, eb]])):
                # styloids measured, an epicondyle estimated (by the hinge)
                frame = self.elbow_frame(r, p, ok)
                angles = None if frame is None else forearm_angles(frame, p[wa], p[wb])
                if angles is not None:
                    seen = (angles[0], angles[1], True)
            measured_now = bool(ok[wa] or ok[wb]) or (seen is not None and seen[2])
            self.unmeasured[r] = 0 if measured_now else self.unmeasured[r] + 1
            pinned_now = bool(ok[wa] and ok[wb]) or r in self.pinned
            self.unpinned[r] = 0 if pinned_now else self.unpinned[r] + 1
            if seen is None:  # the last angles stay, older by a frame
                self.age[r] += 1
                continue
            theta, psi, measured = seen
            old = self.angles[r]
            if not (ok[wa] and ok[wb]):
                self.velocity[r] = self._fitted_speed(r, theta, psi, measured, old)
            elif measured and np.all(np.isfinite(old)):
                steps = self.age[r] + 1
                d = np.array([math.remainder(theta - old[0], math.tau), math.remainder(psi - old[1], math.tau)]) / steps
                vel = self.velocity[r]
                self.velocity[r] = np.where(np.isfinite(vel), vel + self.beta * (d - vel), d)
            elif measured:
                self.velocity[r] = 0.0
            self.angles[r] = (theta, psi)
            self.age[r] = 0

    def _fitted_speed(self, r: int, theta: float, psi: float, measured: bool, old: np.ndarray) -> np.ndarray:
        """Arm r's angular speeds after a fit to one styloid (with or without views).

        The fit leans on the prediction where the styloid does not pin an angle: that step is no
        evidence of speed (it would feed itself), and a pinned step carries the styloid's and the
        elbow axis' noise (2-4 degrees per frame of supination at 320x240). So each angle's speed
        decays, and takes the step in by the steady-state Kalman gain of a constant-speed model:
        process noise the unknown angular acceleration over a frame, measurement noise the step's
        variance from the fit's data. Flexion, pinned by a styloid 24 cm from the elbow, keeps its
        speed through the fits; supination, from a styloid 2-3 cm off the forearm's axis, mostly
        decays."""
        vel = np.nan_to_num(self.velocity[r]) * self.decay
        var = self.var.get(r)
        if measured and var is not None and np.all(np.isfinite(old)):
            steps = self.age[r] + 1
            d = np.array([math.remainder(theta - old[0], math.tau),
                          math.remainder(psi - old[1], math.tau)]) / steps
            q = (self.accel_rad_s2 / (self.fps * self.fps)) ** 2
            for i in range(2):
                noise = 2.0 * var[i] / (steps * steps)
                if math.isfinite(noise):
                    pss = 0.5 * (q + math.sqrt(q * q + 4.0 * q * noise))
                    gain = min(pss / (pss + noise), self.beta)
                    vel[i] += gain * (d[i] - vel[i])
        return vel
