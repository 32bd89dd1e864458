"""The shared-memory ring: records round-trip, readers see every sample in order, never a torn one."""

import threading
from multiprocessing import shared_memory

import numpy as np
import pytest

from tracking.live.ring import (ImageLayout, ImageSlot, LayoutError, RingLayout, RingReader, RingWriter, decode_line,
                                encode_line)


@pytest.fixture
def block():
    """A writer and a reader on two handles of one shared-memory block."""
    layout = RingLayout(n_markers=14, n_cameras=4, n_angles=16, ring_size=8)
    shm = shared_memory.SharedMemory(create=True, size=layout.nbytes)
    other = shared_memory.SharedMemory(shm.name)
    writer = RingWriter(shm.buf, layout, initialize=True)
    reader = RingReader(other.buf, layout)
    yield layout, writer, reader, shm.buf
    writer.release()
    reader.release()
    other.close()
    shm.close()
    shm.unlink()


def _publish(writer: RingWriter, k: int) -> None:
    rec = writer.scratch
    rec["frame_index"] = 100 + k
    rec["time_s"] = k / 30.0
    rec["positions_m"] = np.full((14, 3), float(k))
    rec["status"] = k % 3
    rec["angles_deg"] = np.arange(16) + k
    rec["stamps_s"] = k / 30.0 + np.array([0.0, 0.011, -0.004, np.nan])
    rec["message"] = encode_line(f"sample {k}")
    writer.publish()


def test_samples_round_trip_in_order(block):
    layout, writer, reader, buf = block
    assert reader.read_new() == [] and reader.latest() is None
    for k in range(5):
        _publish(writer, k)
    got = reader.read_new()
    assert [int(r["number"]) for r in got] == [0, 1, 2, 3, 4]
    assert [int(r["frame_index"]) for r in got] == [100, 101, 102, 103, 104]
    np.testing.assert_array_equal(got[3]["positions_m"], np.full((14, 3), 3.0))
    np.testing.assert_array_equal(got[4]["angles_deg"], np.arange(16) + 4)
    np.testing.assert_array_equal(got[1]["stamps_s"], 1 / 30.0 + np.array([0.0, 0.011, -0.004, np.nan]))
    assert decode_line(got[2]["message"]) == "sample 2"
    assert int(reader.latest()["frame_index"]) == 104
    assert reader.read_new() == [] and reader.dropped == 0


def test_a_reader_that_falls_behind_counts_what_it_lost(block):
    layout, writer, reader, buf = block
    for k in range(20):
        _publish(writer, k)
    got = reader.read_new()
    assert [int(r["number"]) for r in got] == list(range(12, 20))  # the ring keeps the last 8
    assert reader.dropped == 12


def test_a_restarted_writer_continues_the_numbering(block):
    layout, writer, reader, buf = block
    for k in range(3):
        _publish(writer, k)
    again = RingWriter(buf, layout)
    assert again.latest_frame_index() == 102
    _publish(again, 3)
    assert [int(r["number"]) for r in reader.read_new()] == [0, 1, 2, 3]
    again.release()


def test_a_torn_slot_is_never_returned(block):
    layout, writer, reader, buf = block
    _publish(writer, 0)
    latest_seq = np.ndarray((), "<u8", buffer=buf, offset=layout.header_bytes)
    latest_seq[()] = int(latest_seq) + 1  # as if the writer died in the middle of the latest slot
    assert reader.latest() is None
    del latest_seq


def test_concurrent_reader_sees_consistent_records(block):
    """A reader thread copying while the writer writes: every record is internally consistent."""
    layout, writer, reader, buf = block
    n = 3000
    bad = []
    seen = []

    def read():
        while len(seen) < 200 or (seen and seen[-1] < n - 1):
            rec = reader.latest()
            if rec is None:
                continue
            k = int(rec["frame_index"]) - 100
            if not (rec["positions_m"] == float(k)).all() or not (rec["angles_deg"] == np.arange(16) + k).all():
                bad.append(k)
            seen.append(k)

    t = threading.Thread(target=read)
    t.start()
    for k in range(n):
        _publish(writer, k)
    t.join(timeout=30)
    assert not t.is_alive()
    assert not bad
    assert seen == sorted(seen)


def test_layout_mismatch_is_refused(block):
    layout, writer, reader, buf = block
    with pytest.raises(LayoutError, match="same source configuration"):
        RingReader(buf, RingLayout(10, 4, 16, 8))


def test_encode_line_keeps_one_line_and_whole_characters():
    assert encode_line("a\nb\tc") == b"a b c"
    raw = encode_line("é" * 200, size=11)
    assert raw.decode("utf-8") == "é" * 5


def test_images_round_trip():
    layout = ImageLayout(2, (32, 24))
    shm = shared_memory.SharedMemory(create=True, size=layout.nbytes)
    try:
        slot = ImageSlot(shm.buf, layout, initialize=True)
        assert slot.read() is None
        images = [np.full((24, 32, 3), k * 50, np.uint8) for k in range(2)]
        slot.write(images, 7)
        frame, got = slot.read()
        assert frame == 7
        for a, b in zip(images, got):
            np.testing.assert_array_equal(a, b)
        with pytest.raises(ValueError):
            slot.write([np.zeros((48, 64, 3), np.uint8)] * 2, 8)
        slot.release()
    finally:
        shm.close()
        shm.unlink()
