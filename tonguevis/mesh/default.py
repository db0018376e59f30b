"""The shipped default tongue (built by ``scripts/build_meshes.py`` into ``meshes/``)."""

from __future__ import annotations

from pathlib import Path

from tonguevis.errors import MeshError
from tonguevis.mesh.landmarks import Landmarks, read_landmarks
from tonguevis.mesh.readers import read_mesh
from tonguevis.mesh.tetmesh import TetMesh
from tonguevis.paths import MESH_DIR, SHIPPED_TONGUE

DEFAULT_MESH_NAME = SHIPPED_TONGUE.name
DEFAULT_LANDMARKS_NAME = "tongue_landmarks.json"
CONTEXT_SURFACES = {"jaw": "jaw.stl", "palate": "palate.stl"}


def default_mesh_path() -> Path:
    """Path of the shipped tongue mesh (``meshes/tongue.vtu``)."""
    return SHIPPED_TONGUE


def default_landmarks_path() -> Path:
    """Path of the shipped tongue's landmarks JSON."""
    return MESH_DIR / DEFAULT_LANDMARKS_NAME


def context_surface_path(name: str) -> Path:
    """Path of a shipped context surface: ``"jaw"`` or ``"palate"``."""
    if name not in CONTEXT_SURFACES:
        raise MeshError(f"unknown context surface {name!r}; shipped: {sorted(CONTEXT_SURFACES)}")
    return MESH_DIR / CONTEXT_SURFACES[name]


def load_default_mesh() -> TetMesh:
    """The shipped tongue: about 1,800 nodes, metres, our frame."""
    path = default_mesh_path()
    if not path.exists():
        raise MeshError("the default mesh is missing; run `python scripts/build_meshes.py`", path)
    return read_mesh(path, unit="m")


def load_default_landmarks(mesh: TetMesh | None = None) -> Landmarks:
    """Landmarks of the shipped tongue (checked against ``mesh`` when given)."""
    return read_landmarks(default_landmarks_path(), mesh)
