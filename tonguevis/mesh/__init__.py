"""Tetrahedral meshes: the :class:`TetMesh` container, readers, checks and landmarks."""

from tonguevis.errors import MeshError
from tonguevis.mesh.axes import ARTISYNTH_AXES, apply_axes, axes_matrix
from tonguevis.mesh.default import (
    context_surface_path,
    default_landmarks_path,
    default_mesh_path,
    load_default_landmarks,
    load_default_mesh,
)
from tonguevis.mesh.landmarks import (
    ANCHOR_NAMES,
    SENSOR_NAMES,
    Landmarks,
    find_landmarks,
    midline_y,
    read_landmarks,
)
from tonguevis.mesh.quality import tet_quality
from tonguevis.mesh.readers import read_mesh
from tonguevis.mesh.surfaces import dorsal_surface_nodes, inferior_surface_nodes, read_surface
from tonguevis.mesh.tetmesh import TetMesh, boundary_faces, signed_tet_volumes

__all__ = [
    "ANCHOR_NAMES", "ARTISYNTH_AXES", "Landmarks", "MeshError", "SENSOR_NAMES", "TetMesh",
    "apply_axes", "axes_matrix", "boundary_faces", "context_surface_path", "default_landmarks_path",
    "default_mesh_path", "dorsal_surface_nodes", "find_landmarks", "inferior_surface_nodes",
    "load_default_landmarks", "load_default_mesh", "midline_y", "read_landmarks", "read_mesh",
    "read_surface", "signed_tet_volumes", "tet_quality",
]
