"""Per-frame drawing data of a simulated motion, made from q when a frame is shown (no Qt).

A frame's state is its modal displacement q (100 numbers); what the 3D view
draws (deformed surface, displacement magnitude, elastic energy density) is
reconstructed from it when the frame is shown, for the drawn nodes only (the
surface's and the sensors'), in float32.  :class:`MotionFrames` computes
:data:`BLOCK` consecutive frames at once (vectorised) and keeps at most
:data:`CACHE_FRAMES` of them, the blocks nearest in use to the cursor; so
opening a recording costs the same whatever its length, and a 30-minute one
holds a few MB of drawing data instead of gigabytes.  The colour ranges come
from at most :data:`COLOUR_FRAMES` frames spread evenly over the motion.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.render.energy_density import EnergyDensity

#: Frames reconstructed together when the cursor reaches one not in the cache.
BLOCK = 16
#: Most frames kept (whole blocks, the least recently shown dropped first): a few MB on our tongue.
CACHE_FRAMES = 256
#: Most frames sampled, evenly spread over the motion, for the colour ranges (all of a shorter motion).
COLOUR_FRAMES = 2000

#: Scalar quantities per node, with the unit the colour bar shows.
SCALARS = {
    "displacement": ("displacement", "mm"),
    "energy": ("energy density", "J/m³"),
}


def model_material(model) -> tuple[float, float]:
    """(Young's modulus Pa, Poisson's ratio) of a tongue model (paper defaults if absent)."""
    from tonguevis.sim.material import Material

    material = getattr(model, "material", None) or Material()
    return float(material.young), float(material.poisson)


class PerFrame:
    """``[i]`` -> one frame's array, computed on demand; a slice or index array stacks frames
    (O(frames selected)); ``[i, ...]`` and ``[:, nodes]`` index into the result."""

    def __init__(self, get, n_frames: int):
        self._get = get
        self._n = int(n_frames)

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, key):
        rest = ()
        if isinstance(key, tuple):
            key, rest = key[0], key[1:]
        if isinstance(key, (int, np.integer)):
            i = int(key) + (self._n if key < 0 else 0)
            if not 0 <= i < self._n:
                raise IndexError(f"frame {int(key)} outside the motion's {self._n} frames")
            out = self._get(i)
            return out[rest] if rest else out
        stacked = np.stack([self._get(int(i)) for i in np.arange(self._n)[key]])
        return stacked[(slice(None),) + rest] if rest else stacked


class MotionFrames:
    """What the 3D view draws for any frame of ``motion``, made when asked for.

    Attributes (F frames, n mesh nodes, S driving sensors):
    nodes : (k,) int64, the nodes computed: the surface's and the driving sensors'
        (every node with ``surface_only=False``).
    points : ``points[i]`` (n, 3) float32 node positions at frame i, metres: the
        computed nodes deformed, the others (inside the tongue, which nothing
        draws) at rest; ``motion.displacement(i)`` gives the whole mesh.
    scalars : name -> ``scalars[name][i]`` (n,) float32; ``displacement`` in mm (|u|),
        ``energy`` in J/m³ (density of the unwarped modal displacement Φq, whose
        volume integral is the motion's energy ½ qᵀΛq); 0 at nodes not computed.
    sensor_points : ``sensor_points[i]`` (S, 3) float32, the driving sensors' nodes, deformed.
    targets : (F, S, 3) float32, measured (aligned) sensor positions.
    clim : name -> (low, high) colour range, from at most ``colour_frames`` frames
        spread evenly over the motion (every frame of a shorter one).
    At most ``cache_frames`` frames are kept (:attr:`cached_frames`).
    """

    def __init__(self, motion, progress: ProgressCallback | None = None, block: int = BLOCK,
                 cache_frames: int = CACHE_FRAMES, surface_only: bool = True, colour_frames: int = COLOUR_FRAMES):
        model = motion.model
        self.motion = motion
        self.times = np.asarray(motion.times, dtype=np.float64)
        self.block = max(1, int(block))
        self.cache_frames = max(self.block, int(cache_frames))
        self.surface_only = bool(surface_only)
        self._rest = np.asarray(model.mesh.points, dtype=np.float32)
        n_nodes = len(self._rest)
        sensor_nodes = np.asarray(motion.sensor_nodes, dtype=np.int64)
        if surface_only:
            faces = getattr(model, "surface_faces", None)
            faces = faces() if callable(faces) else faces
            faces = model.mesh.boundary_faces() if faces is None else faces
            self.nodes = np.union1d(np.unique(np.asarray(faces, dtype=np.int64)), sensor_nodes)
        else:
            self.nodes = np.arange(n_nodes, dtype=np.int64)
        self._sensor_index = np.searchsorted(self.nodes, sensor_nodes)
        self.targets = np.asarray(motion.targets, dtype=np.float32)
        self._energy_ops = None
        self._cache: OrderedDict[int, dict] = OrderedDict()
        self._lock = threading.Lock()
        self.points = PerFrame(self._points, self.n_frames)
        self.sensor_points = PerFrame(lambda i: self._entry(i)["points"][i - self._start(i)][self._sensor_index],
                                      self.n_frames)
        self.scalars = {"displacement": PerFrame(lambda i: self._scalar(i, "displacement"), self.n_frames),
                        "energy": PerFrame(lambda i: self._scalar(i, "energy"), self.n_frames)}
        self.clim = self._colour_ranges(colour_frames, progress) if colour_frames else {}
        report(progress, 1, 1, "frames ready")

    @property
    def n_frames(self) -> int:
        return int(len(self.times))

    @property
    def cached_frames(self) -> int:
        """Frames whose drawing data is held now (at most ``cache_frames``)."""
        with self._lock:
            return sum(len(entry["points"]) for entry in self._cache.values())

    def frame_at(self, t: float) -> int:
        """Index of the frame nearest time ``t`` (seconds), clipped."""
        from tonguevis.sim.motion import nearest_frame

        return nearest_frame(self.times, t)

    def whole_mesh(self) -> "MotionFrames":
        """The same motion with every node computed (for exports of the volume mesh); no colour ranges."""
        frames = MotionFrames(self.motion, block=self.block, cache_frames=self.cache_frames, surface_only=False,
                              colour_frames=0)
        frames.clim = dict(self.clim)
        return frames

    # -- one frame -------------------------------------------------------------------
    def _points(self, i: int) -> np.ndarray:
        out = self._rest.copy()
        out[self.nodes] = self._entry(i)["points"][i - self._start(i)]
        return out

    def _scalar(self, i: int, name: str) -> np.ndarray:
        out = np.zeros(len(self._rest), dtype=np.float32)
        out[self.nodes] = self._entry(i, energy=name == "energy")[name][i - self._start(i)]
        return out

    def _start(self, i: int) -> int:
        return (i // self.block) * self.block

    def _entry(self, i: int, energy: bool = False) -> dict:
        """The cached block of frame ``i`` (computed now if need be; the oldest blocks dropped)."""
        key = i // self.block
        with self._lock:
            entry = self._cache.get(key)
            if entry is not None:
                self._cache.move_to_end(key)
        if entry is None:
            frames = slice(key * self.block, min((key + 1) * self.block, self.n_frames))
            u = self.motion.model.displacements(self.motion.q[frames], warping=self.motion.warping,
                                                dtype=np.float32, nodes=self.nodes)
            entry = {"points": self._rest[self.nodes] + u, "displacement": 1e3 * np.linalg.norm(u, axis=2)}
            with self._lock:
                self._cache[key] = entry
                while len(self._cache) * self.block > self.cache_frames:
                    self._cache.popitem(last=False)
        if energy and "energy" not in entry:
            entry["energy"] = self._energy(slice(key * self.block, key * self.block + len(entry["points"])))
        return entry

    # -- energy density ----------------------------------------------------------------
    def _energy(self, frames) -> np.ndarray:
        """(f, k) float32 energy density (J/m³) at the computed nodes for the frames ``frames``."""
        if self._energy_ops is None:
            self._energy_ops = NodalEnergy(self.motion.model, self.motion.q.shape[1], self.nodes)
        return self._energy_ops(self.motion.q[frames])

    # -- colour ranges -----------------------------------------------------------------
    def _colour_ranges(self, most: int, progress: ProgressCallback | None) -> dict[str, tuple[float, float]]:
        """0 to a high percentile of each scalar over frames spread evenly over the motion."""
        n = self.n_frames
        sample = np.unique(np.round(np.linspace(0, n - 1, min(n, int(most)))).astype(np.int64)) if n else \
            np.zeros(0, dtype=np.int64)
        values = {"displacement": [], "energy": []}
        step = 256
        for start in range(0, len(sample), step):
            report(progress, start, len(sample), f"colour ranges from {len(sample)} frames")
            picks = sample[start:start + step]
            u = self.motion.model.displacements(self.motion.q[picks], warping=self.motion.warping,
                                                dtype=np.float32, nodes=self.nodes)
            values["displacement"].append(1e3 * np.linalg.norm(u, axis=2))
            values["energy"].append(self._energy(picks))
        # Energy concentrates at the anchors: a lower percentile keeps the rest of the tongue readable.
        return {"displacement": _colour_range(values["displacement"], 99.5),
                "energy": _colour_range(values["energy"], 98.0)}


class NodalEnergy:
    """Elastic energy density (J/m³) at ``nodes`` straight from q.

    The strains of the unwarped modal displacement Φq are linear in q, so with the
    strain operator B of the tets around the nodes, every frame's strains are one
    dense product q (BΦ)ᵀ; each node's value is the volume-weighted mean of its tets'
    (:class:`~tonguevis.render.energy_density.EnergyDensity`, whose ``nodal`` is the
    plain reference).  ``NodalEnergy(model, m, nodes)(q)`` : (f, m) -> (f, k) float32.
    """

    def __init__(self, model, modes: int, nodes: np.ndarray):
        self.density = EnergyDensity(np.asarray(model.mesh.points, dtype=np.float64), model.mesh.tets,
                                     *model_material(model))
        average = self.density.node_average.tocsr()[np.asarray(nodes, dtype=np.int64)]
        tets = np.unique(average.indices)
        rows = (6 * tets[:, None] + np.arange(6)).ravel()
        phi = model.basis(modes).phi
        self.strain_modes = np.asarray(self.density.strain_operator()[rows] @ phi, dtype=np.float32).T  # (m, 6 t)
        self.average = average[:, tets]

    def __call__(self, q: np.ndarray) -> np.ndarray:
        strains = np.atleast_2d(np.asarray(q, dtype=np.float32)) @ self.strain_modes
        return np.asarray((self.average @ self.density.from_strains(strains).T).T, dtype=np.float32)


def _colour_range(chunks: list[np.ndarray], percentile: float) -> tuple[float, float]:
    """0 to a high percentile of the values (a few extreme nodes do not wash out the rest)."""
    values = np.concatenate([c.ravel() for c in chunks]) if chunks else np.zeros(0)
    finite = values[np.isfinite(values)]
    high = float(np.percentile(finite, percentile)) if finite.size else 1.0
    return (0.0, high if high > 0 else 1.0)
