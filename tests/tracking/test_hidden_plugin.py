"""A new hidden-marker estimator is one file: registered by name, chosen by the marker set's
``estimator:`` key, run by the Estimator and by the tracker; an unknown name is a one-line error."""

from pathlib import Path

import numpy as np
import pytest

from tracking.errors import ContentError
from tracking.hidden import Estimator, FrameInputs, HiddenMethod, estimator_config, register
from tracking.markerset import load_markerset
from tracking.sim.body import BodyDimensions, BodyModel
from tracking.sim.motions import load_motion
from tracking.sim.studio import SimulationSettings, studio_from_settings
from tracking.marker_status import MarkerStatus
from tracking.tracker import Tracker

SEATED = Path(__file__).resolve().parents[2] / "content" / "markersets" / "upper_limb_seated.yaml"


@register
class StayPut(HiddenMethod):
    """The whole estimator: a hidden marker stays where it was last (no fallback)."""

    name = "stay_put"
    fallback = None
    max_hidden_s = 3.0

    def estimate(self, frame: FrameInputs, k: int) -> np.ndarray:
        return frame.base[k].copy()


@pytest.fixture(scope="module", autouse=True)
def _forget_stay_put_afterwards():
    from tracking.hidden import registry

    yield
    registry.unregister(StayPut.name)


def _markerset(tmp_path, estimator="stay_put"):
    """The seated marker set with the inner elbow markers (M*E2) estimated by ``estimator``."""
    text = SEATED.read_text(encoding="utf-8")
    old = "M*E2: {estimator: hinge,"
    assert old in text
    path = tmp_path / "stay_put.yaml"
    path.write_text(text.replace(old, f"M*E2: {{estimator: {estimator},"), encoding="utf-8")
    return load_markerset(path)


def test_a_registered_estimator_is_chosen_by_name_from_the_marker_set(tmp_path):
    ms = _markerset(tmp_path)
    cfg = estimator_config(ms)
    k = ms.index("MRE2")
    assert cfg["methods"][k] == "stay_put" and cfg["methods"][ms.index("MRE1")] == 3  # hinge's code
    assert cfg["max_hidden_s"][k] == 3.0  # the estimator's own default where the file gives none
    dims = BodyDimensions.from_percentile(50, "female")
    body, motion = BodyModel(dims, ms), load_motion("elbow_flexion_supination", dims)
    est = Estimator(**cfg, fps=30.0)
    measured = np.ones(ms.n_markers, dtype=bool)
    for i in range(20):
        measured[k] = i < 10
        truth = body.markers_m(motion.pose_at(1.0 + i / 30.0))
        p, s = est.update(np.where(measured[:, None], truth, np.nan), measured)
        if i == 9:
            last = p[k].copy()
    assert s[k] == MarkerStatus.ESTIMATED and est.used[k] == StayPut.code
    assert np.array_equal(p[k], last)


def test_an_unknown_estimator_name_is_a_one_line_error_at_load(tmp_path):
    with pytest.raises(ContentError, match=r"hidden_markers\.markers\.M\*E2\.estimator.*stay_put") as e:
        _markerset(tmp_path, "no_such_estimator")
    assert "\n" not in str(e.value) and "tracking/hidden/methods" in str(e.value)


def test_the_tracker_runs_the_registered_estimator(tmp_path):
    """The seed's experiment hides MRE2 from about 1.9 s: the tracker built with the marker set
    that names the estimator estimates it there with it."""
    ms = _markerset(tmp_path)
    k = ms.index("MRE2")
    studio, motion = studio_from_settings(
        SimulationSettings(motion="right_external_rotation", size_px=(320, 240), fps=10.0))
    with studio:
        tracker = Tracker(studio.cameras, ms, fps=10.0)
        before, stayed = None, []
        for sf in studio.play(motion, 10.0, seconds=2.4, noise_sigma=1.5):
            sample = tracker.step(sf.frames.images, sf.frames.time_s)
            if sample.status[k] == MarkerStatus.ESTIMATED:
                assert tracker.estimator.used[k] == StayPut.code
                stayed.append(np.allclose(sample.positions_m[k], before))
            before = sample.positions_m[k].copy()
    assert len(stayed) >= 3 and all(stayed), stayed


def test_registry_names_codes_and_fallbacks():
    from tracking.hidden import Method, registry

    assert {"constant_velocity", "neighbours", "rigid", "hinge", "forearm", "stay_put"} <= set(registry.names())
    codes = [registry.get(n).code for n in registry.names()]
    assert len(set(codes)) == len(codes) and StayPut.code >= len(Method)
    assert [m.name for m in registry.chain(registry.get("hinge"))] == ["hinge", "rigid", "neighbours"]
    assert registry.resolve(Method.RIGID) is registry.get("rigid") and registry.resolve("stay_put").code == StayPut.code
    with pytest.raises(ValueError, match="lower-case"):
        register(type("Bad", (HiddenMethod,), {"name": "Bad Name"}))
    register(type("LoopA", (HiddenMethod,), {"name": "loop_a", "fallback": "loop_b"}))
    register(type("LoopB", (HiddenMethod,), {"name": "loop_b", "fallback": "loop_a"}))
    try:
        with pytest.raises(ValueError, match="circle"):
            Estimator(["loop_a"], np.zeros((1, 1)))
    finally:
        registry.unregister("loop_a")
        registry.unregister("loop_b")
    assert "loop_a" not in registry.names()
    with pytest.raises(ValueError, match="hinge estimator but has no hinge"):
        Estimator(["hinge"], np.zeros((1, 1)))
