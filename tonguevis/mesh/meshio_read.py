"""meshio's reader made quiet and thread-safe: one reader for the tetrahedral meshes and the surfaces."""

from __future__ import annotations

import threading

import numpy as np

#: quiet_meshio_read swaps the process's sys.stdout and sys.stderr: one read at a time.  Two reads in two
#: threads (the app simulates a compared recording beside the open one, each reading the palate) used to
#: interleave their swaps and leave sys.stdout pointing at one of the captures for good: every later
#: print was lost (``tonguevis view --compare ... --screenshot`` printed nothing and a GUI test was flaky).
_QUIET_READ = threading.Lock()


def quiet_meshio_read(path):
    """meshio.read, with meshio's stderr chatter captured and its ``sys.exit``
    on unparsable XML turned into :class:`meshio.ReadError`."""
    import contextlib
    import io

    import meshio

    import warnings

    chatter = io.StringIO()
    try:
        # meshio's STL sniffing overflows on some headers (a harmless RuntimeWarning).
        with _QUIET_READ, contextlib.redirect_stderr(chatter), contextlib.redirect_stdout(chatter), \
                warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            return meshio.read(path)
    except SystemExit as exc:
        raise meshio.ReadError(" ".join(chatter.getvalue().split()) or "unreadable file") from exc
