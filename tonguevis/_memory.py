"""Giving freed memory back to the system (glibc keeps it otherwise)."""

from __future__ import annotations

import sys


def release_freed_memory() -> None:
    """Hand the memory freed so far back to the system.

    glibc keeps what a thread freed in that thread's arena, and blocks under its mmap threshold
    (up to 32 MB) in the heap: after a phase that made and dropped many such arrays (preparing a
    30-minute recording, the frame loop's and the figures' threads) the process stayed 150-300 MB
    above what it held, which is what a long session's peak is made of.  A no-op elsewhere.
    """
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL("libc.so.6").malloc_trim(0)
        except (OSError, AttributeError):  # not glibc (musl): nothing kept that way
            pass
