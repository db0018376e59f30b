"""The nodal curl operator of modal warping (Choi & Ko 2005).

In a linear tet the displacement gradient is constant, so each element has an
infinitesimal rotation w_e = ½ curl u = ½ Σ_a ∇N_a × u_a.  Averaging w_e over
the elements around a node, weighted by element volume, gives the node's
rotation vector.  The whole map u -> w is one sparse (3n, 3n) matrix.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from tonguevis.sim.assembly import shape_gradients


def _cross_matrices(g: np.ndarray) -> np.ndarray:
    """(..., 3, 3) matrices [g]× with [g]× v = g × v."""
    z = np.zeros(g.shape[:-1])
    gx, gy, gz = g[..., 0], g[..., 1], g[..., 2]
    return np.stack(
        [np.stack([z, -gz, gy], -1), np.stack([gz, z, -gx], -1), np.stack([-gy, gx, z], -1)], -2
    )


def element_curl_blocks(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k, 4, 3, 3) blocks B with w_e = Σ_a B[e, a] u_a, and (k,) |volumes| (m³)."""
    grads, vol = shape_gradients(points, tets)
    return 0.5 * _cross_matrices(grads), np.abs(vol)


def nodal_curl_operator(points: np.ndarray, tets: np.ndarray) -> sp.csr_matrix:
    """Sparse C (3n, 3n): nodal rotation vectors w = C u (node-major DOFs).

    w_i = Σ_{e∋i} V_e w_e / Σ_{e∋i} V_e.  Nodes in no element get w = 0.
    """
    n = len(points)
    blocks, vol = element_curl_blocks(points, tets)
    node_weight = np.bincount(tets.ravel(), weights=np.repeat(vol, 4), minlength=n)
    node_weight[node_weight == 0] = 1.0
    k = len(tets)
    # Entry (node i of tet e, axis r) <- (node b of tet e, axis c): V_e B[e, b, r, c] / W_i.
    i_node = np.broadcast_to(tets[:, :, None, None, None], (k, 4, 4, 3, 3))
    b_node = np.broadcast_to(tets[:, None, :, None, None], (k, 4, 4, 3, 3))
    r = np.broadcast_to(np.arange(3)[None, None, None, :, None], (k, 4, 4, 3, 3))
    c = np.broadcast_to(np.arange(3)[None, None, None, None, :], (k, 4, 4, 3, 3))
    vals = vol[:, None, None, None, None] * np.broadcast_to(blocks[:, None], (k, 4, 4, 3, 3))
    vals = vals / node_weight[i_node]
    rows = (3 * i_node + r).ravel()
    cols = (3 * b_node + c).ravel()
    return sp.coo_matrix((vals.ravel(), (rows, cols)), shape=(3 * n, 3 * n)).tocsr()
