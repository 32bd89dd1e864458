"""Shared-memory layout of the live tracker: a header, a latest-sample slot and a ring of samples.

One writer (the tracker process) and any number of readers (the game) share two blocks:

- the **sample block**: a header (magic, layout version, sizes, the count of samples written,
  heartbeat, process state, error count, rates) then the *latest* slot then a ring of ``N`` slots.
  Every slot is one fixed-layout record (:func:`sample_dtype`), so a sample is a numpy
  structured scalar that the reader copies out;
- the **image block**: the camera images of the latest frame set (for the camera monitor).

Consistency without locks (a *seqlock*): each slot starts with a sequence number that the writer
makes odd before it writes and even after. A reader copies the slot and accepts the copy only
when the number was even and unchanged across the copy, so it never sees a torn record; if the
writer was in the middle of that slot, the reader tries again. Sample ``n`` (counted from 0 since
the block was created) goes to ring slot ``n % N`` with sequence ``2 n + 2``, so the number also
tells the reader which sample a slot holds; the header's count is raised only after the slot is
complete, so a writer that dies mid-write leaves nothing a reader waits for.

The memory model this relies on is the one of x86-64 and of numpy element stores on aligned
8-byte fields: stores become visible in program order. ARM would need fences (not a target).

Pure numpy on a ``memoryview``: tests create the writer and the reader on two
:class:`multiprocessing.shared_memory.SharedMemory` handles in one process.
"""

from __future__ import annotations

import enum
import time
from dataclasses import dataclass

import numpy as np

from calibration.errors import RehabError

MAGIC = 0x5245484142_4C5632  # "REHABLV2"
LAYOUT_VERSION = 3  # 3: the images' stamps (stamps_s) in every sample
#: Bytes of the one-line message of a sample and of the error line of the header (UTF-8).
MESSAGE_BYTES = 240
#: A reader gives up on a slot after this many torn copies in a row (the writer is far faster
#: than that at rewriting one slot, so it only happens if the writer died mid-write).
MAX_RETRIES = 64


class LayoutError(RehabError):
    """A shared-memory block does not hold the layout this code expects."""


class ProcessState(enum.IntEnum):
    """What the tracker process reports in the header."""

    STARTING = 0  # attached, building the source and the tracker
    RUNNING = 1
    PAUSED = 2
    STOPPED = 3  # left its loop on request
    FAILED = 4  # could not start (the error line says why)


def sample_dtype(n_markers: int, n_cameras: int, n_angles: int) -> np.dtype:
    """The fixed record of one published sample.

    Fields (world metres, pixels, degrees; NaN where not available):
        seq: seqlock sequence number (odd while being written).
        number: sample number since the block was created (0, 1, ...).
        frame_index, time_s: the source's frame number and time stamp.
        t_frame_ready_s: ``time.perf_counter()`` in the writer when the frame set was ready.
        t_published_s: ``time.perf_counter()`` just before the record was written.
        step_ms: tracker step time for this frame set.
        source_ms: time the source took to deliver the frame set (render or capture).
        state: ``tracking.tracker.TrackingState``.
        positions_m (M, 3), status (M,) uint8, angles_deg (A,), windows_px (M, C, 3),
        uv_px (M, C, 2), truth_m (M, 3).
        stamps_s (C,): the instant of each camera's image the tracker used (the source's stamps,
            the set's instant when the source gives none; the live camera check measures each
            camera's clock from them).
        message: UTF-8 bytes, NUL padded.
    """
    m, c, a = int(n_markers), int(n_cameras), int(n_angles)
    return np.dtype([
        ("seq", "<u8"),
        ("number", "<i8"),
        ("frame_index", "<i8"),
        ("time_s", "<f8"),
        ("t_frame_ready_s", "<f8"),
        ("t_published_s", "<f8"),
        ("step_ms", "<f8"),
        ("source_ms", "<f8"),
        ("state", "<i8"),
        ("positions_m", "<f8", (m, 3)),
        ("angles_deg", "<f8", (a,)),
        ("windows_px", "<f8", (m, c, 3)),
        ("uv_px", "<f8", (m, c, 2)),
        ("truth_m", "<f8", (m, 3)),
        ("stamps_s", "<f8", (c,)),
        ("status", "u1", (m,)),
        ("message", f"S{MESSAGE_BYTES}"),
    ], align=True)


#: The header of the sample block. Scalars written by one side only, each an aligned 8-byte
#: store; the error line has its own sequence number.
HEADER_DTYPE = np.dtype([
    ("magic", "<u8"),
    ("version", "<u8"),
    ("n_markers", "<i8"),
    ("n_cameras", "<i8"),
    ("n_angles", "<i8"),
    ("ring_size", "<i8"),
    ("record_bytes", "<i8"),
    ("written", "<i8"),  # samples completely written (the next sample's number)
    ("heartbeat_s", "<f8"),  # perf_counter of the writer's last loop turn
    ("pid", "<i8"),  # the writer's process id
    ("state", "<i8"),  # ProcessState
    ("source_fps", "<f8"),  # frame sets per second delivered, recent average
    ("step_ms", "<f8"),  # mean tracker step time, recent average
    ("errors", "<i8"),  # frame sets whose processing raised
    ("error_seq", "<u8"),
    ("error", f"S{MESSAGE_BYTES}"),
    ("warning_seq", "<u8"),  # the source's current warnings, "; "-joined ("" when none)
    ("warning", f"S{MESSAGE_BYTES}"),
], align=True)


def _pad(nbytes: int) -> int:
    return (nbytes + 63) // 64 * 64


def encode_line(text: str, size: int = MESSAGE_BYTES) -> bytes:
    """One line of text as at most ``size`` UTF-8 bytes, never cutting a character."""
    raw = " ".join(str(text).split()).encode("utf-8")
    if len(raw) <= size:
        return raw
    return raw[:size].decode("utf-8", errors="ignore").encode("utf-8")


def decode_line(raw: bytes) -> str:
    return bytes(raw).rstrip(b"\0").decode("utf-8", errors="replace")


@dataclass(frozen=True, slots=True)
class RingLayout:
    """Sizes of the sample block.

    Attributes:
        n_markers, n_cameras, n_angles: array sizes of a record.
        ring_size: slots in the ring (samples a reader may fall behind without losing any).
    """

    n_markers: int
    n_cameras: int
    n_angles: int
    ring_size: int = 256

    def __post_init__(self) -> None:
        if self.ring_size < 2:
            raise LayoutError(f"ring_size {self.ring_size} is too small: give at least 2 slots")

    @property
    def record(self) -> np.dtype:
        return sample_dtype(self.n_markers, self.n_cameras, self.n_angles)

    @property
    def header_bytes(self) -> int:
        return _pad(HEADER_DTYPE.itemsize)

    @property
    def record_bytes(self) -> int:
        return _pad(self.record.itemsize)

    @property
    def nbytes(self) -> int:
        """Size of the whole block: header, latest slot, ring."""
        return self.header_bytes + (1 + self.ring_size) * self.record_bytes


class _Views:
    """Numpy views of a sample block."""

    def __init__(self, buf: memoryview, layout: RingLayout) -> None:
        if len(buf) < layout.nbytes:
            raise LayoutError(f"shared block of {len(buf)} bytes is smaller than the {layout.nbytes} the layout needs")
        self.layout = layout
        self.header = np.ndarray((), HEADER_DTYPE, buffer=buf, offset=0)
        rec = layout.record
        # A record is padded to 64 bytes: view the slots as raw rows, each row's head as a record.
        rows = np.ndarray((1 + layout.ring_size, layout.record_bytes), np.uint8, buffer=buf, offset=layout.header_bytes)
        self.slots = [row[: rec.itemsize].view(rec).reshape(()) for row in rows]
        self.seqs = [np.ndarray((), "<u8", buffer=buf, offset=layout.header_bytes + k * layout.record_bytes)
                     for k in range(1 + layout.ring_size)]

    def release(self) -> None:
        """Drop every view, so that the shared memory can be closed."""
        self.header = None
        self.slots = []
        self.seqs = []


def _copy_slot(views: _Views, k: int) -> np.ndarray | None:
    """A consistent copy of slot ``k`` (0 = latest, 1.. = ring), or None if never written or torn."""
    seq = views.seqs[k]
    slot = views.slots[k]
    for attempt in range(MAX_RETRIES):
        if attempt >= 4:
            time.sleep(0)  # the writer was preempted mid-write: let it finish
        s1 = int(seq)
        if s1 == 0:
            return None
        if s1 & 1:
            continue
        out = slot.copy()
        if int(seq) == s1:
            return out
    return None


class RingWriter:
    """Writes samples into a sample block (the tracker process's side).

    Args:
        buf: the block's memory (``SharedMemory.buf``).
        layout: its sizes.
        initialize: write a fresh header (the block's creator); otherwise the header must match
            the layout, and writing continues after the samples already in the block (a restarted
            tracker process).
    """

    def __init__(self, buf: memoryview, layout: RingLayout, *, initialize: bool = False) -> None:
        self._v = _Views(buf, layout)
        self.layout = layout
        h = self._v.header
        if initialize:
            np.frombuffer(buf, np.uint8, count=layout.nbytes)[:] = 0
            h["n_markers"], h["n_cameras"], h["n_angles"] = layout.n_markers, layout.n_cameras, layout.n_angles
            h["ring_size"], h["record_bytes"] = layout.ring_size, layout.record_bytes
            h["version"] = LAYOUT_VERSION
            h["magic"] = MAGIC
        else:
            check_header(h, layout)
        self._scratch = np.zeros((), layout.record)

    @property
    def header(self) -> np.ndarray:
        """The header record (a view: assign fields to publish them)."""
        return self._v.header

    @property
    def scratch(self) -> np.ndarray:
        """A private record to fill before :meth:`publish` (avoids building one per sample)."""
        return self._scratch

    @property
    def written(self) -> int:
        return int(self._v.header["written"])

    def latest_frame_index(self) -> int | None:
        """The frame index of the newest complete sample (None if none): a restarted writer
        continues after it."""
        n = self.written
        if n == 0:
            return None
        # the latest slot, or the ring's copy if the previous writer died while writing it
        for k in (0, 1 + (n - 1) % self.layout.ring_size):
            rec = _copy_slot(self._v, k)
            if rec is not None:
                return int(rec["frame_index"])
        return None

    def publish(self, record: np.ndarray | None = None) -> int:
        """Write ``record`` (default: :attr:`scratch`) as the next sample; returns its number.

        The ``seq`` and ``number`` fields are set here.
        """
        rec = self._scratch if record is None else record
        n = self.written
        rec["number"] = n
        for k in (1 + n % self.layout.ring_size, 0):
            seq = self._v.seqs[k]
            seq[()] = 2 * n + 1
            rec["seq"] = 2 * n + 1
            self._v.slots[k][()] = rec
            seq[()] = 2 * n + 2
        self._v.header["written"] = n + 1
        return n

    def set_error(self, line: str) -> None:
        """Publish the error line (one line; also counts it)."""
        h = self._v.header
        h["error_seq"] = int(h["error_seq"]) + 1  # odd: being written
        h["error"] = encode_line(line)
        h["error_seq"] = int(h["error_seq"]) + 1
        h["errors"] = int(h["errors"]) + 1

    def set_warning(self, line: str) -> None:
        """Publish the source's current warnings as one line ("" clears them)."""
        h = self._v.header
        h["warning_seq"] = int(h["warning_seq"]) + 1  # odd: being written
        h["warning"] = encode_line(line)
        h["warning_seq"] = int(h["warning_seq"]) + 1

    def release(self) -> None:
        self._v.release()


def check_header(header: np.ndarray, layout: RingLayout) -> None:
    """Raise :class:`LayoutError` unless the header was written for ``layout``."""
    if int(header["magic"]) != MAGIC or int(header["version"]) != LAYOUT_VERSION:
        raise LayoutError("the shared block is not a live-tracker sample block of this version: "
                          "restart the game so both sides run the same code")
    got = tuple(int(header[k]) for k in ("n_markers", "n_cameras", "n_angles", "ring_size", "record_bytes"))
    want = (layout.n_markers, layout.n_cameras, layout.n_angles, layout.ring_size, layout.record_bytes)
    if got != want:
        raise LayoutError(f"the shared block holds (markers, cameras, angles, ring, record bytes) {got}, "
                          f"expected {want}: both sides must use the same source configuration")


class RingReader:
    """Reads samples from a sample block (the game's side).

    Each reader keeps its own position, so :meth:`read_new` returns every sample published since
    its previous call, in order, unless the reader fell more than the ring behind (then the
    oldest are skipped and counted in :attr:`dropped`).
    """

    def __init__(self, buf: memoryview, layout: RingLayout) -> None:
        self._v = _Views(buf, layout)
        self.layout = layout
        check_header(self._v.header, layout)
        self.next_number = int(self._v.header["written"])
        self.dropped = 0

    @property
    def header(self) -> np.ndarray:
        return self._v.header

    def written(self) -> int:
        return int(self._v.header["written"])

    def read_new(self) -> list[np.ndarray]:
        """Copies of every sample published since the last call, oldest first."""
        end = self.written()
        n = self.next_number
        size = self.layout.ring_size
        if end - n > size:
            self.dropped += end - n - size
            n = end - size
        out = []
        while n < end:
            rec = _copy_slot(self._v, 1 + n % size)
            if rec is not None and int(rec["number"]) == n:
                out.append(rec)
            else:  # overwritten while we read (we fell a whole ring behind) or torn for good
                self.dropped += 1
            n += 1
        self.next_number = end
        return out

    def latest(self) -> np.ndarray | None:
        """A copy of the newest sample (None before the first)."""
        return _copy_slot(self._v, 0)

    def error_line(self) -> str:
        """The writer's last error line ("" if none)."""
        return self._line("error")

    def warning_line(self) -> str:
        """The source's current warnings ("" if none)."""
        return self._line("warning")

    def _line(self, field: str) -> str:
        h = self._v.header
        for _ in range(MAX_RETRIES):
            s1 = int(h[f"{field}_seq"])
            if s1 & 1:
                continue
            raw = bytes(h[field])
            if int(h[f"{field}_seq"]) == s1:
                return decode_line(raw)
        return ""

    def release(self) -> None:
        self._v.release()


# ============================================================================ images
IMAGE_HEADER_DTYPE = np.dtype([
    ("seq", "<u8"),
    ("frame_index", "<i8"),
    ("n_cameras", "<i8"),
    ("height", "<i8"),
    ("width", "<i8"),
], align=True)


@dataclass(frozen=True, slots=True)
class ImageLayout:
    """Sizes of the image block: ``n_cameras`` BGR images of ``size_px`` (width, height)."""

    n_cameras: int
    size_px: tuple[int, int]

    @property
    def shape(self) -> tuple[int, int, int, int]:
        w, h = self.size_px
        return (self.n_cameras, h, w, 3)

    @property
    def header_bytes(self) -> int:
        return _pad(IMAGE_HEADER_DTYPE.itemsize)

    @property
    def nbytes(self) -> int:
        return self.header_bytes + int(np.prod(self.shape))


class ImageSlot:
    """The latest frame set's images in shared memory, seqlocked like a sample slot.

    Args:
        buf: the block's memory.
        layout: its sizes.
        initialize: write a fresh header (the block's creator).
    """

    def __init__(self, buf: memoryview, layout: ImageLayout, *, initialize: bool = False) -> None:
        if len(buf) < layout.nbytes:
            raise LayoutError(f"image block of {len(buf)} bytes is smaller than the {layout.nbytes} the layout needs")
        self.layout = layout
        self._h = np.ndarray((), IMAGE_HEADER_DTYPE, buffer=buf, offset=0)
        self._images = np.ndarray(layout.shape, np.uint8, buffer=buf, offset=layout.header_bytes)
        c, h, w, _ = layout.shape
        if initialize:
            self._h["seq"] = 0
            self._h["n_cameras"], self._h["height"], self._h["width"] = c, h, w
        elif (int(self._h["n_cameras"]), int(self._h["height"]), int(self._h["width"])) != (c, h, w):
            raise LayoutError("the image block was made for other cameras: both sides must use the same source configuration")

    def write(self, images, frame_index: int) -> None:
        """Copy one (H, W, 3) uint8 image per camera into the block."""
        seq = int(self._h["seq"])
        self._h["seq"] = seq + 1 if seq % 2 == 0 else seq + 2
        for k, img in enumerate(images):
            self._images[k] = img
        self._h["frame_index"] = frame_index
        self._h["seq"] = int(self._h["seq"]) + 1

    def read(self) -> tuple[int, list[np.ndarray]] | None:
        """(frame index, copies of the images), or None before the first write or if torn."""
        for attempt in range(16):
            if attempt:
                time.sleep(0.0005)  # a frame set takes ~1 ms to write
            s1 = int(self._h["seq"])
            if s1 == 0:
                return None
            if s1 & 1:
                continue
            frame = int(self._h["frame_index"])
            images = self._images.copy()
            if int(self._h["seq"]) == s1:
                return frame, list(images)
        return None

    def release(self) -> None:
        self._h = None
        self._images = None
