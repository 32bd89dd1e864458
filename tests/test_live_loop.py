"""The tracker process's per-frame work, driven directly (no process): grab, track, publish."""

from multiprocessing import shared_memory

import numpy as np
import pytest

from tracking.live.process import TrackerLoop
from tracking.live.protocol import Pause, PatientInput, Reidentify, Resume, SetMotion, SetPatientInput, SourceConfig, Stop
from tracking.live.ring import ImageLayout, ImageSlot, RingLayout, RingReader, RingWriter
from tracking.live.source import SimSource, SourceFrame, angle_names_for
from tracking.status import MarkerStatus
from tracking.tracker import TrackingState

CONFIG = SourceConfig(size=(320, 240), fps=30.0, motion="reference")


@pytest.fixture(scope="module")
def source():
    src = SimSource(CONFIG)
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

    def grab(self, index, time_s, identified):
        if index == 1:
            raise OSError("camera 3 unplugged")
        return self.inner.grab(index, time_s, identified)

    def handle(self, command):
        self.inner.handle(command)


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
        def grab(self, index, time_s, identified):
            f = self.inner.grab(index, time_s, identified)
            return SourceFrame([img[:100] for img in f.images], f.truth_m, f.t_ready_s, f.source_ms)

    loop = TrackerLoop(_Short(source), writer, slot, fps=CONFIG.fps)
    assert not loop.step()
    assert reader.error_line() == ("source error at frame 0: LiveError: camera cam1 delivered 320x100 uint8 images "
                                   "but is calibrated for 320x240 uint8 BGR: recalibrate or set the camera size")
    assert reader.read_new() == []
