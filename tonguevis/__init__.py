"""tonguevis: physics-based deformable tongue visualisation from EMA recordings.

A reproduction of Yang et al. 2013 ("Physics-Based Deformable Tongue
Visualization").  The heavy parts load lazily so ``import tonguevis`` is light.
"""

from __future__ import annotations

__version__ = "0.1.0"

_LAZY = {
    "read_recording": "tonguevis.io",
    "Recording": "tonguevis.io",
    "read_mesh": "tonguevis.mesh",
    "TetMesh": "tonguevis.mesh",
    "TongueModel": "tonguevis.sim",
    "ModalBasis": "tonguevis.sim",
    "Motion": "tonguevis.sim",
    "simulate": "tonguevis.sim",
    "RunSettings": "tonguevis.sim",
    "set_log_level": "tonguevis._logging",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'tonguevis' has no attribute {name!r}")
