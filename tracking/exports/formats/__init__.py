"""The export formats, one per module, each registered by name on import.

Every module of this package is imported here, so a new export format is a new file: an
:class:`~tracking.exports.registry.ExportFormat` subclass decorated with
:func:`~tracking.exports.registry.register`.
"""

import importlib
import pkgutil

for _module in pkgutil.iter_modules(__path__):
    importlib.import_module(f"{__name__}.{_module.name}")
