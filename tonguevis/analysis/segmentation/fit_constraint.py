"""Constraint modes (eqs. 10-13): the static response of a partition to its boundary.

Boundary DOFs ``B`` are the partition's interface nodes (nodes it shares with
any tet outside it) plus the user-constrained nodes in it (the anchors, §5.2);
the rest are internal, ``I``, the partition's free surface included.  The fit
keeps the target on ``B`` and fills ``I`` with ``ũ_I = −K_II⁻¹ K_IB u_B``, the
partition's *own* stiffness (assembled from its tets only).  That is eq. (13)
without ever forming Φ_con: one sparse factorisation of ``K_II`` and one
multi-column solve with every frame (or target column) as a right-hand side.

Speed: the global CSR pattern and each tet's slots in it are computed once, so a
partition's stiffness is a ``bincount`` (and a candidate = partition + ring
reuses the partition's assembled values); factorisations are kept in a small
cache so the final all-frames fit of an accepted partition does not refactor.
The result does not depend on Young's modulus (it cancels), only on Poisson's
ratio.

A partition whose boundary does not hold it (fewer than three non-collinear
boundary nodes, e.g. the one partition of a mesh without constraints) has
floppy rigid motions: ``K_II`` is singular along them and the right-hand side
has no component there, so a tiny diagonal shift (1e-9 of the mean diagonal)
and three steps of iterative refinement against the unshifted matrix give the
solution without them (with no boundary at all, ``ũ = 0``: the constraint
subspace is empty).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from tonguevis.analysis.segmentation.fitter import LocalFitter
from tonguevis.sim.assembly import element_stiffness, shape_gradients

SHIFT = 1e-9
SYSTEM_CACHE = 4  # factorisations kept (each up to ~100 MB for a whole 1,800-node tongue)
ASSEMBLY_CACHE = 24  # assembled partition stiffness values kept (~2 MB each)


@dataclass
class PartitionSystem:
    """The factorised interior problem of one tet set.

    interior, boundary : sorted node ids; solve : callable on (3|I|, c) arrays
    or None when there is nothing to solve; k_ib : (3|I|, 3|B|) sparse;
    interior_weights : (|I|,) lumped volumes, m³.
    """

    interior: np.ndarray
    boundary: np.ndarray
    solve: object
    k_ib: sp.csr_matrix | None
    interior_weights: np.ndarray

    def fit_interior(self, values: np.ndarray) -> np.ndarray:
        """Interior fit (c, |I|, 3) for target columns ``values`` (c, n, 3)."""
        c = values.shape[0]
        if self.solve is None or len(self.boundary) == 0:
            return np.zeros((c, len(self.interior), 3))
        y_b = np.transpose(values[:, self.boundary, :], (1, 2, 0)).reshape(-1, c)
        x = self.solve(-(self.k_ib @ y_b))
        return np.transpose(x.reshape(len(self.interior), 3, c), (2, 0, 1))


def _dofs(nodes: np.ndarray) -> np.ndarray:
    return (3 * nodes[:, None] + np.arange(3)).ravel()


def _refined(solve, matrix, steps: int = 3):
    """Solve with a shifted factorisation, then refine against the unshifted matrix.

    The residual stays in the range of the (singular) matrix, so refinement
    removes the shift's bias without growing the free rigid component.
    """

    def refined(rhs: np.ndarray) -> np.ndarray:
        x = solve(rhs)
        for _ in range(steps):
            x = x + solve(rhs - matrix @ x)
        return x

    return refined


def _block_pattern(tets: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSR pattern of the global stiffness and each element entry's slot in it.

    Built on node pairs (16 per tet, not 144) and expanded to 3 x 3 blocks: DOF
    row ``3a+i`` holds, for each neighbour ``b`` of ``a`` in increasing order,
    the columns ``3b, 3b+1, 3b+2``.  Returns slots (k, 144) in the order of
    the flattened (12, 12) element matrices, indices and indptr.
    """
    k = len(tets)
    a = np.repeat(tets, 4, axis=1)  # (k, 16): a of pair (a_loc, b_loc)
    b = np.tile(tets, (1, 4))
    pair_keys, pair_slot = np.unique((a * n_nodes + b).ravel(), return_inverse=True)
    pair_slot = pair_slot.reshape(k, 4, 4)
    rows = pair_keys // n_nodes
    neighbours = pair_keys % n_nodes
    degree = np.bincount(rows, minlength=n_nodes)
    node_ptr = np.concatenate([[0], np.cumsum(degree)])
    an = tets[:, :, None, None, None]  # (k, 4, 1, 1, 1) node a of local a_loc
    i = np.arange(3)[None, None, :, None, None]
    j = np.arange(3)[None, None, None, None, :]
    rank = (pair_slot - node_ptr[tets][:, :, None])[:, :, None, :, None]  # position of b in a's row
    slots = 9 * node_ptr[an] + 3 * i * degree[an] + 3 * rank + j
    slots = slots.reshape(k, 144)
    row_node = np.repeat(np.arange(n_nodes), 3)
    row_i = np.tile(np.arange(3), n_nodes)
    indptr = np.concatenate([9 * node_ptr[row_node] + 3 * row_i * degree[row_node], [9 * node_ptr[-1]]])
    lengths = 3 * degree[row_node]
    starts = 3 * node_ptr[row_node]
    offsets = np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    column_block = (3 * neighbours[:, None] + np.arange(3)).ravel()
    indices = column_block[np.repeat(starts, lengths) + offsets]
    return slots.astype(np.int64), indices.astype(np.int64), indptr.astype(np.int64)


class ConstraintFitter(LocalFitter):
    """Constraint-mode fit of tet sets (eq. 13) with the partition's own stiffness."""

    mode = "constraint"

    def __init__(self, *args, poisson: float = 0.49, **kwargs):
        self.poisson = float(poisson)
        super().__init__(*args, **kwargs)

    def _prepare(self) -> None:
        grads, vol = shape_gradients(self.points, self.tets)
        # Young's modulus cancels in K_II^-1 K_IB: use 1 Pa.
        self._element_values = element_stiffness(grads, vol, 1.0, self.poisson).reshape(len(self.tets), 144)
        self._slots, self._indices, self._indptr = _block_pattern(self.tets, len(self.points))
        self._nnz = len(self._indices)
        self._assembled: OrderedDict[bytes, np.ndarray] = OrderedDict()
        self._systems: OrderedDict[bytes, PartitionSystem] = OrderedDict()
        self.n_factorisations = 0

    # ------------------------------------------------------------------ pieces
    def _assemble(self, members: np.ndarray, base: np.ndarray | None) -> np.ndarray:
        """CSR values of the set's own stiffness on the global pattern."""
        key = self.key(members)
        found = self._assembled.get(key)
        if found is not None:
            self._assembled.move_to_end(key)
            return found
        start = None
        if base is not None and len(base):
            base_key = self.key(base)
            start = self._assembled.get(base_key)
            if start is not None:
                self._assembled.move_to_end(base_key)
        if start is not None:
            # candidate = partition + ring (growth) or partition ± one tet (adjustment)
            values = start.copy()
            in_members = np.zeros(len(self.tets), dtype=bool)
            in_members[members] = True
            in_base = np.zeros(len(self.tets), dtype=bool)
            in_base[base] = True
            added = np.flatnonzero(in_members & ~in_base)
            removed = np.flatnonzero(in_base & ~in_members)
            if len(added):
                values += np.bincount(self._slots[added].ravel(), weights=self._element_values[added].ravel(),
                                      minlength=self._nnz)
            if len(removed):
                values -= np.bincount(self._slots[removed].ravel(), weights=self._element_values[removed].ravel(),
                                      minlength=self._nnz)
        else:
            values = np.bincount(self._slots[members].ravel(), weights=self._element_values[members].ravel(),
                                 minlength=self._nnz)
        self._assembled[key] = values
        if len(self._assembled) > ASSEMBLY_CACHE:
            self._assembled.popitem(last=False)
        return values

    def _pinned(self, boundary: np.ndarray) -> bool:
        """Whether boundary nodes hold every rigid motion (≥ 3 non-collinear nodes)."""
        if len(boundary) < 3:
            return False
        p = self.points[boundary]
        p = p - p.mean(axis=0)
        sv = np.linalg.svd(p, compute_uv=False)
        return bool(sv[1] > 1e-9 * max(sv[0], 1e-300))

    def system(self, members: np.ndarray, base: np.ndarray | None = None) -> PartitionSystem:
        """The (cached) factorised interior system of the tet set."""
        members, key = self.sorted_members(members)
        found = self._systems.get(key)
        if found is not None:
            self._systems.move_to_end(key)
            return found
        nodes, weights = self.node_weights(members)
        on_boundary = np.zeros(len(self.points), dtype=bool)
        on_boundary[self.graph.boundary_nodes(members)] = True
        on_boundary |= self.constrained
        inner = ~on_boundary[nodes]
        interior, boundary = nodes[inner], nodes[~inner]
        solve, k_ib = None, None
        if len(interior) and len(boundary):
            values = self._assemble(members, base)
            k = sp.csr_matrix((values, self._indices, self._indptr), shape=(3 * len(self.points),) * 2)
            rows = k[_dofs(interior)]
            k_ii = rows[:, _dofs(interior)]
            k_ii = sp.csc_matrix((k_ii.data, k_ii.indices, k_ii.indptr), shape=k_ii.shape)  # symmetric: CSR = CSC
            k_ib = rows[:, _dofs(boundary)].tocsr()
            pinned = self._pinned(boundary)
            shifted = k_ii if pinned else k_ii + SHIFT * k_ii.diagonal().mean() * sp.identity(k_ii.shape[0],
                                                                                             format="csc")
            # SPD: no pivoting, symmetric ordering; wider supernodes (relax, panel) factor ~30 % faster.
            # (SuperLU needs relax <= panel_size: relax 40 with panel 20 corrupted the heap.)
            lu = spla.splu(shifted, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, relax=10, panel_size=10,
                           options={"SymmetricMode": True})
            self.n_factorisations += 1
            solve = lu.solve if pinned else _refined(lu.solve, k_ii)
        found = PartitionSystem(interior, boundary, solve, k_ib, weights[inner])
        self._systems[key] = found
        if len(self._systems) > SYSTEM_CACHE:
            self._systems.popitem(last=False)
        return found

    # ------------------------------------------------------------------ fits
    def _compute_error(self, members: np.ndarray, base: np.ndarray | None) -> float:
        system = self.system(members, base)
        if len(system.interior) == 0:
            return 0.0
        fit = system.fit_interior(self.columns)  # (c, |I|, 3)
        diff = fit - self.columns[:, system.interior, :]
        return float(np.einsum("cpi,cpi,p->", diff, diff, system.interior_weights))

    def approximate(self, members: np.ndarray, displacements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nodes (p,) of the set and its constraint-mode fit (F, p, 3), m, of each frame."""
        system = self.system(members)
        nodes = self.graph.nodes_of(members)
        fit = np.array(displacements[:, nodes, :], dtype=np.float64, copy=True)
        if len(system.interior):
            where = np.searchsorted(nodes, system.interior)
            fit[:, where, :] = system.fit_interior(displacements)
        return nodes, fit
