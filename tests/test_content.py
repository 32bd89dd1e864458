"""Every content YAML file loads and validates."""

import pytest

from content import content_path
from tracking.content_loader import available
from tracking.markerset import load_markerset
from tracking.sim.body import BodyDimensions
from tracking.sim.motions import load_motion
from tracking.sim.rigs import load_rig

ALL_YAML = sorted(p.relative_to(content_path()) for p in content_path().rglob("*.yaml"))


def test_content_folder_is_not_empty():
    assert len(ALL_YAML) >= 10


@pytest.mark.parametrize("name", available("markersets"))
def test_markersets_load(name):
    ms = load_markerset(name)
    assert ms.n_markers == len(set(ms.names))


@pytest.mark.parametrize("name", available("rigs"))
def test_rigs_load(name):
    cams = load_rig(name, (320, 240))
    assert len(cams) >= 2


@pytest.mark.parametrize("name", available("motions"))
def test_motions_load(name):
    motion = load_motion(name, BodyDimensions.from_percentile(50, "female"))
    assert motion.duration_s > 1.0


def test_every_yaml_file_belongs_to_a_known_kind():
    kinds = {"markersets", "rigs", "motions", "rom_tests", "games"}
    assert {p.parts[0] for p in ALL_YAML} <= kinds
