"""Pure geometry shared by the simulated studio, the file formats and the game's avatar.

``rotations`` (3x3 rotations, the humerus orientation in clinical terms), ``meshes`` (unit
triangle meshes) and ``glsl`` (shader source strings). Numpy only: no GL context, no files, so
that the avatar and the BVH writer need not import the simulator (:mod:`tracking.sim`).
"""
