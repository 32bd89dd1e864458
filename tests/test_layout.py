"""The packages' dependencies point one way (docs/ARCHITECTURE.md, "Packages").

Each check imports a group of modules in a fresh interpreter (so that nothing the test session
loaded before counts) and lists the modules that group must not load: the simulated studio stays
out of the per-frame path and of the game's rendering, and the pure packages (formats, colour,
geometry) load neither the drivers nor the simulator nor the game, GL or pygame.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

_PROBE = """
import importlib, json, pkgutil, sys
names = json.loads(sys.argv[1])
for name in [n for n in names if not n.endswith(".*")]:
    importlib.import_module(name)
for name in [n[:-2] for n in names if n.endswith(".*")]:
    package = importlib.import_module(name)
    for info in pkgutil.walk_packages(package.__path__, name + "."):
        if not info.name.rsplit(".", 1)[-1].endswith("bench"):
            importlib.import_module(info.name)
print(json.dumps(sorted(sys.modules)))
"""


def _loaded(modules: list[str]) -> list[str]:
    env = dict(os.environ, SDL_VIDEODRIVER="dummy", SDL_AUDIODRIVER="dummy")
    out = subprocess.run([sys.executable, "-c", _PROBE, json.dumps(modules)], capture_output=True, text=True,
                         cwd=ROOT, env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def _plain(names: list[str]) -> list[str]:
    return [n for n in names if not n.endswith(".*")]


@pytest.mark.parametrize("group, forbidden", [
    # the per-frame path and the live process: no simulator, no game
    (["tracking.tracker", "tracking.live.process", "tracking.pipeline.*", "tracking.hidden.*",
      "tracking.labelling.*"], ("tracking.sim", "tracking.drivers", "game", "pygame")),
    # the application's rendering: the avatar and the scenes take their GL helpers from
    # tracking.geometry, never from the simulator
    (["game.app", "game.avatar.*", "game.scenes.*", "game.gfx.*"], ("tracking.sim",)),
    # pure packages: formats (and the export formats' plug-ins), colour and geometry
    (["tracking.io.*", "tracking.exports.*", "tracking.colour.*", "tracking.geometry.*"],
     ("tracking.sim", "tracking.drivers", "tracking.live", "game", "pygame", "moderngl")),
], ids=["per-frame path", "game rendering", "pure packages"])
def test_group_does_not_load(group, forbidden):
    loaded = _loaded(group)
    assert set(_plain(group)) <= set(loaded)
    bad = [m for m in loaded if any(m == f or m.startswith(f + ".") for f in forbidden)]
    assert bad == [], f"{group} loads {bad}"
