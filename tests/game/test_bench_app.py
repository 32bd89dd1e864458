"""``rehab bench``'s application figure runs with and without a display, after the simulator's
figures made an EGL context current in the benchmarking process (a window's GLX context opened
in that process afterwards ended it with an X error, BadAccess on X_GLXMakeCurrent)."""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest

from game.cli import bench_app

pytestmark = pytest.mark.timeout(240)


@pytest.fixture
def egl_current():
    """An EGL context made current in this process, as the simulator's benchmarks leave it."""
    from tracking.sim.renderer import OffscreenGLUnavailable, create_context

    try:
        ctx = create_context()
    except OffscreenGLUnavailable as exc:  # pragma: no cover - depends on the machine
        pytest.skip(str(exc))
    ctx.clear(0.0, 0.0, 0.0)
    yield ctx
    ctx.release()


@pytest.fixture
def xvfb(monkeypatch):
    """A virtual X display (Xvfb) for the duration of the test; skipped where Xvfb is not installed."""
    binary = shutil.which("Xvfb")
    if binary is None:
        pytest.skip("Xvfb is not installed")
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen([binary, "-displayfd", str(write_fd), "-screen", "0", "1280x720x24", "-nolisten", "tcp"],
                            pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write_fd)
    with os.fdopen(read_fd) as f:
        number = f.readline().strip()
    if not number:  # pragma: no cover - depends on the machine
        proc.kill()
        pytest.skip("Xvfb did not start")
    monkeypatch.setenv("DISPLAY", f":{number}")
    monkeypatch.delenv("SDL_VIDEODRIVER", raising=False)
    monkeypatch.setenv("SDL_AUDIODRIVER", "dummy")
    yield f":{number}"
    proc.terminate()
    proc.wait(10)


def test_the_application_figure_in_a_window_after_the_simulator_used_egl(egl_current, xvfb):
    summary = bench_app(1.5, window=True)
    assert summary.frames >= 5 and summary.fps > 0


def test_the_application_figure_headless(egl_current, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setenv("SDL_AUDIODRIVER", "dummy")
    summary = bench_app(1.5, window=False)
    assert summary.frames >= 5 and summary.fps > 0
