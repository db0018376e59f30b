"""Workarounds for bugs of the Qt bindings, applied once when the app starts."""

from __future__ import annotations

from PySide6 import QtCore  # noqa: F401 (Qt's own module: this one is only needed with PySide6)


def keep_none_alive() -> None:
    """Work around PySide6 6.12 on Python < 3.12: every call of a Qt method returning void (``repaint``,
    ``setText``, ``processEvents``, painting ...) drops one reference to ``None`` (measured: 100 calls,
    refcount -100).  The live view makes about a hundred such calls per frame at up to 100 frames a
    second, so within a second None's count (about 5000) reaches zero and Python aborts
    ("none_dealloc").  None is never freed anyway: its count is raised once by 2**40 (centuries of
    frames), as Python 3.12 makes it immortal.  A no-op elsewhere (PyPy, Python >= 3.12)."""
    import ctypes
    import platform
    import sys

    if sys.version_info >= (3, 12) or platform.python_implementation() != "CPython" or \
            getattr(keep_none_alive, "done", False):
        return
    ctypes.c_ssize_t.from_address(id(None)).value += 2 ** 40  # ob_refcnt, the first field of every object
    keep_none_alive.done = True
