"""Constraint modes (eqs. 10-13): the static response of a partition to its boundary.

Boundary DOFs ``B`` are the partition's interface nodes (nodes it shares with
any tet outside it) plus the user-constrained nodes in it (the anchors, §5.2);
the rest are internal, ``I``, the partition's free surface included.  The fit
keeps the target on ``B`` and fills ``I`` with ``ũ_I = −K_II⁻¹ K_IB u_B``
(eq. 13) without ever forming Φ_con: one sparse factorisation of ``K_II`` and
one multi-column solve with every frame as a right-hand side.

Why everything depends on ``I`` alone: every tet holding an internal node
belongs to the partition, so the rows of the partition's own stiffness at
internal nodes *are* the rows of the whole mesh's stiffness there.  Hence
``K_II`` and ``K_IB`` are slices of one global matrix assembled once, the
lumped weights of internal nodes are the global ones, boundary nodes carry no
error, and the error of a tet set is a function of its internal node set.
Two candidates with the same internal nodes (common when a rival takes a few
tets off a ring) share one memo entry and one factorisation.  The tests check
this against a dense solve with the partition's own stiffness.

The result does not depend on Young's modulus (it cancels), only on Poisson's
ratio.  A partition whose boundary does not hold it (fewer than three
non-collinear nodes around the internal ones, e.g. one partition and two
constrained nodes) is singular along its free rigid motions, which the
right-hand side does not excite: a tiny diagonal shift (1e-9 of the mean
diagonal) plus three steps of iterative refinement against the unshifted
matrix give the solution without them.  With no boundary at all, ``ũ = 0``
(the constraint subspace is empty).
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from tonguevis.analysis.segmentation.fitter import CORES, LocalFitter, worker_pool
from tonguevis.sim.assembly import assemble_stiffness

SHIFT = 1e-9
SYSTEM_CACHE = 4  # factorisations kept (each up to ~100 MB for a whole 1,800-node tongue)
#: SuperLU releases the GIL: the column blocks of a many-frame solve go to this many threads.
SOLVE_THREADS = CORES
#: Right-hand sides per SuperLU solve call (measured: 4 columns per call beat 1 and 27 on a
#: 5,000-DOF tongue system by 1.7x and 7x).
SOLVE_BLOCK = 4
#: Largest number of internal nodes a cached factorisation may have beyond a new set for
#: the new set to be solved through it (each costs 3 extra right-hand sides).
MAX_DROPPED = 8


@dataclass
class InteriorSystem:
    """The factorised problem of one internal node set.

    interior : (i,) sorted internal nodes; mask : (n,) bool of them; around :
    (a,) sorted nodes coupled to them (the boundary nodes that matter);
    solve : callable on (3i, c) arrays, or None when nothing is to be solved;
    direct : whether ``solve`` is a plain factorisation (it can then serve
    smaller internal sets); k_ia : (3i, 3a) sparse; weights : (i,) lumped
    volumes of the internal nodes, m³.
    """

    interior: np.ndarray
    mask: np.ndarray
    around: np.ndarray
    solve: object
    direct: bool
    k_ia: sp.csr_matrix | None
    weights: np.ndarray

    def fit(self, values: np.ndarray) -> np.ndarray:
        """Internal fit (c, i, 3) for target columns ``values`` (c, n, 3)."""
        c = values.shape[0]
        if self.solve is None:
            return np.zeros((c, len(self.interior), 3))
        y_a = np.transpose(values[:, self.around, :], (1, 2, 0)).reshape(-1, c)
        x = self.solve(-(self.k_ia @ y_a))
        return np.transpose(x.reshape(len(self.interior), 3, c), (2, 0, 1))

    def error(self, values: np.ndarray) -> float:
        """Σ_j Σ_i w_i |ũ_ij − y_ij|² over the internal nodes (m²·m³)."""
        if len(self.interior) == 0:
            return 0.0
        diff = self.fit(values) - values[:, self.interior, :]
        return float(np.einsum("cpi,cpi,p->", diff, diff, self.weights))


def _blocked(solve, threaded: bool):
    """``solve`` applied 4 columns at a time (SciPy's SuperLU: ~7x faster per column than
    27 at once), the blocks spread over threads when ``threaded``."""

    def blocked(rhs: np.ndarray) -> np.ndarray:
        if rhs.ndim == 1:
            return solve(rhs)
        blocks = [np.ascontiguousarray(rhs[:, i:i + SOLVE_BLOCK]) for i in range(0, rhs.shape[1], SOLVE_BLOCK)]
        if threaded and SOLVE_THREADS > 1 and len(blocks) > 1:
            parts = list(worker_pool("tonguevis-solve", SOLVE_THREADS).map(solve, blocks))
        else:
            parts = [solve(block) for block in blocks]
        return np.concatenate(parts, axis=1)

    return blocked


def _principal(parent: InteriorSystem, interior: np.ndarray):
    """Solve with the principal submatrix of ``parent``'s matrix on ``interior`` ⊂ its nodes.

    A rival often takes a few tets off a proposal's ring, so the proposal's
    internal set loses a few nodes ``D`` and its matrix is the old one without
    their rows and columns.  With the old factorisation ``A``:
    ``z = A⁻¹(b − E λ)``, ``(Eᵀ A⁻¹ E) λ = Eᵀ A⁻¹ b`` pins ``z_D = 0`` and
    leaves the exact solution on the other DOFs: 3|D| extra columns instead of
    a new factorisation.
    """
    keep = np.searchsorted(parent.interior, interior)
    dropped = np.setdiff1d(np.arange(len(parent.interior)), keep)
    keep_dofs, drop_dofs = _dofs(keep), _dofs(dropped)
    n_old = 3 * len(parent.interior)
    unit = np.zeros((n_old, len(drop_dofs)))
    unit[drop_dofs, np.arange(len(drop_dofs))] = 1.0
    z_unit = parent.solve(unit)
    capacitance = z_unit[drop_dofs]

    def solve(rhs: np.ndarray) -> np.ndarray:
        wide = np.zeros((n_old,) + rhs.shape[1:])
        wide[keep_dofs] = rhs
        z = parent.solve(wide)
        multipliers = np.linalg.solve(capacitance, z[drop_dofs])
        return (z - z_unit @ multipliers)[keep_dofs]

    return solve


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


def _factorise(matrix: sp.csc_matrix):
    # SPD: no pivoting, symmetric ordering; wider supernodes (relax, panel) factor ~30 % faster.
    # (SuperLU needs relax <= panel_size: relax 40 with panel 20 corrupted the heap.)
    # No equilibration either: the stiffness is symmetric and needs no scaling without pivoting.
    return spla.splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, relax=16, panel_size=16,
                     options={"SymmetricMode": True, "Equil": False})


class ConstraintFitter(LocalFitter):
    """Constraint-mode fit of tet sets (eq. 13); see the module notes."""

    mode = "constraint"
    threads = CORES

    def __init__(self, *args, poisson: float = 0.49, **kwargs):
        self.poisson = float(poisson)
        super().__init__(*args, **kwargs)

    def _prepare(self) -> None:
        # Young's modulus cancels in K_II^-1 K_IB: use 1 Pa.
        self._stiffness = assemble_stiffness(self.points, self.tets, 1.0, self.poisson).tocsr()
        self._stiffness.sort_indices()
        self._lumped = np.bincount(self.tets.ravel(), weights=np.repeat(self.tet_volumes / 4.0, 4),
                                   minlength=len(self.points))
        self._interior_memo: dict[bytes, float] = {}
        self._systems: OrderedDict[bytes, InteriorSystem] = OrderedDict()
        self._lock = threading.Lock()  # the system cache is shared by the fitting threads
        self.n_factorisations = 0
        self.n_reused = 0  # systems solved through a larger cached factorisation

    def interior_nodes(self, members: np.ndarray) -> np.ndarray:
        """Sorted internal nodes of the set: all their tets inside, not constrained."""
        count = np.bincount(self.tets[members].ravel(), minlength=len(self.points))
        return np.flatnonzero((count == self.graph.node_valence) & (count > 0) & ~self.constrained)

    def _pinned(self, around: np.ndarray) -> bool:
        """Whether the nodes around the interior hold every rigid motion (≥ 3 non-collinear)."""
        if len(around) < 3:
            return False
        p = self.points[around]
        sv = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
        return bool(sv[1] > 1e-9 * max(sv[0], 1e-300))

    def system(self, interior: np.ndarray) -> InteriorSystem:
        """The (cached) factorised system of an internal node set."""
        mask = np.zeros(len(self.points), dtype=bool)
        mask[interior] = True
        key = np.packbits(mask).tobytes()
        with self._lock:
            found = self._systems.get(key)
            if found is not None:
                self._systems.move_to_end(key)
                return found
        rows = self._stiffness[_dofs(interior)]
        coupled = np.zeros(len(self.points), dtype=bool)
        coupled[rows.indices // 3] = True
        around = np.flatnonzero(coupled & ~mask)
        solve, k_ia, direct, parent = None, None, False, None
        if len(interior) and len(around):
            k_ia = rows[:, _dofs(around)].tocsr()
            threaded = len(interior) >= 300 and self.threads > 1
            pinned = self._pinned(around)
            if pinned:
                parent = self._parent(mask, len(interior))
            if parent is not None:
                solve = _principal(parent, interior)
            else:
                k_ii = rows[:, _dofs(interior)]
                k_ii = sp.csc_matrix((k_ii.data, k_ii.indices, k_ii.indptr), shape=k_ii.shape)  # symmetric
                if pinned:
                    try:
                        solve, direct = _blocked(_factorise(k_ii).solve, threaded), True
                    except RuntimeError:  # exactly singular: a floating piece the rule did not see
                        solve = None
                if solve is None:
                    shift = SHIFT * k_ii.diagonal().mean()
                    shifted = _factorise(k_ii + shift * sp.identity(k_ii.shape[0], format="csc"))
                    solve = _refined(_blocked(shifted.solve, threaded), k_ii)
        found = InteriorSystem(interior, mask, around, solve, direct, k_ia, self._lumped[interior])
        with self._lock:
            if parent is not None:
                self.n_reused += 1
            else:
                self.n_factorisations += solve is not None
            self._systems[key] = found
            if len(self._systems) > SYSTEM_CACHE:
                self._systems.popitem(last=False)
        return found

    def _parent(self, mask: np.ndarray, size: int) -> InteriorSystem | None:
        """A cached plain factorisation whose internal nodes hold ``mask``'s and at most
        MAX_DROPPED more (see :func:`_principal`)."""
        with self._lock:
            cached = list(self._systems.values())
        for system in reversed(cached):
            extra = len(system.interior) - size
            if system.direct and 0 < extra <= MAX_DROPPED and not np.any(mask & ~system.mask):
                return system
        return None

    def _compute_error(self, members: np.ndarray) -> float:
        interior = self.interior_nodes(members)
        mask = np.zeros(len(self.points), dtype=bool)
        mask[interior] = True
        key = np.packbits(mask).tobytes()
        found = self._interior_memo.get(key)
        if found is None:
            if self._still_boundary(members, mask, self.columns):  # ũ_I = 0, nothing to solve
                y = self.columns[:, interior, :]
                found = float(np.einsum("cpi,cpi,p->", y, y, self._lumped[interior]))
            else:
                found = self.system(interior).error(self.columns)
            self._interior_memo[key] = found
        return found

    def _still_boundary(self, members: np.ndarray, interior_mask: np.ndarray, values: np.ndarray) -> bool:
        """Whether the target is zero on every non-internal node of the set (e.g. the whole
        mesh with the anchors as its only boundary): then the fit is zero."""
        nodes = self.graph.nodes_of(members)
        return not np.any(values[:, nodes[~interior_mask[nodes]], :])

    def approximate(self, members: np.ndarray, displacements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nodes (p,) of the set and its constraint-mode fit (F, p, 3), m, of each frame."""
        nodes = self.graph.nodes_of(members)
        interior = self.interior_nodes(members)
        fit = np.array(displacements[:, nodes, :], dtype=np.float64, copy=True)
        if len(interior):
            mask = np.zeros(len(self.points), dtype=bool)
            mask[interior] = True
            where = np.searchsorted(nodes, interior)
            if self._still_boundary(members, mask, displacements):
                fit[:, where, :] = 0.0
            else:
                fit[:, where, :] = self.system(interior).fit(displacements)
        return nodes, fit
