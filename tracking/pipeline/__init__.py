"""The tracker's per-frame stages (docs/ARCHITECTURE.md, "A frame set's way through the tracker").

Each module is one stage, a function of the rig's constants (:class:`state.Setup`), the knobs
(:class:`params.TrackerParams`), the markers' memory (:class:`state.MarkerMemory`) and the frame
set on its way (:class:`state.FrameState`); :class:`tracking.tracker.Tracker` passes a frame set
through them. Pure computation on arrays: no files, processes or GL.
"""
