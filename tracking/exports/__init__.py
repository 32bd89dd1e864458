"""Export formats: the files ``rehab track`` writes from a tracked recording, found by name.

Each format is one module of :mod:`tracking.exports.formats` with an
:class:`~tracking.exports.registry.ExportFormat` subclass decorated with
:func:`~tracking.exports.registry.register`: its name (the keyword of
:func:`tracking.drivers.offline.write_results`), its ``rehab track`` option, help text, file
suffix and ``write(run, path)``. Every module there is imported, so a new export format is a new
file; the command line's options, its "nothing to write" message and its overwrite checks are
made from the registry. The writers themselves (and their readers) stay in :mod:`tracking.io`;
what they are given is a :class:`~tracking.exports.tracked.TrackedRecording` (docs/FILES.md).
"""

from tracking.exports import formats as _builtin  # noqa: F401  (registers the built-in formats)
from tracking.exports.registry import ExportFormat, formats, get, names, register, unregister
from tracking.exports.tracked import TrackedRecording

__all__ = ["ExportFormat", "TrackedRecording", "formats", "get", "names", "register", "unregister"]
