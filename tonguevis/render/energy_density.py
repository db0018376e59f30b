"""Elastic energy density of a displacement field, per tet and per node (no Qt).

Used to colour the tongue surface by where the deformation stores energy.
For a linear tetrahedron the strain is constant, ε = sym(∇u) with
∇u = Σ_a u_a ⊗ ∇N_a, and isotropic linear elasticity stores
ψ = μ ε:ε + ½ λ (tr ε)² joules per cubic metre.  Summed over tets with their
volumes this is ½ uᵀ K u, so for the modal (unwarped) displacement Φq it adds
up to the motion's energy U = ½ qᵀ Λ q (eq. 6): the colour and the energy
curve tell the same story.  For a motion, the strains are linear in q: with the
strain operator B, every frame's strains are one dense product q (BΦ)ᵀ
(:meth:`EnergyDensity.strain_operator`), proven equal to the direct
per-element formula (:meth:`EnergyDensity.element`) in the tests.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from tonguevis.sim.assembly import lame, shape_gradients


class EnergyDensity:
    """Energy density of displacement fields on one mesh.

    points : (n, 3) rest node positions, metres; tets : (k, 4) node indices.
    young : Young's modulus in Pa; poisson : Poisson's ratio.
    """

    def __init__(self, points: np.ndarray, tets: np.ndarray, young: float, poisson: float):
        self.tets = np.asarray(tets, dtype=np.int64)
        grads, volumes = shape_gradients(np.asarray(points, dtype=np.float64), self.tets)
        self.grads = grads  # (k, 4, 3) 1/m
        self.volumes = np.abs(volumes)  # (k,) m³
        self.lam, self.mu = lame(young, poisson)
        n, k = len(points), len(self.tets)
        # Nodal value = volume-weighted mean over the tets around the node.
        rows = self.tets.ravel()
        cols = np.repeat(np.arange(k), 4)
        weights = np.repeat(self.volumes, 4)
        incidence = sp.csr_matrix((weights, (rows, cols)), shape=(n, k))
        total = np.asarray(incidence.sum(axis=1)).ravel()
        total[total == 0] = 1.0  # nodes in no tet get 0
        self.node_average = sp.diags(1.0 / total) @ incidence  # (n, k)

    def strain_operator(self) -> sp.csr_matrix:
        """B (6k, 3n): the strains (ε_xx, ε_yy, ε_zz, ε_yz, ε_xz, ε_xy per tet, tensor shear)
        of a node-major displacement vector.  B Φ gives every mode's strains, so the
        strains of all frames are one dense product q (BΦ)ᵀ."""
        k = len(self.tets)
        g = self.grads  # (k, 4, 3)
        dof = 3 * self.tets[:, :, None] + np.arange(3)  # (k, 4, 3): dof of node a, direction i
        rows, cols, vals = [], [], []
        for c, (i, j) in enumerate(((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))):
            row = np.repeat(6 * np.arange(k) + c, 4)
            if i == j:
                rows.append(row); cols.append(dof[:, :, i].ravel()); vals.append(g[:, :, j].ravel())
            else:  # ε_ij = ½ (∂u_i/∂x_j + ∂u_j/∂x_i)
                rows += [row, row]
                cols += [dof[:, :, i].ravel(), dof[:, :, j].ravel()]
                vals += [0.5 * g[:, :, j].ravel(), 0.5 * g[:, :, i].ravel()]
        n_dofs = 3 * self.node_average.shape[0]
        return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                             shape=(6 * k, n_dofs))

    def from_strains(self, strains: np.ndarray) -> np.ndarray:
        """(..., k) energy density in J/m³ from (..., 6k) strains in the order of :meth:`strain_operator`."""
        e = np.asarray(strains).reshape(strains.shape[:-1] + (-1, 6))
        normal, shear = e[..., :3], e[..., 3:]
        trace = normal.sum(axis=-1)
        return (self.mu * (np.einsum("...c,...c->...", normal, normal) + 2 * np.einsum("...c,...c->...", shear, shear))
                + 0.5 * self.lam * trace**2)

    def to_nodes(self, per_element: np.ndarray) -> np.ndarray:
        """(..., n) volume-weighted node averages of (..., k) element values."""
        flat = per_element.reshape(-1, per_element.shape[-1])
        out = (self.node_average @ flat.T).T
        return out.reshape(per_element.shape[:-1] + (self.node_average.shape[0],))

    def element(self, u: np.ndarray) -> np.ndarray:
        """(..., k) energy density in J/m³ of displacements ``u`` (..., n, 3) metres."""
        ue = np.asarray(u)[..., self.tets, :]  # (..., k, 4, 3)
        grad_u = np.einsum("...kai,kaj->...kij", ue, self.grads)  # ∂u_i/∂x_j
        strain = 0.5 * (grad_u + np.swapaxes(grad_u, -1, -2))
        trace = np.trace(strain, axis1=-2, axis2=-1)
        return self.mu * np.einsum("...ij,...ij->...", strain, strain) + 0.5 * self.lam * trace**2

    def total(self, u: np.ndarray) -> np.ndarray:
        """(...) total elastic energy in joules (Σ ψ_e V_e = ½ uᵀKu)."""
        return self.element(u) @ self.volumes

    def nodal(self, u: np.ndarray) -> np.ndarray:
        """(..., n) energy density averaged onto nodes (volume-weighted), J/m³."""
        return self.to_nodes(self.element(u))
