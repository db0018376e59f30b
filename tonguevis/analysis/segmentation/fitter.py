"""What the rigid and constraint fits share: the tet set -> error map and its memo.

A fit, and so its error, depends on the tet set alone (its nodes, its own
stiffness, its boundary = nodes shared with tets outside it, plus the
user-constrained nodes).  :meth:`LocalFitter.error` therefore memoises errors by
the set, across the rounds of Algorithm 5.1, across the re-segmentations of
autoseeding and across post-adjustment: a candidate whose neighbourhood did not
change is never computed twice.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from tonguevis.analysis.segmentation.graph import TetGraph
from tonguevis.analysis.segmentation.target import SegmentationTarget


class LocalFitter:
    """Base class: error and approximation of the target on tet sets.

    points : (n, 3) rest positions, m; tets : (k, 4); graph : their TetGraph;
    target : the SegmentationTarget; constrained : (c,) user-constrained nodes
    (constraint modes only).
    Counters: ``n_evaluations`` (errors asked), ``n_computed`` (not from memo).
    """

    mode = "base"
    #: threads for independent fits (SuperLU releases the GIL; rigid fits are too quick to bother)
    threads = 1

    def __init__(self, points: np.ndarray, tets: np.ndarray, graph: TetGraph, target: SegmentationTarget,
                 constrained: np.ndarray | None = None):
        self.points = np.asarray(points, dtype=np.float64)
        self.tets = np.asarray(tets, dtype=np.int64)
        self.graph = graph
        self.target = target
        self.columns = target.columns
        self.tet_volumes = np.abs(_volumes(self.points, self.tets))
        self.constrained = np.zeros(len(self.points), dtype=bool)
        if constrained is not None and len(constrained):
            self.constrained[np.asarray(constrained, dtype=np.int64)] = True
        self._memo: dict[bytes, float] = {}
        self.n_evaluations = 0
        self.n_computed = 0
        self._prepare()

    def _prepare(self) -> None:  # pragma: no cover - overridden
        pass

    def sorted_members(self, members: np.ndarray) -> tuple[np.ndarray, bytes]:
        """The set's tets in increasing order and its key (no sort: a mask)."""
        mask = np.zeros(len(self.tets), dtype=bool)
        mask[members] = True
        return np.flatnonzero(mask), np.packbits(mask).tobytes()

    def volume(self, members: np.ndarray) -> float:
        """Rest volume of the tet set, m³."""
        return float(self.tet_volumes[members].sum())

    def node_weights(self, members: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nodes (p,) of the set and their lumped volumes (p,) in m³ (V_E/4 per tet corner)."""
        lumped = np.bincount(self.tets[members].ravel(), weights=np.repeat(self.tet_volumes[members] / 4.0, 4),
                             minlength=len(self.points))
        nodes = np.flatnonzero(lumped > 0)
        return nodes, lumped[nodes]

    def error(self, members: np.ndarray) -> float:
        """Squared approximation error ‖ũ − u‖² of the set (m²·m³; divide by volume for e_P)."""
        self.n_evaluations += 1
        members, key = self.sorted_members(members)
        found = self._memo.get(key)
        if found is None:
            found = self._compute_error(members)
            self._memo[key] = found
            self.n_computed += 1
        return found

    def errors(self, sets: list[np.ndarray]) -> list[float]:
        """:meth:`error` of several tet sets; threaded when the fitter allows it."""
        if self.threads > 1 and len(sets) > 1:
            return list(worker_pool("tonguevis-fit", self.threads).map(self.error, sets))
        return [self.error(members) for members in sets]

    def _compute_error(self, members: np.ndarray) -> float:  # pragma: no cover
        raise NotImplementedError

    def approximate(self, members: np.ndarray, displacements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nodes (p,) of the set and the fit (F, p, 3), m, of each (F, n, 3) frame."""
        raise NotImplementedError  # pragma: no cover


_POOLS: dict[str, ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()
#: CPU cores worth using (the benchmarks' machine has 2).
CORES = max(1, min(2, os.cpu_count() or 1))


def worker_pool(name: str, workers: int) -> ThreadPoolExecutor:
    """A process-wide thread pool per purpose (separate pools, so nested use cannot deadlock)."""
    with _POOLS_LOCK:
        pool = _POOLS.get(name)
        if pool is None:
            pool = _POOLS[name] = ThreadPoolExecutor(max_workers=workers, thread_name_prefix=name)
        return pool


def _volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    from tonguevis.mesh.tetmesh import signed_tet_volumes

    return signed_tet_volumes(points, tets)
