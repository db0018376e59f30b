"""Small meshes and plain reference implementations for the segmentation tests.

The references use no caching, no moments, no SVD of the frames and dense
solves, written straight from the paper's equations, so that the fast
library path can be checked against them.
"""

from __future__ import annotations

import numpy as np

from tonguevis.mesh.tetmesh import signed_tet_volumes
from tonguevis.sim.assembly import element_stiffness, shape_gradients

# Kuhn subdivision of a cube into six tets sharing the main diagonal (0 -> 7);
# corners numbered by bits (x, y, z) so neighbouring cubes conform.
_KUHN = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7], [0, 4, 6, 7]])


def bar_mesh(nx: int = 12, ny: int = 2, nz: int = 2, length: float = 0.12, width: float = 0.02,
             height: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """A structured tet bar along x: (n, 3) points in m and (k, 4) positive tets."""
    xs, ys, zs = np.linspace(0, length, nx + 1), np.linspace(0, width, ny + 1), np.linspace(0, height, nz + 1)
    grid = np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1).reshape(-1, 3)

    def node(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    i, j, k = i.ravel(), j.ravel(), k.ravel()
    corners = np.stack([node(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)) for c in range(8)], axis=1)
    tets = corners[:, _KUHN].reshape(-1, 4)
    negative = signed_tet_volumes(grid, tets) < 0
    tets[negative] = tets[negative][:, [0, 2, 1, 3]]
    return grid, tets


def bent_bar_displacement(points: np.ndarray, start: float, end: float, angle: float) -> np.ndarray:
    """Linearised bending of the bar's middle [start, end] (m) by ``angle`` (rad).

    Left of ``start`` nothing moves; on [start, end] the centreline curves
    (deflection w'' = angle / (end - start)); right of ``end`` the bar turns
    as a rigid body (an infinitesimal rotation), so both ends are exactly
    rigid and only the middle bends.
    """
    x, z = points[:, 0], points[:, 2]
    z0 = 0.5 * (z.min() + z.max())
    kappa = angle / (end - start)
    s = np.clip(x, start, end) - start
    slope = kappa * s
    w = 0.5 * kappa * s**2 + kappa * (end - start) * np.clip(x - end, 0, None)
    return np.stack([-(z - z0) * slope, np.zeros_like(x), w], axis=1)


def end_nodes(points: np.ndarray) -> np.ndarray:
    """Nodes on the two end faces (x = min and x = max) of a bar."""
    x = points[:, 0]
    return np.flatnonzero(np.isclose(x, x.min()) | np.isclose(x, x.max()))


def tet_containing_x(points: np.ndarray, tets: np.ndarray, x: float) -> int:
    """The tet whose centroid is nearest the bar's axis at abscissa ``x``."""
    c = points[tets].mean(axis=1)
    mid = 0.5 * (points.min(axis=0) + points.max(axis=0))
    return int(np.argmin((c[:, 0] - x) ** 2 + 0.1 * ((c[:, 1] - mid[1]) ** 2 + (c[:, 2] - mid[2]) ** 2)))


# ---------------------------------------------------------------------- references
def lumped_weights(points, tets, members):
    """dict node -> lumped volume over the tets ``members`` (plain loop)."""
    vol = np.abs(signed_tet_volumes(points, tets))
    weights: dict[int, float] = {}
    for e in members:
        for a in tets[e]:
            weights[int(a)] = weights.get(int(a), 0.0) + vol[e] / 4.0
    return weights


def reference_rigid_fit(points, tets, members, frames):
    """Eq. (9) with the explicit 3p x 6 rigid basis and a weighted dense lstsq; (nodes, (F, p, 3))."""
    weights = lumped_weights(points, tets, members)
    nodes = np.array(sorted(weights))
    w = np.array([weights[n] for n in nodes])
    basis = np.zeros((3 * len(nodes), 6))
    for row, n in enumerate(nodes):
        x = points[n]
        basis[3 * row:3 * row + 3, :3] = np.eye(3)
        basis[3 * row:3 * row + 3, 3:] = [[0, x[2], -x[1]], [-x[2], 0, x[0]], [x[1], -x[0], 0]]  # θ × x
    sw = np.repeat(np.sqrt(w), 3)
    fits = []
    for u in frames:
        y = u[nodes].ravel()
        coef, *_ = np.linalg.lstsq(basis * sw[:, None], y * sw, rcond=None)
        fits.append((basis @ coef).reshape(-1, 3))
    return nodes, np.array(fits)


def reference_constraint_fit(points, tets, members, frames, constrained=(), poisson=0.49):
    """Eq. (13) with a dense stiffness assembled element by element; (nodes, (F, p, 3))."""
    members = list(members)
    inside = set(members)
    nodes = sorted({int(a) for e in members for a in tets[e]})
    boundary = set(int(n) for n in constrained if n in set(nodes))
    for e in range(len(tets)):
        if e not in inside:
            boundary |= {int(a) for a in tets[e] if int(a) in set(nodes)}
    interior = [n for n in nodes if n not in boundary]
    boundary = sorted(boundary)
    index = {n: i for i, n in enumerate(nodes)}
    grads, vol = shape_gradients(points, tets[members])
    ke = element_stiffness(grads, vol, 1.0, poisson)
    k = np.zeros((3 * len(nodes), 3 * len(nodes)))
    for local, e in enumerate(members):
        dofs = [3 * index[int(a)] + i for a in tets[e] for i in range(3)]
        k[np.ix_(dofs, dofs)] += ke[local]
    dofs_i = [3 * index[n] + i for n in interior for i in range(3)]
    dofs_b = [3 * index[n] + i for n in boundary for i in range(3)]
    fits = []
    for u in frames:
        fit = u[nodes].copy()
        if dofs_i and dofs_b:
            ub = fit.ravel()[dofs_b]
            kii = k[np.ix_(dofs_i, dofs_i)]
            if len(boundary) < 3 or np.linalg.matrix_rank(points[boundary] - points[boundary].mean(0), tol=1e-12) < 2:
                ui = np.linalg.lstsq(kii, -k[np.ix_(dofs_i, dofs_b)] @ ub, rcond=1e-10)[0]
            else:
                ui = np.linalg.solve(kii, -k[np.ix_(dofs_i, dofs_b)] @ ub)
            flat = fit.ravel()
            flat[dofs_i] = ui
            fit = flat.reshape(-1, 3)
        elif dofs_i:
            fit[[index[n] for n in interior]] = 0.0
        fits.append(fit)
    return np.array(nodes), np.array(fits)


def reference_error(points, tets, members, frames, weights, fit_function):
    """Σ_f w_f Σ_i lumped_i |ũ_i − u_i|² over the partition (eq. 5 numerator, lumped norm)."""
    lumped = lumped_weights(points, tets, members)
    nodes, fits = fit_function(points, tets, members, frames)
    w = np.array([lumped[n] for n in nodes])
    total = 0.0
    for f, u in enumerate(frames):
        total += weights[f] * float(np.sum(w * np.sum((fits[f] - u[nodes]) ** 2, axis=1)))
    return total


def reference_one_ring(tets, members, labels):
    """Unassigned tets sharing a face (three nodes) with a tet of ``members`` (plain loops)."""
    faces = {}
    for e, tet in enumerate(tets):
        for skip in range(4):
            face = tuple(sorted(int(a) for i, a in enumerate(tet) if i != skip))
            faces.setdefault(face, []).append(e)
    ring = set()
    members = set(int(m) for m in members)
    for shared in faces.values():
        if len(shared) == 2:
            a, b = shared
            if a in members and labels[b] < 0:
                ring.add(b)
            if b in members and labels[a] < 0:
                ring.add(a)
    return sorted(ring)


def reference_greedy(points, tets, seeds, frames, weights, fit_function):
    """Algorithm 5.1 recomputing every candidate every round, no caching."""
    labels = -np.ones(len(tets), dtype=int)
    members = [[s] for s in seeds]
    for i, s in enumerate(seeds):
        labels[s] = i
    vol = np.abs(signed_tet_volumes(points, tets))
    while (labels < 0).any():
        best, best_error, best_ring = None, np.inf, None
        for i, m in enumerate(members):
            ring = reference_one_ring(tets, m, labels)
            if not ring:
                continue
            candidate = m + ring
            error = reference_error(points, tets, candidate, frames, weights, fit_function) / vol[candidate].sum()
            if error < best_error:
                best, best_error, best_ring = i, error, ring
        members[best] = members[best] + best_ring
        labels[best_ring] = best
    return labels


def box_model():
    """A 60 x 40 x 30 mm block 'tongue' (tip at +x) anchored on the back of its floor, with
    TT, TD, TL, TR on its top: small and fast enough to simulate a demo recording in a test."""
    from types import SimpleNamespace

    from tonguevis.mesh.tetmesh import TetMesh
    from tonguevis.sim.model import TongueModel

    points, tets = bar_mesh(6, 4, 3, length=0.06, width=0.04, height=0.03)

    def node(x, y, z):
        return int(np.argmin(np.linalg.norm(points - [x, y, z], axis=1)))

    sensors = {"TT": node(0.05, 0.02, 0.03), "TD": node(0.03, 0.02, 0.03),
               "TL": node(0.04, 0.03, 0.03), "TR": node(0.04, 0.01, 0.03)}
    anchors = np.flatnonzero((points[:, 2] < 1e-9) & (points[:, 0] < 0.025))
    return TongueModel(TetMesh(points, tets), SimpleNamespace(sensors=sensors, anchors=anchors))
