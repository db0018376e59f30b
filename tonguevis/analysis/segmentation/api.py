"""One call for scripts, the CLI and the GUI: :func:`segment`.

``segment(model_or_mesh, target, mode, seeds=..., progress=...)`` runs
Algorithm 5.1 from given seeds, or autoseeding (eqs. 14-15) to a partition
count or a relative global error, then optionally the post-segmentation
adjustment, and returns a :class:`SegmentationResult`.
"""

from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.analysis.segmentation.adjust import adjust_boundaries
from tonguevis.analysis.segmentation.errors import SegmentationError
from tonguevis.analysis.segmentation.evaluate import Evaluation, evaluate, target_norm
from tonguevis.analysis.segmentation.fit_constraint import ConstraintFitter
from tonguevis.analysis.segmentation.fit_rigid import RigidFitter
from tonguevis.analysis.segmentation.fitter import LocalFitter
from tonguevis.analysis.segmentation.graph import TetGraph
from tonguevis.analysis.segmentation.greedy import grow_partitions, seed_regions
from tonguevis.analysis.segmentation.result import SegmentationResult
from tonguevis.analysis.segmentation.target import SegmentationTarget

from tonguevis._logging import logger

MODES = ("rigid", "constraint")
DEFAULT_THRESHOLD = 0.05
MAX_AUTO_PARTITIONS = 24
#: Post-adjustment budget (tried moves) per mode: a rigid move costs microseconds,
#: a constraint move two sparse factorisations.
DEFAULT_ADJUST_EVALUATIONS = {"rigid": 5000, "constraint": 60}


def make_fitter(points: np.ndarray, tets: np.ndarray, target: SegmentationTarget, mode: str,
                constrained_nodes: Sequence[int] | None = None, poisson: float = 0.49,
                graph: TetGraph | None = None) -> LocalFitter:
    """The fitter of ``mode`` on a mesh (the engine behind :func:`segment`)."""
    if mode not in MODES:
        raise SegmentationError(f"segmentation mode must be one of {', '.join(MODES)}, got {mode!r}")
    points = np.asarray(points, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    if target.n_nodes != len(points):
        raise SegmentationError(f"the target has {target.n_nodes} nodes but the mesh has {len(points)}")
    graph = graph or TetGraph.from_tets(tets, len(points))
    if mode == "rigid":
        return RigidFitter(points, tets, graph, target)
    constrained = None if constrained_nodes is None else np.asarray(constrained_nodes, dtype=np.int64)
    if constrained is not None and len(constrained) and (constrained.min() < 0 or constrained.max() >= len(points)):
        raise SegmentationError(f"constrained nodes outside the mesh's {len(points)} nodes")
    return ConstraintFitter(points, tets, graph, target, constrained, poisson=poisson)


def _mesh_of(model_or_mesh: Any):
    """(points, tets, anchors or None, poisson or None) of a TongueModel or a TetMesh."""
    mesh = getattr(model_or_mesh, "mesh", model_or_mesh)
    if not hasattr(mesh, "points") or not hasattr(mesh, "tets"):
        raise SegmentationError(f"expected a TongueModel or a TetMesh, got {type(model_or_mesh).__name__}")
    anchors = getattr(model_or_mesh, "anchors", None)
    if anchors is None and hasattr(model_or_mesh, "landmarks"):
        anchors = getattr(model_or_mesh.landmarks, "anchors", None)
    material = getattr(model_or_mesh, "material", None)
    poisson = getattr(material, "poisson", None)
    return mesh.points, mesh.tets, anchors, poisson


def segment(
    model_or_mesh: Any,
    target: SegmentationTarget,
    mode: str = "constraint",
    seeds: str | Sequence = "auto",
    n_partitions: int | None = None,
    threshold: float | None = DEFAULT_THRESHOLD,
    constrained_nodes: Sequence[int] | None = None,
    adjust: bool = False,
    max_adjust_evaluations: int | None = None,
    poisson: float | None = None,
    progress: ProgressCallback | None = None,
    threads: int | None = None,
) -> SegmentationResult:
    """Segment a mesh by how well local rigid or constraint modes fit ``target``.

    model_or_mesh : a TongueModel (its anchors are the default constrained
        nodes and its Poisson ratio is used) or a TetMesh.
    target : SegmentationTarget (one frame or an energy-weighted production).
    mode : ``"rigid"`` (eq. 9) or ``"constraint"`` (eq. 13).
    seeds : ``"auto"`` (eqs. 14-15), or a list of seed tets (ints, or arrays of
        tets for seed regions) for Algorithm 5.1.
    n_partitions, threshold : autoseeding stops at this many partitions, or
        once the relative global error ‖ũ − u‖²/‖u‖² is at most ``threshold``
        (default 0.05, the paper's "5 percent e_G"), whichever comes first.
    constrained_nodes : nodes whose fit must equal the target (constraint
        modes); ``None`` = the model's anchors, ``[]`` = none.
    adjust : run the post-segmentation adjustment (§5.3: "extra refinement can
        be performed"); off by default since with constraint modes every
        tried move costs two sparse factorisations.
    max_adjust_evaluations : moves tried at most (default 5000 rigid, 60 constraint).
    progress : ``progress(done, total, message)``, may raise Cancelled.
    threads : threads for independent fits and solves (None: the fitter's
        default, up to 2 for constraint modes; 1 where processes already run
        one per core, as in ``tonguevis batch``).  The result does not depend on it.
    """
    started = time.perf_counter()
    points, tets, anchors, model_poisson = _mesh_of(model_or_mesh)
    if constrained_nodes is None:
        constrained_nodes = anchors if mode == "constraint" and anchors is not None else []
    poisson = poisson if poisson is not None else (model_poisson if model_poisson is not None else 0.49)
    fitter = make_fitter(points, tets, target, mode, constrained_nodes, poisson)
    if threads is not None:
        fitter.threads = max(1, int(threads))
    history: list[tuple[int, float]] = []
    automatic = isinstance(seeds, str)
    if automatic:
        if seeds != "auto":
            raise SegmentationError(f"seeds must be 'auto' or a list of tets, got {seeds!r}")
        labels, seed_tets, evaluation, history = autoseed(fitter, n_partitions, threshold, progress)
    else:
        regions = seed_regions(seeds, len(tets))
        labels = grow_partitions(fitter, regions, progress, f"growing {len(regions)} partitions")
        seed_tets = np.array([r[0] for r in regions], dtype=np.int64)
        evaluation = evaluate(fitter, labels)
        history.append((int(labels.max()) + 1, evaluation.relative_error))
    if len(seed_tets) < int(labels.max()) + 1:  # unreachable components got partitions
        extra = [int(np.flatnonzero(labels == p)[0]) for p in range(len(seed_tets), int(labels.max()) + 1)]
        seed_tets = np.concatenate([seed_tets, extra]).astype(np.int64)
    if adjust and labels.max() > 0:
        budget = max_adjust_evaluations if max_adjust_evaluations is not None else DEFAULT_ADJUST_EVALUATIONS[mode]
        labels, trace = adjust_boundaries(fitter, labels, seed_tets, evaluation.element_errors, budget,
                                          progress=progress)
        if len(trace) > 1:
            norm = target_norm(fitter) or 1.0
            history.extend((int(labels.max()) + 1, value / norm) for value in trace[1:])
            evaluation = evaluate(fitter, labels)
    result = _result(points, tets, target, mode, labels, seed_tets, constrained_nodes, evaluation, history)
    result.metadata.update({
        "description": target.description,
        "seeding": "auto" if automatic else "user",
        "threshold": threshold if automatic else None,
        "adjusted": bool(adjust),
        "poisson": poisson,
        "seconds": time.perf_counter() - started,
        "fits_computed": fitter.n_computed,
        "fits_asked": fitter.n_evaluations,
        "factorisations": getattr(fitter, "n_factorisations", 0),
        "solved_through_larger_factorisation": getattr(fitter, "n_reused", 0),
    })
    report(progress, 1, 1, f"{result.n_partitions} partitions, e_G {100 * result.relative_error:.1f} %")
    return result


def autoseed(fitter: LocalFitter, n_partitions: int | None, threshold: float | None,
             progress: ProgressCallback | None = None) -> tuple[np.ndarray, np.ndarray, Evaluation, list]:
    """Autoseeding (§5.3): one partition, then seed the worst element and regrow, until done.

    The first partition spans the mesh; its seed is its central tet (centroid
    nearest the mesh's; the paper leaves it open, and a corner seed could
    share a uniform region with the next seed and squeeze it).  Each step
    seeds a new partition at the element of largest e_E (eq. 14) and reruns
    Algorithm 5.1 from all seeds.  The seeds persist between steps, so the
    regrowth repeats many earlier proposals, which the fitter's memo returns
    without solving.  Returns labels, seeds, the evaluation and the
    [(partitions, relative e_G)] history.
    """
    if n_partitions is None and threshold is None:
        raise SegmentationError("autoseeding needs a partition count or an error threshold")
    if n_partitions is not None and n_partitions < 1:
        raise SegmentationError(f"the partition count must be at least 1, got {n_partitions}")
    if threshold is not None and not 0 <= threshold < 1:
        raise SegmentationError(f"the error threshold is a fraction in [0, 1), got {threshold}")
    graph = fitter.graph
    k = len(fitter.tets)
    labels = np.zeros(k, dtype=np.int64)
    for i, component in enumerate(graph.components(np.arange(k))):
        labels[component] = i
    evaluation = evaluate(fitter, labels)
    n_current = int(labels.max()) + 1
    seeds = [graph.central(np.flatnonzero(labels == p), fitter.points) for p in range(n_current)]
    history = [(n_current, evaluation.relative_error)]
    limit = n_partitions if n_partitions is not None else MAX_AUTO_PARTITIONS
    while n_current < limit and n_current < k:
        if threshold is not None and evaluation.relative_error <= threshold:
            break
        order = np.argsort(-evaluation.element_errors, kind="stable")
        taken = set(seeds)
        seeds.append(int(next(t for t in order if int(t) not in taken)))
        message = f"autoseeding: {len(seeds)} partitions (e_G was {100 * evaluation.relative_error:.1f} %)"
        labels = grow_partitions(fitter, seeds, progress, message)
        evaluation = evaluate(fitter, labels)
        n_current = int(labels.max()) + 1
        history.append((n_current, evaluation.relative_error))
        logger.info("autoseeding: %d partitions, relative e_G %.4f", n_current, evaluation.relative_error)
    return labels, np.array(seeds, dtype=np.int64), evaluation, history


def _result(points, tets, target, mode, labels, seeds, constrained, evaluation: Evaluation,
            history) -> SegmentationResult:
    return SegmentationResult(
        points=np.asarray(points, dtype=np.float64), tets=np.asarray(tets, dtype=np.int64),
        target=target.displacements, frame_weights=target.weights, frame_times=target.times, mode=mode,
        labels=labels, seeds=np.asarray(seeds, dtype=np.int64),
        constrained_nodes=np.asarray(constrained, dtype=np.int64).reshape(-1),
        approximation=evaluation.approximation, split_nodes=evaluation.split_nodes,
        split_partition=evaluation.split_partition, split_tets=evaluation.split_tets,
        element_errors=evaluation.element_errors, partition_errors=evaluation.partition_errors,
        global_error=evaluation.global_error, relative_error=evaluation.relative_error,
        history=np.asarray(history, dtype=np.float64).reshape(-1, 2),
    )
