"""Colours and type sizes of the whole application, in one place.

Calm and readable from a couple of metres away: a dark blue-grey room, soft panels, one teal
accent for what is selected or working, amber for "wait / attention", a muted red only for
failures. Sizes are font pixel sizes of pygame's bundled font at a 1280x720 window.
"""

from __future__ import annotations

from types import MappingProxyType

BACKGROUND = (27, 33, 43)
BACKGROUND_GL = (27 / 255, 33 / 255, 43 / 255)
PANEL = (38, 46, 59, 235)
PANEL_EDGE = (66, 78, 97)
OVERLAY = (16, 20, 27, 190)
TEXT = (236, 240, 245)
TEXT_DIM = (163, 174, 190)
TEXT_FAINT = (104, 115, 132)
ACCENT = (94, 200, 190)         # teal: selected, tracking, good
ACCENT_DARK = (34, 86, 88)
ATTENTION = (242, 190, 92)      # amber: waiting, estimated, restarting
FAILURE = (232, 112, 104)       # muted red: lost, failed

#: Marker status colours (tracking.marker_status.MarkerStatus: 0 lost, 1 measured, 2 estimated).
STATUS_COLOURS = MappingProxyType({0: FAILURE, 1: ACCENT, 2: ATTENTION})

TITLE = 76
LARGE = 52
MEDIUM = 38
BODY = 30
SMALL = 24

MARGIN = 28
RADIUS = 18
