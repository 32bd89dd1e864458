"""Drawing for the game: the window or headless screen, the 2D canvas, the 3D views' cameras and
dynamic resolution, the theme, and the camera check's overlay on each camera's image
(``camera_overlay``)."""
