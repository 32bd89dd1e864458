"""The therapist's limits of a game: stepping them on the game menu, their words, storing them per patient.

A limit left unset (None) lets the game's difficulty ramp decide; each limit has a *free* value
(what the ramp reaches at its hardest, e.g. the smallest size) and a direction that is stricter
(a smaller range, a bigger smallest target, a shorter hold, more time per target, a lower highest
level; for the lowest level, the one the session starts at and never falls below, a higher one).
Stepping a limit back past its free value unsets it. Stored per patient and game in the
database (``game_limits``, JSON of :class:`game.exergames.spec.TherapistLimits`); a stored value
that is no longer valid for the game (the content changed) is ignored with a warning.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pydantic

from game.db import Database
from game.db.accounts import record
from game.exergames.spec import GameSpec, TherapistLimits, check_limits, limit_bounds

log = logging.getLogger(__name__)

#: The limits in the order the menu shows them.
LIMIT_KEYS = ("min_level", "max_level", "max_range", "min_size", "max_hold_s", "min_time_s")
#: +1: a bigger value departs from the game's own (is stricter: easier for the patient, or for the
#: lowest level a higher floor); -1: a smaller one does.
_STRICTER = {"min_level": 1, "max_level": -1, "max_range": -1, "min_size": 1, "max_hold_s": -1, "min_time_s": 1}
LABELS = {"min_level": "Lowest level", "max_level": "Highest level", "max_range": "Farthest target",
          "min_size": "Smallest target", "max_hold_s": "Longest hold", "min_time_s": "Time per target"}


def free_value(spec: GameSpec, key: str) -> float:
    """What the difficulty ramp reaches at its hardest for ``key`` (an unset limit; for the lowest
    level, the game's own ``min_level``)."""
    d = spec.difficulty
    return {"min_level": d.min_level, "max_level": 1.0, "max_range": max(d.top_fraction.easy, d.top_fraction.hard),
            "min_size": min(d.size.easy, d.size.hard), "max_hold_s": max(d.hold_s.easy, d.hold_s.hard),
            "min_time_s": min(d.time_limit_s.easy, d.time_limit_s.hard)}[key]


def step_size(spec: GameSpec, key: str) -> float:
    return {"min_level": 1.0 / 9.0, "max_level": 1.0 / 9.0, "max_range": 0.05, "min_size": spec.game_kind.size_step,
            "max_hold_s": 0.1, "min_time_s": 1.0}[key]


def step_limit(spec: GameSpec, limits: TherapistLimits, key: str, direction: int) -> TherapistLimits:
    """``limits`` with ``key`` one step up (``direction`` +1) or down (-1), within the game's bounds."""
    free = free_value(spec, key)
    current = getattr(limits, key)
    value = (free if current is None else current) + direction * step_size(spec, key)
    lo, hi = limit_bounds(spec)[key]
    if (value - free) * _STRICTER[key] <= 1e-9:
        new = None                                    # no stricter than the game itself: unset
    else:
        new = round(min(max(value, lo), hi), 4)
    return limits.model_copy(update={key: new})


def describe(spec: GameSpec, limits: TherapistLimits, key: str) -> str:
    """The limit's value in words for the menu ("95 % of the measured range", "6 cm"); an unset
    limit shows the game's own value (:func:`whose` says which)."""
    value = getattr(limits, key)
    shown = free_value(spec, key) if value is None else value
    if key in ("min_level", "max_level"):
        text = f"level {1 + round(shown * 9)}"
    elif key == "max_range":
        text = f"{round(shown * 100)} % of the measured range"
    elif key == "min_size":
        text = spec.game_kind.size_words(shown)
    elif key == "max_hold_s":
        text = f"{shown:.1f} s"
    else:
        text = f"at least {shown:.0f} s"
    return text


def describe_all(spec: GameSpec, limits: TherapistLimits) -> str:
    """Every limit set for the patient in words ("Highest level: level 7; Longest hold: 2.0 s"), for
    the audit; "the game's own limits" when none is set."""
    set_keys = [k for k in LIMIT_KEYS if getattr(limits, k) is not None]
    return "; ".join(f"{LABELS[k]}: {describe(spec, limits, k)}" for k in set_keys) or "the game's own limits"


def whose(limits: TherapistLimits, key: str) -> str:
    """Whose the limit's value is: ``the game's own`` (unset: what the game's difficulty reaches;
    the menu said "no limit", read as if nothing bounded the game) or ``set for this patient``."""
    return "the game's own" if getattr(limits, key) is None else "set for this patient"


def parse_limits(spec: GameSpec, text: str) -> TherapistLimits:
    """Stored JSON -> limits checked against the game; the game's own ``limits`` when it is not valid."""
    try:
        return check_limits(spec, TherapistLimits.model_validate(json.loads(text)))
    except (ValueError, pydantic.ValidationError) as exc:
        log.warning("stored limits of %s ignored (%s): using the game's own", spec.name,
                    str(exc).splitlines()[0])
        return spec.limits


def load_limits(db_path: Path, patient_id: str, specs) -> dict[str, TherapistLimits]:
    """The therapist's limits of each game for a patient: the stored ones, else the game's own."""
    with Database(db_path) as db:
        stored = db.game_limits(patient_id)
    return {spec.name: parse_limits(spec, stored[spec.name]) if spec.name in stored else spec.limits
            for spec in specs}


def save_limits(db_path: Path, patient_id: str, spec: GameSpec, limits: TherapistLimits, *,
                account: str = "") -> None:
    """Store the limits of one game for a patient (all keys, unset ones as null) and audit who set
    them (``account``: the signed-in therapist, "" without accounts)."""
    check_limits(spec, limits)
    with Database(db_path) as db:
        db.set_game_limits(patient_id, spec.name, limits.model_dump_json())
        record(db, account, "limits", patient_id, f"{spec.name}: {describe_all(spec, limits)}")
