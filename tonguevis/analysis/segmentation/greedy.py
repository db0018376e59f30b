"""Algorithm 5.1: competitive one-ring growth from seeds.

Every round each partition proposes itself plus its one-ring; only the proposal
with the smallest error ``e_P`` (eq. 4, or eq. 5 for a sequence) is kept, the
others roll back.  A proposal stays valid until its ring changes, which happens
only when the winner takes tets of that ring, so proposals are kept between
rounds and recomputed only then (and the fitter's memo catches identical sets).
"""

from __future__ import annotations


import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.analysis.segmentation.errors import SegmentationError
from tonguevis.analysis.segmentation.fitter import LocalFitter
from tonguevis.analysis.segmentation.graph import UNASSIGNED

from tonguevis._logging import logger


def seed_regions(seeds, n_tets: int) -> list[np.ndarray]:
    """Seeds as a list of tet id arrays (an int is a one-tet seed); checks they are disjoint."""
    regions = []
    for seed in seeds:
        region = np.unique(np.atleast_1d(np.asarray(seed, dtype=np.int64)))
        if len(region) == 0:
            raise SegmentationError("an empty seed region was given")
        if region.min() < 0 or region.max() >= n_tets:
            raise SegmentationError(f"seed tets {region.tolist()[:5]} outside the mesh's {n_tets} tets")
        regions.append(region)
    if not regions:
        raise SegmentationError("at least one seed is needed")
    all_tets = np.concatenate(regions)
    if len(np.unique(all_tets)) != len(all_tets):
        raise SegmentationError("seed regions overlap: each tet can seed one partition only")
    return regions


def grow_partitions(fitter: LocalFitter, seeds, progress: ProgressCallback | None = None,
                    message: str = "growing partitions") -> np.ndarray:
    """Run Algorithm 5.1 from ``seeds`` (tet ids or tet id arrays); return (k,) labels.

    Parts of the mesh no partition can reach (another connected component)
    get a partition of their own, seeded at their first tet.
    """
    graph = fitter.graph
    k = graph.n_tets
    regions = seed_regions(seeds, k)
    labels = np.full(k, UNASSIGNED, dtype=np.int64)
    for i, region in enumerate(regions):
        labels[region] = i
    members = [region.copy() for region in regions]
    proposals: list[tuple[np.ndarray, float] | None] = [None] * len(members)
    assigned = int((labels != UNASSIGNED).sum())
    report(progress, assigned, k, message)
    while assigned < k:
        pending = [i for i, proposal in enumerate(proposals) if proposal is None]
        rings = {i: graph.one_ring(members[i], labels) for i in pending}
        jobs = [(i, np.concatenate([members[i], rings[i]])) for i in pending if len(rings[i])]
        errors = fitter.errors([candidate for _, candidate in jobs])  # independent: threaded
        for (i, candidate), error in zip(jobs, errors):
            proposals[i] = (rings[i], error / fitter.volume(candidate))
        for i in pending:
            if not len(rings[i]):
                proposals[i] = (rings[i], np.inf)
        errors = np.array([p[1] for p in proposals])
        if not np.isfinite(errors).any():
            # Nothing touches the unassigned tets: a separate component.
            start = int(np.flatnonzero(labels == UNASSIGNED)[0])
            logger.info("segmentation: tet %d is unreachable from the seeds; it seeds a new partition", start)
            labels[start] = len(members)
            members.append(np.array([start]))
            proposals.append(None)
            assigned += 1
            continue
        winner = int(np.argmin(errors))
        ring = proposals[winner][0]
        labels[ring] = winner
        members[winner] = np.concatenate([members[winner], ring])
        assigned += len(ring)
        proposals[winner] = None
        for i, proposal in enumerate(proposals):
            if proposal is not None and len(proposal[0]) and np.any(labels[proposal[0]] != UNASSIGNED):
                proposals[i] = None  # its ring lost tets to the winner
        report(progress, assigned, k, message)
    return labels
