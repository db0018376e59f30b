"""Vectorised assembly of linear-tetrahedron stiffness and mass matrices.

DOF ordering everywhere in tonguevis: node-major, ``3 * node + axis``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def shape_gradients(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of the four linear shape functions of every tet.

    Returns ``grads`` (k, 4, 3) in 1/m, ``grads[e, a]`` = ∇N_a, and the
    (k,) signed volumes in m³.
    """
    p = points[tets]  # (k, 4, 3)
    edges = p[:, 1:, :] - p[:, :1, :]  # (k, 3, 3) rows = x_a - x_0
    det = np.linalg.det(edges)
    inv = np.linalg.inv(edges)  # columns of inv are ∇N_1..∇N_3
    g123 = np.transpose(inv, (0, 2, 1))  # (k, 3, 3): row a-1 = ∇N_a
    g0 = -g123.sum(axis=1, keepdims=True)
    return np.concatenate([g0, g123], axis=1), det / 6.0


def lame(young: float, poisson: float) -> tuple[float, float]:
    """Lamé parameters (λ, μ) in Pa."""
    lam = young * poisson / ((1 + poisson) * (1 - 2 * poisson))
    mu = young / (2 * (1 + poisson))
    return lam, mu


def element_stiffness(grads: np.ndarray, volumes: np.ndarray, young: float, poisson: float) -> np.ndarray:
    """(k, 12, 12) element stiffness matrices of isotropic linear elasticity.

    K_e[3a+i, 3b+j] = V (λ g_a,i g_b,j + μ g_a,j g_b,i + μ δ_ij g_a·g_b).
    """
    lam, mu = lame(young, poisson)
    v = np.abs(volumes)[:, None, None, None, None]
    gg = np.einsum("kai,kbj->kaibj", grads, grads)  # g_a,i g_b,j
    dot = np.einsum("kai,kbi->kab", grads, grads)
    ke = lam * gg + mu * np.transpose(gg, (0, 1, 4, 3, 2))
    ke = ke + mu * dot[:, :, None, :, None] * np.eye(3)[None, None, :, None, :]
    return (v * ke).reshape(-1, 12, 12)


def element_dofs(tets: np.ndarray) -> np.ndarray:
    """(k, 12) global DOF indices of every tet (node-major)."""
    return (3 * tets[:, :, None] + np.arange(3)[None, None, :]).reshape(-1, 12)


def scatter(elements: np.ndarray, tets: np.ndarray, n_nodes: int) -> sp.csr_matrix:
    """Sum (k, 12, 12) element matrices into a (3n, 3n) CSR matrix."""
    dofs = element_dofs(tets)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    n = 3 * n_nodes
    return sp.coo_matrix((elements.ravel(), (rows, cols)), shape=(n, n)).tocsr()


def assemble_stiffness(points: np.ndarray, tets: np.ndarray, young: float, poisson: float) -> sp.csr_matrix:
    """Global stiffness K (3n, 3n) in N/m."""
    grads, vol = shape_gradients(points, tets)
    return scatter(element_stiffness(grads, vol, young, poisson), tets, len(points))


def element_mass(volumes: np.ndarray, density: float) -> np.ndarray:
    """(k, 12, 12) consistent mass matrices: ρV/20 (1 + δ_ab) δ_ij."""
    m4 = (np.ones((4, 4)) + np.eye(4)) / 20.0
    block = np.kron(m4, np.eye(3))
    return density * np.abs(volumes)[:, None, None] * block[None]


def assemble_mass(points: np.ndarray, tets: np.ndarray, density: float) -> sp.csr_matrix:
    """Global consistent mass M (3n, 3n) in kg."""
    _, vol = shape_gradients(points, tets)
    return scatter(element_mass(vol, density), tets, len(points))
