"""Raw pygame events become the game's actions here, once, through one key map.

Scenes only ever see :class:`Action` values (a key pressed or released) and :class:`Pointer`
events in normalized window coordinates, so they are driven by tests without pygame events and
do not care about the window size. What a key means in a scene is the scene's business: the
arrow keys navigate menus and lean the simulated patient's trunk in the live view.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Iterable, Mapping

import pygame


class Action(enum.Enum):
    """What the user asked for, independent of the key that asked."""

    UP = "up"
    DOWN = "down"
    LEFT = "left"
    RIGHT = "right"
    SELECT = "select"
    BACK = "back"
    QUIT = "quit"
    SWITCH_ARM = "switch arm"
    ROTATE_IN = "rotate forearm inward"      # pronation
    ROTATE_OUT = "rotate forearm outward"    # supination
    NEXT_MOTION = "next motion"
    REIDENTIFY = "re-identify markers"
    MONITOR = "camera monitor"
    TOGGLE_FPS = "frame rate"


#: The one key map (read-only). Keys absent here do nothing.
KEYMAP: Mapping[int, Action] = MappingProxyType({
    pygame.K_UP: Action.UP,
    pygame.K_DOWN: Action.DOWN,
    pygame.K_LEFT: Action.LEFT,
    pygame.K_RIGHT: Action.RIGHT,
    pygame.K_w: Action.UP,
    pygame.K_s: Action.DOWN,
    pygame.K_a: Action.LEFT,
    pygame.K_d: Action.RIGHT,
    pygame.K_RETURN: Action.SELECT,
    pygame.K_KP_ENTER: Action.SELECT,
    pygame.K_SPACE: Action.SELECT,
    pygame.K_ESCAPE: Action.BACK,
    pygame.K_BACKSPACE: Action.BACK,
    pygame.K_TAB: Action.SWITCH_ARM,
    pygame.K_q: Action.ROTATE_IN,
    pygame.K_e: Action.ROTATE_OUT,
    pygame.K_m: Action.NEXT_MOTION,
    pygame.K_r: Action.REIDENTIFY,
    pygame.K_c: Action.MONITOR,
    pygame.K_F1: Action.TOGGLE_FPS,
    pygame.K_f: Action.TOGGLE_FPS,
})


@dataclass(frozen=True, slots=True)
class Press:
    """A mapped key went down (``down``) or up."""

    action: Action
    down: bool = True
    #: the key's name ("escape", "backspace", "w"; "" from tests and scripts), for text entry, where
    #: Backspace erases and a letter is typed rather than an action (not compared)
    key: str = field(default="", compare=False)


@dataclass(frozen=True, slots=True)
class Typed:
    """Text typed on the keyboard (pygame's TEXTINPUT), for the scenes that take text (sign-in)."""

    text: str


class PointerKind(enum.Enum):
    MOVE = "move"
    PRESS = "press"
    RELEASE = "release"
    WHEEL = "wheel"


@dataclass(frozen=True, slots=True)
class Pointer:
    """A mouse event.

    Attributes:
        kind: move, press, release or wheel.
        x: 0 at the window's left edge, 1 at its right edge.
        y: 0 at the top, 1 at the bottom.
        button: 1 left, 2 middle, 3 right (0 for moves and the wheel).
        wheel: wheel clicks, + away from the user (WHEEL only).
    """

    kind: PointerKind
    x: float
    y: float
    button: int = 0
    wheel: float = 0.0


InputEvent = Press | Pointer | Typed


class InputMapper:
    """Turns pygame events into :class:`Press` / :class:`Pointer` events and tracks held actions.

    Args:
        window_px: window (width, height) in pixels, to normalize pointer positions.
        keymap: key code -> action.
    """

    def __init__(self, window_px: tuple[int, int], keymap: Mapping[int, Action] = KEYMAP) -> None:
        self.window_px = (max(1, int(window_px[0])), max(1, int(window_px[1])))
        self.keymap = keymap
        self.held: set[Action] = set()
        self.pointer = (0.5, 0.5)

    def _norm(self, pos: tuple[int, int]) -> tuple[float, float]:
        return pos[0] / self.window_px[0], pos[1] / self.window_px[1]

    def map(self, events: Iterable[pygame.event.Event]) -> list[InputEvent]:
        """Mapped events in order; unmapped keys and other event types are dropped."""
        out: list[InputEvent] = []
        for ev in events:
            if ev.type == pygame.QUIT:
                out.append(Press(Action.QUIT))
            elif ev.type in (pygame.KEYDOWN, pygame.KEYUP):
                action = self.keymap.get(ev.key)
                if action is None:
                    continue
                down = ev.type == pygame.KEYDOWN
                if down and action in self.held:
                    continue  # key repeat
                (self.held.add if down else self.held.discard)(action)
                out.append(Press(action, down, pygame.key.name(ev.key)))
            elif ev.type == pygame.TEXTINPUT:
                out.append(Typed(ev.text))
            elif ev.type == pygame.MOUSEMOTION:
                self.pointer = self._norm(ev.pos)
                out.append(Pointer(PointerKind.MOVE, *self.pointer))
            elif ev.type in (pygame.MOUSEBUTTONDOWN, pygame.MOUSEBUTTONUP):
                if ev.button in (4, 5):  # SDL1-style wheel buttons; MOUSEWHEEL carries the wheel
                    continue
                self.pointer = self._norm(ev.pos)
                kind = PointerKind.PRESS if ev.type == pygame.MOUSEBUTTONDOWN else PointerKind.RELEASE
                out.append(Pointer(kind, *self.pointer, button=ev.button))
            elif ev.type == pygame.MOUSEWHEEL:
                out.append(Pointer(PointerKind.WHEEL, *self.pointer, wheel=float(ev.y)))
            elif ev.type == pygame.WINDOWFOCUSLOST:
                # keys released while another window has focus never send KEYUP here
                for action in sorted(self.held, key=lambda a: a.value):
                    out.append(Press(action, False))
                self.held.clear()
        return out
