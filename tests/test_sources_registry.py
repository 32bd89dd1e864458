"""A new camera type is one module registered by name (docs/SOURCES.md "A new camera type"):
this test module is one, a camera type whose cameras see a grey wall for three frame sets."""

import numpy as np
import pytest

import tracking.sources as sources
from tracking.live.protocol import LiveError, SetMotion, SourceConfig
from tracking.live.source import calibration_file_for, open_source, resolve_config, source_geometry
from tracking.markerset import load_markerset
from tracking.sim.rigs import load_rig
from tracking.sources.base import FrameRequest, FrameSet, InOrderSource, warnings_and_end

N_SETS = 3


class GreyCameras(InOrderSource):
    """Cameras that deliver ``N_SETS`` grey frame sets, then end."""

    def __init__(self, cameras, markerset, fps):
        super().__init__()
        self.cameras, self.markerset, self.fps = cameras, markerset, fps
        self.k, self.ended = 0, ""

    def open(self):
        pass

    def read_next(self):
        if self.k >= N_SETS:
            self.ended = f"the grey cameras ended after {N_SETS} frame sets"
            return None
        c, t = len(self.cameras), self.k / self.fps
        images = tuple(np.full((cam.size_px[1], cam.size_px[0], 3), 128, np.uint8) for cam in self.cameras)
        self.k += 1
        return FrameSet(self.k - 1, t, images, np.full(c, t), np.zeros(c, bool))

    def warnings(self):
        return ()

    def end_reason(self):
        return self.ended

    def close(self):
        pass


def geometry(config):
    return tuple(load_rig(config.rig, tuple(config.size))), load_markerset(config.markerset)


def from_config(config):
    return GreyCameras(*geometry(config), config.fps)


@pytest.fixture
def grey_kind(monkeypatch):
    monkeypatch.setattr(sources, "KINDS", dict(sources.KINDS))  # the registration ends with the test
    sources.register("grey", __name__)
    return SourceConfig(kind="grey", size=(64, 48), fps=10.0)


def test_a_registered_camera_type_is_opened_by_its_name(grey_kind):
    grey_kind.check()
    cameras, markerset = source_geometry(grey_kind)
    assert len(cameras) == 4 and cameras[0].size_px == (64, 48) and markerset.n_markers == 14
    # the optional hooks left out: no calibration file (the nominal colours), the size as given
    assert calibration_file_for(grey_kind) is None and resolve_config(grey_kind) == grey_kind
    source = open_source(grey_kind)
    first = source.read(FrameRequest(0, 0.0, False))
    assert source.read(FrameRequest(0, 0.0, True)) is first  # the live loop's warm-up set, again
    assert first.images[0].shape == (48, 64, 3) and first.source_ms >= 0.0
    assert [source.read(FrameRequest(k, k / 10.0)).index for k in (1, 2)] == [1, 2]
    assert source.read(FrameRequest(3, 0.3)) is None
    assert warnings_and_end(source) == ("the grey cameras ended after 3 frame sets",)
    with pytest.raises(LiveError, match="plays no motions"):
        source.handle(SetMotion("reach"))


def test_an_unknown_kind_is_one_line_naming_the_registered_ones():
    with pytest.raises(LiveError, match="source kind 'nope': give one of sim, recording, cameras or module:function"):
        SourceConfig(kind="nope").check()
