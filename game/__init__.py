"""The application: the pygame + moderngl game, its scenes, and the ``rehab`` command line."""

import os as _os

# pygame greets on stdout when first imported; the command line's output is for figures and results.
_os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
