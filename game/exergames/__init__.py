"""Exercise games whose targets lie inside the patient's measured range of motion.

``spec`` (content YAML), ``targets`` (placement in joint-angle space and forward kinematics),
``session`` (rules, difficulty, pauses, the log), ``autoplay`` (the simulated patient playing by
itself), ``audio`` (cues). Pure logic except ``audio``; the scene is ``game.scenes.game_play``.
"""
