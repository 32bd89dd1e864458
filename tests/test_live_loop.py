"""The tracker process's per-frame work, driven directly (no process): grab, track, publish."""

from multiprocessing import shared_memory

import numpy as np
import pytest

from tracking.live.process import TrackerLoop
from tracking.live.protocol import Pause, PatientInput, Reidentify, Resume, SetMotion, SetPatientInput, SourceConfig, Stop
from tracking.live.ring import ImageLayout, ImageSlot, RingLayout, RingReader, RingWriter
import dataclasses

from tracking.live.source import angle_names_for
from tracking.sources.sim import SimulatedSource
from tracking.marker_status import MarkerStatus
from tracking.tracker import TrackingState

CONFIG = SourceConfig(size=(320, 240), fps=30.0, motion="reference")


@pytest.fixture(scope="module")
def source():
    src = SimulatedSource(CONFIG)
    yield src
    src.close()


@pytest.fixture
def blocks(source):
    ring = RingLayout(source.markerset.n_markers, len(source.cameras), len(angle_names_for(source.markerset)), 16)
    images = ImageLayout(len(source.cameras), CONFIG.size)
    shm = shared_memory.SharedMemory(create=True, size=ring.nbytes)
    img = shared_memory.SharedMemory(create=True, size=images.nbytes)
    writer = RingWriter(shm.buf, ring, initialize=True)
    slot = ImageSlot(img.buf, images, initialize=True)
    reader = RingReader(shm.buf, ring)
    yield writer, slot, reader
    for part in (writer, slot, reader):
        part.release()
    for s in (shm, img):
        s.close()
        s.unlink()


def test_steps_publish_tracked_samples_and_images(source, blocks):
    writer, slot, reader = blocks
    source.handle(Reidentify())
    loop = TrackerLoop(source, writer, slot, fps=CONFIG.fps)
    for _ in range(4):
        assert loop.step()
    got = reader.read_new()
    assert [int(r["frame_index"]) for r in got] == [0, 1, 2, 3]
    last = got[-1]
    assert int(last["state"]) == TrackingState.TRACKING
    assert (last["status"] == MarkerStatus.MEASURED).all()
    err = np.linalg.norm(last["positions_m"] - last["truth_m"], axis=1)
    assert err.max() < 0.008
    assert float(last["time_s"]) == pytest.approx(3 / 30.0)
    # the simulated cameras give no stamps of their own: each image at the set's instant
    assert last["stamps_s"].shape == (4,) and (last["stamps_s"] == last["time_s"]).all()
    names = loop.angle_names
    elbow = float(last["angles_deg"][names.index("right_elbow_flexion")])
    assert 0 < elbow < 30  # the reference pose: elbows nearly straight
    frame, images = slot.read()
    assert frame == 3 and len(images) == 4
    assert float(writer.header["step_ms"]) > 0
    # a restarted loop on the same block continues the frame numbering
    again = TrackerLoop(source, writer, slot, fps=CONFIG.fps, tracker=loop.tracker)
    assert again.frame_index == 4


def test_commands(source, blocks):
    writer, slot, reader = blocks
    loop = TrackerLoop(source, writer, slot, fps=CONFIG.fps)
    assert loop.handle(Pause()) and loop.paused
    assert loop.handle(Resume()) and not loop.paused
    assert loop.handle(SetPatientInput(PatientInput(side="left")))
    assert source.patient_input.side == "left"
    assert loop.handle(SetMotion("no_such_motion"))  # reported, not raised
    assert int(writer.header["errors"]) == 1
    assert "source error" in reader.error_line() and "no_such_motion" in reader.error_line()
    assert source.motion is not None and source.motion.name == "reference"  # the motion kept playing
    assert not loop.handle(Stop())


class _Broken:
    """A source whose second frame set fails."""

    def __init__(self, inner):
        self.inner, self.cameras, self.markerset = inner, inner.cameras, inner.markerset

    def read(self, request):
        if request.index == 1:
            raise OSError("camera 3 unplugged")
        return self.inner.read(request)

    def handle(self, command):
        self.inner.handle(command)

    def warnings(self):
        return self.inner.warnings()

    def end_reason(self):
        return self.inner.end_reason()


def test_a_failing_frame_is_an_error_line_and_the_loop_goes_on(source, blocks):
    writer, slot, reader = blocks
    loop = TrackerLoop(_Broken(source), writer, slot, fps=CONFIG.fps)
    assert loop.step()
    assert not loop.step()
    assert reader.error_line() == "source error at frame 1: OSError: camera 3 unplugged"
    assert loop.step()
    assert [int(r["frame_index"]) for r in reader.read_new()] == [0, 2]


def test_images_of_the_wrong_size_are_refused_before_tracking(source, blocks):
    writer, slot, reader = blocks

    class _Short(_Broken):
        def read(self, request):
            f = self.inner.read(request)
            return dataclasses.replace(f, images=tuple(img[:100] for img in f.images))

    loop = TrackerLoop(_Short(source), writer, slot, fps=CONFIG.fps)
    assert not loop.step()
    assert reader.error_line() == ("source error at frame 0: LiveError: camera cam1 delivered 320x100 uint8 images "
                                   "but is calibrated for 320x240 uint8 BGR: recalibrate or set the camera size")
    assert reader.read_new() == []


class _FakeClock:
    def __init__(self):
        self.now_s = 100.0

    def __call__(self):
        return self.now_s


class _Conn:
    """The control pipe: waiting on it passes fake time; Stop once ``until_s`` is reached."""

    def __init__(self, clock, until_s):
        self.clock, self.until_s = clock, until_s

    def poll(self, timeout_s=0.0):
        if self.clock.now_s >= self.until_s:
            return True
        self.clock.now_s += timeout_s
        return False

    def recv(self):
        return Stop()


class _Slow(_Broken):
    """A machine too busy for the frame rate: every frame set takes 2.5 frame periods."""

    def __init__(self, inner, clock, paced_by_clock):
        super().__init__(inner)
        self.clock, self.paced_by_clock, self.times = clock, paced_by_clock, []

    def read(self, request):
        self.clock.now_s += 2.5 / CONFIG.fps
        self.times.append(request.time_s)
        return self.inner.read(request)


@pytest.mark.realtime
@pytest.mark.parametrize("paced_by_clock", [True, False])
def test_a_late_loop_drops_frame_sets_of_a_source_tied_to_the_clock(source, blocks, paced_by_clock):
    """Issue 25: on a busy machine the simulated patient played in slow motion (one frame period of
    motion per frame set tracked, however long it took). A source tied to the clock, like a camera,
    is asked for the frame set due now: its motion time follows the wall clock, the late frame sets
    are dropped. A recording (not tied to the clock) still plays every frame set."""
    writer, slot, reader = blocks
    clock = _FakeClock()
    slow = _Slow(source, clock, paced_by_clock)
    source.handle(Reidentify())
    loop = TrackerLoop(slow, writer, slot, fps=CONFIG.fps, clock=clock)
    start_s = clock.now_s
    loop.run(_Conn(clock, start_s + 1.0))
    got = reader.read_new()
    indices = [int(r["frame_index"]) for r in got]
    assert len(indices) >= 10 and indices[0] == 0
    elapsed_s = clock.now_s - start_s
    if paced_by_clock:
        # each frame set is the one due when it was grabbed: its time stamp is the clock's, within
        # one period, and the steps between them are the 2-3 periods the tracking took
        assert {b - a for a, b in zip(indices, indices[1:])} <= {2, 3}
        assert float(got[-1]["time_s"]) == pytest.approx(elapsed_s, abs=3.5 / CONFIG.fps)
        assert loop.dropped_frames == indices[-1] - len(indices) + 1 > 0
    else:
        assert indices == list(range(len(indices)))
        assert float(got[-1]["time_s"]) < 0.5 * elapsed_s   # a recording's own time: every frame set
        assert loop.dropped_frames == 0
    assert [round(t * CONFIG.fps) for t in slow.times] == indices


def test_a_loop_on_time_grabs_every_frame_set_at_its_time(source, blocks):
    writer, slot, reader = blocks
    clock = _FakeClock()

    class _Quick(_Slow):
        def read(self, request):
            self.clock.now_s += 0.2 / CONFIG.fps
            return self.inner.read(request)

    loop = TrackerLoop(_Quick(source, clock, True), writer, slot, fps=CONFIG.fps, clock=clock)
    loop.run(_Conn(clock, clock.now_s + 0.5))
    indices = [int(r["frame_index"]) for r in reader.read_new()]
    assert indices == list(range(len(indices))) and 15 <= len(indices) <= 16
    assert loop.dropped_frames == 0


def test_the_simulated_patient_is_tied_to_the_wall_clock_unless_asked_for_frame_time(source):
    from tracking.live.protocol import LiveError

    assert source.paced_by_clock                    # the default: like a camera
    frames = SimulatedSource(SourceConfig(size=(320, 240), fps=30.0, motion="reference", sim_clock="frames"))
    try:
        assert not frames.paced_by_clock
    finally:
        frames.close()
    with pytest.raises(LiveError, match="sim_clock 'fast': give one of wall, frames"):
        SourceConfig(sim_clock="fast").check()
