"""Which way a tongue mesh faces: its axis mapping onto ours, found from its shape.

A mesh from another lab comes in that lab's frame (ArtiSynth's ``tongue3.1``:
x backwards, y down, z lateral).  :func:`find_axes` tries each of the 24
proper rotations that permute and flip the axes (the mappings
:mod:`tonguevis.mesh.axes` can write, e.g. ``"-x,-z,-y"``) and keeps the one
under which the mesh's boundary best matches the shipped tongue's boundary,
both centred on their volume centroids and scaled to the same volume (so the
size and the position of the mesh do not matter, only its shape).  The match
is the mean of the two mean nearest-neighbour distances (template to mesh and
mesh to template), in units of the cube root of the volume.

The result says how sure it is (:attr:`AxesFit.margin`, second-best over best
misfit): a tongue is not symmetric front to back or top to bottom, so the true
mapping wins clearly (1.9 on the ArtiSynth tongue); a box or a ball does not.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from tonguevis.errors import MeshError
from tonguevis.mesh.axes import axes_matrix
from tonguevis.mesh.tetmesh import TetMesh

#: Below this margin (second-best misfit / best misfit) the shape does not tell the axes.
MIN_MARGIN = 1.3
IDENTITY = "x,y,z"


@dataclass(frozen=True)
class AxesFit:
    """The mapping of a mesh's axes onto ours that best matches the shipped tongue.

    axes : the mapping, e.g. ``"-x,-z,-y"`` (``"x,y,z"``: already in our frame).
    misfit : its shape misfit (dimensionless: distance / cube root of the volume).
    identity_misfit : the misfit of the mesh as it is.
    margin : second-best misfit / best misfit (>= 1); below :data:`MIN_MARGIN` the
        shape does not decide.
    """

    axes: str
    misfit: float
    identity_misfit: float
    margin: float

    @property
    def decided(self) -> bool:
        """Whether the shape tells the axes clearly (margin >= :data:`MIN_MARGIN`)."""
        return self.margin >= MIN_MARGIN

    @property
    def in_our_frame(self) -> bool:
        """True unless another mapping fits clearly better than the mesh as it is."""
        return self.axes == IDENTITY or self.identity_misfit < MIN_MARGIN * self.misfit


def proper_axis_mappings() -> list[str]:
    """The 24 signed axis permutations with determinant +1, identity first."""
    mappings = []
    for perm in itertools.permutations("xyz"):
        for signs in itertools.product(("", "-"), repeat=3):
            text = ",".join(s + a for s, a in zip(signs, perm))
            if np.linalg.det(axes_matrix(text)) > 0:
                mappings.append(text)
    return mappings


def _shipped_tongue() -> TetMesh:
    """The shipped tongue (``meshes/tongue.vtu``, metres) as the template, read by meshio alone: the mesh
    readers find axes with this module, so it cannot read through them."""
    from tonguevis.mesh.meshio_read import quiet_meshio_read
    from tonguevis.paths import SHIPPED_TONGUE

    if not SHIPPED_TONGUE.exists():
        raise MeshError("the default mesh is missing; run `python scripts/build_meshes.py`", SHIPPED_TONGUE)
    mesh = quiet_meshio_read(SHIPPED_TONGUE)
    return TetMesh(np.asarray(mesh.points, dtype=np.float64), np.asarray(mesh.cells_dict["tetra"], dtype=np.int64),
                   {"source": str(SHIPPED_TONGUE)})


def _normalised_boundary(mesh: TetMesh) -> np.ndarray:
    """Boundary nodes centred on the volume centroid, in units of the cube root of the volume."""
    volumes = np.abs(mesh.tet_volumes())
    total = float(volumes.sum())
    if not total > 0:
        raise MeshError("the mesh has no volume: cannot tell its axes", mesh.metadata.get("source"))
    centroid = np.average(mesh.points[mesh.tets].mean(axis=1), axis=0, weights=volumes)
    boundary = mesh.points[np.unique(mesh.boundary_faces())]
    return (boundary - centroid) / total ** (1.0 / 3.0)


def find_axes(mesh: TetMesh, template: TetMesh | None = None) -> AxesFit:
    """The axis mapping under which ``mesh`` looks most like ``template`` (default: the shipped tongue).

    ``mesh`` may be in any units and anywhere in space; only its shape counts.
    """
    from scipy.spatial import cKDTree  # lazy: keeps `import tonguevis` light

    if template is None:
        template = _shipped_tongue()
    reference = _normalised_boundary(template)
    reference_tree = cKDTree(reference)
    points = _normalised_boundary(mesh)
    misfits = {}
    for mapping in proper_axis_mappings():
        turned = points @ axes_matrix(mapping).T
        there = reference_tree.query(turned)[0].mean()
        back = cKDTree(turned).query(reference)[0].mean()
        misfits[mapping] = 0.5 * float(there + back)
    ranked = sorted(misfits, key=misfits.get)
    best, second = misfits[ranked[0]], misfits[ranked[1]]
    return AxesFit(ranked[0], best, misfits[IDENTITY], second / best if best > 0 else float("inf"))
