"""Range-of-motion (ROM) tests: the test definitions (content), the test logic over tracker samples.

- :mod:`game.rom.spec`: ROM tests as content (``content/rom_tests/*.yaml``), validated at load.
- :mod:`game.rom.session`: :class:`RomTestSession`, the pure state machine that the ROM test scene
  and ``rehab rom-test`` share (start position -> recording -> done, accept or discard).
- :mod:`game.rom.simulated`: one test run on the simulated patient through the real tracker.
- :mod:`game.rom.visit`: :class:`RomVisit`, one patient's tests in a sitting: the previous results
  read and the accepted ones stored (the database's side of the ROM test scenes).

No pygame, OpenGL, processes or files in the logic: it takes samples and returns values; the
database is reached only through ``visit``.
"""
