"""The estimator's configuration from a marker set's ``hidden_markers:`` section.

Marker names become indices, the side wildcards are already expanded by the marker-set loader,
and each marker's ``estimator:`` name is looked up in :mod:`tracking.hidden.registry` (an unknown
name is a one-line ContentError naming the known ones).
"""

from __future__ import annotations

import numpy as np

from tracking.errors import ContentError
from tracking.hidden import registry
from tracking.hidden.codes import Method
from tracking.hidden.layout import Forearm, Hinge


def _method(name: "str | int | Method", markerset) -> registry.HiddenMethod:
    try:
        return registry.resolve(name)
    except ValueError as e:
        raise ContentError(f"marker set {markerset.name}: hidden_markers: {e} (a new estimator is a file in "
                           "tracking/hidden/methods/)") from None


def estimator_config(markerset, *, method: "Method | str | None" = None,
                     own_velocity: bool = False) -> dict:
    """Keyword arguments of :class:`~tracking.hidden.Estimator` from a marker set.

    Args:
        markerset: a :class:`~tracking.markerset.MarkerSet` (its ``hidden`` configuration and
            body ``segments``).
        method: one estimator for every marker instead of the file's choice (comparisons).
        own_velocity: equation 6 as the paper writes it (with the marker's own last velocity).

    ``methods`` holds :class:`~tracking.hidden.codes.Method` values for the built-in estimators
    and the registered name for the others.
    """
    names = list(markerset.names)
    index = {n: i for i, n in enumerate(names)}
    cfg = markerset.hidden
    m = len(names)
    weights = np.zeros((m, m))
    for name, row in cfg.weights.items():
        for other, s in row.items():
            weights[index[name], index[other]] = s
    chosen = [_method(e, markerset) for e in cfg.estimators]
    if method is not None:
        chosen = [_method(method, markerset)] * m
    hinges = []
    for a, b, shoulder, wa, wb in cfg.elbows:
        a, b, s, wa, wb = (index[n] for n in (a, b, shoulder, wa, wb))
        hinges += [Hinge(a, b, s, (wa, wb)), Hinge(b, a, s, (wa, wb))]
    forearms = []
    for wa, wb, ea, eb in cfg.forearms:
        wa, wb, ea, eb = (index[n] for n in (wa, wb, ea, eb))
        forearms += [Forearm(wa, wb, (ea, eb)), Forearm(wb, wa, (ea, eb))]
    return {
        "methods": [Method(x.code) if x.code < len(Method) else x.name for x in chosen],
        "weights": weights,
        "segments": [tuple(index[n] for n in g) for g in cfg.rigid_groups],
        "hinges": hinges,
        "forearms": forearms,
        "length_pairs": [(index[a], index[b]) for a, b in cfg.length_pairs],
        "trunk": None if cfg.trunk is None else tuple(index[n] for n in cfg.trunk),
        "body_segments": list(markerset.segments),
        "own_velocity": own_velocity,
        "tolerance_m": cfg.drift_tolerance_m,
        "max_hidden_s": [cfg.max_hidden_s.get(x.name, x.max_hidden_s) for x in chosen],
        "max_unsupported_s": cfg.max_unsupported_s,
        "velocity_decay_s": list(cfg.velocity_decay_s),
    }
