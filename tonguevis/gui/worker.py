"""The app's one job runner: a long task in a worker thread, with progress, Cancel, and errors as dialogs.

Every long task of the app (simulating a recording, segmenting, the exports, the
palate fit, the Energy tab's corpus) goes through :func:`run_job`::

    job = run_job(parent, "Segmentation", function, on_done)

``function(progress)`` runs off the GUI thread and *returns* what it made; it
assigns nothing to a window, a view or the app model (they are not thread-safe):
``on_done(result)`` receives the result on the GUI thread, and writes it where it
belongs.  ``progress(done, total, message)`` moves the progress dialog and raises
:class:`~tonguevis.errors.Cancelled` once Cancel was pressed.  A failure becomes an
error dialog titled "<title> failed" (the parent's ``show_error`` when it has one).
"""

from __future__ import annotations

from dataclasses import dataclass

import time
import traceback
from typing import Any, Callable

from PySide6.QtCore import QThread, Signal

from tonguevis.errors import Cancelled, TonguevisError

from tonguevis._logging import logger

#: Outcomes of a job, as :attr:`Job.ended` reports them.
OUTCOMES = ("ok", "failed", "cancelled")


class Job(QThread):
    """Runs ``function(progress=callback)`` off the GUI thread.

    Signals (delivered on the GUI thread): ``progressed(done, total, message)``,
    ``succeeded(result)``, ``failed(message)``, ``cancelled()``, and ``ended(outcome)``
    once the thread has finished (``outcome`` one of :data:`OUTCOMES`).  :meth:`cancel`
    makes the next progress callback raise :class:`Cancelled`.  With ``partial=True`` the
    function is also given ``partial(result)`` to hand over a first, incomplete result
    (``partial_ready(result)``, on the GUI thread) while it goes on.
    """

    progressed = Signal(int, int, str)
    partial_ready = Signal(object)
    succeeded = Signal(object)
    failed = Signal(str)
    cancelled = Signal()
    ended = Signal(str)

    #: Seconds between progress signals: callers may report every frame, and each
    #: signal is a queued cross-thread call the GUI thread must process.
    MIN_INTERVAL = 0.05

    def __init__(self, function, parent=None, title: str = "job", partial: bool = False):
        super().__init__(parent)
        self.function = function
        self.partial = partial
        self.title = title
        self.outcome: str | None = None
        self.dialog = None
        self.show_progress = None  # the dialog's progress slot
        self._cancel = False
        self._last = 0.0
        # A method of this object (which lives on the GUI thread): called there, after the thread ended.
        self.finished.connect(self._ended)

    def _ended(self) -> None:
        self.ended.emit(self.outcome or "failed")

    def cancel(self) -> None:
        self._cancel = True

    @property
    def cancel_requested(self) -> bool:
        return self._cancel

    def _progress(self, done: int, total: int, message: str = "") -> None:
        if self._cancel:
            raise Cancelled()
        now = time.monotonic()
        if now - self._last >= self.MIN_INTERVAL or done >= total:
            self._last = now
            self.progressed.emit(int(done), int(total), str(message))

    def run(self) -> None:
        try:
            extra = {"partial": self.partial_ready.emit} if self.partial else {}
            result = self.function(progress=self._progress, **extra)
        except Cancelled:
            self.outcome = "cancelled"
            self.cancelled.emit()
        except (TonguevisError, OSError) as exc:
            self.outcome = "failed"
            self.failed.emit(str(exc))
        except Exception as exc:  # a bug: keep the app alive, show the trace in the log
            logger.error("%s failed:\n%s", self.title, traceback.format_exc())
            self.outcome = "failed"
            self.failed.emit(f"unexpected {type(exc).__name__}: {exc}")
        else:
            self.outcome = "ok"
            self.succeeded.emit(result)

    def stop(self, wait_ms: int = 30000) -> None:
        """Cancel and wait for the thread (closing a window, replacing a job)."""
        if self.isRunning():
            self.cancel()
            self.wait(wait_ms)


def show_job_error(parent, title: str, message: str, path=None):
    """An error dialog over ``parent``: its own ``show_error(title, message, path)`` when it has one
    (the window keeps it as ``last_dialog`` and says it in the status bar), else a plain one."""
    show = getattr(parent, "show_error", None)
    if show is not None:
        return show(title, message, path)
    from tonguevis.gui.dialogs import error_box

    return error_box(parent, title, message, path)


@dataclass(frozen=True)
class JobReactions:
    """What else a job does besides giving its result (:func:`run_job`), all optional.

    on_failed(message), on_cancelled(), on_ended(outcome) : more reactions (after the error dialog).
    on_partial(result) : a first, incomplete result, on the GUI thread (``function`` is then called with
        ``partial=`` too, see :class:`Job`); once it is in, the window is usable again: the modal
        dialog closes and the progress goes on in ``status`` ("<title>: <message> (n %)").
    status(text) : where "<title>: cancelled" goes (e.g. the app model's status line).
    explain(message) -> message : more words for the error dialog (what to try instead).
    path : the file the error dialog names.
    """

    on_failed: Callable[[str], None] | None = None
    on_cancelled: Callable[[], None] | None = None
    on_ended: Callable[[str], None] | None = None
    on_partial: Callable[[Any], None] | None = None
    status: Callable[[str], None] | None = None
    explain: Callable[[str], str] | None = None
    path: Any = None


def run_job(parent, title: str, function: Callable[..., Any], on_done: Callable[[Any], None] | None = None,
            reactions: JobReactions | None = None, *, label: str | None = None, dialog: bool = True,
            min_duration_ms: int = 300) -> Job:
    """Run ``function(progress=...)`` in a :class:`Job` behind a window-modal progress dialog with Cancel.

    parent : the widget the dialog and the error dialog belong to (owns the job).
    title : names the task: "<title>…" in the dialog, "<title> failed" on the error dialog.
    on_done(result) : on the GUI thread once it succeeded; the only place its result is used.
    reactions : :class:`JobReactions`, what else happens (failed, cancelled, ended, a partial result, the
        status line, the error dialog's words and file).
    label : the progress dialog's first text (default "<title>…").
    dialog : False for no progress dialog (the caller shows progress from ``job.progressed``);
    min_duration_ms : how long a job runs before its dialog shows.
    """
    r = reactions if reactions is not None else JobReactions()
    on_failed, on_cancelled, on_ended, on_partial = r.on_failed, r.on_cancelled, r.on_ended, r.on_partial
    status, explain, path = r.status, r.explain, r.path
    job = Job(function, parent, title, partial=on_partial is not None)
    if dialog:
        from PySide6.QtCore import Qt
        from PySide6.QtWidgets import QProgressDialog

        box = QProgressDialog(label or f"{title}…", "Cancel", 0, 1000, parent)
        box.setWindowTitle(f"tonguevis: {title.lower()}")
        box.setWindowModality(Qt.WindowModality.WindowModal)
        box.setMinimumDuration(min_duration_ms)
        box.setValue(0)
        box.canceled.connect(job.cancel)

        def show_progress(done: int, total: int, message: str) -> None:
            box.setMaximum(max(total, 1))
            box.setValue(min(done, total))
            if message:
                box.setLabelText(message)

        job.progressed.connect(show_progress)
        job.show_progress = show_progress
        job.finished.connect(box.reset)
        job.dialog = box
    if on_done is not None:
        job.succeeded.connect(on_done)
    if on_partial is not None:
        job.partial_ready.connect(on_partial)
        job.partial_ready.connect(lambda _result: _carry_on_in_the_background(job, title, status))

    def failed(message: str) -> None:
        show_job_error(parent, f"{title} failed", explain(message) if explain else message, path)
        if on_failed is not None:
            on_failed(message)

    def cancelled() -> None:
        if status is not None:
            status(f"{title}: cancelled")
        if on_cancelled is not None:
            on_cancelled()

    job.failed.connect(failed)
    job.cancelled.connect(cancelled)
    if on_ended is not None:
        job.ended.connect(on_ended)
    job.start()
    return job


def _carry_on_in_the_background(job: Job, title: str, status: Callable[[str], None] | None) -> None:
    """After a partial result: close the job's modal dialog (the window is usable) and report the
    rest of its progress in ``status``, if given."""
    if job.dialog is not None:
        job.progressed.disconnect(job.show_progress)
        job.dialog.reset()
        job.dialog = None
    if status is not None:
        job.progressed.connect(lambda done, total, message: status(
            f"{title}: {message or 'working'} ({100 * done // max(total, 1)} %)"))
