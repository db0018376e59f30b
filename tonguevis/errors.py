"""Exception types of tonguevis.

Every error a user can cause with a bad file or bad settings is a subclass of
:class:`TonguevisError`, itself a :class:`ValueError`, and its message names the
file (when there is one), what was expected and what was found.  The CLI prints
such errors as one line; the GUI shows them in a dialog.
"""

from __future__ import annotations

import os


class TonguevisError(ValueError):
    """Base class of every user-facing error of tonguevis."""

    def __init__(self, message: str, path: str | os.PathLike | None = None):
        self.path = None if path is None else os.fspath(path)
        if self.path is not None and self.path not in message:
            message = f"{self.path}: {message}"
        super().__init__(message)


class RecordingError(TonguevisError):
    """An EMA recording could not be read, written or used."""


class MeshError(TonguevisError):
    """A mesh could not be read or is not a usable tetrahedral mesh."""


class ModelError(TonguevisError):
    """A tongue model or modal basis could not be built or used."""


class SimulationError(TonguevisError):
    """A simulation could not run with the given recording and model."""


class Cancelled(Exception):
    """Raised inside long work when the user asked to cancel it."""


class ExportError(TonguevisError):
    """An export (video, VTK series, ParaView series) could not be written."""
