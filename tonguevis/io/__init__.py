"""Reading and writing EMA recordings (one container: :class:`Recording`).

``read_recording(path, sensor_map=None, **options)`` detects the format from the
file's content and extension; ``write_recording(rec, path)`` picks the writer
from the extension.  Formats register themselves in :mod:`tonguevis.io.registry`.
"""

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Audio, Label, Recording
from tonguevis.io.registry import (
    FORMATS, RecordingFormat, detect_format, read_recording, register_format, registered_formats,
    supported_formats, write_recording,
)
from tonguevis.io.sensor_map import apply_sensor_map, load_sensor_map

__all__ = [
    "Audio", "FORMATS", "Label", "Recording", "RecordingError", "RecordingFormat",
    "apply_sensor_map", "detect_format", "load_sensor_map", "read_recording",
    "register_format", "registered_formats", "supported_formats", "write_recording",
]
