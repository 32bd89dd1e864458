"""Marker tracking: colour extraction, multi-view geometry, labelling, gap filling, joint angles.

Pure per-frame computation lives in its own modules (arrays in, arrays out); sources, files and
processes are separate. The simulated patient studio is in :mod:`tracking.sim`.
"""
