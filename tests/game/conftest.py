"""Shared fixtures of the game's tests."""

from __future__ import annotations

import pytest

from game.gfx.screen import GraphicsUnavailable, open_screen


@pytest.fixture
def open_headless(monkeypatch):
    """A function that opens an offscreen screen of a given size (SDL dummy driver, EGL); the test
    is skipped where the machine has no offscreen OpenGL; every screen opened is closed after it."""
    monkeypatch.setenv("SDL_VIDEODRIVER", "dummy")
    opened = []

    def open_(size_px: tuple[int, int]):
        try:
            screen = open_screen(size_px, "test", headless=True)
        except GraphicsUnavailable as exc:  # pragma: no cover - depends on the machine
            pytest.skip(str(exc))
        opened.append(screen)
        return screen

    yield open_
    for screen in reversed(opened):
        screen.close()
