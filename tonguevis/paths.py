"""Where the embedded data lives and where caches go."""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_DIR = PACKAGE_DIR.parent
MESH_DIR = REPO_DIR / "meshes"
DATA_DIR = REPO_DIR / "data"


def cache_dir() -> Path:
    """Folder for cached modal bases (``$TONGUEVIS_CACHE`` or ~/.cache/tonguevis)."""
    root = os.environ.get("TONGUEVIS_CACHE")
    path = Path(root) if root else Path.home() / ".cache" / "tonguevis"
    path.mkdir(parents=True, exist_ok=True)
    return path
