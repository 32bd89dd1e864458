"""The live avatar: skeleton from markers, smooth interpolation, shaded body rendering.

- :mod:`game.avatar.skeleton`: markers + status -> :class:`SkeletonPose` (pure numpy).
- :mod:`game.avatar.interpolate`: poses at 15-30 Hz -> a smooth pose at the display rate; look fading.
- :mod:`game.avatar.shapes`: a pose -> ellipsoids and capsules (pure numpy).
- :mod:`game.avatar.renderer`: draws them with moderngl into the bound framebuffer.
- :mod:`game.avatar.live`: :class:`LiveAvatar`, all of the above for a game scene.
- :mod:`game.avatar.fps_bench`: render speed offscreen.
"""
