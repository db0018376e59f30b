"""What a segmentation approximates: one frame (eq. 4) or a weighted sequence (eq. 5).

Errors use the volume-lumped norm ``‖v‖²_P = Σ_{E∈P} (V_E/4) Σ_{a∈E} |v_a|²``
(m² · m³), so ``e_P = ‖ũ − u‖²_P / V_P`` is the mean squared deviation over the
partition's volume in m².  The paper's eq. (4) sums squared DOFs unweighted; the
lumped weights give the same ranking on a uniform mesh and make the error
independent of how finely each region happens to be meshed (our tongue meshes
are not uniform).  Element (eq. 14), partition (eq. 4/5) and global (eq. 15)
errors are then consistent: ``e_G V = Σ_E e_E V_E = Σ_P e_P V_P``.

For a sequence the frame errors are weighted by the elastic energy ``U_f``
(eq. 5).  Every fit is linear in the target, so the weighted sum over frames
equals a sum over the columns of ``Y = U diag(w)^½`` and, by the SVD
``Y = A S Bᵀ``, over the few columns of ``A S``: :attr:`columns` keeps those
whose singular values matter, which makes a 50-frame production nearly as
cheap to segment as one frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tonguevis.analysis.segmentation.errors import SegmentationError


@dataclass
class SegmentationTarget:
    """Target displacements and how the frames are weighted.

    displacements : (F, n, 3) float64, metres, of every mesh node.
    weights : (F,) float64, non-negative, summing to 1 (energy shares, eq. 5).
    times : (F,) float64, seconds (NaN when unknown).
    description : what the target is, for titles and metadata.
    """

    displacements: np.ndarray
    weights: np.ndarray
    times: np.ndarray
    description: str = ""
    _columns: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        u = np.asarray(self.displacements, dtype=np.float64)
        if u.ndim == 2:
            u = u[None]
        if u.ndim != 3 or u.shape[2] != 3 or u.shape[0] == 0:
            raise SegmentationError(f"target displacements must be (frames, nodes, 3), got shape {u.shape}")
        if not np.all(np.isfinite(u)):
            raise SegmentationError("target displacements contain NaN or infinite values")
        w = np.asarray(self.weights, dtype=np.float64).reshape(-1)
        if len(w) != len(u) or np.any(w < 0) or not np.isfinite(w).all() or w.sum() <= 0:
            raise SegmentationError(f"frame weights must be {len(u)} non-negative numbers with a positive sum")
        self.displacements = u
        self.weights = w / w.sum()
        t = np.full(len(u), np.nan) if self.times is None else np.asarray(self.times, dtype=np.float64).reshape(-1)
        if len(t) != len(u):
            raise SegmentationError(f"{len(t)} frame times for {len(u)} target frames")
        self.times = t

    @classmethod
    def frame(cls, displacement: np.ndarray, time: float = np.nan, description: str = "") -> "SegmentationTarget":
        """A single-frame target (eq. 4) from an (n, 3) displacement in metres."""
        return cls(np.asarray(displacement, dtype=np.float64)[None], np.ones(1), np.array([time]), description)

    @classmethod
    def sequence(cls, displacements: np.ndarray, energy: np.ndarray, times: np.ndarray | None = None,
                 description: str = "") -> "SegmentationTarget":
        """A whole production (eq. 5): (F, n, 3) displacements weighted by (F,) energies in J."""
        energy = np.asarray(energy, dtype=np.float64)
        if energy.shape != (len(displacements),):
            raise SegmentationError(f"energy must have one value per frame ({len(displacements)}), got {energy.shape}")
        if not np.any(energy > 0):
            raise SegmentationError("the production has no elastic energy: nothing to segment")
        return cls(displacements, np.clip(energy, 0.0, None), times, description)

    @property
    def n_frames(self) -> int:
        return int(self.displacements.shape[0])

    @property
    def n_nodes(self) -> int:
        return int(self.displacements.shape[1])

    @property
    def peak_frame(self) -> int:
        """Index of the frame of largest weight (peak energy for a production)."""
        return int(np.argmax(self.weights))

    @property
    def columns(self) -> np.ndarray:
        """(r, n, 3) columns whose unit-weight errors sum to the weighted frame error.

        ``Σ_f w_f ‖L u_f‖² = Σ_j ‖L y_j‖²`` for every linear ``L`` applied node
        by node; singular values below 1e-7 of the largest are dropped (their
        share of the squared norm is under 1e-14 each).
        """
        if self._columns is None:
            y = self.displacements * np.sqrt(self.weights)[:, None, None]
            if self.n_frames == 1:
                self._columns = y
            else:
                flat = y.reshape(self.n_frames, -1)
                # Gram route: F x F eigenproblem instead of an SVD of the long side.
                gram = flat @ flat.T
                values, vectors = np.linalg.eigh(gram)
                keep = values > (1e-7 ** 2) * max(values.max(), 0.0)
                if not keep.any():
                    keep[-1] = True
                # columns A S = Y^T B  (rows of flat are frames)
                self._columns = (vectors[:, keep].T @ flat).reshape(-1, self.n_nodes, 3)
        return self._columns
