"""Seed 001's reduced nonlinear tongue: StVK on blended quadratic domains (§6-7; issue 26, item 1).

**Kinematics (Eqs. 5-7).**  One domain is seeded at each driving sensor node and one at
the node nearest the tongue's centre of mass.  Domain j moves a point x by
u = t + A y + Q_o ỹ + Q_e ŷ (y = (x − s_j)/L, ỹ = (y₁², y₂², y₃²), ŷ = (y₁y₂, y₂y₃, y₁y₃),
s_j the seed, L = :data:`LENGTH_SCALE`): 3 translation, 9 affine, 9 homogeneous and 9
heterogeneous quadratic DOFs, 30 in all, in the paper's order (t, a₁, a₂, a₃, q_o1..3,
q_e1..3), each in metres.  Centring and scaling x is a change of coordinates of the same
space (the paper's absolute-x terms differ from these by translation and affine terms of
the same domain) that keeps the DOFs of one size.  The domains' fields are blended by
location-dependent weights, u(x) = Σ_j w^j(x) G^j(x) q^j, evaluated at the nodes: the
model is the full linear-tet mesh restricted to that subspace, B = [G¹ … G^d] (3n, 30d),
so its force, tangent and mass are the full mesh's projected (Bᵀf, BᵀKB, BᵀMB) and it
converges to :mod:`tonguevis.sim.stvk` as the subspace grows (the paper evaluates F from
the analytic gradient of w G instead, Eq. 10; at nodes both are the same field).
One weight per domain serves all four kinds of DOF (the paper's w_t = w_a = w_o = w_e).

**Weights (§7), as built here.**  For each seed, the principal direction p is the
eigenvector of the largest eigenvalue of A = H_ppH_pp + H_pwH_pwᵀ (Eq. 14): A = XᵀX with
X = K⁻¹ on the seed's three columns, the anchors and the other seeds held (Eq. 12).  Then
the static solve that prescribes u = p at the seed and holds the anchors fully and the
other seeds only along p (pᵀu = 0: the paper's relaxed boundary) gives the weight
w = clip(pᵀu, 0, 1) at every node (1 at its seed, 0 at the anchors and, along p, at the
other seeds).  Departure from the paper, said plainly: the domain *boundary* is not held.
The paper also holds the boundary of each flooded domain along p; with every weight then
vanishing on its own domain's boundary, the nodes where two domains meet would have no
weight at all (nothing could move them), so here each weight covers the whole mesh and the
domains from flooding (:func:`flood_domains`, nearest seed along mesh edges) are computed,
kept in the cache and reported, but do not cut the weights.  The weights are not
normalised to sum to one (near the anchors they all fall to zero, as the tongue's own
displacement does).

**Dynamics (Eq. 11).**  Backward Euler in the reduced coordinates z (B made
mass-orthonormal, BᵀMB = I), Rayleigh damping C = αI + βBᵀK₀B, the reduced StVK force
over every tet of the mesh by default (exact; compiled by :mod:`tonguevis.sim.domains_kernel`,
~0.75 ms a force on the shipped tongue against ~5.5 ms through NumPy: with ~1.6-2.5 forces a
frame, :meth:`DomainModel.integrate_fast`, this bounds the frame loop at a few hundred frames/s on
one core) or by an optional cubature
(:mod:`tonguevis.sim.cubature`: ~20x less work, its error stated there), solved by Newton with the
sensor constraints as hard multipliers on the targets :func:`tonguevis.sim.simulate.drive_schedule`
makes (the compliant projection, with the domain model's own linear stiffness, and the
dropout handover; the same constraints as the modal methods').  Newton keeps the tangent of
the previous iteration or frame while the force residual falls fast (modified Newton) and
refreshes it otherwise.  :meth:`DomainModel.integrate` is the plain reference loop (NumPy force,
Newton to 0.1 µm); :meth:`DomainModel.integrate_fast` the default one (compiled force, the previous
frame's force carried to a first step, Newton to 1 µm), proven within a stated distance of it.

Units SI: z and the domain DOFs in m, forces in N, stiffness in N/m.
"""

from __future__ import annotations

import hashlib
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from tonguevis._files import atomic_write
from tonguevis.errors import ModelError
from tonguevis.sim.stvk import StVK

from tonguevis._logging import logger

DOFS_PER_DOMAIN = 30
#: Length (m) the quadratic terms are measured in: y = (x - seed) / L; about a third of the tongue.
LENGTH_SCALE = 0.03
CACHE_VERSION = 1
#: Columns of the blended basis whose mass is below this share of the largest are dropped (dependent).
DEPENDENCE = 1e-10
#: simulate_domains(scheme=...): see its docstring.
SCHEMES = ("newton", "linearised", "reference")
#: Newton's tolerance (m, on the step's nodal size) in the fast schemes: 1 µm (the reference's is 0.1 µm).
FAST_TOLERANCE = 1e-6


# ---------------------------------------------------------------------------------------- kinematics
def domain_columns(points: np.ndarray, seed_point: np.ndarray, weight: np.ndarray,
                   length: float = LENGTH_SCALE) -> np.ndarray:
    """(3n, 30) G^j of one domain at the nodes: u = G q for its 30 DOFs (Eq. 6), node-major rows.

    points : (n, 3) m; seed_point : (3,) m; weight : (n,) w^j at the nodes.
    Column order: t (3), a₁ a₂ a₃ (3 each), q_o1..3 (3 each), q_e1..3 (3 each), i.e. for
    component i the entries u_i gets from t_i, a_i·y, q_oi·ỹ and q_ei·ŷ.
    """
    y = (np.asarray(points, dtype=np.float64) - seed_point) / length
    n = len(y)
    ones = np.ones((n, 1))
    tilde = y ** 2
    hat = np.column_stack([y[:, 0] * y[:, 1], y[:, 1] * y[:, 2], y[:, 0] * y[:, 2]])
    out = np.zeros((n, 3, DOFS_PER_DOMAIN))
    for i in range(3):
        out[:, i, i] = 1.0  # translation t_i
        for block, values in ((3, y), (12, tilde), (21, hat)):
            out[:, i, block + 3 * i: block + 3 * i + 3] = values
    out *= np.asarray(weight, dtype=np.float64)[:, None, None]
    del ones
    return out.reshape(3 * n, DOFS_PER_DOMAIN)


def flood_domains(points: np.ndarray, tets: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """(n,) the domain (index into ``seeds``) of every node: the nearest seed along mesh edges (flooding)."""
    from scipy.sparse.csgraph import dijkstra

    pairs = np.array([(a, b) for a in range(4) for b in range(a + 1, 4)])
    edges = np.unique(np.sort(tets[:, pairs].reshape(-1, 2), axis=1), axis=0)
    length = np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1)
    n = len(points)
    graph = sp.coo_matrix((length, (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    _, _, sources = dijkstra(graph, directed=False, indices=np.asarray(seeds), min_only=True,
                             return_predecessors=True)
    lookup = {int(s): k for k, s in enumerate(seeds)}
    return np.array([lookup.get(int(s), -1) for s in sources], dtype=np.int64)


def _dofs(nodes) -> np.ndarray:
    return (3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)).ravel()


def material_aware_weights(stiffness: sp.spmatrix, anchors: np.ndarray, seeds: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray]:
    """(weights (n, d), principal directions (d, 3)) of the domains seeded at ``seeds`` (§7; see the module
    docstring for the boundary conditions).  stiffness : (3n, 3n) linear K at rest, N/m; anchors : node ids."""
    n = stiffness.shape[0] // 3
    seeds = np.asarray(seeds, dtype=np.int64)
    k = sp.csr_matrix(stiffness)
    weights = np.zeros((n, len(seeds)))
    directions = np.zeros((len(seeds), 3))
    anchor_dofs = _dofs(anchors)
    for j, seed in enumerate(seeds):
        others = np.delete(seeds, j)
        # principal direction: unit forces at the seed, anchors and other seeds held (Eqs. 12-14)
        held = np.zeros(3 * n, dtype=bool)
        held[anchor_dofs] = True
        held[_dofs(others)] = True
        free = np.flatnonzero(~held)
        lu = spla.splu(k[free][:, free].tocsc())
        rhs = np.zeros((len(free), 3))
        pos = np.searchsorted(free, _dofs([seed]))
        rhs[pos, np.arange(3)] = 1.0
        x = lu.solve(rhs)
        vals, vecs = np.linalg.eigh(x.T @ x)
        p = vecs[:, -1]
        directions[j] = p
        # weight: u = p at the seed, pᵀu = 0 at the other seeds, anchors fixed
        held = np.zeros(3 * n, dtype=bool)
        held[anchor_dofs] = True
        held[_dofs([seed])] = True
        free = np.flatnonzero(~held)
        u = np.zeros(3 * n)
        u[_dofs([seed])] = p
        cons = np.zeros((len(others), 3 * n))
        for r, other in enumerate(others):
            cons[r, _dofs([other])] = p
        cons_f = sp.csr_matrix(cons[:, free])
        kkt = sp.bmat([[k[free][:, free], cons_f.T], [cons_f, None]], format="csc")
        rhs = np.concatenate([-(k[free] @ u), np.zeros(len(others))])
        sol = spla.spsolve(kkt, rhs)
        u[free] = sol[:len(free)]
        weights[:, j] = np.clip(u.reshape(n, 3) @ p, 0.0, 1.0)
    return weights, directions


def centre_seed(model, exclude: np.ndarray) -> int:
    """The node nearest the tongue's centre of mass (volume-weighted tet centroids), not in ``exclude``."""
    from tonguevis.mesh.tetmesh import signed_tet_volumes

    pts, tets = model.mesh.points, model.mesh.tets
    vol = np.abs(signed_tet_volumes(pts, tets))
    centre = (pts[tets].mean(axis=1) * vol[:, None]).sum(axis=0) / vol.sum()
    d = np.linalg.norm(pts - centre, axis=1)
    d[np.asarray(exclude, dtype=np.int64)] = np.inf
    return int(np.argmin(d))


# ---------------------------------------------------------------------------------------- the model
@dataclass
class DomainWeights:
    """What the domains of one model and seed set are (cached on disk).

    seeds : (d,) node ids (the sensor nodes, then the centre's); weights : (n, d) w^j at the nodes;
    directions : (d, 3) principal directions; partition : (n,) flooded domain of each node; key : cache key.
    """

    seeds: np.ndarray
    weights: np.ndarray
    directions: np.ndarray
    partition: np.ndarray
    key: str = ""
    info: dict[str, Any] = field(default_factory=dict)


def domains_key(model, seeds: np.ndarray) -> str:
    h = hashlib.sha256()
    h.update(f"domains v{CACHE_VERSION} L={LENGTH_SCALE}|".encode())
    h.update(model.basis_key(1).encode())  # mesh, material and anchors
    h.update(np.ascontiguousarray(seeds, dtype=np.int64).tobytes())
    return h.hexdigest()[:32]


def save_weights(dw: DomainWeights, path: Path) -> None:
    """Write ``dw`` as .npz (no pickle), atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)

    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, seeds=dw.seeds, weights=dw.weights, directions=dw.directions, partition=dw.partition,
                     key=np.array(dw.key), version=np.array(CACHE_VERSION))

    atomic_write(path, write)


def _cached_arrays(path: Path, key: str, what: str) -> dict | None:
    """The arrays of the cache file ``path`` when it is this version's and ``key``'s; None when absent, stale
    or unreadable (the last said: ``what`` is then computed again)."""
    path = Path(path)
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            if int(data["version"]) != CACHE_VERSION or str(data["key"]) != key:
                return None
            return {name: np.array(data[name]) for name in data.files}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        logger.warning("ignoring unreadable %s cache %s (%s): computed again", what, path, exc)
        return None


def load_weights(path: Path, key: str) -> DomainWeights | None:
    """The cached domains, or None if absent, stale or unreadable (then they are computed again)."""
    arrays = _cached_arrays(path, key, "domain weights")
    if arrays is None:
        return None
    return DomainWeights(arrays["seeds"], arrays["weights"], arrays["directions"], arrays["partition"], key,
                         {"loaded_from": str(path)})


def _basis_path(key: str) -> Path:
    from tonguevis.paths import cache_dir

    return cache_dir() / f"domains-basis-{key}.npz"


def _load_basis(key: str):
    """(eigenvalues, domain_dofs, basis) cached for the domains ``key`` (which covers the mesh, the material,
    the anchors and the seeds), or None."""
    arrays = _cached_arrays(_basis_path(key), key, "domain basis")
    if arrays is None:
        return None
    return arrays["eigenvalues"], arrays["domain_dofs"], arrays["basis"]


def _save_basis(key: str, eigenvalues, domain_dofs, basis) -> None:
    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez(fh, eigenvalues=eigenvalues, domain_dofs=domain_dofs, basis=basis, key=np.array(key),
                     version=np.array(CACHE_VERSION))

    try:
        atomic_write(_basis_path(key), write)
    except OSError as exc:
        logger.warning("could not cache the domain basis at %s: %s", _basis_path(key), exc)


def domain_weights(model, sensor_nodes, cache: bool = True) -> DomainWeights:
    """The domains of ``model`` seeded at ``sensor_nodes`` and its centre: from the disk cache or computed."""
    nodes = np.asarray(sensor_nodes, dtype=np.int64)
    if len(np.unique(nodes)) != len(nodes):
        raise ModelError(f"two sensors share a node ({nodes.tolist()}): one domain per sensor needs distinct nodes")
    if np.isin(nodes, model.anchors).any():
        raise ModelError("a sensor node is an anchor: its domain could not move")
    seeds = np.append(nodes, centre_seed(model, np.concatenate([nodes, model.anchors])))
    key = domains_key(model, seeds)
    path = None
    if cache:
        from tonguevis.paths import cache_dir

        path = cache_dir() / f"domains-{key}.npz"
        loaded = load_weights(path, key)
        if loaded is not None:
            return loaded
    t0 = time.perf_counter()
    weights, directions = material_aware_weights(model.stiffness, model.anchors, seeds)
    partition = flood_domains(model.mesh.points, model.mesh.tets, seeds)
    dw = DomainWeights(seeds, weights, directions, partition, key, {"solve_s": time.perf_counter() - t0})
    if path is not None:
        try:
            save_weights(dw, path)
        except OSError as exc:
            logger.warning("could not cache the domains at %s: %s", path, exc)
    return dw


class DomainModel:
    """The reduced StVK model of ``model`` on quadratic domains seeded at ``sensor_nodes`` and the centre.

    basis : (3n, r) B, mass-orthonormal (BᵀMB = I) and diagonalising the rest stiffness (BᵀK₀B = diag
        ``eigenvalues``): the subspace's own vibration modes, r ≤ 30 d (dependent columns dropped);
    domain_dofs : (30d, r) q = domain_dofs @ z gives the paper's 30 DOFs per domain from z;
    solid : the full-mesh :class:`~tonguevis.sim.stvk.StVK` of the model's mesh and material.
    """

    def __init__(self, model, sensor_nodes, cache: bool = True, young: float | None = None,
                 poisson: float | None = None, backend: str = "warp"):
        from tonguevis._backend import check_backend

        self.backend = check_backend(backend)
        self.model = model
        self.domains = domain_weights(model, sensor_nodes, cache=cache)
        mat = model.material
        self.solid = StVK(model.mesh.points, model.mesh.tets, mat.young if young is None else young,
                          mat.poisson if poisson is None else poisson, mat.density)
        from tonguevis._blas import single_threaded_blas

        loaded = _load_basis(self.domains.key) if cache else None
        if loaded is not None:  # the model's mass and stiffness are then not even assembled (0.25 s)
            self.eigenvalues, self.domain_dofs, self.basis = loaded
        else:
            with single_threaded_blas():  # 150 x 150 eigenproblems: two threads on a busy core took 0.5 s
                self.eigenvalues, self.domain_dofs, self.basis = self._subspace(model)
            if cache:
                _save_basis(self.domains.key, self.eigenvalues, self.domain_dofs, self.basis)
        self.rest_tangent = np.diag(self.eigenvalues)  # BᵀK₀B
        self.sensor_nodes = np.asarray(sensor_nodes, dtype=np.int64)
        self._tet_dofs = (3 * model.mesh.tets[:, :, None] + np.arange(3)).reshape(-1, 12)
        self._scatter = self._tet_dofs.ravel()  # (12k,) DOF of each tet's (node, axis) entry
        self._df_cache = None  # dF/dz, built when first needed (88 MB and 0.3 s on the shipped tongue)
        self._compiled = None
        self.cubature = None  # every tet (see use_cubature)

    def _subspace(self, model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(eigenvalues (r,), domain_dofs (30d, r), basis (3n, r)) of the blended domains of ``model``."""
        pts = model.mesh.points
        g = np.hstack([domain_columns(pts, pts[s], self.domains.weights[:, j])
                       for j, s in enumerate(self.domains.seeds)])
        gram = g.T @ (model.mass @ g)
        vals, vecs = np.linalg.eigh(gram)
        keep = vals > DEPENDENCE * vals.max()
        dofs = vecs[:, keep] / np.sqrt(vals[keep])
        basis = g @ dofs
        # z along the subspace's own vibration modes: BᵀMB = I and BᵀK₀B = Λ diagonal, so the modal
        # machinery (compliant projection, point stiffness, energy at rest) takes the domains as they are.
        lam, rot = np.linalg.eigh(basis.T @ (model.stiffness @ basis))
        return lam, dofs @ rot, basis @ rot  # eigenvalues 1/s², ascending

    @property
    def _df(self) -> np.ndarray:
        """(k, 9, r) dF/dz per tet: F_ij = δ_ij + Σ_a u_ai g_aj with u = B z, so constant."""
        if self._df_cache is None:
            b_tet = self.basis[self._tet_dofs].reshape(len(self._tet_dofs), 4, 3, -1)  # (k, 4, 3, r)
            self._df_cache = np.einsum("kair,kaj->kijr", b_tet, self.solid.grads).reshape(len(b_tet), 9, -1)
        return self._df_cache

    @property
    def _df2(self) -> np.ndarray:
        """(9k, r) :attr:`_df` flattened."""
        return self._df.reshape(-1, self._df.shape[-1])

    @property
    def compiled(self):
        """The warp kernels of the exact force, energy and tangent (:class:`tonguevis.sim.domains_kernel.CompiledStVK`)."""
        if self._compiled is None:
            from tonguevis.sim.domains_kernel import CompiledStVK

            self._compiled = CompiledStVK(self)
        return self._compiled

    @property
    def n_dofs(self) -> int:
        return int(self.basis.shape[1])

    def rows(self, nodes) -> np.ndarray:
        """(S, 3, r) rows of B at ``nodes``."""
        return self.basis[_dofs(nodes)].reshape(len(np.atleast_1d(nodes)), 3, -1)

    def displacement(self, z: np.ndarray) -> np.ndarray:
        """(..., n, 3) m for z (..., r)."""
        z = np.asarray(z, dtype=np.float64)
        return (z @ self.basis.T).reshape(*z.shape[:-1], -1, 3)

    # --------------------------------------------------------------------------- reduced StVK
    def _deformation(self, z: np.ndarray) -> np.ndarray:
        return (self._df2 @ z).reshape(-1, 3, 3) + np.eye(3)

    def energy(self, z: np.ndarray) -> float:
        """Elastic StVK energy (J) of the shape B z."""
        e, _, _ = self.solid.stresses(self._deformation(z))
        tr = np.trace(e, axis1=1, axis2=2)
        psi = self.solid.mu * np.einsum("kij,kij->k", e, e) + 0.5 * self.solid.lam * tr ** 2
        return float(self.solid.volumes @ psi)

    def use_cubature(self, cubature) -> None:
        """Evaluate :meth:`force` and :meth:`tangent` by ``cubature`` (a :class:`tonguevis.sim.cubature.Cubature`
        of this model), or over every tet again (None)."""
        self.cubature = cubature

    def force(self, z: np.ndarray) -> np.ndarray:
        """(r,) reduced internal force, N: over every tet (compiled with ``backend="warp"``, else
        :meth:`full_force`), or the cubature's (:meth:`use_cubature`)."""
        if self.cubature is not None:
            return self.cubature.force(z)
        return self.compiled.force(z) if self.backend == "warp" else self.full_force(z)

    def tangent(self, z: np.ndarray) -> np.ndarray:
        """(r, r) reduced tangent, N/m: over every tet (compiled with ``backend="warp"``, else
        :meth:`full_tangent`), or the cubature's (:meth:`use_cubature`)."""
        if self.cubature is not None:
            return self.cubature.tangent(z)
        return self.compiled.tangent(z) if self.backend == "warp" else self.full_tangent(z)

    def full_force(self, z: np.ndarray) -> np.ndarray:
        """(r,) reduced internal force Bᵀ f_int(Bz), N (Eq. 8 over every tet).

        Through the nodes (u = Bz, the tets' forces summed at the nodes, Bᵀf): 14 times fewer
        operations than through dF/dz (9k × r), which a test proves equal."""
        u = (self.basis @ z).reshape(-1, 3)
        solid = self.solid
        f_grad = np.eye(3) + np.einsum("kai,kaj->kij", u[solid.tets], solid.grads)
        _, _, p = solid.stresses(f_grad)
        fe = np.einsum("kij,kaj->kai", p * solid.volumes[:, None, None], solid.grads)  # (k, 4, 3)
        nodal = np.bincount(self._scatter, weights=fe.ravel(), minlength=3 * solid.n_nodes)
        return -(nodal @ self.basis)

    def force_through_gradients(self, z: np.ndarray) -> np.ndarray:
        """:meth:`force` by dF/dz: −Σ_e V_e (∂F_e/∂z)ᵀ P_e, the paper's Eq. 8 as written (the plain reference)."""
        _, _, p = self.solid.stresses(self._deformation(z))
        return -(self.solid.volumes[:, None] * p.reshape(-1, 9)).ravel() @ self._df2

    def full_tangent(self, z: np.ndarray) -> np.ndarray:
        """(r, r) reduced tangent stiffness Bᵀ K(Bz) B, N/m (Eq. 9 over every tet)."""
        # The sparse product is 3x faster than projecting each element's 12 x 12 block (0.08 against 0.23 s).
        k = self.solid.tangent(self.displacement(z))
        return self.basis.T @ (k @ self.basis)

    # --------------------------------------------------------------------------- solves
    def solve_static(self, targets: np.ndarray, nodes=None, steps: int = 4, tol: float = 1e-8,
                     max_iter: int = 40) -> tuple[np.ndarray, bool]:
        """(z (r,), converged): the reduced StVK equilibrium with ``nodes`` (default the sensor nodes) held at
        ``targets`` (S, 3) m (hard), reached in ``steps`` load steps; Newton on the KKT system
        [K_r Rᵀ; R 0], a backtracking line search on the energy once the constraints hold.
        tol : on the reduced force residual relative to its first value and on |Rz − c| in m."""
        nodes = self.sensor_nodes if nodes is None else np.asarray(nodes, dtype=np.int64)
        rows = self.rows(nodes).reshape(-1, self.n_dofs)
        c_all = np.asarray(targets, dtype=np.float64).ravel()
        z = np.zeros(self.n_dofs)
        ok = True
        for step in range(1, steps + 1):
            c = c_all * step / steps
            z, ok = self._constrained_newton(z, rows, c, lambda v: 0.0, lambda v: 0.0, 0.0, tol, max_iter)
            if not ok:
                break
        return z, ok

    def _constrained_newton(self, z, rows, c, extra_energy, extra_force, extra_tangent, tol, max_iter,
                            tangent=None):
        """Newton for min Π(z) = E(z) + extra_energy(z) s.t. rows z = c; returns (z, converged) (and keeps the
        last tangent in ``self._last_tangent`` for a modified-Newton reuse)."""
        n_c, r = len(c), self.n_dofs
        mu = np.zeros(n_c)
        ref = None
        k = tangent
        for it in range(max_iter):
            self.iterations = it
            g = -self.force(z) - extra_force(z)  # gradient of the potential
            con = c - rows @ z
            held = rows.T @ mu
            res = np.abs(g + held).max()  # force balance with the last multipliers
            # relative to the forces at play (the elastic and the constraint forces), N
            ref = max(ref or 0.0, np.abs(g).max(), np.abs(held).max(), 1e-300)
            if it > 0 and res <= tol * ref and np.abs(con).max() <= tol:
                self._last_tangent = k
                return z, True
            if k is None or it > 0:
                k = self.tangent(z) + extra_tangent
            kkt = np.block([[k, rows.T], [rows, np.zeros((n_c, n_c))]])
            sol = np.linalg.solve(kkt, np.concatenate([-g, con]))
            dz, mu = sol[:r], sol[r:]
            t = 1.0
            if np.abs(con).max() <= tol:  # feasible: keep the potential from rising
                p0 = self.energy(z) + extra_energy(z)
                while t > 1e-4 and not self.energy(z + t * dz) + extra_energy(z + t * dz) <= p0 + 1e-14 * abs(p0):
                    t *= 0.5
            z = z + t * dz
        self._last_tangent = k
        return z, False

    def integrate(self, targets: np.ndarray, dt: float, alpha: float, beta: float, tolerance: float = 1e-7,
                  max_iterations: int = 20, progress=None):
        """Backward Euler (Eq. 11) of every frame, the sensor nodes held at ``targets`` (F, S, 3) m (NaN: that
        sensor does not act in that frame); returns an :class:`~tonguevis.sim.newmark.IntegrationResult`
        with q = z (F, r) and residual (F, S) m.

        Per frame, z₁ minimises the incremental potential ½|z₁ − z₀ − h v₀|²/h² + ½ Δzᵀ C Δz / h + E(z₁)
        (mass I, C = αI + β diag Λ) subject to the acting sensors' rows R z₁ = c; Newton on its KKT system
        with the tangent of the previous iteration (or frame) kept while the step shrinks at least 4x per
        iteration, refreshed otherwise.  tolerance : m, on the Newton step's largest nodal size
        (estimated as |Δz| / √mass) and on the constraint.  A frame that is not finite keeps the previous
        shape with the velocity reset (``recovered``), as the modal integrators do.
        """
        from tonguevis._blas import single_threaded_blas
        from tonguevis._progress import report
        from tonguevis.sim.newmark import IntegrationResult

        targets = np.asarray(targets, dtype=np.float64)
        n_frames, n_s, _ = targets.shape
        r, h = self.n_dofs, float(dt)
        rows_all = self.rows(self.sensor_nodes)  # (S, 3, r)
        damping = alpha + beta * self.eigenvalues  # diagonal C
        inertia = np.diag(1.0 / h ** 2 + damping / h)
        scale = np.sqrt(float(self.model.mass.sum()) / 3.0)  # |z| ≈ √mass × displacement
        q = np.zeros((n_frames, r))
        residual = np.full((n_frames, n_s), np.nan)
        converged = np.zeros(n_frames, dtype=bool)
        iterations = np.zeros(n_frames, dtype=np.int64)
        recovered = np.zeros(n_frames, dtype=bool)
        z0, v0 = np.zeros(r), np.zeros(r)
        solver = _KKT(inertia + self.rest_tangent)
        with single_threaded_blas():  # 150 x 150 algebra: threads only wait on each other (a solve took 44 ms)
            for i in range(n_frames):
                acting = np.all(np.isfinite(targets[i]), axis=1)
                rows = rows_all[acting].reshape(-1, r)
                c = targets[i, acting].ravel()
                z = z0 + h * v0
                ok, last = False, np.inf
                for it in range(1, max_iterations + 1):
                    dz_ = z - z0
                    grad = (dz_ - h * v0) / h ** 2 + damping * dz_ / h - self.force(z)
                    step = solver.solve(acting, rows, -grad, c - rows @ z)
                    z = z + step
                    size = np.linalg.norm(step) / scale
                    iterations[i] = it
                    if size <= tolerance:
                        ok = True
                        break
                    if size > 0.25 * last:  # slow: a fresh tangent at the new iterate
                        solver = _KKT(inertia + self.tangent(z))
                    last = size
                self._frame_done(i, z, z0, v0, h, ok, acting, rows, c, q, converged, residual, recovered)
                if not recovered[i]:
                    v0 = (z - z0) / h
                else:
                    v0 = np.zeros(r)
                z0 = q[i]
                if progress is not None and (i % 200 == 0 or i == n_frames - 1):
                    report(progress, i + 1, n_frames, "integrating the domains (StVK)")
        return IntegrationResult(q, None, None, residual, converged, iterations, recovered)

    def integrate_fast(self, targets: np.ndarray, dt: float, alpha: float, beta: float, tolerance: float = 1e-6,
                       max_iterations: int = 20, linearised: bool = False, refresh: float = 0.5, carry: bool = True,
                       progress=None):
        """:meth:`integrate`'s backward Euler, made fast: returns (:class:`~tonguevis.sim.newmark.IntegrationResult`,
        energy (F,) J of each frame's shape).

        The same incremental potential, constraints, predictor (z₀ + h v₀), stopping rule and recovery as
        :meth:`integrate` (the reference), with:

        * the exact force over every tet by the compiled kernel (:meth:`force`, ``backend="warp"``);
        * ``carry``: before the first force call of a frame, a Newton step on the previous frame's last
          force carried to the predictor by the stiffness, f ≈ f_last − K (z − z_last): it costs no
          force and lands near the solution (1.6 forces a frame instead of 3.0 on the demo);
        * each Newton matrix's KKT solve as two precomputed dense operators per set of acting sensors
          (a step is two r × r products);
        * the tangent refreshed only when the step shrinks less than ``refresh``× per iteration (0.25 in
          :meth:`integrate`; at 0.5 the rest tangent serves a whole trial of the demo);
        * the frame's energy from the last force call, carried to the accepted shape to second order
          (E(z + s) ≈ E(z) − f·s + ½ sᵀK s, K the stiffness part of the Newton matrix; the last step is
          under the tolerance, so the energy is within 1e-5 of :meth:`energies`).

        tolerance : m, on the Newton step's nodal size (|Δz|/√mass) as in :meth:`integrate`; 1e-6 here (1e-7
        there).  Each frame then stops within about a step of that size of its solution; over a trial
        the shapes differ from :meth:`integrate`'s by the figures scripts/bench_domains.py prints
        (largest node difference 0.003 mm on the demo, 0.12 mm on the Opti-Speech /ta/ 009, RMS under
        0.005 mm; tests/sim/test_domains.py bounds it on a 12 mm raise).
        linearised : one force call a frame (after the carried step), whatever the step's size: one
        linearised backward-Euler step; ``converged`` then says only whether that step was below
        ``tolerance``, and the energies are measured afresh (its step is not small).  Its cost in
        accuracy is printed by scripts/bench_domains.py (tenths of a mm at most).
        """
        from tonguevis._blas import single_threaded_blas
        from tonguevis._progress import report
        from tonguevis.sim.newmark import IntegrationResult

        targets = np.asarray(targets, dtype=np.float64)
        n_frames, n_s, _ = targets.shape
        r, h = self.n_dofs, float(dt)
        rows_all = self.rows(self.sensor_nodes)  # (S, 3, r)
        damping = alpha + beta * self.eigenvalues
        inertia = np.diag(1.0 / h ** 2 + damping / h)
        scale = np.sqrt(self.solid.density * float(self.solid.volumes.sum()))  # √mass, as in integrate
        q = np.zeros((n_frames, r))
        energy = np.zeros(n_frames)
        residual = np.full((n_frames, n_s), np.nan)
        converged = np.zeros(n_frames, dtype=bool)
        iterations = np.zeros(n_frames, dtype=np.int64)
        recovered = np.zeros(n_frames, dtype=bool)
        z0, v0 = np.zeros(r), np.zeros(r)
        f_last = z_last = None
        stiffness = self.rest_tangent
        solver = _DenseKKT(inertia + stiffness)
        iterations_allowed = 1 if linearised else max_iterations
        with single_threaded_blas():
            for i in range(n_frames):
                acting = np.all(np.isfinite(targets[i]), axis=1)
                rows = rows_all[acting].reshape(-1, r)
                c = targets[i, acting].ravel()
                z = z0 + h * v0
                if carry and f_last is not None:  # a first Newton step on the last force, carried here by the
                    dz_ = z - z0                    # stiffness: no force call
                    grad = (dz_ - h * v0) / h ** 2 + damping * dz_ / h - (f_last - stiffness @ (z - z_last))
                    z = z + solver.solve(acting, rows, -grad, c - rows @ z)
                ok, last, e_z = False, np.inf, 0.0
                for it in range(1, iterations_allowed + 1):
                    dz_ = z - z0
                    f = self.force(z)
                    f_last, z_last = f, z
                    e_z = self.compiled.last_energy if self.cubature is None and self.backend == "warp" else None
                    grad = (dz_ - h * v0) / h ** 2 + damping * dz_ / h - f
                    step = solver.solve(acting, rows, -grad, c - rows @ z)
                    if e_z is not None:  # the energy at z + step, to second order
                        e_z = e_z - f @ step + 0.5 * step @ (stiffness @ step)
                    z = z + step
                    size = np.linalg.norm(step) / scale
                    iterations[i] = it
                    if size <= tolerance:
                        ok = True
                        break
                    if it < iterations_allowed and size > refresh * last:  # slow: a fresh tangent here
                        stiffness = self.tangent(z)
                        solver = _DenseKKT(inertia + stiffness)
                    last = size
                self._frame_done(i, z, z0, v0, h, ok, acting, rows, c, q, converged, residual, recovered)
                energy[i] = np.nan if (e_z is None or recovered[i] or linearised) else e_z
                v0 = np.zeros(r) if recovered[i] else (z - z0) / h
                if recovered[i]:
                    f_last = None
                z0 = q[i]
                if progress is not None and (i % 200 == 0 or i == n_frames - 1):
                    report(progress, i + 1, n_frames, "integrating the domains (StVK)")
        missing = ~np.isfinite(energy)
        if missing.any():  # the cubature's or NumPy's force, or recovered frames: measured afresh
            energy[missing] = self.energies(q[missing])
        return IntegrationResult(q, None, None, residual, converged, iterations, recovered), energy

    @staticmethod
    def _frame_done(i, z, z0, v0, h, ok, acting, rows, c, q, converged, residual, recovered):
        """Store frame i (a non-finite one keeps the previous shape and is flagged recovered)."""
        if not np.all(np.isfinite(z)):
            z, recovered[i] = z0.copy(), True
        q[i], converged[i] = z, ok and not recovered[i]
        if len(c):
            residual[i, acting] = np.linalg.norm((rows @ z - c).reshape(-1, 3), axis=1)

    def energies(self, z: np.ndarray, chunk: int = 64) -> np.ndarray:
        """(F,) StVK elastic energy (J) of every frame of z (F, r), vectorised over chunks of frames
        (compiled with ``backend="warp"``)."""
        z = np.atleast_2d(np.asarray(z, dtype=np.float64))
        if self.backend == "warp":
            return self.compiled.energies(z)
        out = np.empty(len(z))
        vol, mu, lam = self.solid.volumes, self.solid.mu, self.solid.lam
        for start in range(0, len(z), chunk):
            block = z[start:start + chunk]
            f_grad = (block @ self._df2.T).reshape(len(block), -1, 3, 3) + np.eye(3)
            e = 0.5 * (np.einsum("fkmi,fkmj->fkij", f_grad, f_grad) - np.eye(3))
            tr = np.trace(e, axis1=2, axis2=3)
            out[start:start + len(block)] = (mu * np.einsum("fkij,fkij->fk", e, e) + 0.5 * lam * tr ** 2) @ vol
        return out


class _KKT:
    """Solves [A Rᵀ; R 0][x; λ] = [b; d] for a fixed A (r, r) by a Cholesky factor of A (SPD: the inertia
    and damping terms keep it so) and the Schur complement R A⁻¹ Rᵀ of each set of acting sensors (kept)."""

    def __init__(self, a: np.ndarray):
        from scipy.linalg import cho_factor, cho_solve, lu_factor, lu_solve

        try:
            self.factor, self._solve = cho_factor(a), cho_solve
        except np.linalg.LinAlgError:  # a tangent softer than the inertia (buckling): LU instead
            self.factor, self._solve = lu_factor(a), lu_solve
        self._schur: dict[bytes, tuple] = {}

    def solve(self, acting: np.ndarray, rows: np.ndarray, b: np.ndarray, d: np.ndarray) -> np.ndarray:
        from scipy.linalg import lu_factor, lu_solve

        ab = self._solve(self.factor, b)
        if len(d) == 0:
            return ab
        key = np.asarray(acting).tobytes()
        if key not in self._schur:
            a_rt = self._solve(self.factor, rows.T)
            self._schur[key] = (a_rt, lu_factor(rows @ a_rt))
        a_rt, schur = self._schur[key]
        lam = lu_solve(schur, rows @ ab - d)
        return ab - a_rt @ lam


class _DenseKKT:
    """:class:`_KKT`'s solve as dense operators: for a fixed A (r, r) and each set of acting sensors (rows R),
    x = P b + Q d with P = A⁻¹ − A⁻¹Rᵀ S⁻¹ R A⁻¹, Q = A⁻¹Rᵀ S⁻¹, S = R A⁻¹ Rᵀ (built once per set: ~1 ms
    at r = 150; a solve is then two products, against ~0.2 ms of LAPACK calls)."""

    def __init__(self, a: np.ndarray):
        from scipy.linalg import cho_factor, cho_solve, lu_factor, lu_solve

        eye = np.eye(len(a))
        try:
            self.inverse = cho_solve(cho_factor(a), eye)
        except np.linalg.LinAlgError:  # a tangent softer than the inertia (buckling): LU instead
            self.inverse = lu_solve(lu_factor(a), eye)
        self._ops: dict[bytes, tuple] = {}

    def solve(self, acting: np.ndarray, rows: np.ndarray, b: np.ndarray, d: np.ndarray) -> np.ndarray:
        if len(d) == 0:
            return self.inverse @ b
        key = np.asarray(acting).tobytes()
        if key not in self._ops:
            a_rt = self.inverse @ rows.T
            q = np.linalg.solve(rows @ a_rt, a_rt.T).T  # A⁻¹Rᵀ S⁻¹ (S symmetric)
            self._ops[key] = (self.inverse - q @ (rows @ self.inverse), q)
        p, q = self._ops[key]
        return p @ b + q @ d


# ---------------------------------------------------------------------------------------- simulate(method="domains")
def domains_model(model, domain_model: DomainModel):
    """A shallow copy of ``model`` whose basis of r "modes" is the domain subspace B (eigenvalues Λ of its
    rest stiffness, no warping): every reconstruction, figure and view of a :class:`Motion` (u = B z) then
    works on a domains motion unchanged.  The mesh, material and FEM matrices are shared."""
    import copy

    from tonguevis.sim.modal import ModalBasis, free_dofs_for

    r = domain_model.n_dofs
    key = f"domains-{domain_model.domains.key}"
    basis = ModalBasis(domain_model.basis, domain_model.eigenvalues, free_dofs_for(model.mesh.n_nodes, model.anchors),
                       key, {"method": "domains", "seeds": domain_model.domains.seeds.tolist()})
    copied = copy.copy(model)
    copied._bases = {r: basis}
    copied._rotation_matrices = {key: np.zeros_like(domain_model.basis)}
    copied._transposed = {}
    copied.base_model = model
    copied.domain_model = domain_model
    return copied
