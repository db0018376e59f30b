"""Single-threaded BLAS for small products.

Threaded BLAS pays a wake-up for every call; for the small products of one
frame (a 1 × m by m × 3n product) or ARPACK's vector operations that costs
far more than the work, and when the other core is busy it costs
milliseconds (measured: 3.6 ms against 0.04 ms for one frame's product on
two cores under load).  Large batched products keep all threads.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager

_lock = threading.Lock()
_controller = None


@contextmanager
def single_threaded_blas():
    """Run the block with one BLAS thread (a cached threadpoolctl controller: ~10 µs)."""
    global _controller
    with _lock:
        if _controller is None:
            from threadpoolctl import ThreadpoolController

            _controller = ThreadpoolController()
    with _controller.limit(limits=1, user_api="blas"):
        yield
