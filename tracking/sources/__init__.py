"""Frame sources: where the synchronized camera images come from, behind one interface.

- :class:`~tracking.sources.recording.RecordingSource`: a recording folder (videos or image
  folders, docs/INTERFACES.md), read frame set by frame set;
- :class:`~tracking.sources.cameras.CameraSource`: live cameras through OpenCV, one reader thread
  per camera, frames grouped by their time stamps;
- :class:`~tracking.sources.sim.SimulatedSource`: the simulated patient playing a scripted motion,
  rendered by the virtual cameras.

Each is a :class:`~tracking.sources.base.FrameSource`: ``open()``, ``read() ->
SourceFrameSet | None`` (None: the source has ended), ``warnings()``, ``close()``, ``cameras``,
``fps``. The live tracker process (:mod:`tracking.live`) and ``rehab record`` use only that.
"""

from tracking.sources.base import FrameSource, SourceError, SourceFrameSet

__all__ = ["FrameSource", "SourceError", "SourceFrameSet"]
