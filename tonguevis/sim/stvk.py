"""A plain full-mesh St. Venant-Kirchhoff reference on linear tetrahedra (seed 001 §6's material).

The reference every reduced model is checked against (issue 26): no subspace, no
cubature, every tet of the mesh, the exact tangent.  Per tet the displacement
gradient is constant, F = I + Σ_a u_a ⊗ ∇N_a; the Green strain E = ½(FᵀF − I), the
second Piola-Kirchhoff stress S = λ tr(E) I + 2μ E, the first P = F S, the energy
density Ψ = μ E:E + λ/2 tr²(E) (seed 001, §6).  The internal force on node a of tet e
is f_a = −V_e P ∇N_a (N, the negative gradient of the elastic energy), and the
tangent stiffness K = −∂f/∂u is, per tet (indices a, b nodes; i, k axes),

    K_e[a i, b k] = V (δ_ik ∇N_a·S∇N_b + λ (F∇N_a)_i (F∇N_b)_k
                       + μ (∇N_a·∇N_b)(FFᵀ)_ik + μ (F∇N_b)_i (F∇N_a)_k),

which at u = 0 (F = I, S = 0) is the linear elasticity of
:func:`tonguevis.sim.assembly.element_stiffness` (a test checks both, and the tangent
against finite differences of the force).

Material: Young's modulus and Poisson's ratio are arguments; :meth:`StVK.from_model`
takes the model's :class:`~tonguevis.sim.material.Material` (whose defaults are the
papers' E = 6,912 Pa, ν = 0.49, ρ = 1,000 kg/m³).  Units SI throughout: points and
displacements (n, 3) in m, forces (n, 3) in N, stiffness (3n, 3n) in N/m, node-major
DOFs ``3 * node + axis`` as everywhere in tonguevis.

Solvers: :func:`solve_static` (Newton with load stepping and a backtracking line
search on the energy, prescribed displacements, fixed nodes, nodal loads) and
:func:`dynamic_step` (one backward-Euler step, seed 001's Eq. 11 integrator, solved by
Newton to convergence, with Rayleigh damping C = αM + βK₀ on the rest stiffness).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from tonguevis.errors import SimulationError
from tonguevis.sim.assembly import assemble_mass, lame, scatter, shape_gradients


#: Newton stops below this free-DOF residual (N) whatever the relative tolerance (round-off of the forces).
ABS_TOL = 1e-13


class StVK:
    """St. Venant-Kirchhoff elasticity of a linear-tet mesh.

    points : (n, 3) rest positions, m; tets : (k, 4) node ids (any orientation);
    young : Pa; poisson : dimensionless; density : kg/m³.
    """

    def __init__(self, points: np.ndarray, tets: np.ndarray, young: float = 6912.0, poisson: float = 0.49,
                 density: float = 1000.0):
        self.points = np.asarray(points, dtype=np.float64)
        self.tets = np.asarray(tets, dtype=np.int64)
        self.young, self.poisson, self.density = float(young), float(poisson), float(density)
        self.lam, self.mu = lame(self.young, self.poisson)
        grads, vol = shape_gradients(self.points, self.tets)
        self.grads = grads  # (k, 4, 3) 1/m
        self.volumes = np.abs(vol)  # (k,) m³
        if np.any(self.volumes <= 0):
            raise SimulationError(f"{int(np.sum(self.volumes <= 0))} tets of the mesh have no volume")

    @classmethod
    def from_model(cls, model) -> "StVK":
        """The StVK solid of a :class:`~tonguevis.sim.model.TongueModel` (its mesh and its material's E, ν, ρ)."""
        m = model.material
        return cls(model.mesh.points, model.mesh.tets, m.young, m.poisson, m.density)

    @property
    def n_nodes(self) -> int:
        return len(self.points)

    # ------------------------------------------------------------------ kinematics and stress
    def deformation_gradient(self, u: np.ndarray) -> np.ndarray:
        """(k, 3, 3) F = I + ∇u per tet for displacements ``u`` (n, 3) m."""
        u = np.asarray(u, dtype=np.float64).reshape(-1, 3)
        return np.eye(3) + np.einsum("kai,kaj->kij", u[self.tets], self.grads)

    def stresses(self, f_grad: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Green strain E, second and first Piola-Kirchhoff stresses S and P = F S (each (k, 3, 3), Pa) of F (k, 3, 3)."""
        e = 0.5 * (np.einsum("kmi,kmj->kij", f_grad, f_grad) - np.eye(3))
        tr = np.trace(e, axis1=1, axis2=2)
        s = self.lam * tr[:, None, None] * np.eye(3) + 2.0 * self.mu * e
        return e, s, f_grad @ s

    def energy(self, u: np.ndarray) -> float:
        """Elastic energy Σ V Ψ, J."""
        e, _, _ = self.stresses(self.deformation_gradient(u))
        tr = np.trace(e, axis1=1, axis2=2)
        psi = self.mu * np.einsum("kij,kij->k", e, e) + 0.5 * self.lam * tr ** 2
        return float(self.volumes @ psi)

    def internal_force(self, u: np.ndarray) -> np.ndarray:
        """(n, 3) internal force, N: −∂(energy)/∂u, per tet −V P ∇N_a summed at the nodes."""
        _, _, p = self.stresses(self.deformation_gradient(u))
        fe = -self.volumes[:, None, None] * np.einsum("kij,kaj->kai", p, self.grads)  # (k, 4, 3)
        out = np.zeros((self.n_nodes, 3))
        np.add.at(out, self.tets, fe)
        return out

    def element_tangents(self, u: np.ndarray) -> np.ndarray:
        """(k, 12, 12) element tangent stiffness matrices −∂f_e/∂u_e, N/m (see the module docstring)."""
        f_grad = self.deformation_gradient(u)
        _, s, _ = self.stresses(f_grad)
        g = self.grads
        fg = np.einsum("kij,kaj->kai", f_grad, g)  # (k, 4, 3): F ∇N_a
        gsg = np.einsum("kai,kij,kbj->kab", g, s, g)
        gg = np.einsum("kai,kbi->kab", g, g)
        ff = np.einsum("kim,kjm->kij", f_grad, f_grad)  # F Fᵀ
        eye = np.eye(3)
        ke = (gsg[:, :, None, :, None] * eye[None, None, :, None, :]
              + self.lam * np.einsum("kai,kbj->kaibj", fg, fg)
              + self.mu * gg[:, :, None, :, None] * ff[:, None, :, None, :]
              + self.mu * np.einsum("kbi,kaj->kaibj", fg, fg))
        return (self.volumes[:, None, None, None, None] * ke).reshape(-1, 12, 12)

    def tangent(self, u: np.ndarray) -> sp.csr_matrix:
        """(3n, 3n) tangent stiffness K(u) = −∂f/∂u, N/m, sparse."""
        return scatter(self.element_tangents(u), self.tets, self.n_nodes)

    def mass(self) -> sp.csr_matrix:
        """(3n, 3n) consistent mass, kg."""
        return assemble_mass(self.points, self.tets, self.density)


@dataclass
class StaticResult:
    """u (n, 3) m; converged; iterations (Newton, over all load steps); residual: largest free-DOF force, N;
    reaction (n, 3) N: the force the supports and prescribed nodes exert (zero on free nodes)."""

    u: np.ndarray
    converged: bool
    iterations: int
    residual: float
    reaction: np.ndarray = field(repr=False, default=None)


def _dofs(nodes: np.ndarray) -> np.ndarray:
    return (3 * np.asarray(nodes, dtype=np.int64)[:, None] + np.arange(3)).ravel()


def _constrained(n_nodes: int, fixed, prescribed_nodes, fixed_dofs) -> np.ndarray:
    """Boolean (3n,) mask of the DOFs whose displacement is given."""
    mask = np.zeros(3 * n_nodes, dtype=bool)
    for nodes in (fixed, prescribed_nodes):
        if nodes is not None and len(nodes):
            mask[_dofs(nodes)] = True
    if fixed_dofs is not None and len(fixed_dofs):
        mask[np.asarray(fixed_dofs, dtype=np.int64)] = True
    return mask


def _newton(solid: StVK, u: np.ndarray, free: np.ndarray, extra_force, extra_tangent, tol: float, max_iter: int,
            merit) -> tuple[np.ndarray, bool, int, float]:
    """Newton on the free DOFs of r(u) = f_int(u) + extra_force(u) = 0 with a backtracking line search on
    ``merit`` (the total potential); returns (u flat, converged, iterations, largest free residual N)."""
    scale = None
    for it in range(1, max_iter + 1):
        r = solid.internal_force(u).ravel() + extra_force(u)
        res = np.abs(r[free]).max() if free.any() else 0.0
        if scale is None:
            scale = max(res, 1e-30)
        if res <= max(tol * scale, ABS_TOL):
            return u, True, it - 1, res
        k = solid.tangent(u) + extra_tangent
        kff = k[free][:, free].tocsc()
        try:
            du = spla.splu(kff).solve(r[free])
        except RuntimeError:  # singular tangent (e.g. a buckled state): a least-squares step
            du = spla.lsqr(kff, r[free])[0]
        step = np.zeros_like(u)
        step[free] = du
        m0, t = merit(u), 1.0
        while t > 1e-6 and not merit(u + t * step) <= m0 + 1e-12 * abs(m0):
            t *= 0.5
        u = u + t * step
    r = solid.internal_force(u).ravel() + extra_force(u)
    res = np.abs(r[free]).max() if free.any() else 0.0
    return u, bool(res <= max(tol * (scale or 0.0), ABS_TOL)), max_iter, res


def solve_static(solid: StVK, fixed=None, prescribed: dict | tuple | None = None, loads: np.ndarray | None = None,
                 fixed_dofs=None, steps: int = 1, tol: float = 1e-9, max_iter: int = 50,
                 u0: np.ndarray | None = None) -> StaticResult:
    """Static equilibrium f_int(u) + f_ext = 0 by Newton with load stepping.

    fixed : node ids held at rest; fixed_dofs : single DOF ids (3·node + axis) held where
    ``u0`` puts them (at rest by default: rollers; a non-zero u0 there prescribes them); prescribed : (nodes (p,), displacements (p, 3) m), reached in ``steps``
    equal increments together with the loads; loads : (n, 3) N external nodal forces.
    tol : Newton stops when the largest free-DOF residual is below tol × the first
    residual of the step (relative), N.  Each Newton step is a sparse LU solve of the free
    block of the tangent; a backtracking line search keeps the total potential from rising.
    """
    n = solid.n_nodes
    p_nodes, p_disp = (np.zeros(0, dtype=np.int64), np.zeros((0, 3))) if prescribed is None else (
        np.asarray(prescribed[0], dtype=np.int64), np.asarray(prescribed[1], dtype=np.float64).reshape(-1, 3))
    given = _constrained(n, fixed, p_nodes, fixed_dofs)
    free = ~given
    loads = np.zeros((n, 3)) if loads is None else np.asarray(loads, dtype=np.float64).reshape(n, 3)
    u = np.zeros(3 * n) if u0 is None else np.asarray(u0, dtype=np.float64).ravel().copy()
    total_it, ok, res = 0, True, 0.0
    for step in range(1, steps + 1):
        frac = step / steps
        if len(p_nodes):
            u[_dofs(p_nodes)] = frac * p_disp.ravel()
        f_ext = frac * loads.ravel()
        u, ok, it, res = _newton(solid, u, free, lambda _u, f=f_ext: f, 0.0 * sp.eye(3 * n, format="csr"),
                                 tol, max_iter, lambda v, f=f_ext: solid.energy(v) - f @ v)
        total_it += it
        if not ok:
            break
    reaction = -(solid.internal_force(u).ravel() + loads.ravel())
    reaction[free] = 0.0
    return StaticResult(u.reshape(n, 3), ok, total_it, float(res), reaction.reshape(n, 3))


@dataclass
class DynamicState:
    """u, v (n, 3): displacement (m) and velocity (m/s)."""

    u: np.ndarray
    v: np.ndarray


class Dynamics:
    """Backward-Euler time stepping of the full StVK mesh (the reference of seed 001's Eq. 11).

    Per step h: M (v₁ − v₀)/h = f_int(u₁) − C v₁ + f_ext, u₁ = u₀ + h v₁, solved for
    Δu = u₁ − u₀ by Newton (Jacobian M/h² + C/h + K(u₁)); prescribed nodes take their
    given displacement at the end of the step, fixed nodes stay at rest.  Rayleigh
    damping C = α M + β K₀ (K₀ the rest stiffness), α in 1/s, β in s.
    """

    def __init__(self, solid: StVK, dt: float, alpha: float = 0.0, beta: float = 0.0, fixed=None):
        self.solid, self.dt = solid, float(dt)
        self.m = solid.mass()
        self.c = alpha * self.m + beta * solid.tangent(np.zeros((solid.n_nodes, 3)))
        self.fixed = np.zeros(0, dtype=np.int64) if fixed is None else np.asarray(fixed, dtype=np.int64)

    def step(self, state: DynamicState, prescribed: tuple | None = None, loads: np.ndarray | None = None,
             tol: float = 1e-9, max_iter: int = 30) -> tuple[DynamicState, bool]:
        """One step from ``state``; prescribed : (nodes, displacements (p, 3) m at the end of the step);
        loads (n, 3) N.  Returns (new state, converged)."""
        solid, h, n = self.solid, self.dt, self.solid.n_nodes
        p_nodes = np.zeros(0, dtype=np.int64) if prescribed is None else np.asarray(prescribed[0], dtype=np.int64)
        free = ~_constrained(n, self.fixed, p_nodes, None)
        u0, v0 = state.u.ravel(), state.v.ravel()
        f_ext = np.zeros(3 * n) if loads is None else np.asarray(loads, dtype=np.float64).ravel()
        u = u0 + h * v0  # explicit predictor
        u[~free] = u0[~free]
        if len(p_nodes):
            u[_dofs(p_nodes)] = np.asarray(prescribed[1], dtype=np.float64).ravel()
        m, c = self.m, self.c

        # r(u) = f_int(u) + extra(u) with extra = f_ext − M(Δu/h − v₀)/h − C Δu/h: the negative gradient of
        # the incremental potential W(u) + ½|Δu − h v₀|²_M/h² + ½ Δuᵀ C Δu/h − f_extᵀu.
        def extra(v):
            du = v - u0
            return f_ext - m @ (du / h - v0) / h - c @ du / h

        def merit(v):
            du = v - u0
            w = du - h * v0
            return solid.energy(v) + 0.5 * w @ (m @ w) / h ** 2 + 0.5 * du @ (c @ du) / h - f_ext @ v

        u, ok, _, _ = _newton(solid, u, free, extra, (m / h ** 2 + c / h).tocsr(), tol, max_iter, merit)
        v = (u - u0) / h
        return DynamicState(u.reshape(n, 3), v.reshape(n, 3)), ok
