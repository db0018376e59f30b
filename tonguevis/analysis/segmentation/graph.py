"""Face connectivity of a tet mesh, the vocabulary of partitions (§5).

A *partition* is a face-connected set of tets (two tets are connected when they
share a triangle); its *one-ring* is the set of unassigned tets sharing a face
with it.  Partitions are kept as a label per tet (``-1`` = unassigned).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from tonguevis.mesh.tetmesh import TET_FACES

UNASSIGNED = -1


@dataclass
class TetGraph:
    """Face adjacency and node incidence of a tet mesh.

    tets : (k, 4) int64 node ids.
    n_nodes : number of mesh nodes.
    neighbours : (k, 4) int64, the tet across each face, ``-1`` on the surface.
    node_valence : (n,) int64, how many tets hold each node.
    """

    tets: np.ndarray
    n_nodes: int
    neighbours: np.ndarray
    node_valence: np.ndarray

    @classmethod
    def from_tets(cls, tets: np.ndarray, n_nodes: int) -> "TetGraph":
        tets = np.ascontiguousarray(tets, dtype=np.int64)
        k = len(tets)
        faces = np.sort(tets[:, TET_FACES].reshape(-1, 3), axis=1)  # (4k, 3), face f of tet f // 4
        order = np.lexsort((faces[:, 2], faces[:, 1], faces[:, 0]))
        sorted_faces = faces[order]
        same = np.all(sorted_faces[1:] == sorted_faces[:-1], axis=1)
        first = order[:-1][same]  # face slots of the two tets sharing a face
        second = order[1:][same]
        neighbours = np.full(4 * k, UNASSIGNED, dtype=np.int64)
        neighbours[first] = second // 4
        neighbours[second] = first // 4
        valence = np.bincount(tets.ravel(), minlength=n_nodes).astype(np.int64)
        return cls(tets, int(n_nodes), neighbours.reshape(k, 4), valence)

    @property
    def n_tets(self) -> int:
        return int(len(self.tets))

    @cached_property
    def adjacency(self) -> sp.csr_matrix:
        """(k, k) symmetric 0/1 face-adjacency matrix."""
        rows = np.repeat(np.arange(self.n_tets), 4)
        cols = self.neighbours.ravel()
        keep = cols >= 0
        data = np.ones(int(keep.sum()), dtype=np.int8)
        return sp.csr_matrix((data, (rows[keep], cols[keep])), shape=(self.n_tets, self.n_tets))

    @cached_property
    def node_tets(self) -> sp.csr_matrix:
        """(n, k) 0/1 incidence: row i holds the tets containing node i."""
        rows = self.tets.ravel()
        cols = np.repeat(np.arange(self.n_tets), 4)
        data = np.ones(len(rows), dtype=np.int8)
        return sp.csr_matrix((data, (rows, cols)), shape=(self.n_nodes, self.n_tets))

    def stays_connected_without(self, inside: np.ndarray, tet: int) -> bool:
        """Whether the face-connected set ``inside`` ((k,) bool mask) stays connected without ``tet``.

        Cheap local test first: the set's face neighbours of ``tet`` joined
        through tets around ``tet``'s nodes (sufficient); the whole set is
        searched only when that fails.
        """
        around = self.neighbours[tet]
        around = around[(around >= 0)]
        around = around[inside[around]]
        if len(around) <= 1:  # a leaf stays attached; a lone tet leaves nothing (or nothing connected)
            return len(around) == 1
        star = self.node_tets[self.tets[tet]].indices
        local = np.unique(star[inside[star] & (star != tet)])
        position = {int(t): i for i, t in enumerate(local)}
        seen = {int(around[0])}
        stack = [int(around[0])]
        while stack:
            current = stack.pop()
            for other in self.neighbours[current]:
                other = int(other)
                if other in position and other not in seen:
                    seen.add(other)
                    stack.append(other)
        if all(int(t) in seen for t in around):
            return True
        rest = np.flatnonzero(inside)
        return self.is_connected(rest[rest != tet])

    def one_ring(self, members: np.ndarray, labels: np.ndarray) -> np.ndarray:
        """Sorted unassigned tets sharing a face with the tets ``members``."""
        around = self.neighbours[members].ravel()
        around = around[around >= 0]
        mask = np.zeros(self.n_tets, dtype=bool)
        mask[around[labels[around] == UNASSIGNED]] = True
        return np.flatnonzero(mask)

    def boundary_nodes(self, members: np.ndarray) -> np.ndarray:
        """Sorted nodes of the tet set ``members`` that also belong to a tet outside it."""
        inside = np.bincount(self.tets[members].ravel(), minlength=self.n_nodes)
        return np.flatnonzero((inside > 0) & (inside < self.node_valence))

    def nodes_of(self, members: np.ndarray) -> np.ndarray:
        """Sorted nodes of the tet set ``members``."""
        return np.flatnonzero(np.bincount(self.tets[members].ravel(), minlength=self.n_nodes))

    def is_connected(self, members: np.ndarray) -> bool:
        """Whether the tet set ``members`` is face-connected (an empty set is not)."""
        if len(members) == 0:
            return False
        sub = self.adjacency[members][:, members]
        n_components, _ = connected_components(sub, directed=False)
        return n_components == 1

    def components(self, members: np.ndarray) -> list[np.ndarray]:
        """The face-connected components of the tet set ``members`` (tet id arrays)."""
        members = np.asarray(members, dtype=np.int64)
        sub = self.adjacency[members][:, members]
        _, which = connected_components(sub, directed=False)
        return [members[which == c] for c in range(int(which.max()) + 1)] if len(members) else []

    def central(self, members: np.ndarray, points: np.ndarray) -> int:
        """The tet of ``members`` whose centroid is nearest the set's centroid (ties: lowest id)."""
        members = np.asarray(members, dtype=np.int64)
        centres = points[self.tets[members]].mean(axis=1)
        middle = centres.mean(axis=0)
        return int(members[int(np.argmin(np.sum((centres - middle) ** 2, axis=1)))])
