"""Where the embedded data lives and where caches go."""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_DIR = PACKAGE_DIR.parent
MESH_DIR = REPO_DIR / "meshes"
#: The shipped tongue (``scripts/build_meshes.py``): :func:`tonguevis.mesh.default.load_default_mesh` reads it.
SHIPPED_TONGUE = MESH_DIR / "tongue.vtu"
DATA_DIR = REPO_DIR / "data"
#: The demo plain ``tonguevis`` opens: speaker 1's synthetic /ta/ train with its sound
#: (the tongue tip's closure against the ridge is the clearest first look at the model).
DEMO_RECORDING = DATA_DIR / "spk1_ta.tsv"


def cache_dir() -> Path:
    """Folder for cached modal bases (``$TONGUEVIS_CACHE`` or ~/.cache/tonguevis)."""
    root = os.environ.get("TONGUEVIS_CACHE")
    path = Path(root) if root else Path.home() / ".cache" / "tonguevis"
    path.mkdir(parents=True, exist_ok=True)
    return path
