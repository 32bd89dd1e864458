"""The live tracker's colour table: learnt colours from the calibration file, and the online adapter
(SourceConfig.adapt_colours) following a lighting drift, driven through TrackerLoop.step (no process)."""

from contextlib import contextmanager
from multiprocessing import shared_memory

import numpy as np
import pytest

from game.cli import main
from tracking.colour.adapt import ColourAdapter
from tracking.live.process import TrackerLoop, make_tracker
from tracking.live.protocol import SourceConfig
from tracking.live.ring import RingLayout, RingReader, RingWriter
from tracking.live.source import angle_names_for, open_source
from tracking.sources.base import FrameRequest
from tracking.marker_status import MarkerStatus


@pytest.fixture(scope="module")
def drifting(tmp_path_factory):
    """4 s at 15 fps, 40 % darker and a warm cast reached at the end (the nominal table loses the magenta)."""
    rec = tmp_path_factory.mktemp("drift") / "rec"
    assert main(["simulate", str(rec), "--motion", "shoulder_abduction", "--size", "320x240", "--fps", "15",
                 "--seconds", "4", "--drift", "0.4", "--cast", "1.3,1.0,0.7"]) == 0
    return rec


@contextmanager
def tracker_loop(config: SourceConfig, slots: int):
    """A TrackerLoop over the source of ``config`` writing into a ring of ``slots`` samples:
    yields (source, loop, reader, adapter); everything is closed after."""
    source = open_source(config)
    try:
        tracker, adapter = make_tracker(config, source)
        ring = RingLayout(source.markerset.n_markers, len(source.cameras), len(angle_names_for(source.markerset)), slots)
        shm = shared_memory.SharedMemory(create=True, size=ring.nbytes)
        try:
            writer = RingWriter(shm.buf, ring, initialize=True)
            reader = RingReader(shm.buf, ring)
            yield source, TrackerLoop(source, writer, None, fps=config.fps, tracker=tracker, adapter=adapter), reader, adapter
            writer.release()
            reader.release()
        finally:
            shm.close()
            shm.unlink()
    finally:
        source.close()


def run_loop(config: SourceConfig):
    """Every frame set of the source through a TrackerLoop; returns (status (T, M) per published sample, adapter)."""
    with tracker_loop(config, 128) as (_, loop, reader, adapter):
        while loop.step():
            pass
        status = np.array([r["status"] for r in reader.read_new()])
    return status, adapter


def test_the_adapter_keeps_every_marker_measured_through_a_lighting_drift(drifting):
    fixed, none = run_loop(SourceConfig(kind="recording", path=str(drifting), fps=15.0))
    adapted, adapter = run_loop(SourceConfig(kind="recording", path=str(drifting), fps=15.0, adapt_colours=True))
    assert none is None and isinstance(adapter, ColourAdapter) and adapter.updates >= 2
    assert fixed.shape == adapted.shape and fixed.shape[0] >= 55
    last = slice(-15, None)  # the last second: the darkest, most cast light
    assert np.all(adapted[last] == MarkerStatus.MEASURED)
    assert np.all(adapted == MarkerStatus.MEASURED)
    assert np.mean(fixed[last] == MarkerStatus.MEASURED) < 0.9  # the fixed table loses markers there


def test_learnt_colours_in_the_calibration_are_used_live(drifting, tmp_path):
    from calibration.files import load_calibration, save_calibration_toml
    from tracking.colour.adapt import calibration_colours, save_colours_to_calibration
    from tracking.colour.learn import ColourModel
    from tracking.markerset import load_markerset

    calib = tmp_path / "calibration.toml"
    save_calibration_toml(calib, load_calibration(drifting / "calibration.toml"))
    ms = load_markerset("upper_limb_seated")
    # A table that labels nothing: with it the tracker can identify no marker, so its use shows.
    models = [ColourModel(0.0, 18.0, 0.8, (255, 0, 0))] * ms.palette.shape[0]
    save_colours_to_calibration(calib, ms, models, np.zeros((256, 256), np.uint8))
    assert calibration_colours(calib, ms) is not None
    config = SourceConfig(kind="recording", path=str(drifting), calibration=str(calib), fps=15.0)
    source = open_source(config)
    try:
        tracker, adapter = make_tracker(config, source)
        assert adapter is None
        frame = source.read(FrameRequest(0, 0.0, False))
        sample = tracker.step(frame.images, 0.0)
        assert not np.any(sample.status == MarkerStatus.MEASURED)
    finally:
        source.close()


def test_taught_colours_sent_to_the_loop_replace_its_table(drifting):
    from tracking.colour.adapt import nominal_models
    from tracking.live.protocol import SetColours

    config = SourceConfig(kind="recording", path=str(drifting), fps=15.0, adapt_colours=True)
    with tracker_loop(config, 8) as (source, loop, reader, adapter):
        tracker = loop.tracker
        models = nominal_models(source.markerset.palette)
        labels = np.zeros((256, 256), np.uint8)
        assert loop.handle(SetColours(tuple(models), labels))
        assert loop.adapter is not adapter and tracker.table is loop.adapter.table
        assert not tracker.table.lut.any()  # the table of the (empty) labels sent
        assert loop.handle(SetColours(tuple(models[:2]), labels))  # wrong count: reported, table kept
        assert tracker.table is loop.adapter.table and "colours error" in reader.error_line()
