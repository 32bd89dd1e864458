"""Marker tracking: colour extraction, multi-view geometry, labelling, gap filling, joint angles.

The per-frame math lives at the top and in ``pipeline/``, ``labelling/``, ``hidden/``, ``colour/``
and ``geometry/`` (arrays in, arrays out); file formats are in ``io/``, frame sources in
``sources/``, the commands' drivers in ``drivers/``, the background process in ``live/`` and the
simulated patient studio in :mod:`tracking.sim` (docs/ARCHITECTURE.md, "Packages").
"""
