"""Plain colour words for the messages to the therapist ('the 4 cyan markers')."""

from __future__ import annotations

import colorsys
from typing import Iterable

import numpy as np


def colour_word(rgb: Iterable[int]) -> str:
    """A plain colour name for an sRGB colour (0-255), by hue: 'yellow', 'cyan', ..."""
    r, g, b = (float(c) / 255.0 for c in rgb)
    h, s, v = colorsys.rgb_to_hsv(r, g, b)
    if v < 0.2:
        return "black"
    if s < 0.25:
        return "white" if v > 0.8 else "grey"
    hue = h * 360.0
    for limit, word in ((15, "red"), (40, "orange"), (70, "yellow"), (165, "green"), (200, "cyan"),
                        (255, "blue"), (290, "purple"), (345, "magenta")):
        if hue < limit:
            return word
    return "red"


def palette_words(palette: np.ndarray) -> list[str]:
    """Colour names of a (K, 3) palette, with the RGB added where two colours share a name."""
    words = [colour_word(c) for c in palette]
    return [w if words.count(w) == 1 else f"{w} ({','.join(str(int(v)) for v in c)})" for w, c in zip(words, palette)]
