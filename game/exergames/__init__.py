"""Exercise games whose targets lie inside the patient's measured range of motion.

``spec`` (content YAML), ``kinds`` (one module per kind of game, registered by name: what a
reach, a rotation or a key game does differently), ``targets`` (placement in joint-angle space
and forward kinematics), ``session`` (rules, difficulty, pauses, the log), ``visit`` (the
database: the measured range read, the log stored), ``autoplay`` (the simulated patient playing by
itself), ``audio`` (cues). Pure logic except ``audio`` and ``visit``; the scene is
``game.scenes.game_play``.
"""
