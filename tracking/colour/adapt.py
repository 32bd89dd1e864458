"""Online colour adaptation: the tracker's table follows the lighting, from the tracked markers.

:class:`ColourAdapter` owns a learned table (:mod:`tracking.colour.learn`) that starts as the
nominal one. Every ``every`` frame sets, after :meth:`tracking.tracker.Tracker.step`, it projects
the markers measured this frame into each camera and takes the pixels of the inner part of the
largest ``max_discs`` ball views of each colour (``inner`` of the projected radius) for the
colour's histogram; pixels drawn at random from outside all balls' discs go to the background's.
A view is used only where the current table still labels at least half of it with the marker's
colour (so a ball hidden behind the arm in that camera teaches nothing) and, of its pixels, only
those within ``loose_hue_deg`` of the colour's current hue with saturation >=
``loose_saturation``: that band is wider than the table's, so pixels the table has begun to miss
as the light drifts are learned and pull the model along. The models are refitted with
forgetting ``rate``; the first update (at identification) replaces the nominal table at once,
later ones stage their changed table entries (:meth:`tracking.colour.learn.LutBuilder.stage`),
colours the cameras see first, and each frame set rewrites ``max(budget, pending / every)`` of
them in place. The tracker, which reads ``table.lut`` at every window, sees each rewrite from its
next frame, and the table is never more than one update behind the models.
"""

from __future__ import annotations

import base64
import logging
import time
import tomllib
import zlib
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from calibration.camera import Camera
from calibration.files import read_metadata_section, write_metadata_section
from tracking.colour.learn import (
    ColourModel,
    ColourStats,
    LutBuilder,
    fit_models,
    hsv_bytes,
    label_hue_saturation,
    nominal_hue_deg,
    disc_pixels,
    outside_discs_sample,
)
from tracking.colour.table import ColourTable, DEFAULT_HUE_TOL_DEG, DEFAULT_MIN_SATURATION
from tracking.errors import ContentError, RecordingError
from tracking.markerset import MarkerSet
from tracking.marker_status import MarkerStatus

log = logging.getLogger(__name__)

HUE_UNITS_PER_DEG = 256.0 / 360.0


def nominal_models(palette_rgb: np.ndarray) -> list[ColourModel]:
    """The nominal table's rule as models: palette hue +-20 deg, saturation >= 0.8 x the palette's."""
    pal = np.asarray(palette_rgb, dtype=np.float64)
    sat = (pal.max(axis=1) - pal.min(axis=1)) / np.maximum(pal.max(axis=1), 1.0)
    return [ColourModel(float(h), DEFAULT_HUE_TOL_DEG, float(DEFAULT_MIN_SATURATION * s), tuple(int(c) for c in rgb))
            for h, s, rgb in zip(nominal_hue_deg(palette_rgb), sat, np.asarray(palette_rgb))]


class ColourAdapter:
    """Learns the marker colours from tracked markers and keeps a full table up to date.

    Args:
        cameras: the tracker's cameras (same order as the images).
        markerset: the marker set (colours, ball radius).
        every: learn from every this many frame sets.
        rate: share of the colour statistics replaced by one update (exponential forgetting).
        inner: fraction of the projected ball radius whose pixels are learned.
        max_discs: ball views learned per colour per update at most (the largest ones).
        background_samples: pixels drawn per camera per update for the background.
        start: learned (models, label_hs) to start from (:func:`read_colours`; default nominal).
        budget: table entries rewritten per frame set at least, while changes are pending (a model
            change is spread over the frames until the next update: ``max(budget, pending /
            every)`` per frame set; ~30 ns of CPU per entry).
        seed: random seed of the background sampling.

    Attributes:
        table: the :class:`ColourTable` to give the tracker; its ``lut`` is rewritten in place.
        models: the current colour models.
        seconds: wall time of every :meth:`observe` call (the per-frame cost of adaptation).
        cpu_seconds: the same as CPU time of the calling thread (what the work costs on a machine
            shared with other jobs, where wall time also counts waiting for a core).
    """

    def __init__(self, cameras: Sequence[Camera], markerset: MarkerSet, *, every: int = 60, rate: float = 0.3,
                 inner: float = 0.6, background_samples: int = 1500,
                 start: tuple[list[ColourModel], np.ndarray] | None = None,
                 budget: int = 4000, max_discs: int = 4, seed: int = 0):
        if every < 1 or not 0.0 < rate <= 1.0:
            raise ValueError("every must be >= 1 and rate in (0, 1]")
        self.cameras = tuple(cameras)
        self.markerset = markerset
        self.every, self.rate, self.inner = int(every), float(rate), float(inner)
        self.background_samples = int(background_samples)
        self.budget = int(budget)
        self.max_discs = int(max_discs)
        self.rng = np.random.default_rng(seed)
        self.colour = markerset.colour_index
        self.stats = ColourStats(markerset.palette.shape[0])
        self.builder = LutBuilder(markerset.palette.shape[0])
        self.models = nominal_models(markerset.palette) if start is None else list(start[0])
        self.builder.build(label_hue_saturation(self.models) if start is None else start[1])
        self.table: ColourTable = self.builder.table(self.models)
        self.loose_hue_deg = 40.0
        self.loose_saturation = 0.3
        self.updates = 0
        self.seconds: list[float] = []
        self.cpu_seconds: list[float] = []
        self._frames = 0
        self._share = 0

    def observe(self, images: Sequence[np.ndarray], positions_m: np.ndarray, status: np.ndarray, *,
                force: bool = False) -> bool:
        """Learn from one frame set after the tracker's step (every ``every`` calls, or ``force``).

        Args:
            images: the frame set's BGR images.
            positions_m: (M, 3) the tracker's marker positions (NaN where lost).
            status: (M,) the tracker's :class:`MarkerStatus` per marker.

        Returns:
            True if the table was updated.
        """
        t0, c0 = time.perf_counter(), time.thread_time()
        self._frames += 1
        self.builder.apply(max(self.budget, self._share))
        measured = np.asarray(status) == MarkerStatus.MEASURED
        if (not force and (self._frames - 1) % self.every) or not measured.any():
            self._timed(t0, c0)
            return False
        k_count = self.stats.n_colours
        class_px: list[list[np.ndarray]] = [[] for _ in range(k_count)]
        bg_px = []
        lut = self.table.lut
        known = np.isfinite(positions_m).all(axis=1)
        p = np.where(known[:, None], positions_m, 0.0)
        geometry = []  # per camera: (uv, radius px)
        for cam, img in zip(self.cameras, images):
            depth = cam.world_to_camera(p)[:, 2]
            f = (cam.K[0, 0] + cam.K[1, 1]) / 2.0
            r_px = np.where(known & (depth > 0), f * self.markerset.radius_m / np.maximum(depth, 1e-6), np.nan)
            geometry.append((cam.project(p), r_px))
            # background: everything away from every known ball (estimated ones included)
            far = known & np.isfinite(r_px)
            bg = outside_discs_sample(img, geometry[-1][0][far], 2.0 * r_px[far] + 3.0, self.background_samples, self.rng)
            bg_px.append(hsv_bytes(bg))
        # the largest discs of each colour first (most pixels for the work), at most max_discs
        views = [(r_px[m], c, m) for c, (_, r_px) in enumerate(geometry) for m in np.flatnonzero(measured)
                 if np.isfinite(r_px[m])]
        used = np.zeros(k_count, int)
        for r, c, m in sorted(views, reverse=True):
            k = int(self.colour[m])
            if used[k] >= self.max_discs:
                continue
            px = disc_pixels(images[c], geometry[c][0][m], self.inner * r)
            if len(px) < 3:
                continue
            words = px[:, 0].astype(np.uint32) | px[:, 1].astype(np.uint32) << 8 | px[:, 2].astype(np.uint32) << 16
            if np.count_nonzero(lut[words] == k + 1) * 2 < len(px):
                continue  # hidden in this camera, or another ball in front
            hsv = hsv_bytes(px)
            dh = np.abs((hsv[:, 0] / HUE_UNITS_PER_DEG - self.models[k].hue_deg + 180.0) % 360.0 - 180.0)
            class_px[k].append(hsv[(dh <= self.loose_hue_deg) & (hsv[:, 1] >= self.loose_saturation * 255)])
            used[k] += 1
        first = self.updates == 0
        rate = 1.0 if first else self.rate
        for k in range(k_count):
            if class_px[k]:
                self.stats.add(k + 1, np.concatenate(class_px[k]), rate)
        self.stats.add(0, np.concatenate(bg_px), rate)
        counts = self.stats.counts()
        models = list(self.models)
        fitted = fit_models_partial(self.stats)
        for k in range(k_count):
            if counts[k + 1] > 0:
                models[k] = fitted[k]
        self.models = models
        labels = label_hue_saturation(self.models, self.stats)
        # colours the cameras see first: a pending change to a colour nobody shows can wait
        seen = self.stats.hist / np.maximum(self.stats.counts(), 1e-12)[:, None, None]
        priority = np.repeat(seen.sum(axis=0), 256 // seen.shape[2], axis=1)
        if first:
            queued = self.builder.update(labels)  # at identification: the nominal table is replaced at once
        else:
            queued = self.builder.stage(labels, priority)
        # spread what is pending over the frames until the next update, so that the table never
        # lags more than one update behind (``budget`` is the least per frame)
        pending = self.builder.pending
        self._share = int((self.builder.starts[pending + 1] - self.builder.starts[pending]).sum()) // self.every + 1
        self.updates += 1
        self._timed(t0, c0)
        log.debug("colour update %d: %d table entries queued", self.updates, queued)
        return True

    def _timed(self, t0: float, c0: float) -> None:
        self.seconds.append(time.perf_counter() - t0)
        self.cpu_seconds.append(time.thread_time() - c0)

    def flush(self) -> int:
        """Apply every pending table change now (e.g. before saving). Returns colours rewritten."""
        return self.builder.apply()

    def save(self, path: Path) -> None:
        """Write the learned colours as TOML (models for people, the label table for the tracker)."""
        self.flush()
        save_colours(path, self.markerset, self.models, self.builder.label_hs)


def fit_models_partial(stats: ColourStats) -> list[ColourModel | None]:
    """:func:`fit_models` for the classes that have pixels; None for the others."""
    out: list[ColourModel | None] = []
    for k in range(stats.n_colours):
        if stats.hist[k + 1].sum() <= 0:
            out.append(None)
            continue
        one = ColourStats(1, stats.min_value)
        one.hist[1] = stats.hist[k + 1]
        out.append(fit_models(one)[0])
    return out


CALIBRATION_SECTION = "marker_colours"
"""The learnt colours' section in a calibration file: ``[metadata.marker_colours]``."""


def colours_toml(markerset: MarkerSet, models: Sequence[ColourModel], label_hs: np.ndarray, *, prefix: str = "") -> str:
    """Learnt colours as TOML: ``markerset``, one ``[[colour]]`` table per colour (nominal RGB, the
    learnt hue, band, saturation floor and a representative RGB, for people), and ``[table]`` with
    the packed (hue, saturation) labels (for the tracker). ``prefix`` nests it all under a table
    (``"metadata.marker_colours"``: ``[metadata.marker_colours]``, ``[[metadata.marker_colours.colour]]``, ...).
    """
    dot = f"{prefix}." if prefix else ""
    lines = [f"[{prefix}]"] if prefix else []
    lines += [f'markerset = "{markerset.name}"', ""]
    for nominal, m in zip(np.asarray(markerset.palette).tolist(), models):
        lines += [f"[[{dot}colour]]", f"nominal_rgb = {nominal}", f"rgb = {list(m.rgb)}",
                  f"hue_deg = {m.hue_deg:.2f}", f"hue_tol_deg = {m.hue_tol_deg:.2f}", f"sat_floor = {m.sat_floor:.3f}", ""]
    packed = base64.b64encode(zlib.compress(np.ascontiguousarray(label_hs, np.uint8).tobytes(), 9)).decode()
    lines += [f"[{dot}table]", "# (hue byte, saturation byte) -> label, 256 x 256 uint8, zlib + base64",
              f'label_hs = "{packed}"', ""]
    return "\n".join(lines)


def save_colours(path: Path, markerset: MarkerSet, models: Sequence[ColourModel], label_hs: np.ndarray) -> None:
    """Learned colours -> a TOML colour file of their own (:func:`colours_toml`)."""
    header = "# Marker colours learned by `rehab colour learn` (tracking/colour/adapt.py).\n"
    Path(path).write_text(header + colours_toml(markerset, models, label_hs), encoding="utf-8")


def save_colours_to_calibration(path: Path, markerset: MarkerSet, models: Sequence[ColourModel], label_hs: np.ndarray) -> None:
    """Learned colours -> the ``[metadata.marker_colours]`` section of a TOML calibration file
    (replacing an older one; the cameras are kept as they are)."""
    text = ("# Marker colours learned by `rehab calibrate colour` (tracking/colour/adapt.py)\n"
            + colours_toml(markerset, models, label_hs, prefix=f"metadata.{CALIBRATION_SECTION}"))
    write_metadata_section(path, CALIBRATION_SECTION, text)


def load_colours(path: Path, markerset: MarkerSet) -> ColourTable:
    """A learned colour file (or a calibration file holding learnt colours) -> a full
    :class:`ColourTable` for the tracker.

    Raises:
        ContentError: the file is missing, malformed, or for other colours.
    """
    return table_from_colours(*read_colours(path, markerset))


def table_from_colours(models: Sequence[ColourModel], label_hs: np.ndarray) -> ColourTable:
    """Learnt colours (models, (256, 256) labels) -> the full table."""
    builder = LutBuilder(len(models))
    builder.build(label_hs)
    return builder.table(list(models))


def calibration_colours(path: Path, markerset: MarkerSet) -> tuple[list[ColourModel], np.ndarray] | None:
    """The learnt colours saved in a calibration file, or None when it holds none.

    Raises:
        ContentError: the section is malformed or for other colours.
    """
    section = read_metadata_section(path, CALIBRATION_SECTION)
    if section is None:
        return None
    return _colours_from_data(section, Path(path), markerset)


def read_colours(path: Path, markerset: MarkerSet) -> tuple[list[ColourModel], np.ndarray]:
    """A learned colour file, or a calibration file with learnt colours -> (models, (256, 256)
    hue-saturation labels).

    Raises:
        ContentError: the file is missing, malformed, or for another number of colours.
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ContentError(f"{path}: no such colour file; make one with `rehab colour learn RECORDING --out {path.name}`") from None
    except Exception as exc:
        raise ContentError(f"{path}: not a learned colour file ({exc}); make it again with `rehab colour learn`") from None
    meta = data.get("metadata")
    if "colour" not in data and isinstance(meta, dict) and isinstance(meta.get(CALIBRATION_SECTION), dict):
        data = meta[CALIBRATION_SECTION]
    elif "colour" not in data and isinstance(meta, dict):
        raise ContentError(f"{path}: this calibration holds no learnt colours: add them with `rehab calibrate colour`")
    return _colours_from_data(data, path, markerset)


def _colours_from_data(data: dict, path: Path, markerset: MarkerSet) -> tuple[list[ColourModel], np.ndarray]:
    try:
        colours = data["colour"]
        label_hs = np.frombuffer(zlib.decompress(base64.b64decode(data["table"]["label_hs"])), np.uint8).reshape(256, 256)
        models = [ColourModel(float(c["hue_deg"]), float(c["hue_tol_deg"]), float(c["sat_floor"]),
                              tuple(int(v) for v in c["rgb"])) for c in colours]
        nominal = [tuple(c["nominal_rgb"]) for c in colours]
    except Exception as exc:
        raise ContentError(f"{path}: not a learned colour file ({exc}); make it again with `rehab colour learn`") from None
    k = markerset.palette.shape[0]
    if nominal != [tuple(c) for c in np.asarray(markerset.palette).tolist()] or label_hs.max() > k:
        raise ContentError(f"{path}: learned for the colours {nominal}, but the marker set {markerset.name} has "
                           f"{np.asarray(markerset.palette).tolist()}: learn them again for this marker set")
    return models, label_hs


def learn_colours(frame_sets: Iterable, cameras: Sequence[Camera], markerset: MarkerSet, *, frames: int = 30,
                  table: ColourTable | None = None) -> ColourAdapter:
    """Learn the marker colours from the first frames of a recording that starts in the reference pose.

    The tracker identifies the markers with ``table`` (default: the nominal one); from then on,
    each of ``frames`` frame sets adds the pixels of the measured markers' balls and of the rest of
    the images with equal weight (a running mean).

    Args:
        frame_sets: :class:`tracking.io.recording.FrameSet` objects in time order.
        cameras: calibrated cameras, in the order of the images.
        markerset: the marker set worn.
        frames: frame sets to learn from after identification.

    Raises:
        RecordingError: the markers were never identified, or a marker colour was never measured.
    """
    # lazy: the tracker only to learn colours from a recording (the game imports this module)
    from tracking.tracker import Tracker, TrackingState

    tracker = Tracker(cameras, markerset, table=table)
    adapter = ColourAdapter(cameras, markerset, every=1)
    message = "no frames"
    for fs in frame_sets:
        sample = tracker.step(fs.images, fs.time_s)
        if sample.state != TrackingState.TRACKING:
            message = sample.message or "not identified"
            continue
        adapter.rate = 1.0 / (adapter.updates + 1)
        adapter.observe(fs.images, sample.positions_m, sample.status)
        if adapter.updates >= frames:
            break
    if adapter.updates == 0:
        raise RecordingError(f"the markers were never identified ({message}): the recording must start with "
                             "the patient in the reference pose")
    missing = [tuple(c) for c, n in zip(np.asarray(markerset.palette).tolist(), adapter.stats.counts()[1:]) if n <= 0]
    if missing:
        raise RecordingError(f"the marker colour(s) {missing} were never measured in the first frames: make sure "
                             "every marker is seen by two cameras in the reference pose")
    adapter.flush()
    return adapter
