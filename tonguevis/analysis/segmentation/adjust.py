"""Post-segmentation adjustment (§5.3, Fig. 10): move interface tets while e_G falls.

For a tet on an interface, ``e'_G`` is computed as if it belonged to the
neighbouring partition; the move is kept only if ``e'_G < e_G``, so the global
error never rises.  Moving a tet changes only its two partitions (every other
partition keeps its tets, hence its boundary and its fit), so ``e'_G`` needs two
fits, both memoised.  Moves that would empty or split a partition, or move a
seed, are not tried.  Candidates are tried by decreasing element error, where
a gain is likeliest; ``max_evaluations`` bounds the work (constraint fits cost
a sparse factorisation each).
"""

from __future__ import annotations

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.analysis.segmentation.fitter import LocalFitter

RELATIVE_GAIN = 1e-10  # a move must lower e_G by more than this share (no churn on round-off)


def adjust_boundaries(fitter: LocalFitter, labels: np.ndarray, seeds: np.ndarray, element_errors: np.ndarray,
                      max_evaluations: int | None = None, max_passes: int = 20,
                      progress: ProgressCallback | None = None) -> tuple[np.ndarray, list[float]]:
    """Improve ``labels`` by single-tet moves; return new labels and the e_G·V trace.

    The trace starts with the error before adjustment and has one entry per
    accepted move (squared-norm units, m²·m³; divide by the mesh volume for e_G).
    """
    graph = fitter.graph
    labels = np.array(labels, dtype=np.int64, copy=True)
    n_partitions = int(labels.max()) + 1
    members = [np.flatnonzero(labels == p) for p in range(n_partitions)]
    errors = [fitter.error(m) for m in members]
    total = float(sum(errors))
    trace = [total]
    is_seed = np.zeros(len(labels), dtype=bool)
    is_seed[np.asarray(seeds, dtype=np.int64)] = True
    evaluations = 0
    budget = np.inf if max_evaluations is None else int(max_evaluations)
    for _ in range(max_passes):
        moved = False
        candidates = _candidates(graph, labels, element_errors, is_seed)
        for step, (tet, to) in enumerate(candidates):
            if evaluations >= budget:
                return labels, trace
            source = int(labels[tet])
            nb = graph.neighbours[tet]
            if source == to or not np.any(labels[nb[nb >= 0]] == to) or len(members[source]) < 2:
                continue
            inside = labels == source
            if not graph.stays_connected_without(inside, tet):
                continue
            shrunk = members[source][members[source] != tet]
            grown = np.append(members[to], tet)
            evaluations += 1
            e_source = fitter.error(shrunk)
            e_to = fitter.error(grown)
            new_total = total - errors[source] - errors[to] + e_source + e_to
            if new_total < total - RELATIVE_GAIN * trace[0]:
                labels[tet] = to
                members[source], members[to] = shrunk, np.sort(grown)
                errors[source], errors[to] = e_source, e_to
                total = float(new_total)
                trace.append(total)
                moved = True
            report(progress, step + 1, len(candidates), f"adjusting interfaces: {len(trace) - 1} moves")
        if not moved:
            break
    return labels, trace


def _candidates(graph, labels: np.ndarray, element_errors: np.ndarray, is_seed: np.ndarray) -> list[tuple[int, int]]:
    """(tet, neighbouring partition) pairs on interfaces, largest element error first."""
    nb = graph.neighbours
    other = np.where(nb >= 0, labels[np.maximum(nb, 0)], labels[:, None])
    tets, faces = np.nonzero(other != labels[:, None])
    pairs = np.unique(np.stack([tets, other[tets, faces]], axis=1), axis=0)
    pairs = pairs[~is_seed[pairs[:, 0]]]
    order = np.argsort(-element_errors[pairs[:, 0]], kind="stable")
    return [(int(t), int(q)) for t, q in pairs[order]]
