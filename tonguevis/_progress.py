"""Progress reporting shared by the CLI (tqdm) and the GUI (a callback).

Long-running library functions take ``progress=None``: a callable
``progress(done, total, message) -> None`` or ``None``.  The callable may raise
:class:`tonguevis.errors.Cancelled` to stop the work; the GUI uses that for its
cancel button.  :func:`tqdm_progress` builds such a callable around a tqdm bar.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Callable, Iterator, Optional


ProgressCallback = Callable[[int, int, str], None]


def report(progress: Optional[ProgressCallback], done: int, total: int, message: str = "") -> None:
    """Call ``progress`` if there is one (cheap no-op otherwise)."""
    if progress is not None:
        progress(done, total, message)


@contextmanager
def tqdm_progress(description: str, disable: bool = False, unit: str = "step") -> Iterator[ProgressCallback]:
    """A progress callback drawing a tqdm bar on stderr (counting ``unit``), closed on exit.

    While the bar is drawn, log lines (the CLI's warnings) go through ``tqdm.write``: each on a
    line of its own above the bar, not glued onto the bar's line."""
    from tqdm import tqdm
    from tqdm.contrib.logging import logging_redirect_tqdm

    bar = tqdm(total=1, desc=description, disable=disable, leave=False, unit=unit)

    def callback(done: int, total: int, message: str = "") -> None:
        if bar.total != total:
            bar.total = max(int(total), 1)
        bar.n = int(done)
        if message:
            bar.set_postfix_str(message, refresh=False)
        bar.refresh()

    try:
        with logging_redirect_tqdm(tqdm_class=tqdm):
            yield callback
    finally:
        bar.close()
