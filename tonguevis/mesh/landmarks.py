"""Named landmarks of a tongue mesh: EMA sensor nodes and the five anchors.

Placement rule (paper §3, with TB and TBK added), for any tongue mesh in our frame
(x anterior, y left, z up):

- midline = the symmetry plane y = y0: the volume centroid's y, refined by
  matching the boundary to its own mirror image;
- tip = the most anterior point of the midsagittal section (y = y0);
- TT, TB, TD, TBK: on the dorsal surface midline at 10, 20, 30 and 45 mm of *arc
  length* along the midsagittal dorsal contour from the tip (a tape measure laid
  on the tongue, as a sensor is placed; the contour climbs over the rounded tip);
- TL, TR: at the antero-posterior level of the 20 mm point, 10 mm in (measured
  along y) from the left/right lateral edge of the mesh at that level;
- each point is then snapped to the nearest unused dorsal-surface node (upward
  facing, nothing above), so a node lies within about an edge length of the rule;
- anchors (Fig. 4: the jaw and hyoid attachments): the inferior-surface nodes
  (facing down, nothing below) in the lowest 15 % of the height form the floor;
  two anchors at the genioglossus insertion under the front of the floor (3 % of
  the length behind its front, towards the mandibular symphysis) and three
  towards the hyoid under the back of the root (5 % of the length before its
  back), placed on the midline (hyoid) and halfway from it to the floor's
  lateral extent in that region (at least 6 % of the length from the midline),
  each snapped to the nearest unused floor node.
Any landmark can be overridden by node id.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from tonguevis.errors import MeshError
from tonguevis.mesh.surfaces import dorsal_surface_nodes, inferior_surface_nodes, surface_heights
from tonguevis.mesh.tetmesh import TetMesh

#: Arc length (m) of each midline sensor behind the tip, along the dorsal contour.
MIDLINE_SENSORS = {"TT": 0.010, "TB": 0.020, "TD": 0.030, "TBK": 0.045}
#: Lateral sensors: level (arc length behind the tip, m) and inset from the edge (m).
LATERAL_LEVEL = 0.020
LATERAL_INSET = 0.010
SENSOR_NAMES = ("TT", "TB", "TD", "TBK", "TL", "TR")
ANCHOR_NAMES = ("jaw_right", "jaw_left", "hyoid_right", "hyoid_mid", "hyoid_left")

_SAMPLE_STEP = 2.5e-4   # m between samples of the midsagittal contour


@dataclass
class Landmarks:
    """Landmark node ids of one mesh.

    sensors : sensor name -> node id (e.g. ``{"TT": 812, ...}``).
    anchors : (5,) int node ids fixed during simulation (jaw and hyoid attachments),
        in the order of :data:`ANCHOR_NAMES`.
    metadata : free-form (how they were found, overrides applied, midline y in m).
    """

    sensors: dict[str, int]
    anchors: np.ndarray
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.sensors = {str(k): int(v) for k, v in self.sensors.items()}
        self.anchors = np.asarray(self.anchors, dtype=np.int64).reshape(-1)

    def check(self, mesh: TetMesh, path: str | os.PathLike | None = None) -> None:
        """Raise MeshError unless every id is a node of ``mesh`` and anchors are distinct."""
        ids = np.concatenate([np.fromiter(self.sensors.values(), np.int64, len(self.sensors)), self.anchors])
        bad = ids[(ids < 0) | (ids >= mesh.n_nodes)]
        if bad.size:
            raise MeshError(f"landmark node ids {bad.tolist()} are not nodes of a {mesh.n_nodes}-node mesh", path)
        if np.unique(self.anchors).size != self.anchors.size:
            raise MeshError(f"anchor node ids must be distinct, found {self.anchors.tolist()}", path)

    def sensor_positions(self, mesh: TetMesh) -> dict[str, np.ndarray]:
        """Sensor name -> (3,) rest position in metres."""
        return {name: mesh.points[node].copy() for name, node in self.sensors.items()}

    def to_json(self, mesh: TetMesh | None = None, mesh_file: str | None = None) -> str:
        """JSON text; with ``mesh``, each landmark also records its position (m)."""
        def entry(node: int, **extra) -> dict:
            item = {"node": int(node), **extra}
            if mesh is not None:
                item["position_m"] = [round(float(v), 9) for v in mesh.points[node]]
            return item

        names = list(self.metadata.get("anchor_names", ANCHOR_NAMES))
        names += [f"anchor{i}" for i in range(len(names), self.anchors.size)]
        document = {
            "format": "tonguevis-landmarks",
            "version": 1,
            "mesh": mesh_file,
            "n_nodes": None if mesh is None else mesh.n_nodes,
            "frame": "x anterior, y left, z up; metres",
            "sensors": {name: entry(node) for name, node in self.sensors.items()},
            "anchors": [entry(node, name=names[i]) for i, node in enumerate(self.anchors)],
            "metadata": _jsonable(self.metadata),
        }
        return json.dumps(document, indent=1) + "\n"

    @classmethod
    def from_json(cls, text: str, path: str | os.PathLike | None = None) -> "Landmarks":
        """Parse :meth:`to_json` output; MeshError on anything malformed."""
        try:
            document = json.loads(text)
            sensors = {str(name): int(item["node"]) for name, item in document["sensors"].items()}
            anchors = [int(item["node"]) for item in document["anchors"]]
            metadata = dict(document.get("metadata") or {})
            metadata["anchor_names"] = [str(item.get("name", f"anchor{i}"))
                                        for i, item in enumerate(document["anchors"])]
            if document.get("n_nodes") is not None:
                metadata["n_nodes"] = int(document["n_nodes"])
            positions = {name: item.get("position_m") for name, item in document["sensors"].items()}
            metadata["positions_m"] = {k: v for k, v in positions.items() if v is not None}
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise MeshError(f"malformed landmarks JSON ({type(exc).__name__}: {exc}); expected 'sensors' "
                            f"{{name: {{'node': id}}}} and 'anchors' [{{'node': id}}, ...]", path) from exc
        return cls(sensors, np.array(anchors, dtype=np.int64), metadata)


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items() if k != "positions_m"}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def read_landmarks(path: str | os.PathLike, mesh: TetMesh | None = None) -> Landmarks:
    """Read a landmarks JSON; with ``mesh``, check the ids (and recorded positions) fit it."""
    try:
        text = open(path, encoding="utf-8").read()
    except OSError as exc:
        raise MeshError(f"cannot read landmarks ({exc.strerror or exc})", path) from exc
    landmarks = Landmarks.from_json(text, path)
    if mesh is not None:
        expected = landmarks.metadata.get("n_nodes")
        if expected is not None and expected != mesh.n_nodes:
            raise MeshError(f"landmarks were made for a {expected}-node mesh, this one has {mesh.n_nodes}", path)
        landmarks.check(mesh, path)
        for name, position in landmarks.metadata.get("positions_m", {}).items():
            if np.linalg.norm(mesh.points[landmarks.sensors[name]] - position) > 1e-6:
                raise MeshError(f"sensor {name}: node {landmarks.sensors[name]} is not at the recorded "
                                f"position {position}; the landmarks belong to another mesh", path)
    return landmarks


def midline_y(mesh: TetMesh) -> float:
    """y (m) of the mesh's sagittal symmetry plane.

    Start from the volume centroid's y; then, among planes within 5 % of the
    width of it, keep the one whose mirror image of the boundary nodes lies
    closest (median nearest-neighbour distance) to the boundary itself.
    """
    from scipy.spatial import cKDTree  # lazy: keeps `import tonguevis` light

    centroids = mesh.points[mesh.tets].mean(axis=1)
    volumes = np.abs(mesh.tet_volumes())
    y_centroid = float(np.average(centroids[:, 1], weights=volumes))
    boundary = mesh.points[np.unique(mesh.boundary_faces())]
    tree = cKDTree(boundary)
    width = float(np.ptp(boundary[:, 1]))
    candidates = y_centroid + np.linspace(-0.05, 0.05, 41) * width
    cost = []
    for c in candidates:                                         # 41 KD-tree queries
        mirrored = boundary * [1.0, -1.0, 1.0] + [0.0, 2.0 * c, 0.0]
        cost.append(np.median(tree.query(mirrored)[0]))
    best = int(np.argmin(cost))
    return float(candidates[best])


def midsagittal_dorsum(mesh: TetMesh, y0: float, faces: np.ndarray | None = None) -> np.ndarray:
    """(q, 3) polyline of the dorsal contour in the plane y = y0, from the tip backwards.

    Its first point is the tip: the most anterior point of the midsagittal section,
    at the middle of its height there.
    """
    x_max, x_min = mesh.points[:, 0].max(), mesh.points[:, 0].min()
    xs = np.arange(x_max, x_min, -_SAMPLE_STEP)
    heights = surface_heights(mesh, np.column_stack([xs, np.full_like(xs, y0)]), faces)
    hit = np.nonzero(~np.isnan(heights[:, 0]))[0]
    if hit.size < 2:
        raise MeshError("the midsagittal plane misses the mesh: is it a tongue in our frame?",
                        mesh.metadata.get("source"))
    # Refine the tip between the last miss and the first hit by bisection-free sampling.
    first = hit[0]
    x_front = xs[first]
    if first > 0:
        fine = np.linspace(xs[first - 1], xs[first], 26)
        fine_h = surface_heights(mesh, np.column_stack([fine, np.full_like(fine, y0)]), faces)
        ok = np.nonzero(~np.isnan(fine_h[:, 0]))[0]
        x_front = fine[ok[0]]
        tip_z = 0.5 * (fine_h[ok[0], 0] + fine_h[ok[0], 1])
    else:
        tip_z = 0.5 * (heights[first, 0] + heights[first, 1])
    # Keep the contiguous run of hits from the front.
    gaps = np.nonzero(np.diff(hit) > 1)[0]
    run = hit[: gaps[0] + 1] if gaps.size else hit
    contour = np.column_stack([xs[run], np.full(run.size, y0), heights[run, 1]])
    return np.vstack([[x_front, y0, tip_z], contour])


def _point_at_arc(polyline: np.ndarray, distance: float) -> np.ndarray:
    seg = np.linalg.norm(np.diff(polyline, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    distance = min(distance, arc[-1])
    return np.array([np.interp(distance, arc, polyline[:, k]) for k in range(3)])


def _nearest_unused(points: np.ndarray, pool: np.ndarray, target: np.ndarray, used: set) -> int:
    order = np.argsort(np.linalg.norm(points[pool] - target, axis=1))
    for i in order:
        if int(pool[i]) not in used:
            used.add(int(pool[i]))
            return int(pool[i])
    raise MeshError("not enough surface nodes to place distinct landmarks")


def find_landmarks(mesh: TetMesh, overrides: Mapping[str, int | Sequence[int]] | None = None) -> Landmarks:
    """Sensor nodes and anchors of a tongue mesh in our frame, by the rule above.

    overrides : ``{"TT": node, ..., "anchors": [5 node ids]}`` replacing the rule.
    """
    source = mesh.metadata.get("source")
    faces = mesh.boundary_faces()
    p = mesh.points
    y0 = midline_y(mesh)
    dorsal = dorsal_surface_nodes(mesh)
    if dorsal.size < len(SENSOR_NAMES):
        raise MeshError(f"only {dorsal.size} dorsal surface nodes: is z up?", source)
    contour = midsagittal_dorsum(mesh, y0, faces)
    used: set[int] = set()
    sensors: dict[str, int] = {}
    targets: dict[str, list[float]] = {}
    for name, arc in MIDLINE_SENSORS.items():
        target = _point_at_arc(contour, arc)
        targets[name] = target.tolist()
        sensors[name] = _nearest_unused(p, dorsal, target, used)

    level = _point_at_arc(contour, LATERAL_LEVEL)
    width = float(np.ptp(p[:, 1]))
    ys = np.arange(0.0, 0.6 * width + _SAMPLE_STEP, _SAMPLE_STEP)
    for name, side in (("TL", 1.0), ("TR", -1.0)):
        line = np.column_stack([np.full_like(ys, level[0]), y0 + side * ys])
        heights = surface_heights(mesh, line, faces)
        inside = np.nonzero(~np.isnan(heights[:, 1]))[0]
        half_width = ys[inside[-1]] if inside.size else 0.0
        offset = max(half_width - LATERAL_INSET, 0.25 * half_width)
        z_top = surface_heights(mesh, np.array([[level[0], y0 + side * offset]]), faces)[0, 1]
        target = np.array([level[0], y0 + side * offset, level[2] if np.isnan(z_top) else z_top])
        targets[name] = target.tolist()
        sensors[name] = _nearest_unused(p, dorsal, target, used)

    anchors = _anchors(mesh, y0, source)
    landmarks = Landmarks(sensors, anchors, {"rule": "tonguevis.mesh.landmarks (paper §3, Fig. 4)",
                                             "midline_y_m": y0, "tip_m": contour[0].tolist(),
                                             "targets_m": targets, "anchor_names": list(ANCHOR_NAMES)})
    if overrides:
        _apply_overrides(landmarks, overrides)
    landmarks.check(mesh, source)
    return landmarks


def _anchors(mesh: TetMesh, y0: float, source) -> np.ndarray:
    p = mesh.points
    inferior = inferior_surface_nodes(mesh)
    z_floor = p[:, 2].min()
    band = inferior[p[inferior, 2] <= z_floor + 0.15 * np.ptp(p[:, 2])]
    if band.size < 5:
        raise MeshError(f"only {band.size} nodes on the floor of the mesh: is z up?", source)
    length = float(np.ptp(p[:, 0]))
    x_front, x_back = p[band, 0].max(), p[band, 0].min()
    front = band[p[band, 0] >= x_front - 0.10 * length]         # under the front of the floor
    back = band[p[band, 0] <= x_back + 0.12 * length]           # under the back of the root
    if front.size < 2 or back.size < 3:
        raise MeshError("too few floor nodes at the front or back for the anchors", source)
    # Each group spreads over the middle half of the floor's width there, so the
    # anchors neither coincide nor climb the sides.
    half_front = max(0.5 * np.abs(p[front, 1] - y0).max(), 0.06 * length)
    half_back = max(0.5 * np.abs(p[back, 1] - y0).max(), 0.06 * length)
    x_jaw, x_hyoid = x_front - 0.03 * length, x_back + 0.05 * length
    targets = [(x_jaw, y0 - half_front), (x_jaw, y0 + half_front),
               (x_hyoid, y0 - half_back), (x_hyoid, y0), (x_hyoid, y0 + half_back)]
    used: set[int] = set()
    picked = [_nearest_unused(p, band, np.array([x, y, z_floor]), used) for x, y in targets]
    jaw, hyoid = picked[:2], picked[2:]
    anchors = np.array(jaw + hyoid, dtype=np.int64)
    if np.unique(anchors).size != 5:
        raise MeshError("could not place five distinct anchors on the floor of the mesh", source)
    return anchors


def _apply_overrides(landmarks: Landmarks, overrides: Mapping[str, int | Sequence[int]]) -> None:
    applied = {}
    for key, value in overrides.items():
        if key == "anchors":
            anchors = np.asarray(value, dtype=np.int64).reshape(-1)
            if anchors.size != 5:
                raise MeshError(f"override 'anchors' needs 5 node ids, found {anchors.size}")
            landmarks.anchors = anchors
            applied[key] = anchors.tolist()
        else:
            if isinstance(value, (list, tuple, np.ndarray)):
                raise MeshError(f"override {key!r} needs one node id, found {value!r}")
            landmarks.sensors[str(key)] = int(value)
            applied[key] = int(value)
    landmarks.metadata["overrides"] = applied
