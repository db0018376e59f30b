"""Simulations in a worker thread, with a progress dialog and a cancel button."""

from __future__ import annotations

import logging
import time
import traceback

from PySide6.QtCore import QThread, Signal

from tonguevis.errors import Cancelled, TonguevisError

log = logging.getLogger("tonguevis")


class Worker(QThread):
    """Runs ``function(progress=callback)`` off the GUI thread.

    Signals (delivered on the GUI thread): ``progressed(done, total, message)``,
    ``succeeded(result)``, ``failed(message)``, ``cancelled()``.  :meth:`cancel`
    makes the next progress callback raise :class:`Cancelled`.
    """

    progressed = Signal(int, int, str)
    succeeded = Signal(object)
    failed = Signal(str)
    cancelled = Signal()

    #: Seconds between progress signals: callers may report every frame, and each
    #: signal is a queued cross-thread call the GUI thread must process.
    MIN_INTERVAL = 0.05

    def __init__(self, function, parent=None):
        super().__init__(parent)
        self.function = function
        self._cancel = False
        self._last = 0.0

    def cancel(self) -> None:
        self._cancel = True

    def _progress(self, done: int, total: int, message: str = "") -> None:
        if self._cancel:
            raise Cancelled()
        now = time.monotonic()
        if now - self._last >= self.MIN_INTERVAL or done >= total:
            self._last = now
            self.progressed.emit(int(done), int(total), str(message))

    def run(self) -> None:
        try:
            result = self.function(progress=self._progress)
        except Cancelled:
            self.cancelled.emit()
        except (TonguevisError, OSError) as exc:
            self.failed.emit(str(exc))
        except Exception as exc:  # a bug: keep the app alive, show the trace in the log
            log.error("simulation failed:\n%s", traceback.format_exc())
            self.failed.emit(f"unexpected {type(exc).__name__}: {exc}")
        else:
            self.succeeded.emit(result)
