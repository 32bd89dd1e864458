"""The live tracker: a background process that measures the patient and publishes every sample.

The game imports only these names (see ``docs/LIVE.md``)::

    from tracking.live import LiveTracker, LiveSample, LiveStatus, SourceConfig, PatientInput
"""

from tracking.live.client import LiveTracker
from tracking.live.protocol import LiveError, LiveSample, LiveStatus, PatientInput, SourceConfig

__all__ = ["LiveTracker", "LiveSample", "LiveStatus", "SourceConfig", "PatientInput", "LiveError"]
