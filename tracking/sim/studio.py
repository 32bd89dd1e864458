"""The simulated studio: a body moving through a motion, imaged by virtual cameras.

It joins the body model (:mod:`tracking.sim.body`), a motion (:mod:`tracking.sim.motions`) and the
renderer (:mod:`tracking.sim.renderer`), adds lighting drift, colour cast and sensor noise, what a
webcam does to the image (:mod:`tracking.sim.imaging`: motion blur, auto exposure / white balance,
MJPEG), and keeps the ground truth (marker centres, per-camera visibility, joint angles). The tracker never
sees the truth: it gets only the images, as from real cameras.
"""

from __future__ import annotations

import csv
import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np
from tqdm import tqdm

from calibration.camera import Camera
from tracking.markerset import MarkerSet, load_markerset
from calibration.files import save_calibration_toml
from tracking.angles import joint_angles
from tracking.errors import ContentError
from tracking.io.csv_tables import write_angles_csv
from tracking.io.recording import FrameSet, RecordingWriter, write_timestamps
from tracking.io.trc import write_trc
from tracking.sim.body import BodyDimensions, BodyModel, Pose
from tracking.sim.clocks import CameraClocks, rolling_marker_positions
from tracking.sim.imaging import Webcam, WebcamPipeline, add_sensor_noise, exposure_offsets_s, integrate_exposure
from tracking.sim.motions import Motion, load_motion
from tracking.sim.renderer import StudioRenderer
from tracking.sim.rigs import load_rig
from tracking.sim.scene import SceneFrame

log = logging.getLogger(__name__)

@dataclass(frozen=True, slots=True)
class SimulationSettings:
    """Everything that defines a simulated recording (all of it is written to meta.yaml)."""

    motion: str = "right_external_rotation"
    rig: str = "ring4"
    n_cameras: int | None = None
    size_px: tuple[int, int] = (640, 480)
    fps: float = 30.0
    seconds: float | None = None
    percentile: float = 50.0
    sex: str = "female"
    noise_sigma: float = 1.5
    brightness_drop: float = 0.0
    colour_cast: tuple[float, float, float] | None = None
    drift_start_s: float = 0.0
    drift_s: float | None = None
    markerset: str = "upper_limb_seated"
    seed: int = 0
    images: bool = False
    msaa: int | None = None
    camera_offsets: tuple[float, ...] | str | None = None
    clock_drift: float = 0.0
    rolling_shutter_s: float = 0.0
    jpeg_quality: int | None = None
    jpeg_chroma: str = "422"
    exposure_s: float = 0.0
    auto_exposure: bool = False
    auto_white_balance: bool = False

    @property
    def webcam(self) -> Webcam:
        """The webcam effects (:mod:`tracking.sim.imaging`) these settings ask for."""
        return Webcam(jpeg_quality=self.jpeg_quality, jpeg_chroma=self.jpeg_chroma, exposure_s=self.exposure_s,
                      auto_exposure=self.auto_exposure, auto_white_balance=self.auto_white_balance)

    def clocks(self, n_cameras: int) -> CameraClocks | None:
        """The cameras' timing (:mod:`tracking.sim.clocks`): ``camera_offsets`` one phase per
        camera in frame periods, or ``"random"`` (drawn in +-0.5 from the seed); ``clock_drift``
        the largest rate difference (each camera's drawn in +-); None: synchronized global shutters."""
        if self.camera_offsets is None and self.clock_drift == 0 and self.rolling_shutter_s == 0:
            return None
        offsets = self.camera_offsets
        if isinstance(offsets, str) or offsets is None:
            offsets = None if offsets == "random" else (0.0,) * n_cameras
        elif len(offsets) != n_cameras:
            raise ContentError(f"--camera-offsets gives {len(offsets)} offsets for {n_cameras} cameras: give one per "
                               f"camera (fractions of a frame period) or 'random'")
        return CameraClocks.drawn(n_cameras, self.seed, offsets=offsets, drift=self.clock_drift,
                                  readout_s=self.rolling_shutter_s)


@dataclass(frozen=True, slots=True)
class SimFrame:
    """One simulated frame set with its ground truth.

    Attributes:
        frames: the images (what a tracker gets).
        pose: the body pose.
        markers_m: (M, 3) true marker centres, world metres.
        visible_fraction: (C, M) fraction of each marker's disc visible in each camera (0..1).
        merged: (C, M) bool, the marker's disc touches that of another marker of the same colour in
            that camera (one blob shows both: it is a view of neither); None when rendered
            without visibility.
        stamps_s: (C,) instant of each camera's image (its first row's), seconds; None when all
            cameras imaged the frame set's instant (``frames.time_s``, where ``markers_m`` are).
        camera_gains: (C, 3) R, G, B gains of the cameras' auto exposure / white balance applied
            to these images (:class:`tracking.sim.imaging.AutoCamera`); None without them.
    """

    frames: FrameSet
    pose: Pose
    markers_m: np.ndarray
    visible_fraction: np.ndarray
    merged: np.ndarray | None
    stamps_s: np.ndarray | None = None
    camera_gains: np.ndarray | None = None


def merged_markers(cameras: Sequence[Camera], markers_m: np.ndarray, radius_m: float, colour_index: np.ndarray) -> np.ndarray:
    """(C, M) bool: marker discs that touch the disc of another marker of the same colour."""
    out = np.zeros((len(cameras), len(markers_m)), dtype=bool)
    same = (colour_index[:, None] == colour_index[None, :]) & ~np.eye(len(markers_m), dtype=bool)
    for c, cam in enumerate(cameras):
        uv = cam.project(markers_m)
        depth = cam.world_to_camera(markers_m)[:, 2]
        f = (cam.K[0, 0] + cam.K[1, 1]) / 2.0
        r_px = f * radius_m / np.maximum(depth, 1e-6)
        d = np.linalg.norm(uv[:, None, :] - uv[None, :, :], axis=-1)
        out[c] = np.any(same & (d < r_px[:, None] + r_px[None, :] + 1.0), axis=1)
    return out


def expected_marker_pixels(cameras: Sequence[Camera], markers_m: np.ndarray, radius_m: float) -> np.ndarray:
    """(C, M) pixel area of each unoccluded marker ball in each camera (0 outside the image)."""
    out = np.zeros((len(cameras), len(markers_m)))
    for c, cam in enumerate(cameras):
        depth = cam.world_to_camera(markers_m)[:, 2]
        uv = cam.project(markers_m)
        w, h = cam.size_px
        f = (cam.K[0, 0] + cam.K[1, 1]) / 2.0
        with np.errstate(divide="ignore", invalid="ignore"):
            r_px = f * radius_m / depth
        inside = (depth > 0) & (uv[:, 0] > -0.5) & (uv[:, 0] < w - 0.5) & (uv[:, 1] > -0.5) & (uv[:, 1] < h - 0.5)
        out[c] = np.where(inside, np.pi * r_px**2, 0.0)
    return out


class Studio:
    """A body model, its marker set and a camera rig with an offscreen renderer.

    Args:
        cameras: the virtual cameras.
        markerset: the markers worn by the patient.
        dims: body dimensions.
        msaa: renderer anti-aliasing samples (None: the renderer's default).
        ctx: an existing moderngl context to share (e.g. the game's).
    """

    def __init__(self, cameras: Sequence[Camera], markerset: MarkerSet, dims: BodyDimensions, *,
                 msaa: int | None = None, ctx=None):
        self.cameras = tuple(cameras)
        self.markerset = markerset
        self.body = BodyModel(dims, markerset)
        kwargs = {} if msaa is None else {"msaa": msaa}
        self.renderer = StudioRenderer(self.cameras, ctx=ctx, **kwargs)

    def render(self, pose: Pose, index: int, time_s: float, *, exposure: float = 1.0,
               colour_cast: Sequence[float] = (1.0, 1.0, 1.0), noise_sigma: float = 0.0,
               seed: int = 0, with_visibility: bool = True,
               camera_scenes: tuple[Sequence[SceneFrame], np.ndarray, np.ndarray] | None = None) -> SimFrame:
        """Render ``pose`` at ``time_s``; ``camera_scenes``: instead, (one scene per camera, (C, M, 3)
        marker centres drawn in each, (C,) stamps) of cameras imaging at their own instants
        (:meth:`timed_scenes`); ``pose`` then gives the truth at ``time_s``."""
        markers = self.body.markers_m(pose)
        scene = self.body.scene(pose) if camera_scenes is None else list(camera_scenes[0])
        res = self.renderer.render(scene, exposure=exposure, colour_cast=colour_cast,
                                   noise_sigma=noise_sigma, seed=seed, with_visibility=with_visibility)
        if res.marker_pixels is not None:
            if camera_scenes is None:
                expected = expected_marker_pixels(self.cameras, markers, self.markerset.radius_m)
            else:
                expected = np.concatenate([expected_marker_pixels([cam], drawn, self.markerset.radius_m)
                                           for cam, drawn in zip(self.cameras, camera_scenes[1])])
            with np.errstate(divide="ignore", invalid="ignore"):
                vis = np.where(expected > 0, res.marker_pixels / expected, 0.0)
            vis = np.clip(vis, 0.0, 1.0)
        else:
            vis = np.full((len(self.cameras), self.markerset.n_markers), np.nan)
        merged = None  # an evaluation figure, like the visibility (the live source needs neither)
        if with_visibility:
            merged = merged_markers(self.cameras, markers, self.markerset.radius_m, self.markerset.colour_index)
        stamps = None if camera_scenes is None else np.asarray(camera_scenes[2], dtype=np.float64)
        return SimFrame(FrameSet(index, time_s, res.images), pose, markers, vis, merged, stamps)

    def timed_scenes(self, motion: Motion, index: int, fps: float, clocks: CameraClocks, shift_s: float = 0.0
                     ) -> tuple[list[SceneFrame], np.ndarray, np.ndarray]:
        """Each camera's scene of frame set ``index`` on free-running clocks with rolling shutters
        (:mod:`tracking.sim.clocks`): the body at the instant of the camera's middle row, each
        marker ball at the instant of its own row (``shift_s`` later: an instant of the exposure).
        Returns (scenes, (C, M, 3) drawn marker centres, (C,) stamps: each camera's first-row instant)."""
        stamps = clocks.capture_times(index, fps) + shift_s
        readout = np.asarray(clocks.readout_s)
        markers = rolling_marker_positions(self.cameras, lambda t: self.body.markers_m(motion.pose_at(t)),
                                           stamps, readout)
        scenes = []
        for c in range(len(self.cameras)):
            scene = self.body.scene(motion.pose_at(float(stamps[c] + readout[c] / 2)))
            centre = scene.sphere_centre_m.copy()
            idx = np.asarray(scene.sphere_marker_index)
            ball = idx >= 0
            centre[ball] = markers[c][idx[ball]]
            scenes.append(dataclasses.replace(scene, sphere_centre_m=centre))
        return scenes, markers, stamps

    def play(self, motion: Motion, fps: float, *, seconds: float | None = None, noise_sigma: float = 0.0,
             brightness_drop: float = 0.0, colour_cast: Sequence[float] | None = None, seed: int = 0,
             with_visibility: bool = True, drift_start_s: float = 0.0, drift_s: float | None = None,
             clocks: CameraClocks | None = None, webcam: Webcam | None = None) -> Iterator[SimFrame]:
        """Render a motion frame by frame (``clocks``: cameras on free-running clocks and rolling
        shutters, :meth:`timed_scenes`; the truth stays at the frame sets' nominal instants).

        Lighting drifts linearly from full exposure and no cast at ``drift_start_s`` to
        ``1 - brightness_drop`` and ``colour_cast`` ``drift_s`` seconds later (default: over the
        whole motion), then stays there. ``webcam``: what the cameras do to the images
        (:mod:`tracking.sim.imaging`); a SimFrame's ``camera_gains`` are their auto loops' gains.
        """
        webcam = webcam or Webcam()
        pipeline = WebcamPipeline(webcam, len(self.cameras))
        duration = motion.duration_s if seconds is None else min(seconds, motion.duration_s)
        n = int(np.floor(duration * fps + 1e-9)) + 1
        cast_end = np.asarray(colour_cast if colour_cast is not None else (1.0, 1.0, 1.0), dtype=float)
        ramp_s = max((n - 1) / fps - drift_start_s, 1.0 / fps) if drift_s is None else drift_s
        for i in range(n):
            t = i / fps
            frac = float(np.clip((t - drift_start_s) / ramp_s, 0.0, 1.0)) if ramp_s > 0 else float(t >= drift_start_s)
            timed = None if clocks is None or clocks.synchronous else self.timed_scenes(motion, i, fps, clocks)
            light = dict(exposure=1.0 - brightness_drop * frac, colour_cast=tuple(1.0 + (cast_end - 1.0) * frac))
            blur = webcam.exposure_s > 0.0
            sf = self.render(motion.pose_at(t), i, t, camera_scenes=timed, noise_sigma=0.0 if blur else noise_sigma,
                             seed=seed * 1_000_003 + i, with_visibility=with_visibility, **light)
            if blur:  # the shutter open around the instant: the mean of its instants, then the noise once
                shots = [sf.frames.images]
                for dt in self._exposure_offsets(motion, t, webcam.exposure_s):
                    if dt != 0.0:
                        scenes = None if timed is None else self.timed_scenes(motion, i, fps, clocks, dt)
                        shots.append(self.render(motion.pose_at(t + dt), i, t + dt, camera_scenes=scenes,
                                                 with_visibility=False, **light).frames.images)
                rng = np.random.default_rng((seed, i))
                sf = dataclasses.replace(sf, frames=dataclasses.replace(sf.frames, images=tuple(
                    add_sensor_noise(integrate_exposure(per_cam), noise_sigma, rng) for per_cam in zip(*shots))))
            if not webcam.ideal:
                images, gains = pipeline.apply(sf.frames.images)
                sf = dataclasses.replace(sf, frames=dataclasses.replace(sf.frames, images=images), camera_gains=gains)
            yield sf

    def _exposure_offsets(self, motion: Motion, t: float, exposure_s: float) -> np.ndarray:
        """Instants of an exposure around ``t`` (:func:`tracking.sim.imaging.exposure_offsets_s`),
        dense enough for the fastest ball's image motion in any camera."""
        ends = [self.body.markers_m(motion.pose_at(t + s * exposure_s / 2)) for s in (-1.0, 1.0)]
        motion_px = max(float(np.max(np.linalg.norm(cam.project(ends[1]) - cam.project(ends[0]), axis=1)))
                        for cam in self.cameras)
        return exposure_offsets_s(exposure_s, motion_px)

    def n_frames(self, motion: Motion, fps: float, seconds: float | None = None) -> int:
        duration = motion.duration_s if seconds is None else min(seconds, motion.duration_s)
        return int(np.floor(duration * fps + 1e-9)) + 1

    def close(self) -> None:
        self.renderer.release()

    def __enter__(self) -> "Studio":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def studio_from_settings(settings: SimulationSettings) -> tuple[Studio, Motion]:
    """Build the studio and the motion that a :class:`SimulationSettings` describes."""
    markerset = load_markerset(settings.markerset)
    cameras = load_rig(settings.rig, settings.size_px)
    if settings.n_cameras is not None:
        if not 2 <= settings.n_cameras <= len(cameras):
            raise ContentError(f"--cameras {settings.n_cameras}: the rig {settings.rig} has {len(cameras)} cameras; give 2..{len(cameras)}")
        cameras = cameras[: settings.n_cameras]
    dims = BodyDimensions.from_percentile(settings.percentile, settings.sex)
    motion = load_motion(settings.motion, dims)
    return Studio(cameras, markerset, dims, msaa=settings.msaa), motion


def simulate_recording(out_dir: Path, settings: SimulationSettings, *, progress: bool = False) -> str:
    """Write a recording folder with ground truth; return a one-line summary."""

    out_dir = Path(out_dir)
    studio, motion = studio_from_settings(settings)
    with studio:
        writer = RecordingWriter(out_dir, studio.cameras, settings.fps, images=settings.images)
        truth, vis_rows = [], []
        n = studio.n_frames(motion, settings.fps, settings.seconds)
        clocks = settings.clocks(len(studio.cameras))
        frames = studio.play(motion, settings.fps, seconds=settings.seconds, noise_sigma=settings.noise_sigma,
                             brightness_drop=settings.brightness_drop, colour_cast=settings.colour_cast,
                             seed=settings.seed, drift_start_s=settings.drift_start_s, drift_s=settings.drift_s,
                             clocks=clocks, webcam=settings.webcam)
        stamps, gains = [], []
        try:
            for sf in tqdm(frames, total=n, unit="frame", desc="simulating", disable=not progress):
                writer.write(sf.frames.images)
                truth.append(sf.markers_m)
                vis_rows.append(sf.visible_fraction)
                stamps.append(np.full(len(studio.cameras), sf.frames.time_s) if sf.stamps_s is None else sf.stamps_s)
                if sf.camera_gains is not None:
                    gains.append(sf.camera_gains)
        finally:
            writer.close()
        ms = studio.markerset
        timing = {}
        if clocks is not None:
            timing["camera_clocks"] = clocks.as_meta()
            times = np.arange(len(stamps)) / settings.fps
            write_timestamps(out_dir / "timestamps.csv", [c.name for c in studio.cameras], times, np.stack(stamps))
            if any(clocks.readout_s):  # the calibration says what the cameras do (docs/FILES.md)
                save_calibration_toml(out_dir / "calibration.toml", [
                    dataclasses.replace(c, rolling_shutter_s=r) for c, r in zip(studio.cameras, clocks.readout_s)])
        if not settings.webcam.ideal:
            timing["webcam"] = settings.webcam.as_meta()
        if gains:
            write_camera_gains_csv(out_dir / "truth_camera_gains.csv", [c.name for c in studio.cameras], np.stack(gains))
        writer.write_meta(
            ms.name, ms.rgb,
            source="simulator",
            motion=settings.motion,
            rig=settings.rig,
            cameras=[c.name for c in studio.cameras],
            size=list(settings.size_px),
            body={"percentile": settings.percentile, "sex": settings.sex},
            noise_sigma=settings.noise_sigma,
            brightness_drop=settings.brightness_drop,
            colour_cast=list(settings.colour_cast) if settings.colour_cast else None,
            seed=settings.seed,
            **timing,
        )
    positions_m = np.stack(truth)
    n_frames = len(positions_m)
    frame_idx = np.arange(n_frames)
    times = frame_idx / settings.fps
    write_trc(out_dir / "truth.trc", ms.names, positions_m * 1000.0, settings.fps)
    write_angles_csv(out_dir / "truth_angles.csv", frame_idx, times, joint_angles(positions_m, ms.names, roles=ms.roles))
    write_visibility_csv(out_dir / "truth_visibility.csv", [c.name for c in studio.cameras], ms.names, np.stack(vis_rows))
    return f"wrote {n_frames} frame sets from {len(studio.cameras)} cameras at {settings.size_px[0]}x{settings.size_px[1]} to {out_dir}"


def write_visibility_csv(path: Path, camera_names: Sequence[str], marker_names: Sequence[str], fraction: np.ndarray) -> None:
    """``frame,marker,<cam1>,<cam2>...``: visible fraction (0..1) of each marker in each camera."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "marker", *camera_names])
        for i, per_frame in enumerate(fraction):
            for m, name in enumerate(marker_names):
                w.writerow([i, name, *(f"{v:.3f}" for v in per_frame[:, m])])


def write_camera_gains_csv(path: Path, camera_names: Sequence[str], gains: np.ndarray) -> None:
    """``frame,camera,gain_r,gain_g,gain_b``: the (T, C, 3) gains the cameras' auto exposure and
    white balance applied to each image (1: as the light came)."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "camera", "gain_r", "gain_g", "gain_b"])
        for i, per_frame in enumerate(gains):
            for name, g in zip(camera_names, per_frame):
                w.writerow([i, name, *(f"{v:.4f}" for v in g)])


def read_visibility_csv(path: Path, marker_names: Sequence[str]) -> np.ndarray:
    """Inverse of :func:`write_visibility_csv` -> (T, C, M) fractions."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    n_cams = len(rows[0]) - 2
    index = {n: k for k, n in enumerate(marker_names)}
    n_frames = max(int(r[0]) for r in rows[1:]) + 1
    out = np.zeros((n_frames, n_cams, len(marker_names)))
    for r in rows[1:]:
        out[int(r[0]), :, index[r[1]]] = [float(v) for v in r[2:]]
    return out
