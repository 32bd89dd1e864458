"""Manual colour picks: the ball under a click (drawn balls with known centres), refusals with reasons,
and a table taught from picks that finds a cast magenta the nominal table misses while keeping the
background and a shirt of another colour out."""

import cv2
import numpy as np
import pytest

from tracking.colour.adapt import nominal_models
from tracking.colour.pick import ColourPickError, ManualColours, pick_blob
from tracking.colour.table import ColourTable

PALETTE = np.array([[255, 214, 0], [225, 0, 210], [0, 190, 235]], np.uint8)  # yellow, magenta, cyan (RGB)
CAST_MAGENTA_BGR = (150, 40, 235)  # a magenta under a warm cast: hue ~325 deg, outside the nominal band


def scene():
    img = np.full((240, 320, 3), (95, 100, 105), np.uint8)
    cv2.rectangle(img, (200, 120), (319, 239), (40, 120, 230), -1)  # an orange shirt (BGR), larger than a ball
    cv2.circle(img, (80, 60), 9, CAST_MAGENTA_BGR, -1, cv2.LINE_AA)
    cv2.circle(img, (150, 170), 7, CAST_MAGENTA_BGR, -1, cv2.LINE_AA)
    cv2.circle(img, (40, 200), 8, (0, 200, 250), -1, cv2.LINE_AA)  # a yellow ball
    return img


def test_the_ball_under_the_click_is_found():
    blob = pick_blob(scene(), (82.0, 58.0))
    assert np.linalg.norm(blob.centre_uv - (80, 60)) < 0.5
    assert abs(blob.radius_px - 9) < 1.0
    hsv = cv2.cvtColor(blob.pixels_bgr.reshape(-1, 1, 3), cv2.COLOR_BGR2HSV_FULL).reshape(-1, 3)
    assert len(blob.pixels_bgr) > 150 and np.ptp(hsv[:, 0]) <= 3  # the inside only: no rim mixed with grey
    assert 320 < blob.hue_deg < 332
    assert np.linalg.norm(pick_blob(scene(), (86.0, 60.0)).centre_uv - (80, 60)) < 0.5  # near the rim still works


@pytest.mark.parametrize("uv, reason", [((20, 120), "no coloured pixel"), ((260, 180), "larger than a marker ball"),
                                        ((400, 10), "outside the camera image")])
def test_clicks_off_a_ball_are_refused_with_a_reason(uv, reason):
    with pytest.raises(ColourPickError, match=reason):
        pick_blob(scene(), uv)


def test_a_taught_colour_finds_the_cast_magenta_and_keeps_the_rest_out():
    img = scene()
    nominal = ColourTable.build(PALETTE)
    labels = nominal.classify(img)
    assert labels[60, 80] == 0 and labels[170, 150] == 0  # the nominal table misses the cast magenta
    manual = ManualColours(nominal_models(PALETTE))
    manual.teach(1, img, (80, 60), table=nominal)
    assert manual.picks.tolist() == [0, 1, 0] and 320 < manual.models[1].hue_deg < 332
    taught = manual.table()
    labels = taught.classify(img)
    assert labels[60, 80] == 2 and labels[170, 150] == 2  # both magenta balls, the unclicked one too
    assert labels[200, 40] == 1  # the yellow ball keeps its nominal colour
    assert not labels[125:235, 205:315].any() and not labels[100:110, 10:60].any()  # shirt and wall out
    # A second pick of the same colour averages with the first.
    manual.teach(1, img, (150, 170), table=taught)
    assert manual.picks[1] == 2 and manual.table().classify(img)[60, 80] == 2
    with pytest.raises(ColourPickError, match="choose one of the 3"):
        manual.teach(3, img, (80, 60))
