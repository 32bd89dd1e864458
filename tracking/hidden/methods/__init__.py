"""The hidden-marker estimators, one per module, each registered by name on import.

Every module of this package is imported here, so a new estimator is a new file: a
:class:`~tracking.hidden.registry.HiddenMethod` subclass decorated with
:func:`~tracking.hidden.registry.register`, named in the marker set's ``estimator:`` key.
"""

import importlib
import pkgutil

for _module in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_module.name}")
