"""The application: the pygame + moderngl game, its scenes, and the ``rehab`` command line."""
