"""Final fits of a labelled mesh: approximation, element, partition and global errors.

Rigid fits do not agree at interfaces, so the approximation is stored on a
*split* mesh: every partition has its own copy of its nodes (``split_nodes``
names the mesh node of each copy, ``split_tets`` indexes the copies).  For
constraint modes the copies of an interface node carry the same value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tonguevis.analysis.segmentation.fitter import LocalFitter


@dataclass
class Evaluation:
    """Arrays of :class:`SegmentationResult` computed from labels (see there)."""

    approximation: np.ndarray
    split_nodes: np.ndarray
    split_partition: np.ndarray
    split_tets: np.ndarray
    element_errors: np.ndarray
    partition_errors: np.ndarray
    global_error: float
    relative_error: float


def target_norm(fitter: LocalFitter) -> float:
    """Σ_f w_f ‖u_f‖² over the whole mesh (lumped), m²·m³: e_G of the zero approximation × V."""
    lumped = np.bincount(fitter.tets.ravel(), weights=np.repeat(fitter.tet_volumes / 4.0, 4),
                         minlength=len(fitter.points))
    u = fitter.target.displacements
    return float(np.einsum("f,fni,fni,n->", fitter.target.weights, u, u, lumped))


def evaluate(fitter: LocalFitter, labels: np.ndarray) -> Evaluation:
    """Fit every partition to every target frame and measure the errors (eqs. 14, 4/5, 15)."""
    target = fitter.target
    u = target.displacements
    weights = target.weights
    n_partitions = int(labels.max()) + 1
    tets = fitter.tets
    split_tets = np.empty_like(tets)
    element_errors = np.zeros(len(tets))
    pieces, split_nodes, split_partition = [], [], []
    offset = 0
    for p in range(n_partitions):
        members = np.flatnonzero(labels == p)
        nodes, fit = fitter.approximate(members, u)
        local = np.searchsorted(nodes, tets[members])
        split_tets[members] = local + offset
        diff = fit[:, local, :] - u[:, tets[members], :]  # (F, m, 4, 3)
        element_errors[members] = np.einsum("f,fmai,fmai->m", weights, diff, diff) / 4.0
        pieces.append(fit)
        split_nodes.append(nodes)
        split_partition.append(np.full(len(nodes), p, dtype=np.int64))
        offset += len(nodes)
    volumes = fitter.tet_volumes
    weighted = volumes * element_errors
    partition_volume = np.bincount(labels, weights=volumes, minlength=n_partitions)
    partition_errors = np.bincount(labels, weights=weighted, minlength=n_partitions) / partition_volume
    total = float(weighted.sum())
    norm = target_norm(fitter)
    return Evaluation(
        approximation=np.concatenate(pieces, axis=1),
        split_nodes=np.concatenate(split_nodes),
        split_partition=np.concatenate(split_partition),
        split_tets=split_tets,
        element_errors=element_errors,
        partition_errors=partition_errors,
        global_error=total / float(volumes.sum()),
        relative_error=total / norm if norm > 0 else 0.0,
    )
