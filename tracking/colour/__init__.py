"""Marker colours (docs/COLOUR.md): the colour lookup table and what adjusts it.

``table`` (the nominal 2^24-entry lookup table from the marker set's colours), ``learn`` (per-class
hue and saturation statistics and models, pure arrays), ``adapt`` (the adapter that learns from the
tracked markers and owns the table the tracker reads) and ``pick`` (the manual pick of the camera
check).
"""
