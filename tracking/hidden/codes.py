"""The built-in estimators' codes (``Estimator.used``) and the verdict that drops an estimate."""

from __future__ import annotations

from enum import IntEnum

import numpy as np

#: An estimator's verdict: the body cannot pin this marker now (LOST). Compared by identity.
DROP = np.full(3, np.nan)


class Method(IntEnum):
    """How a hidden marker is estimated: the built-in estimators' codes in ``Estimator.used``
    (estimators added as files get the next free codes, :mod:`tracking.hidden.registry`)."""

    CONSTANT_VELOCITY = 0  # equation 5
    NEIGHBOURS = 1         # equation 6
    RIGID = 2              # Kabsch on a segment, falls back to equation 6
    HINGE = 3              # elbow axis (epicondyle markers), falls back to RIGID
    FOREARM = 4            # styloid markers from the elbow and the other styloid, falls back to RIGID

    @classmethod
    def parse(cls, value: "Method | str | int") -> "Method":
        if isinstance(value, str):
            try:
                return cls[value.strip().upper()]
            except KeyError:
                allowed = ", ".join(m.name.lower() for m in cls)
                raise ValueError(f"estimator {value!r} is not one of {allowed}") from None
        return cls(value)
