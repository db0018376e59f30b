"""The tongue model: mesh, landmarks, material, and its (cached) modal basis."""

from __future__ import annotations

from contextlib import nullcontext
import os
import time
from functools import cached_property

from typing import Any

import numpy as np
import scipy.sparse as sp

from tonguevis._backend import check_backend
from tonguevis._blas import single_threaded_blas
from tonguevis._progress import ProgressCallback
from tonguevis.errors import ModelError
from tonguevis.mesh.tetmesh import TetMesh, signed_tet_volumes
from tonguevis.sim.assembly import assemble_mass, assemble_stiffness
from tonguevis.sim.curl import nodal_curl_operator
from tonguevis.sim.material import Material
from tonguevis.sim.modal import ModalBasis, basis_key, free_dofs_for, load_basis, save_basis, solve_modes
from tonguevis.sim.rotation import rotate_accumulated

from tonguevis._logging import logger

CHUNK_FRAMES = 256  # frames reconstructed per batch: bounds memory at ~30 MB for 1,800 nodes
SMALL_BATCH = 16  # up to this many frames the products run on one BLAS thread (see tonguevis._blas)


class TongueModel:
    """A tetrahedral tongue with anchors, sensor landmarks and material.

    mesh : :class:`TetMesh` (points in metres).
    landmarks : object with ``sensors`` (dict name -> node id) and
        ``anchors`` ((a,) node ids fixed to the hyoid and jaw).
    material : :class:`Material`.
    """

    def __init__(self, mesh: TetMesh, landmarks: Any, material: Material | None = None):
        self.mesh = mesh
        self.landmarks = landmarks
        self.material = material or Material()
        anchors = np.unique(np.asarray(landmarks.anchors, dtype=np.int64))
        if len(anchors) < 3:
            raise ModelError(f"a tongue model needs at least 3 anchor nodes, got {len(anchors)}")
        if anchors.min() < 0 or anchors.max() >= mesh.n_nodes:
            raise ModelError(f"anchor node ids {anchors.tolist()} outside the mesh's {mesh.n_nodes} nodes")
        for name, node in landmarks.sensors.items():
            if not 0 <= int(node) < mesh.n_nodes:
                raise ModelError(f"sensor {name} is mapped to node {node}, which is not in the mesh")
        self.anchors = anchors
        self._bases: dict[int, ModalBasis] = {}
        self._rotation_matrices: dict[str, np.ndarray] = {}
        self._transposed: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}

    # ------------------------------------------------------------------ builders
    @classmethod
    def default(cls, material: Material | None = None) -> "TongueModel":
        """Our parametric adult tongue shipped in ``meshes/``."""
        from tonguevis.mesh import load_default_landmarks, load_default_mesh

        return cls(load_default_mesh(), load_default_landmarks(), material)

    @classmethod
    def from_mesh(
        cls,
        mesh: TetMesh | str | os.PathLike,
        landmarks: Any = None,
        material: Material | None = None,
        **read_options: Any,
    ) -> "TongueModel":
        """A model of any tet mesh; landmarks found from the geometry unless given.

        ``landmarks`` may be a Landmarks object, a JSON path, or a dict of
        overrides (``{"TT": 12, "anchors": [...]}``) on top of the automatic ones.
        ``read_options`` go to :func:`~tonguevis.mesh.read_mesh` (``unit``, ``axes``;
        ``axes="auto"`` finds the mesh's axes from its shape).

        Automatic landmarks need the mesh in our frame (x anterior, y left, z up):
        a mesh read without ``axes`` whose shape matches our tongue clearly better
        turned (:func:`~tonguevis.mesh.orientation.find_axes`) is refused with
        the mapping that fits, instead of placing the sensors on its side or floor.
        """
        from tonguevis.mesh import find_landmarks, read_landmarks, read_mesh

        if not isinstance(mesh, TetMesh):
            mesh = read_mesh(mesh, **read_options)
        if landmarks is None or isinstance(landmarks, dict):
            if mesh.metadata.get("axes") is None:
                _check_our_frame(mesh)
            landmarks = find_landmarks(mesh, overrides=landmarks)
        elif isinstance(landmarks, (str, os.PathLike)):
            landmarks = read_landmarks(landmarks)
        return cls(mesh, landmarks, material)

    # ------------------------------------------------------------------ FEM
    @cached_property
    def stiffness(self) -> sp.csr_matrix:
        """K (3n, 3n) in N/m."""
        return assemble_stiffness(self.mesh.points, self.mesh.tets, self.material.young, self.material.poisson)

    @cached_property
    def mass(self) -> sp.csr_matrix:
        """Consistent M (3n, 3n) in kg."""
        return assemble_mass(self.mesh.points, self.mesh.tets, self.material.density)

    @cached_property
    def curl_operator(self) -> sp.csr_matrix:
        """C (3n, 3n): nodal rotation vectors w = C u."""
        return nodal_curl_operator(self.mesh.points, self.mesh.tets)

    @cached_property
    def rest_volume(self) -> float:
        """m³."""
        return float(signed_tet_volumes(self.mesh.points, self.mesh.tets).sum())

    @cached_property
    def surface_nodes(self) -> np.ndarray:
        """(k,) the nodes on the surface, sorted (what the views draw)."""
        return np.unique(self.surface_faces)

    @cached_property
    def surface_faces(self) -> np.ndarray:
        """(f, 3) outward boundary triangles."""
        return self.mesh.boundary_faces()

    # ------------------------------------------------------------------ modes
    def basis_key(self, m: int) -> str:
        return basis_key(self.mesh.points, self.mesh.tets, self.material, self.anchors, m)

    def basis(self, m: int = 100, progress: ProgressCallback | None = None, cache: bool = True) -> ModalBasis:
        """The ``m`` lowest modes: from memory, else the disk cache, else solved (and cached)."""
        if m in self._bases:
            return self._bases[m]
        key = self.basis_key(m)
        path = None
        if cache:
            from tonguevis.paths import cache_dir

            path = cache_dir() / f"basis-{key}.npz"
            t0 = time.perf_counter()
            loaded = load_basis(path, key)
            if loaded is not None:
                loaded.info["load_s"] = time.perf_counter() - t0
                self._bases[m] = loaded
                return loaded
        free = free_dofs_for(self.mesh.n_nodes, self.anchors)
        phi_free, vals, info = solve_modes(self.stiffness, self.mass, free, m, progress=progress)
        phi = np.zeros((3 * self.mesh.n_nodes, m))
        phi[free] = phi_free
        basis = ModalBasis(phi, vals, free, key, info)
        if path is not None:
            try:
                save_basis(basis, path)
            except OSError as exc:  # a read-only cache must not stop the simulation
                logger.warning("could not cache the modal basis at %s: %s", path, exc)
        self._bases[m] = basis
        return basis

    def rotation_matrix(self, basis: ModalBasis) -> np.ndarray:
        """W = C Φ (3n, m): nodal rotation vectors per unit modal displacement."""
        if basis.key not in self._rotation_matrices:
            self._rotation_matrices[basis.key] = np.asarray(self.curl_operator @ basis.phi)
        return self._rotation_matrices[basis.key]

    # ------------------------------------------------------------------ reconstruction
    def displacements(
        self, q: np.ndarray, warping: bool = True, backend: str = "warp", dtype=np.float64,
        nodes: np.ndarray | None = None,
    ) -> np.ndarray:
        """(F, n, 3) node displacements in m for modal displacements ``q`` (F, m).

        Linear: Φq.  Warped: ũ_i = R̃((Wq)_i) (Φq)_i, the rotation in warp-lang
        (``backend="warp"``) or NumPy (``"numpy"``).  Frames are processed in chunks to bound
        the temporaries, but the result holds every frame: F × n × 3 values (for a
        long recording iterate over chunks of q instead, see :meth:`Motion.iter_displacements`).
        ``dtype=np.float32`` halves the work for rendering (about 1e-7 relative).
        ``nodes`` : (k,) node ids to reconstruct (e.g. the surface's), giving (F, k, 3); each
        node's displacement depends on its own rows of Φ and W only, so the values equal
        those of the whole mesh.
        """
        dtype = np.dtype(dtype)
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        basis = self.basis(q.shape[1])
        phi_t, w_t = self._reconstruction_matrices(basis, dtype, nodes)
        n = phi_t.shape[1] // 3
        out = np.empty((len(q), n, 3), dtype=dtype)
        q = q.astype(dtype, copy=False)
        small = len(q) <= SMALL_BATCH
        for start in range(0, len(q), CHUNK_FRAMES):
            chunk = q[start : start + CHUNK_FRAMES]
            with single_threaded_blas() if small else nullcontext():
                lin = (chunk @ phi_t).reshape(len(chunk), n, 3)
                w = (chunk @ w_t).reshape(len(chunk), n, 3) if warping else None
            if warping:
                if check_backend(backend) == "warp":
                    from tonguevis.sim.kernels import rotate_accumulated_compiled

                    lin = rotate_accumulated_compiled(w, lin)
                else:
                    lin = rotate_accumulated(w, lin)
            out[start : start + len(chunk)] = lin
        return out

    def modal_fields(self, q: np.ndarray, nodes: np.ndarray | None = None, warping: bool = True,
                     dtype=np.float64) -> tuple[np.ndarray, np.ndarray | None]:
        """(Φq, Wq) at ``nodes`` (all by default) for ``q`` (F, m): (F, k, 3) linear displacement in m
        and rotation vectors in rad (None without ``warping``), in ``dtype``; the two halves of
        :meth:`displacements` before the rotation."""
        dtype = np.dtype(dtype)
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        phi_t, w_t = self._reconstruction_matrices(self.basis(q.shape[1]), dtype, nodes)
        q = q.astype(dtype, copy=False)
        shape = (len(q), phi_t.shape[1] // 3, 3)
        return (q @ phi_t).reshape(shape), (q @ w_t).reshape(shape) if warping else None

    def _reconstruction_matrices(self, basis: ModalBasis, dtype: np.dtype,
                                 nodes: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Φᵀ and Wᵀ (m, 3n) in ``dtype`` (columns of ``nodes`` only, if given), contiguous, kept per
        basis, dtype and node set."""
        if nodes is not None:
            nodes = np.asarray(nodes, dtype=np.int64)
        key = (basis.key, dtype.str, None if nodes is None else nodes.tobytes())
        if key not in self._transposed:
            cols = slice(None) if nodes is None else (3 * nodes[:, None] + np.arange(3)).ravel()
            self._transposed[key] = (
                np.ascontiguousarray(basis.phi[cols].T, dtype=dtype),
                np.ascontiguousarray(self.rotation_matrix(basis)[cols].T, dtype=dtype),
            )
        return self._transposed[key]

    def displacement(self, q: np.ndarray, warping: bool = True) -> np.ndarray:
        """(n, 3) displacement in m for one modal vector ``q`` (m,)."""
        return self.displacements(np.asarray(q)[None, :], warping=warping)[0]

    def volume_change(self, displacements: np.ndarray, backend: str = "warp",
                      nodes: np.ndarray | None = None) -> np.ndarray:
        """(F,) relative volume change (V - V_rest)/V_rest for (F, n, 3) displacements.

        ``nodes``: the displacements are those of these nodes only, (F, k, 3), which must hold
        every surface node (e.g. :attr:`surface_nodes`); the volume is the same.

        The volume of a closed tet mesh is the flux of x/3 through its
        boundary, V = ⅙ Σ_faces p0 · (p1 × p2), which touches only the surface
        (about a fifth of the work of summing every tet); a test checks it
        against the tet sum.  ``backend="warp"`` runs it as a warp-lang kernel, ``"numpy"`` in NumPy.
        """
        d = np.asarray(displacements)
        faces, points = self.surface_faces, self.mesh.points
        if nodes is not None:
            nodes = np.asarray(nodes, dtype=np.int64)
            local = np.full(self.mesh.n_nodes, -1, dtype=np.int64)
            local[nodes] = np.arange(len(nodes))
            faces, points = local[faces], points[nodes]
            if (faces < 0).any():
                raise ValueError("volume_change: nodes must include every surface node")
        out = np.empty(len(d))
        for start in range(0, len(d), CHUNK_FRAMES):
            pts = points[None] + d[start : start + CHUNK_FRAMES]
            if check_backend(backend) == "warp":
                from tonguevis.sim.kernels import enclosed_volumes

                out[start : start + len(pts)] = enclosed_volumes(pts, faces)
            else:
                p0, p1, p2 = (pts[:, faces[:, k]] for k in range(3))
                out[start : start + len(pts)] = np.einsum("fki,fki->f", p0, np.cross(p1, p2)) / 6.0
        return out / self.rest_volume - 1.0

    @cached_property
    def dorsal_nodes(self) -> np.ndarray:
        """Surface nodes a sensor can sit on (upward-facing, not anchors), for snapping."""
        from tonguevis.mesh import dorsal_surface_nodes

        nodes = dorsal_surface_nodes(self.mesh)
        return nodes[~np.isin(nodes, self.anchors)]

    def energy(self, q: np.ndarray) -> np.ndarray:
        """(F,) elastic energy U = ½ qᵀΛq in J for q (F, m)."""
        q = np.atleast_2d(q)
        basis = self.basis(q.shape[1])
        if "stiffness" in basis.info:  # a basis with sensor patches (tonguevis.sim.patches): not diagonal
            return 0.5 * np.einsum("fm,mk,fk->f", q, basis.info["stiffness"], q)
        return 0.5 * np.einsum("fm,m,fm->f", q, basis.eigenvalues, q)

    def __repr__(self) -> str:
        return (
            f"TongueModel({self.mesh.n_nodes} nodes, {self.mesh.n_tets} tets, "
            f"{len(self.anchors)} anchors, sensors {sorted(self.landmarks.sensors)})"
        )


def _check_our_frame(mesh: TetMesh) -> None:
    """MeshError when ``mesh`` clearly lies in another frame than ours, naming the mapping that fits."""
    from tonguevis.errors import MeshError
    from tonguevis.mesh.orientation import find_axes

    fit = find_axes(mesh)
    if fit.in_our_frame:
        return
    raise MeshError(
        f"the mesh does not lie in our frame (x anterior, y left, z up): turned by the axis mapping "
        f"{fit.axes!r} its shape matches a tongue {fit.identity_misfit / fit.misfit:.1f} times better than as "
        f"it is, and the sensors and anchors would land on its side or floor. Read it with "
        f"axes={fit.axes!r} (command line: --mesh-axes={fit.axes}), or axes='auto' to take the mapping found",
        mesh.metadata.get("source"))
