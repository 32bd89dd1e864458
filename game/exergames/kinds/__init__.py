"""Game kinds: what a kind of exercise game does differently, one module per kind, found by name.

A game's YAML names its ``kind`` (``content/games/<name>.yaml``); the kind is a :class:`GameKind`
registered under that name. It says which stored ROM tests bound the targets, where a target
goes and what the patient controls to reach it (the session's rules), how the game's view frames
the avatar and shows the target, how the mouse and the automatic demo move the simulated arm.
Everything else (the session's pauses, difficulty, log, the scene's panel and banner) is shared.

A new kind is one new module in this package that calls :func:`register` at import (every module
here is imported when a kind is first looked up), or any module registered the same way before
its games are loaded (``tests/game/dummy_game_kind.py``); docs/GAMES.md "A new game".
"""

from __future__ import annotations

import importlib
import math
import pkgutil
from dataclasses import dataclass

import numpy as np

from game.exergames.targets import RomLimits, Target

#: The forearm's rotation the keys and the mouse ask of the simulated patient stays within this
#: (degrees either way).
FOREARM_LIMIT_DEG = 85.0


@dataclass(frozen=True, slots=True)
class Framing:
    """Where the game's 3D view looks (:func:`game.scenes.game_play.game_camera`).

    The view aims at the shoulders' midpoint moved ``trunk_share`` of the way down to the pelvis,
    ``up_m`` up, ``forward_m`` forward and ``aside_m`` towards the active side; it is turned
    ``yaw_deg`` towards the active side, looks down by ``pitch_deg`` and frames ``half_m`` metres
    either side of that point (more on a narrow view).
    """

    yaw_deg: float
    pitch_deg: float
    half_m: float
    trunk_share: float = 0.0
    up_m: float = 0.0
    forward_m: float = 0.0
    aside_m: float = 0.0


@dataclass(frozen=True, slots=True)
class Aim:
    """What the mouse aims with (:meth:`GameKind.aim`).

    Attributes:
        view: the avatar's viewport (:class:`game.gfx.view3d.Viewport`); view_proj: its (4, 4) matrix.
        frame: the arm's geometry (:class:`game.exergames.targets.ArmFrame`).
        side: the active arm; river: the rotation game's :class:`game.exergames.river.River` (else None).
        target_hand_m: (3,) the current target's hand position, or None between targets.
    """

    view: object
    view_proj: np.ndarray
    frame: object
    side: str
    river: object = None
    target_hand_m: np.ndarray | None = None


class GameKind:
    """One kind of game. Subclasses set the class attributes and override what differs.

    Attributes:
        name: the ``kind`` of the YAML.
        rom_keys: the keys of the YAML's ``rom`` (the positive and the negative direction's tests,
            in the order of :class:`game.exergames.targets.RomLimits`).
        needs_elbow: the YAML must name the elbow flexion test (``elbow``).
        needs_posture: the YAML must give a ``posture`` (e.g. the elbow at the side).
        river: targets are gates drifting down a river (the YAML's ``difficulty.approach_share``,
            needed then and only then); the scene shows the river beside the avatar.
        logged_angles: the angles whose range used is logged (without the side).
        size_step: a step of the therapist's smallest-target limit on the menu (metres or degrees).
        direction_words: the negative and positive direction in words (the gauge's ends).
        framing: the 3D view.
    """

    name: str = ""
    rom_keys: tuple[str, str] = ("positive", "negative")
    needs_elbow: bool = False
    needs_posture: bool = False
    river: bool = False
    logged_angles: tuple[str, ...] = ()
    size_step: float = 1.0
    direction_words: tuple[str, str] = ("in", "out")
    framing: Framing = Framing(15.0, 10.0, 0.66, trunk_share=0.5, up_m=0.05, forward_m=0.10)

    # ------------------------------------------------------------------ content
    def check(self, spec) -> None:
        """Further checks of a game's YAML (ValueError with one line)."""

    def size_words(self, size: float) -> str:
        """A target size (the smallest-target limit) in words."""
        return f"{size:.0f}\N{DEGREE SIGN} either side"

    # ------------------------------------------------------------------ the session
    def place(self, limits, low_fraction: float, top_fraction: float, rng: np.random.Generator, *,
              direction: int, planes_deg, elbow_range_deg):
        """A :class:`game.exergames.targets.Target` between the fractions of the maximum
        (:func:`game.exergames.targets.place_target`)."""
        raise NotImplementedError

    def hand_m(self, target, frame) -> np.ndarray:
        """(3,) world position of the wrist centre at ``target`` for the arm ``frame``."""
        raise NotImplementedError

    def value(self, reading, target) -> float:
        """The controlled quantity of a reading (the session's ``value_now``); ``target`` is the
        :class:`game.exergames.session.ActiveTarget` on the screen or None."""
        raise NotImplementedError

    def inside(self, reading, target) -> bool:
        """The reading holds ``target`` (it has arrived)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ the view and the simulated patient
    def solid(self, target, frame) -> tuple[np.ndarray, np.ndarray] | None:
        """The target drawn in the avatar's 3D view: an ellipsoid's (3,) centre and (3, 3) axes, or None."""
        return None

    def ring_m(self, target) -> float:
        """Radius (m) of the target's ring on the screen around :attr:`ActiveTarget.hand_m`."""
        return 0.06

    def aim(self, aim: Aim, x_px: float, y_px: float) -> tuple[tuple | None, float | None]:
        """The mouse at (x, y) in the avatar's view: (the simulated hand's target, the forearm's
        rotation in degrees), each None where the mouse does not change it."""
        return None, None

    def auto_input(self, player, target, dt_s: float):
        """The automatic demo's :class:`tracking.live.PatientInput` for ``target``
        (:class:`game.exergames.autoplay.AutoPlayer` gives the ways to move)."""
        return player.hand_at(target.hand_m)

    def draw_readout(self, scene, canvas, x: float, y: float, right: float) -> float:
        """The panel's readout under the time and level (the next y): nothing by default."""
        return y


class AngleGame(GameKind):
    """A game whose targets are one measured angle (``angle``), positive and negative in turn,
    with the elbow at the side."""

    angle: str = ""
    needs_posture = True

    @property
    def logged_angles(self) -> tuple[str, ...]:
        return (self.angle,)

    def place(self, limits, low_fraction, top_fraction, rng, *, direction, planes_deg, elbow_range_deg):
        fraction = float(rng.uniform(low_fraction, top_fraction))
        limit = limits.positive_deg if direction > 0 else limits.negative_deg
        return Target(direction * fraction * limit, limit, fraction)

    def value(self, reading, target) -> float:
        return reading.angles[self.angle]

    def inside(self, reading, target) -> bool:
        v = self.value(reading, target)
        return math.isfinite(v) and abs(v - target.target.value_deg) <= target.size


_KINDS: dict[str, GameKind] = {}
_found = False


def register(kind: GameKind) -> GameKind:
    """Make ``kind`` known by its name (a module calls it at import); returns it.

    A second kind of the same name is refused (ValueError): two modules would claim one name.
    """
    if not kind.name:
        raise ValueError(f"{type(kind).__name__} has no name")
    old = _KINDS.get(kind.name)
    if old is not None and type(old) is not type(kind):
        raise ValueError(f"the game kind {kind.name!r} is registered twice ({type(old).__name__}, {type(kind).__name__})")
    _KINDS[kind.name] = kind
    return kind


def unregister(name: str) -> None:
    """Forget a kind (a test's own kind after the test)."""
    _KINDS.pop(name, None)


def _find() -> None:
    """Import every module of this package once (each registers its kind)."""
    global _found
    if not _found:
        _found = True
        for info in pkgutil.iter_modules(__path__):
            importlib.import_module(f"{__name__}.{info.name}")


def kind_names() -> tuple[str, ...]:
    """The registered kinds' names, sorted."""
    _find()
    return tuple(sorted(_KINDS))


def game_kind(name: str) -> GameKind:
    """The kind registered as ``name``; ValueError naming the known ones otherwise."""
    _find()
    try:
        return _KINDS[name]
    except KeyError:
        raise ValueError(f"unknown game kind {name!r}: one of {', '.join(kind_names())}") from None


def place_target(kind: str, limits: RomLimits, low_fraction: float, top_fraction: float, rng: np.random.Generator,
                 *, direction: int = 1, planes_deg=(0.0,), elbow_range_deg=(20.0, 40.0)) -> Target:
    """A target of the game kind ``kind`` drawn uniformly between ``low_fraction`` and ``top_fraction`` of the maximum.

    Args:
        kind: a registered kind's name (``reach``, ``rotation``, ``forearm``, ...).
        limits: the patient's maxima.
        low_fraction, top_fraction: the band, fractions of the maximum (low < top).
        rng: the game's random generator (seeded: a session is reproducible).
        direction: the angle games: +1 (external rotation, supination) or -1.
        planes_deg: reach: the planes to choose from.
        elbow_range_deg: reach: the elbow bend range, capped by the elbow maximum.
    """
    return game_kind(kind).place(limits, low_fraction, top_fraction, rng, direction=direction, planes_deg=planes_deg,
                                 elbow_range_deg=elbow_range_deg)


def target_hand_m(kind: str, target: Target, frame) -> np.ndarray:
    """(3,) world position of the wrist centre at ``target`` for this arm (:class:`ArmFrame`)."""
    return game_kind(kind).hand_m(target, frame)
