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
over every tet of the mesh (no cubature: the error of a cubature need not be stated
because there is none, and the speed is what that costs), solved by Newton with the
sensor constraints as hard multipliers on the targets :func:`tonguevis.sim.simulate.drive_schedule`
makes (the compliant projection, with the domain model's own linear stiffness, and the
dropout handover; the same constraints as the modal methods').  Newton keeps the tangent of
the previous iteration or frame while the force residual falls fast (modified Newton) and
refreshes it otherwise.

Units SI: z and the domain DOFs in m, forces in N, stiffness in N/m.
"""

from __future__ import annotations

import hashlib
import logging
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

logger = logging.getLogger("tonguevis")

DOFS_PER_DOMAIN = 30
#: Length (m) the quadratic terms are measured in: y = (x - seed) / L; about a third of the tongue.
LENGTH_SCALE = 0.03
CACHE_VERSION = 1
#: Columns of the blended basis whose mass is below this share of the largest are dropped (dependent).
DEPENDENCE = 1e-10


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


def load_weights(path: Path, key: str) -> DomainWeights | None:
    """The cached domains, or None if absent, stale or unreadable (then they are computed again)."""
    path = Path(path)
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            if int(data["version"]) != CACHE_VERSION or str(data["key"]) != key:
                return None
            return DomainWeights(np.array(data["seeds"]), np.array(data["weights"]), np.array(data["directions"]),
                                 np.array(data["partition"]), key, {"loaded_from": str(path)})
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        logger.warning("ignoring unreadable domain cache %s (%s): the weights are computed again", path, exc)
        return None


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

    basis : (3n, r) B, mass-orthonormal (BᵀMB = I), r ≤ 30 d (dependent columns dropped);
    domain_dofs : (30d, r) q = domain_dofs @ z gives the paper's 30 DOFs per domain from z;
    solid : the full-mesh :class:`~tonguevis.sim.stvk.StVK` of the model's mesh and material.
    """

    def __init__(self, model, sensor_nodes, cache: bool = True, young: float | None = None,
                 poisson: float | None = None):
        self.model = model
        self.domains = domain_weights(model, sensor_nodes, cache=cache)
        mat = model.material
        self.solid = StVK(model.mesh.points, model.mesh.tets, mat.young if young is None else young,
                          mat.poisson if poisson is None else poisson, mat.density)
        pts = model.mesh.points
        g = np.hstack([domain_columns(pts, pts[s], self.domains.weights[:, j])
                       for j, s in enumerate(self.domains.seeds)])
        mass = model.mass
        gram = g.T @ (mass @ g)
        vals, vecs = np.linalg.eigh(gram)
        keep = vals > DEPENDENCE * vals.max()
        self.domain_dofs = vecs[:, keep] / np.sqrt(vals[keep])
        self.basis = g @ self.domain_dofs
        self.rest_tangent = self.basis.T @ (model.stiffness @ self.basis)  # BᵀK₀B, N/m per unit z
        self.sensor_nodes = np.asarray(sensor_nodes, dtype=np.int64)
        self._tet_dofs = (3 * model.mesh.tets[:, :, None] + np.arange(3)).reshape(-1, 12)
        # dF/dz per tet: F_ij = δ_ij + Σ_a u_ai g_aj with u = B z, so (k, 9, r) constant
        b_tet = self.basis[self._tet_dofs].reshape(len(model.mesh.tets), 4, 3, -1)  # (k, 4, 3, r)
        self._df = np.einsum("kair,kaj->kijr", b_tet, self.solid.grads).reshape(len(b_tet), 9, -1)
        self._df2 = np.ascontiguousarray(self._df.reshape(-1, self._df.shape[-1]))  # (9k, r)

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

    def force(self, z: np.ndarray) -> np.ndarray:
        """(r,) reduced internal force Bᵀ f_int(Bz), N (Eq. 8 over every tet)."""
        _, _, p = self.solid.stresses(self._deformation(z))
        return -(self.solid.volumes[:, None] * p.reshape(-1, 9)).ravel() @ self._df2

    def tangent(self, z: np.ndarray) -> np.ndarray:
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
