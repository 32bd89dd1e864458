"""A population of simulated patients for judging the labelling on bodies it was never tuned on.

Each draw (one integer seed) is a patient and a reference pose: body size (stature percentile
5-95, woman or man), every marker moved up to 15 mm along the skin off its landmark, the
reference pose varied within its tolerances (each arm 5-40 degrees from the body, flexed or
extended up to 10 degrees, the upper arm turned from 60 degrees in to 15 degrees out, the elbow
flexed up to 30 degrees, the thumb within 30 degrees of forward; the trunk leaning forward,
sideways and turned up to 15 degrees each; the chair turned up to 20 degrees), one colour for
all markers or the marker set's four, and 0-2 markers seen by fewer than two cameras. Rendered
draws are also imaged by a drawn cheap webcam (:func:`draw_imaging`).

Seeds below :data:`REPORTED_SEEDS_FROM` are for tuning (the tests use them); reported figures
come from seeds from there on only, so that nothing reported was looked at while tuning.

:func:`label_draws` runs the labelling on the markers' points (measurement noise added): the
labelling's own figures (rate, swaps, margins, time) without rendering. The rendered check of
the same draws through the tracker is :func:`tracking.sim.validate.validate_population`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from calibration.camera import Camera
from tracking.labelling.rays import RAY_FAR, RAY_FAR_WHOLE, RAY_NEAR, RAY_NEAR_WHOLE, Rays
from tracking.markerset import MarkerSet, load_markerset
from tracking.sim.body import ArmPose, BodyDimensions, BodyModel, Pose
from tracking.geometry.rotations import axis_angle_matrix
from tracking.marker_status import MarkerStatus
from tracking.sim.imaging import Webcam, WebcamPipeline, drawn_webcam
from tracking.sim.rigs import load_rig

#: seeds from here on are reported; below are for tuning
REPORTED_SEEDS_FROM = 100_000
#: the rendered draws are named once the patient has held still this long
HOLD_S = 0.2
#: colour of all markers in the one-colour scheme (the seed paper's set-up)
ONE_COLOUR_RGB = (255, 214, 0)


@dataclass(frozen=True, slots=True)
class Draw:
    """One patient in one reference pose.

    Attributes:
        seed: the draw's seed.
        dims: the body.
        pose: the reference pose as varied.
        yaw_deg: the chair's turn about the vertical (+: towards the patient's left).
        offsets_m: (M, 3) each marker's placement error (along the skin), world metres.
        one_colour: one colour for all markers (else the marker set's colours).
        unseen: markers seen by fewer than two cameras (no 3D point).
    """

    seed: int
    dims: BodyDimensions
    pose: Pose
    yaw_deg: float
    offsets_m: np.ndarray
    one_colour: bool
    unseen: tuple[int, ...]


def draw(seed: int, markerset: MarkerSet, *, one_colour: bool | None = None, max_unseen: int = 2) -> Draw:
    """The draw of ``seed`` (``one_colour`` None: drawn too, half and half).

    A pose the body cannot take is drawn again (from the same generator): an elbow inside the
    trunk, two balls overlapping, a ball inside the chair seat.
    """
    rng = np.random.default_rng(seed)
    for _ in range(100):
        d = _draw_once(seed, rng, markerset, one_colour, max_unseen)
        if _possible(d, markerset):
            return d
    raise RuntimeError(f"no possible pose in 100 draws of seed {seed}")


def _possible(d: Draw, markerset: MarkerSet) -> bool:
    # lazy: `rehab --help` imports this module (REPORTED_SEEDS_FROM): keep it light
    from tracking.sim.identify_sweep import seat_clash

    body = BodyModel(d.dims, markerset)
    if any(body.trunk_gap_m(d.pose, side) < 0.0 for side in ("right", "left")):
        return False
    if seat_clash(body, d.pose, markerset):
        return False
    p = body.markers_m(d.pose) + d.offsets_m
    gap = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.eye(len(p))
    return bool(gap.min() > 2.0 * markerset.radius_m + 0.005)


def _draw_once(seed: int, rng: np.random.Generator, markerset: MarkerSet, one_colour: bool | None, max_unseen: int
               ) -> Draw:
    sex = "female" if rng.random() < 0.5 else "male"
    dims = BodyDimensions.from_percentile(float(rng.uniform(5, 95)), sex)
    arms = []
    for _ in range(2):
        er = float(rng.uniform(-60, 15))
        sup = float(np.clip(-er + rng.uniform(-30, 30), -85, 85))
        arms.append(ArmPose.clinical(flexion_deg=float(rng.uniform(-10, 10)), abduction_deg=float(rng.uniform(5, 40)),
                                     external_rotation_deg=er, elbow_flexion_deg=float(rng.uniform(0, 30)),
                                     forearm_supination_deg=sup, shoulder_shrug_m=float(rng.uniform(-0.01, 0.02))))
    pose = Pose(trunk_forward_lean_deg=float(rng.uniform(-15, 15)), trunk_lateral_lean_deg=float(rng.uniform(-15, 15)),
                trunk_axial_rotation_deg=float(rng.uniform(-15, 15)), right=arms[0], left=arms[1])
    yaw = float(rng.uniform(-20, 20))
    body = BodyModel(dims, markerset)
    _, normal = body.landmarks_m(pose)
    # a random direction along the skin (perpendicular to the normal), up to 15 mm
    v = rng.normal(size=normal.shape)
    v -= np.sum(v * normal, axis=1, keepdims=True) * normal
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    offsets = v * rng.uniform(0, 0.015, size=(len(v), 1))
    if one_colour is None:
        one_colour = bool(rng.random() < 0.5)
    n_unseen = int(rng.integers(0, max_unseen + 1))
    unseen = tuple(sorted(int(k) for k in rng.choice(markerset.n_markers, n_unseen, replace=False)))
    return Draw(seed, dims, pose, yaw, offsets, one_colour, unseen)


def draw_markerset(d: Draw, markerset: MarkerSet) -> MarkerSet:
    """The marker set with the draw's colours."""
    return markerset.with_colours([ONE_COLOUR_RGB]) if d.one_colour else markerset


def markers_m(d: Draw, markerset: MarkerSet) -> np.ndarray:
    """(M, 3) the draw's marker centres, world metres (placement error and chair turn applied)."""
    p = BodyModel(d.dims, markerset).markers_m(d.pose) + d.offsets_m
    rot = axis_angle_matrix(np.array([0.0, 1.0, 0.0]), math.radians(d.yaw_deg))
    centre = np.array([0.0, p[:, 1].mean(), 0.0])
    return centre + (p - centre) @ rot.T


@dataclass(frozen=True, slots=True)
class LabelResult:
    """The labelling of one draw's points."""

    seed: int
    one_colour: bool
    n_unseen: int
    confident: bool
    wrong: int          # markers given another marker's point, among the confident ones (a swap)
    score: float
    margin: float
    time_s: float
    worst: str
    on_rays: bool = False  # the markers without a point are seen by one camera each (a ray)


def single_camera_rays(p_m: np.ndarray, colour: np.ndarray, rng: np.random.Generator, *, noise_m: float = 0.0015,
                       whole_share: float = 0.5):
    """:class:`tracking.labelling.rays.Rays` of balls at ``p_m`` seen by one camera each: a camera 1.7-2.6 m
    away in front of or beside the patient, 1.3-2.5 m high; the ray through the ball's centre
    (``noise_m`` off it), its range the multiples of the blob-size distance of
    :func:`tracking.labelling.rays.single_view_rays` (a blob round with probability ``whole_share``,
    the distance from its size within 3 %; else partly hidden, 0.7-0.95 of the ball's size)."""
    n = len(p_m)
    az = rng.uniform(-100.0, 100.0, n)
    dist, height = rng.uniform(1.7, 2.6, n), rng.uniform(1.3, 2.5, n)
    origin = np.stack([dist * np.sin(np.radians(az)), height, -dist * np.cos(np.radians(az))], axis=1)
    target = p_m + rng.normal(scale=noise_m, size=p_m.shape)
    d = target - origin
    true = np.linalg.norm(d, axis=1)
    whole = rng.random(n) < whole_share
    seen = true * np.where(whole, rng.uniform(0.97, 1.03, n), 1.0 / rng.uniform(0.7, 0.95, n))
    rng_m = np.stack([np.where(whole, RAY_NEAR_WHOLE, RAY_NEAR) * seen, np.where(whole, RAY_FAR_WHOLE, RAY_FAR) * seen],
                     axis=1)
    return Rays(origin, d / true[:, None], np.asarray(colour, np.int64), rng_m, whole)


def label_draws(seeds: Iterable[int], *, noise_m: float = 0.0015, one_colour: bool | None = None,
                markerset: MarkerSet | None = None, rays: bool | None = False) -> list[LabelResult]:
    """Label each draw's points (shuffled, with ``noise_m`` of measurement noise per axis); with
    ``rays``, each marker without a point is seen by one camera (:func:`single_camera_rays`);
    None: a draw with markers without a point is labelled both ways (two results)."""
    # lazy: `rehab --help` imports this module (REPORTED_SEEDS_FROM): keep it light
    from tracking.labelling import Labeller

    base = markerset or load_markerset()
    out = []
    for seed in seeds:
        d = draw(seed, base, one_colour=one_colour)
        ms = draw_markerset(d, base)
        rng = np.random.default_rng(seed + 7919)
        p = markers_m(d, ms) + rng.normal(scale=noise_m, size=(ms.n_markers, 3))
        seen = np.setdiff1d(np.arange(ms.n_markers), d.unseen)
        order = rng.permutation(seen)
        labeller = Labeller.for_markerset(ms)
        r = single_camera_rays(p[list(d.unseen)], ms.colour_index[list(d.unseen)], rng) if d.unseen else None
        ways = (False, True) if rays is None and d.unseen else (bool(rays and d.unseen),)
        for on_rays in ways:
            t0 = time.perf_counter()
            lab = labeller.label(p[order], ms.colour_index[order], r if on_rays else None)
            dt = time.perf_counter() - t0
            wrong = 0
            if lab.confident:
                truth = np.full(ms.n_markers, -1)
                truth[order] = np.arange(len(order))
                wrong = int(np.sum((lab.index != truth) & (lab.index >= 0)))
            worst = "" if lab.worst is None else f"{lab.worst[0]} {lab.worst[1]:.3g}"
            out.append(LabelResult(seed, d.one_colour, len(d.unseen), lab.confident, wrong, lab.score, lab.margin, dt,
                                   worst, on_rays))
    return out


#: camera layouts of the rendered draws: the rigs of content/rigs, two cameras of front4, and
#: random placements of 3 or 4 cameras
LAYOUTS = ("tri3", "front3", "wall3", "ring4", "front4", "corners4", "front4:2", "random3", "random4")


def layout_cameras(name: str, rng: np.random.Generator, size_px: tuple[int, int]):
    """The cameras of a layout of :data:`LAYOUTS` (a random one drawn from ``rng``)."""
    if name.startswith("random"):
        n = int(name[len("random"):])
        w, h = size_px
        f_px = (w / 2.0) / math.tan(math.radians(55.0) / 2.0)
        # spread around the patient: one camera in each of n equal sectors, front sectors first
        base = rng.uniform(-180.0, 180.0)
        cams = []
        for k in range(n):
            az = math.radians(base + 360.0 * k / n + rng.uniform(-25.0, 25.0))
            dist, height = rng.uniform(1.7, 2.6), rng.uniform(1.3, 2.6)
            eye = (dist * math.sin(az), height, -dist * math.cos(az))
            cams.append(Camera.look_at(f"cam{k + 1}", (w, h), f_px, eye, (0.0, 0.95, 0.0)))
        return tuple(cams)
    rig, _, count = name.partition(":")
    cams = load_rig(rig, size_px)
    return cams[:int(count)] if count else cams


@dataclass(frozen=True, slots=True)
class TrackResult:
    """One draw rendered and tracked in one camera layout.

    Attributes:
        identified_s: time from the start of the still reference pose to the names (NaN: never).
        wrong: markers named on another marker's ball (a swap), over every frame after the names.
        named: markers named at identification (the others join later).
        rmse_mm: RMSE of the measured markers against their balls after the names.
        worst_ms, median_ms: per frame-set time of the tracker's step.
        message: the tracker's last message while waiting ("" when named).
    """

    seed: int
    layout: str
    one_colour: bool
    identified_s: float
    wrong: int
    named: int
    rmse_mm: float
    worst_ms: float
    median_ms: float
    message: str


def track_draws(seeds: Iterable[int], *, size_px: tuple[int, int] = (640, 480), fps: float = 30.0,
                seconds: float = 1.0, noise_sigma: float = 1.5, markerset: MarkerSet | None = None,
                webcams: bool = True, progress: bool = False, params=None) -> list[TrackResult]:
    """Render each draw's reference pose (still, ``seconds`` long, sensor noise) in a layout of
    :data:`LAYOUTS` drawn from the seed, and track it from the first frame set.

    ``webcams``: the images are also what a drawn cheap webcam delivers (:func:`draw_imaging`:
    sensor noise, lighting drift, auto exposure / white balance, MJPEG) instead of ``noise_sigma``
    alone. ``params``: the tracker's :class:`~tracking.tracker.TrackerParams` (default: the
    defaults with the population's hold of the reference pose)."""
    from tqdm import tqdm  # lazy: `rehab --help` imports this module (REPORTED_SEEDS_FROM): keep it light

    # lazy: `rehab --help` imports this module (REPORTED_SEEDS_FROM): keep it light
    from tracking.sim.studio import Studio
    # lazy: `rehab --help` imports this module (REPORTED_SEEDS_FROM): keep it light
    from tracking.tracker import Tracker, TrackerParams, TrackingState

    base = markerset or load_markerset()
    seeds = list(seeds)
    out = []
    for seed in tqdm(seeds, unit="draw", desc="rendered draws", leave=False, disable=not progress):
        d = draw(seed, base, max_unseen=0)
        ms = draw_markerset(d, base)
        rng = np.random.default_rng(seed + 104_729)
        layout = LAYOUTS[int(rng.integers(len(LAYOUTS)))]
        cams = layout_cameras(layout, rng, size_px)
        with Studio(cams, ms, d.dims) as studio:
            studio.body = BodyModel(d.dims, ms, d.offsets_m)
            tracker = Tracker(cams, ms, fps=fps, params=params or TrackerParams(identify_hold_s=HOLD_S))
            n = max(int(round(seconds * fps)), tracker.hold_frames + 2)
            imaging = draw_imaging(seed, n, noise_sigma) if webcams else None
            camera = WebcamPipeline(imaging.webcam if imaging else Webcam(), len(cams))
            times, sq, wrong = [], [], 0
            named_at, named, message = -1, 0, ""
            for k in range(n):
                light = imaging.light(k) if imaging else {"noise_sigma": noise_sigma}
                sf = studio.render(d.pose, k, k / fps, seed=seed * 7 + k, with_visibility=False, **light)
                images, _ = camera.apply(sf.frames.images)
                t0 = time.perf_counter()
                s = tracker.step(images, k / fps)
                times.append(time.perf_counter() - t0)
                if s.state != TrackingState.TRACKING:
                    message = s.message
                    continue
                if named_at < 0:
                    named_at, named, message = k, int(np.sum(s.status != MarkerStatus.LOST)), ""
                truth = sf.markers_m
                has = np.isfinite(s.positions_m).all(axis=1)
                d_all = np.linalg.norm(s.positions_m[has][:, None] - truth[None], axis=-1)
                own = d_all[np.arange(has.sum()), np.flatnonzero(has)]
                wrong += int(np.sum((own > 0.015) & (d_all.argmin(axis=1) != np.flatnonzero(has))))
                meas = s.status == MarkerStatus.MEASURED
                sq.extend((np.linalg.norm(s.positions_m[meas] - truth[meas], axis=1) ** 2).tolist())
        out.append(TrackResult(seed, layout, d.one_colour, named_at / fps if named_at >= 0 else math.nan, wrong,
                               named, 1000 * math.sqrt(np.mean(sq)) if sq else math.nan, 1000 * max(times),
                               1000 * float(np.median(times)), message))
    return out


@dataclass(frozen=True, slots=True)
class DrawnImaging:
    """How one rendered draw is imaged: the webcam, sensor noise and a lighting drift over its frames.

    Attributes:
        webcam: auto exposure / white balance, MJPEG, exposure time (a still pose shows no blur).
        noise_sigma: sensor noise, 8-bit units.
        brightness_change: the light's change over the draw's frames (-0.1: 10 % darker).
        colour_cast: (3,) R, G, B gains the light reaches at the last frame.
        n_frames: the frames the drift runs over.
    """

    webcam: Webcam
    noise_sigma: float
    brightness_change: float
    colour_cast: tuple[float, float, float]
    n_frames: int

    def light(self, k: int) -> dict:
        """The renderer's light and noise at frame ``k`` (linear drift from the first frame)."""
        frac = k / max(self.n_frames - 1, 1)
        return {"exposure": 1.0 + self.brightness_change * frac, "noise_sigma": self.noise_sigma,
                "colour_cast": tuple(1.0 + (g - 1.0) * frac for g in self.colour_cast)}


def draw_imaging(seed: int, n_frames: int, noise_sigma: float = 1.5) -> DrawnImaging:
    """The imaging of draw ``seed`` (a generator of its own: the draw and its layout stay as they were):
    a webcam of :func:`tracking.sim.imaging.drawn_webcam`, sensor noise ``noise_sigma`` to 4, the light
    20 % darker to 10 % brighter and a cast of up to 8 % per channel over the frames."""
    rng = np.random.default_rng((seed, 31_337))
    return DrawnImaging(drawn_webcam(rng), float(rng.uniform(noise_sigma, max(noise_sigma, 4.0))),
                        float(rng.uniform(-0.2, 0.1)), tuple(float(g) for g in 1.0 + rng.uniform(-0.08, 0.08, 3)),
                        n_frames)


def _spread(values: list[float], unit: str, digits: int = 0) -> str:
    v = np.asarray([x for x in values if np.isfinite(x)], dtype=np.float64)
    if not len(v):
        return "-"
    q = np.percentile(v, [5, 50, 95])
    return f"median {q[1]:.{digits}f} {unit} (5-95 %: {q[0]:.{digits}f}-{q[2]:.{digits}f}, worst {v.max():.{digits}f})"


def population_report(labelled: list[LabelResult], tracked: list[TrackResult]) -> str:
    """The figures of ``rehab validate --population``: per colour scheme, spread across the draws."""
    lines = []
    if labelled:
        lines.append(f"labelling of the points ({len({x.seed for x in labelled})} draws, seeds {labelled[0].seed}-{labelled[-1].seed}; "
                     "1.5 mm noise, 0-2 markers without a point, seen by no camera or by one):")
        for one in (True, False):
            for unseen, on_rays in ((0, False), (1, False), (1, True), (2, False), (2, True)):
                r = [x for x in labelled if x.one_colour == one and x.n_unseen == unseen and x.on_rays == on_rays]
                if not r:
                    continue
                conf = sum(x.confident for x in r)
                seen_by = (", each seen by one camera" if on_rays else ", seen by none") if unseen else ""
                lines.append(f"  {'one colour ' if one else 'four colours'}, {unseen} without a point{seen_by}: labelled "
                             f"{conf}/{len(r)} ({100 * conf / len(r):.1f} %), swaps {sum(x.wrong for x in r)}, time "
                             + _spread([1000 * x.time_s for x in r], "ms"))
    if tracked:
        lines.append(f"rendered and tracked ({len(tracked)} draws, still reference pose, layouts of 2-4 cameras "
                     "incl. random placements; drawn webcams: sensor noise 1.5-4, light -20..+10 % and a cast over "
                     "the draw, auto exposure / white balance, MJPEG quality 50-95, chroma 4:2:2 or 4:2:0):")
        for one in (True, False):
            r = [x for x in tracked if x.one_colour == one]
            if not r:
                continue
            ok = [x for x in r if np.isfinite(x.identified_s)]
            lines.append(f"  {'one colour ' if one else 'four colours'}: identified {len(ok)}/{len(r)} "
                         f"({100 * len(ok) / len(r):.1f} %), within 1 s {sum(x.identified_s <= 1.0 for x in ok)}; "
                         f"swaps {sum(x.wrong for x in r)}; time to identify "
                         + _spread([x.identified_s for x in ok], "s", 2))
            lines.append("    measured RMSE " + _spread([x.rmse_mm for x in ok], "mm", 2)
                         + "; per frame set " + _spread([x.worst_ms for x in r], "ms") + " (worst of each draw)")
        for layout in LAYOUTS:
            r = [x for x in tracked if x.layout == layout]
            if r:
                ok = sum(np.isfinite(x.identified_s) for x in r)
                waiting = "; ".join(sorted({x.message[:80] for x in r if not np.isfinite(x.identified_s)}))
                lines.append(f"    {layout}: {ok}/{len(r)}" + (f" (waiting: {waiting})" if waiting else ""))
    return "\n".join(lines)
