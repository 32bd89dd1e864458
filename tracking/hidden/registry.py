"""Hidden-marker estimators by name: the marker set's ``estimator:`` key looks them up here.

An estimator is a subclass of :class:`HiddenMethod` decorated with :func:`register`; the
built-in ones are the files of :mod:`tracking.hidden.methods` (every module there is imported,
so a new estimator is a new file there). Each names the estimator it falls back to when it
cannot place a marker (returns None); a result that is not finite goes straight to the chain's
last estimator, and where that gives nothing, the marker's own decaying velocity.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from tracking.hidden.codes import Method
from tracking.hidden.frame import FrameInputs


class HiddenMethod:
    """One way of estimating a hidden marker (stateless: learned state is in ``FrameInputs.state``).

    Class attributes:
        name: the marker set's name for it (``estimator: name``).
        code: its value in ``Estimator.used`` (None: the next free code is given).
        fallback: the estimator tried when this one returns None (None: this one is the last).
        rank: hidden markers are estimated in order of decreasing rank (the elbows' hinges run
            first whatever their rank; others may lean on earlier estimates).
        max_hidden_s: longest occlusion reported where the marker set gives none (seconds).
    """

    name: ClassVar[str]
    code: ClassVar[int | None] = None
    fallback: ClassVar[str | None] = "neighbours"
    rank: ClassVar[int] = 0
    max_hidden_s: ClassVar[float] = 5.0

    def check(self, marker: int, layout) -> None:
        """Raise ValueError if the marker set lacks what this estimator needs for ``marker``."""

    def estimate(self, frame: FrameInputs, k: int) -> np.ndarray | None:
        """(3,) estimate of hidden marker k, None (ill-posed: the fallback's turn) or
        :data:`~tracking.hidden.codes.DROP` (the body cannot pin it now: LOST)."""
        raise NotImplementedError


_METHODS: dict[str, HiddenMethod] = {}


def register(cls: type[HiddenMethod]) -> type[HiddenMethod]:
    """Class decorator: make ``cls`` available under ``cls.name``."""
    name = cls.name
    if not name or name != name.strip().lower() or not name.replace("_", "").isalnum():
        raise ValueError(f"estimator name {name!r}: use lower-case letters, digits and '_'")
    old = _METHODS.get(name)
    if old is not None and type(old).__qualname__ != cls.__qualname__:
        raise ValueError(f"estimator {name!r} is registered twice ({type(old).__module__}, {cls.__module__})")
    if cls.code is None:
        taken = {m.code for m in _METHODS.values() if m.name != name}
        cls.code = next(c for c in range(len(Method), 128) if c not in taken)
    _METHODS[name] = cls()
    return cls


def unregister(name: str) -> None:
    """Forget the estimator called ``name`` (tests that register their own)."""
    _METHODS.pop(name, None)


def names() -> tuple[str, ...]:
    """The registered estimators' names."""
    return tuple(sorted(_METHODS))


def get(name: str) -> HiddenMethod:
    """The estimator called ``name`` (a ValueError lists the known ones)."""
    method = _METHODS.get(name.strip().lower())
    if method is None:
        raise ValueError(f"estimator {name!r} is not one of {', '.join(names())}")
    return method


def resolve(value: "str | int | Method") -> HiddenMethod:
    """The estimator of a name or a code."""
    if isinstance(value, str):
        return get(value)
    for method in _METHODS.values():
        if method.code == int(value):
            return method
    raise ValueError(f"no estimator has code {int(value)}")


def chain(method: HiddenMethod) -> tuple[HiddenMethod, ...]:
    """``method`` and its fallbacks in order (the last is the last resort)."""
    out = [method]
    while out[-1].fallback is not None:
        nxt = get(out[-1].fallback)
        if nxt in out:
            raise ValueError(f"estimator {method.name!r}: its fallbacks run in a circle")
        out.append(nxt)
    return tuple(out)
