"""Tetrahedral meshes: the :class:`TetMesh` container, readers and landmarks."""

from tonguevis.errors import MeshError
from tonguevis.mesh.tetmesh import TetMesh, boundary_faces, signed_tet_volumes

__all__ = ["MeshError", "TetMesh", "boundary_faces", "signed_tet_volumes"]
