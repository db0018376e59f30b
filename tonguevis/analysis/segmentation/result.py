"""The result of a segmentation, :class:`SegmentationResult`, and its files."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from tonguevis._files import atomic_write
from tonguevis.analysis.segmentation.errors import SegmentationError

FORMAT = "tonguevis-segmentation-1"


@dataclass
class SegmentationResult:
    """A segmented mesh and how well each partition's local modes fit the target.

    Mesh and target
        points : (n, 3) rest positions, m.  tets : (k, 4) node ids.
        target : (F, n, 3) target displacements, m.  frame_weights : (F,)
        energy shares summing to 1 (eq. 5; ``[1]`` for one frame).
        frame_times : (F,) s (NaN when unknown).
    Segmentation
        mode : ``"rigid"`` or ``"constraint"``.  labels : (k,) partition id of
        every tet, 0..P-1.  seeds : (P,) seed tet of each partition.
        constrained_nodes : (c,) user-constrained nodes (constraint modes).
    Approximation, on the split mesh (each partition has its own node copies)
        approximation : (F, m, 3) fitted displacement, m.  split_nodes : (m,)
        mesh node of each copy.  split_partition : (m,) its partition.
        split_tets : (k, 4) the tets on the copies.
    Errors (volume-lumped norm, see :mod:`.target`)
        element_errors : (k,) e_E of eq. (14), m² (mean squared corner error,
        energy-weighted over frames).  partition_errors : (P,) e_P, m².
        global_error : e_G of eq. (15), m².  relative_error : e_G divided by
        e_G of the zero approximation, i.e. ‖ũ − u‖² / ‖u‖²; the paper's
        "5 percent e_G" threshold applies to this number.
        history : (h, 2) [partition count, relative error] after each
        autoseeding step and each accepted post-adjustment move.
    metadata : JSON-serialisable notes (source, production, timings).
    """

    points: np.ndarray
    tets: np.ndarray
    target: np.ndarray
    frame_weights: np.ndarray
    frame_times: np.ndarray
    mode: str
    labels: np.ndarray
    seeds: np.ndarray
    constrained_nodes: np.ndarray
    approximation: np.ndarray
    split_nodes: np.ndarray
    split_partition: np.ndarray
    split_tets: np.ndarray
    element_errors: np.ndarray
    partition_errors: np.ndarray
    global_error: float
    relative_error: float
    history: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    metadata: dict[str, Any] = field(default_factory=dict)

    @property
    def n_partitions(self) -> int:
        return int(len(self.partition_errors))

    @property
    def n_frames(self) -> int:
        return int(self.target.shape[0])

    @property
    def peak_frame(self) -> int:
        """The frame of largest weight (the energy peak of a production)."""
        return int(np.argmax(self.frame_weights))

    def target_points(self, frame: int | None = None) -> np.ndarray:
        """(n, 3) target shape of a frame (peak by default), m: rest points + target."""
        frame = self.peak_frame if frame is None else int(frame)
        return self.points + self.target[frame]

    def approximated_points(self, frame: int | None = None) -> np.ndarray:
        """(m, 3) approximated shape on the split mesh (draw with ``split_tets``), m."""
        frame = self.peak_frame if frame is None else int(frame)
        return self.points[self.split_nodes] + self.approximation[frame]

    def partition_rows(self) -> list[dict[str, Any]]:
        """One dict per partition: ``partition``, ``tets``, ``volume_cm3``,
        ``rms_error_mm`` (sqrt of e_P), ``seed`` (tet) and ``centroid_m`` (3 floats)."""
        from tonguevis.mesh.tetmesh import signed_tet_volumes

        volumes = np.abs(signed_tet_volumes(self.points, self.tets))
        centres = self.points[self.tets].mean(axis=1)
        rows = []
        for p in range(self.n_partitions):
            inside = self.labels == p
            rows.append({
                "partition": p,
                "tets": int(inside.sum()),
                "volume_cm3": float(1e6 * volumes[inside].sum()),
                "rms_error_mm": float(1000 * np.sqrt(self.partition_errors[p])),
                "seed": int(self.seeds[p]) if p < len(self.seeds) else -1,
                "centroid_m": np.average(centres[inside], axis=0, weights=volumes[inside]).tolist(),
            })
        return rows

    def nodal_approximation(self) -> np.ndarray:
        """(F, n, 3) approximation per mesh node, averaging the partitions' copies (m).

        Exact for constraint modes (the copies agree); for rigid modes the
        interfaces are where the copies disagree (see :meth:`interface_gap`).
        """
        n = len(self.points)
        count = np.bincount(self.split_nodes, minlength=n).astype(float)
        total = np.zeros((self.n_frames, n, 3))
        np.add.at(total, (slice(None), self.split_nodes), self.approximation)
        return total / np.maximum(count, 1.0)[None, :, None]

    def interface_gap(self) -> np.ndarray:
        """(F, n) largest distance of a node's partition copies from their mean, m.

        Zero off interfaces and, for constraint modes, on them too; for two
        rigid copies it is half their jump.
        """
        mean = self.nodal_approximation()
        gap = np.linalg.norm(self.approximation - mean[:, self.split_nodes], axis=2)
        out = np.zeros((self.n_frames, len(self.points)))
        np.maximum.at(out, (slice(None), self.split_nodes), gap)
        return out

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> Path:
        """Write a ``.npz`` (no pickles); written to a temporary file then renamed."""
        path = Path(path)
        arrays = {f.name: np.asarray(getattr(self, f.name)) for f in fields(self) if f.name != "metadata"}
        arrays["metadata"] = np.array(json.dumps(self.metadata, default=_jsonable))
        arrays["format"] = np.array(FORMAT)
        def write(tmp: Path) -> None:
            with open(tmp, "wb") as handle:
                np.savez_compressed(handle, **arrays)

        atomic_write(path, write)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> "SegmentationResult":
        """Read a file written by :meth:`save`; raises SegmentationError naming the problem."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                if "format" not in data.files or str(data["format"]) != FORMAT:
                    raise SegmentationError(f"not a tonguevis segmentation file (expected format {FORMAT})", path)
                values = {}
                for f in fields(cls):
                    if f.name not in data.files:
                        raise SegmentationError(f"missing array {f.name!r}", path)
                    values[f.name] = data[f.name]
        except (OSError, ValueError) as exc:
            if isinstance(exc, SegmentationError):
                raise
            raise SegmentationError(f"cannot read segmentation file: {exc}", path) from exc
        values["metadata"] = json.loads(str(values["metadata"]))
        values["mode"] = str(values["mode"])
        values["global_error"] = float(values["global_error"])
        values["relative_error"] = float(values["relative_error"])
        result = cls(**values)
        result._check(path)
        return result

    def _check(self, path: Path | None = None) -> None:
        k, n, f = len(self.tets), len(self.points), self.target.shape[0]
        m = len(self.split_nodes)
        problems = []
        if self.mode not in ("rigid", "constraint"):
            problems.append(f"mode {self.mode!r} is not rigid or constraint")
        if self.labels.shape != (k,) or self.element_errors.shape != (k,) or self.split_tets.shape != (k, 4):
            problems.append("per-tet arrays do not match the tets")
        if self.target.shape[1:] != (n, 3) or self.approximation.shape != (f, m, 3):
            problems.append("target/approximation shapes do not match the mesh")
        if len(self.labels) and (self.labels.min() < 0 or self.labels.max() >= self.n_partitions):
            problems.append("labels outside the partitions")
        if m and (self.split_nodes.min() < 0 or self.split_nodes.max() >= n):
            problems.append("split nodes outside the mesh")
        if problems:
            raise SegmentationError("inconsistent segmentation file: " + "; ".join(problems), path)

    def to_meshio(self, frame: int | None = None, split: bool = True):
        """A meshio Mesh of the rest shape with the fields of one frame (peak by default).

        Point data: ``target`` and ``approximation`` (m, warp by them to see the
        shapes), ``error`` |ũ − u| (m).  Cell data: ``partition``,
        ``element_error`` (m²), ``seed`` (1 on seed tets).  With ``split`` the
        partitions have their own node copies, so rigid fits show their gaps.
        """
        import meshio

        frame = self.peak_frame if frame is None else int(frame)
        if not 0 <= frame < self.n_frames:
            raise SegmentationError(f"frame {frame} outside the {self.n_frames} target frames")
        seed = np.zeros(len(self.tets), dtype=np.int64)
        seed[self.seeds] = 1
        cell_data = {"partition": [self.labels.astype(np.int32)], "element_error": [self.element_errors],
                     "seed": [seed.astype(np.int32)]}
        if split:
            points, cells = self.points[self.split_nodes], self.split_tets
            target = self.target[frame][self.split_nodes]
            approx = self.approximation[frame]
        else:
            points, cells = self.points, self.tets
            target = self.target[frame]
            approx = self.nodal_approximation()[frame]
        point_data = {"target": target, "approximation": approx,
                      "error": np.linalg.norm(approx - target, axis=1)}
        return meshio.Mesh(points, [("tetra", cells)], point_data=point_data, cell_data=cell_data)

    def to_vtu(self, path: str | os.PathLike, frame: int | None = None, split: bool = True) -> Path:
        """Write :meth:`to_meshio` as ``.vtu`` (temporary file, then renamed)."""
        path = Path(path)
        mesh = self.to_meshio(frame, split)
        atomic_write(path, lambda tmp: mesh.write(tmp, file_format="vtu"))
        return path


def _jsonable(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)
