"""The compute backends: ``"warp"`` (warp-lang kernels, the default) or ``"numpy"`` (the references).

Importing warp-lang quietly: the library never prints.

warp announces itself on stdout when it initialises and, on machines without
an NVIDIA driver, its native code writes a CUDA warning to stderr.  Both are
noise for a CPU user (the kernels then run on the CPU, as intended), so the
init runs with warp's log level at errors and with the process's C-level
stderr pointed at /dev/null for that call only.
"""

from __future__ import annotations

import os
import sys
import threading

from tonguevis._logging import logger
_lock = threading.Lock()
_warp = None

#: Backend names every ``backend=`` argument accepts.  "warp" here means the
#: warp-lang compiler; modal warping is always called ``warping``.
BACKENDS = ("warp", "numpy")


def check_backend(backend: str) -> str:
    """``backend`` if it is one of :data:`BACKENDS`, else ValueError naming the choices."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {', '.join(map(repr, BACKENDS))}, got {backend!r}")
    return backend


def load_warp():
    """The initialised ``warp`` module (CPU, or CUDA when a GPU is present)."""
    global _warp
    with _lock:
        if _warp is not None:
            return _warp
        import warp as wp

        if hasattr(wp, "LOG_ERROR") and hasattr(wp.config, "log_level"):
            wp.config.log_level = wp.LOG_ERROR
        else:  # older warp
            wp.config.quiet = True
        saved = None
        try:
            sys.stderr.flush()
            saved = os.dup(2)
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 2)
            os.close(devnull)
        except OSError:  # no real file descriptor 2 (embedded interpreters): just init
            saved = None
        try:
            wp.init()
        finally:
            if saved is not None:
                os.dup2(saved, 2)
                os.close(saved)
        logger.debug("warp %s initialised; preferred device %s", wp.__version__, wp.get_preferred_device())
        _warp = wp
        return wp


#: The modules whose warp kernels a simulation launches.
KERNEL_MODULES = ("tonguevis.sim.kernels", "tonguevis.sim.newmark_kernel")


def prepare_kernels(modules=KERNEL_MODULES) -> float:
    """Compile the kernels of ``modules`` now (or load them from warp's kernel cache); returns seconds.

    warp compiles a module on its first launch and keeps the binary in its
    kernel cache (``warp.config.kernel_cache_dir``).  A parent calls this
    before starting worker processes, so the workers load the cached binaries
    instead of each compiling the same kernels at once (about 12 s of a core each).
    """
    import importlib
    import time

    started = time.perf_counter()
    wp = load_warp()
    for name in modules:
        importlib.import_module(name)._build()
        wp.load_module(name, device=wp.get_preferred_device())
    return time.perf_counter() - started
