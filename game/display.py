"""Opening the pygame window, or telling the user in one line why there is none.

SDL, asked for a window on a machine without a display, may fail late, pick a driver that shows
nothing, or (with some drivers) grab the console; so the environment is checked first, with a
pure function, and only then is pygame's display touched.
"""

from __future__ import annotations

import os
import sys
from typing import Mapping

import pygame

from calibration.errors import RehabError

NO_DISPLAY_MESSAGE = (
    "no display found; run 'rehab play --headless --seconds 5 --screenshot play.png' to render offscreen"
)

#: SDL video drivers that open no visible window.
OFFSCREEN_DRIVERS = frozenset({"dummy", "offscreen"})


class NoDisplayError(RehabError):
    """There is no screen to open a window on."""

    def __init__(self, detail: str = "") -> None:
        super().__init__(NO_DISPLAY_MESSAGE if not detail else f"{NO_DISPLAY_MESSAGE} ({detail})")


def has_display(environ: Mapping[str, str], platform: str) -> bool:
    """Whether a visible window can be expected, judged from the environment alone.

    Args:
        environ: the process environment (``os.environ``).
        platform: ``sys.platform``.

    On Linux and the BSDs a window needs an X11 or Wayland server (``DISPLAY`` or
    ``WAYLAND_DISPLAY``), or an explicit on-screen SDL driver such as ``kmsdrm``. Windows and macOS
    always have a desktop when a user runs the command.
    """
    driver = environ.get("SDL_VIDEODRIVER", "").strip().lower()
    if driver:
        return driver not in OFFSCREEN_DRIVERS
    if platform.startswith(("win", "darwin")):
        return True
    return bool(environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY"))


def open_window(size_px: tuple[int, int], title: str, *, headless: bool) -> pygame.Surface:
    """Initialise pygame and return the window's software surface.

    Args:
        size_px: window (width, height).
        title: window caption.
        headless: render offscreen with SDL's dummy driver (no window is shown).

    Raises:
        NoDisplayError: not headless and there is no display, or SDL cannot open the window.
    """
    # SDL would otherwise present the window surface through an OpenGL renderer of its own, whose
    # GLX context, made current on this thread at every flip, displaces the studio's EGL context:
    # moderngl then crashes. A plain X11/Wayland framebuffer is all this window needs. SDL reads
    # both settings when the display subsystem starts, so they must precede init.
    os.environ["SDL_FRAMEBUFFER_ACCELERATION"] = "0"
    if headless:
        os.environ["SDL_VIDEODRIVER"] = "dummy"
    elif not has_display(os.environ, sys.platform):
        raise NoDisplayError()
    try:
        pygame.display.init()
        pygame.font.init()
        surface = pygame.display.set_mode(size_px)
    except pygame.error as exc:
        pygame.quit()
        raise NoDisplayError(str(exc).splitlines()[0] if str(exc) else "") from None
    pygame.display.set_caption(title)
    return surface


def close_window() -> None:
    """Shut pygame's display and fonts down (safe to call twice)."""
    pygame.quit()
