"""The suite on several cores: each worker's share of them, and the tests that need them all.

pytest-xdist runs one worker per core. Two things keep a worker's test from being starved by the
other's (docs/TESTING.md):

- each worker's numeric libraries (OpenBLAS, OpenMP, OpenCV) use its share of the cores, not all of
  them each: two workers whose BLAS threads spin against each other ran a test 6x slower;
- a test marked ``realtime`` checks the rate, latency or deadline of live processes against the wall
  clock; it runs while no other test runs. It takes an exclusive file lock that every other test
  takes shared, behind a turnstile so that a waiting ``realtime`` test is not starved by a stream of
  shared holders.
"""
from __future__ import annotations

import fcntl
import os
import shutil
import tempfile
from pathlib import Path

import pytest

_WORKERS = os.environ.get("PYTEST_XDIST_WORKER_COUNT")
if _WORKERS:   # a worker, before any test module imports numpy or cv2
    _share = str(max(1, (os.cpu_count() or 1) // int(_WORKERS)))
    for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENCV_FOR_THREADS_NUM"):
        os.environ.setdefault(_name, _share)

_LOCK_DIR = "rehab_realtime_lock_dir"
_lock_key = pytest.StashKey[str]()


def pytest_configure(config):
    config.addinivalue_line("markers", "realtime: checks live processes against the wall clock; runs while no other test runs")
    if not hasattr(config, "workerinput") and config.pluginmanager.hasplugin("xdist"):
        config.stash[_lock_key] = tempfile.mkdtemp(prefix="rehab-tests-")


def pytest_unconfigure(config):
    path = config.stash.get(_lock_key, None)
    if path:
        shutil.rmtree(path, ignore_errors=True)



@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):
    """The controller hands each worker the folder of the shared lock files."""
    node.workerinput[_LOCK_DIR] = node.config.stash[_lock_key]


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    folder = getattr(item.config, "workerinput", {}).get(_LOCK_DIR)
    if folder is None:   # one process: nothing runs beside the test
        yield
        return
    exclusive = item.get_closest_marker("realtime") is not None
    with open(Path(folder) / "turnstile", "a") as turnstile, open(Path(folder) / "cores", "a") as cores:
        fcntl.flock(turnstile, fcntl.LOCK_EX)
        fcntl.flock(cores, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        if not exclusive:
            fcntl.flock(turnstile, fcntl.LOCK_UN)
        try:
            yield
        finally:
            fcntl.flock(cores, fcntl.LOCK_UN)
            if exclusive:
                fcntl.flock(turnstile, fcntl.LOCK_UN)
