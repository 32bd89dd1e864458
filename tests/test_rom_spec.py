"""ROM tests as content: every file loads; the standards are kept apart; bad files give one line."""

import pytest
import yaml

from game.rom.spec import STANDARDS, available_rom_tests, load_all_rom_tests, load_rom_test
from tracking.angles import ARM_ANGLES
from tracking.errors import ContentError
from tracking.sim.motions import available_motions

REQUIRED = {
    "shoulder_flexion", "shoulder_extension", "shoulder_abduction", "shoulder_horizontal_flexion",
    "shoulder_horizontal_extension", "shoulder_external_rotation", "shoulder_internal_rotation",
    "elbow_flexion", "forearm_pronation", "forearm_supination",
}


def test_the_upper_limb_tests_exist_for_both_sides():
    assert REQUIRED <= set(available_rom_tests())
    for test in load_all_rom_tests():
        assert set(test.sides) == {"right", "left"}
        assert test.angle in ARM_ANGLES and test.direction in (1, -1)
        assert set(test.references) == set(STANDARDS)
        assert test.instructions and test.watch and test.position_words


def test_every_simulated_motion_named_by_a_test_exists():
    motions = set(available_motions())
    for test in load_all_rom_tests():
        assert "right" in test.simulated_motion
        assert set(test.simulated_motion.values()) <= motions


def test_standards_are_never_mixed_across_test_positions():
    er = load_rom_test("shoulder_external_rotation")
    assert er.normal_deg("jarm") == 60 and er.references["jarm"].comparable
    assert er.references["aaos"].value_deg == 90 and not er.references["aaos"].comparable
    assert er.normal_deg("aaos") is None
    assert "another position" in er.references["aaos"].label()
    ir = load_rom_test("shoulder_internal_rotation")
    assert ir.normal_deg("jarm") == 80 and ir.normal_deg("aaos") is None
    assert load_rom_test("shoulder_extension").normal_deg("jarm") == 50
    assert load_rom_test("shoulder_extension").normal_deg("aaos") == 60


def test_extension_tests_read_the_negative_angle():
    assert load_rom_test("shoulder_extension").angle_name("left") == "left_shoulder_flexion"
    assert load_rom_test("shoulder_extension").direction == -1
    assert load_rom_test("forearm_pronation").direction == -1


@pytest.mark.parametrize("change, message", [
    ({"colour": "red"}, "unknown key"),
    ({"angle": "knee_flexion"}, "not an arm angle"),
    ({"compensations": [{"kind": "trunk_lean", "words": "leaning"}]}, "needs max_deg"),
    ({"start": {"angles": {"elbow_flexion": [30, 0]}}}, "is empty"),
])
def test_a_bad_file_is_one_line_naming_the_file_and_key(tmp_path, change, message):
    from content import content_path

    data = yaml.safe_load(content_path("rom_tests", "shoulder_flexion.yaml").read_text(encoding="utf-8"))
    data.update(change)
    src = tmp_path / "bad.yaml"
    src.write_text(yaml.safe_dump(data), encoding="utf-8")
    with pytest.raises(ContentError) as err:
        load_rom_test(str(src))
    assert message in str(err.value) and str(src) in str(err.value) and "\n" not in str(err.value)


def test_unknown_test_lists_the_names():
    with pytest.raises(ContentError, match="shoulder_flexion"):
        load_rom_test("knee_flexion")
