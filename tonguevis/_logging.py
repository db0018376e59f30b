"""tonguevis's one logger and its ``verbose`` convention (after MNE-Python's ``_logging``).

Every module logs through :data:`logger` (the ``"tonguevis"`` logger); nothing makes its own.
How much is said is set once for the session with :func:`set_log_level` (``tonguevis -v``
does it), or for one call with the ``verbose`` keyword of the functions decorated by
:func:`verbose`::

    tonguevis.simulate(rec, verbose=True)      # this call says what it does
    tonguevis.set_log_level("warning")          # from now on, warnings only

``verbose`` takes a bool (True: "info", False: "warning"), a level name or number, or None
(the session's level).  Warnings (a rest not found, a sensor ignored) are always shown
unless the level is raised above them.
"""

from __future__ import annotations

import contextlib
import functools
import inspect
import logging
from typing import Any, Callable, Iterator, TypeVar

#: The logger every module of tonguevis uses.
logger = logging.getLogger("tonguevis")

F = TypeVar("F", bound=Callable[..., Any])


def _level(verbose: bool | str | int | None) -> int | None:
    """The logging level ``verbose`` stands for (None: leave the level as it is)."""
    if verbose is None:
        return None
    if isinstance(verbose, bool):
        return logging.INFO if verbose else logging.WARNING
    if isinstance(verbose, int):
        return verbose
    if isinstance(verbose, str):
        level = logging.getLevelName(verbose.strip().upper())
        if isinstance(level, int):
            return level
    raise ValueError(f"verbose must be a bool, a level name (debug, info, warning, error) or a number, "
                     f"got {verbose!r}")


#: The warnings :func:`warn_once` has said in this process (each line, as said).
_said: set[str] = set()


def warn_once(line: str, detail: str = "") -> None:
    """Say ``line`` as a warning once per process, and ``detail`` (the longer why) at the info level.

    ``line`` is one short line: what happened and what to do.  A script that simulates
    the same recording again, or the app simulating it again with other settings, is not
    told the same thing twice (the line holds the file and the figures, so another
    recording's is said).  The whole story stays in the run's summary and metadata;
    ``detail`` is shown with ``tonguevis -v`` or ``verbose=True``.
    """
    if line in _said or not logger.isEnabledFor(logging.WARNING):
        return
    _said.add(line)
    logger.warning("%s", line)
    if detail:
        logger.info("%s", detail)


def forget_warnings() -> None:
    """Let :func:`warn_once` say every line again (each ``tonguevis`` command starts afresh; tests)."""
    _said.clear()


def set_log_level(verbose: bool | str | int | None = None) -> None:
    """Set how much tonguevis says from now on (see the module doc); None: "warning"."""
    logger.setLevel(_level(verbose) if verbose is not None else logging.WARNING)


@contextlib.contextmanager
def use_log_level(verbose: bool | str | int | None) -> Iterator[None]:
    """Within the block, tonguevis logs at ``verbose``'s level (None: unchanged)."""
    level = _level(verbose)
    if level is None:
        yield
        return
    old = logger.level
    logger.setLevel(level)
    try:
        yield
    finally:
        logger.setLevel(old)


def verbose(function: F) -> F:
    """Give ``function`` a keyword ``verbose`` (default None: the session's level) that sets the
    log level for that call only.  A function that already has a ``verbose`` parameter receives it too."""
    takes_it = "verbose" in inspect.signature(function).parameters

    @functools.wraps(function)
    def wrapper(*args: Any, verbose: bool | str | int | None = None, **kwargs: Any) -> Any:
        if takes_it:
            kwargs["verbose"] = verbose
        with use_log_level(verbose):
            return function(*args, **kwargs)

    wrapper.__doc__ = (function.__doc__ or "").rstrip() + (
        "\n\n    verbose : bool, level name or None: how much this call logs (see :mod:`tonguevis._logging`)."
        if not takes_it else "")
    return wrapper  # type: ignore[return-value]


@contextlib.contextmanager
def library_quieted(name: str, level: int = logging.WARNING,
                    filters: dict[str, Callable[[logging.LogRecord], bool]] | None = None) -> Iterator[None]:
    """Within the block, another library's logger ``name`` says ``level`` and above only, and each logger named
    in ``filters`` (its children) drops the records its filter refuses.  The only place tonguevis touches loggers
    other than its own."""
    other = logging.getLogger(name)
    old = other.level
    other.setLevel(max(old, level))
    filtered = [(logging.getLogger(child), check) for child, check in (filters or {}).items()]
    for child, check in filtered:
        child.addFilter(check)
    try:
        yield
    finally:
        for child, check in filtered:
            child.removeFilter(check)
        other.setLevel(old)
