"""Reading and writing EMA recordings (one container: :class:`Recording`)."""

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Audio, Label, Recording

__all__ = ["Audio", "Label", "Recording", "RecordingError"]
