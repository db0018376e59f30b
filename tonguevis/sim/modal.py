"""The reduced (modal) basis: lowest vibration modes of the anchored tongue.

Solves K φ = λ M φ on the free DOFs (anchor nodes removed) for the m smallest
eigenvalues by shift-invert Lanczos with a negative shift σ, so K - σM is
positive definite and every mode lies above the shift (no spurious zero or
negative modes), checks each residual ‖Kφ - λMφ‖/‖Kφ‖, mass-normalises, and
caches the result on disk as a ``.npz`` keyed by a hash of everything it
depends on.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zipfile

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from tonguevis._files import atomic_write
from tonguevis._progress import ProgressCallback, report
from tonguevis.errors import ModelError
from tonguevis.sim.material import Material

from tonguevis._logging import logger

CACHE_VERSION = 1
RESIDUAL_TOLERANCE = 1e-6


@dataclass
class ModalBasis:
    """Mass-normalised vibration modes of the anchored mesh.

    phi : (3n, m) float64 mode shapes over all node-major DOFs (rows of anchor
        nodes are zero); units m / (kg^½) so that Φᵀ M Φ = I.
    eigenvalues : (m,) float64, λ = ω² in 1/s², ascending; Φᵀ K Φ = diag(λ).
    free_dofs : (3n - 3a,) int64 DOFs not fixed by anchors.
    key : the cache key (hex) of mesh, material, anchors and m.
    info : solve timings and residuals.
    """

    phi: np.ndarray
    eigenvalues: np.ndarray
    free_dofs: np.ndarray
    key: str = ""
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n_modes(self) -> int:
        return int(self.phi.shape[1])

    @property
    def frequencies_hz(self) -> np.ndarray:
        """(m,) natural frequencies in Hz."""
        return np.sqrt(np.maximum(self.eigenvalues, 0.0)) / (2 * np.pi)


def free_dofs_for(n_nodes: int, anchors: np.ndarray) -> np.ndarray:
    """(3n - 3a,) DOF indices of the nodes that are not anchors."""
    fixed = np.zeros(3 * n_nodes, dtype=bool)
    anchors = np.asarray(anchors, dtype=np.int64)
    fixed[(3 * anchors[:, None] + np.arange(3)).ravel()] = True
    return np.flatnonzero(~fixed)


def basis_key(points: np.ndarray, tets: np.ndarray, material: Material, anchors: np.ndarray, m: int) -> str:
    """Hex hash of everything a modal basis depends on."""
    h = hashlib.sha256()
    h.update(f"v{CACHE_VERSION}|m={m}|".encode())
    h.update(repr(sorted(material.as_dict().items())).encode())
    for arr, dtype in ((points, np.float64), (tets, np.int64), (np.sort(anchors), np.int64)):
        h.update(np.ascontiguousarray(arr, dtype=dtype).tobytes())
    return h.hexdigest()[:32]


def solve_modes(
    stiffness: sp.spmatrix,
    mass: sp.spmatrix,
    free: np.ndarray,
    m: int,
    shift: float | None = None,
    progress: ProgressCallback | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Lowest ``m`` eigenpairs of K φ = λ M φ restricted to ``free`` DOFs.

    Returns (phi_free (f, m), eigenvalues (m,), info).  The shift defaults to
    -1 (1/s²) scaled to the problem so K - σM stays positive definite.
    """
    t0 = time.perf_counter()
    kff = stiffness[free][:, free].tocsc()
    mff = mass[free][:, free].tocsc()
    nfree = kff.shape[0]
    if m >= nfree - 1:
        raise ModelError(f"asked for {m} modes but the mesh has only {nfree} free degrees of freedom")
    sigma = -1.0 if shift is None else float(shift)
    report(progress, 1, 4, "factorising K - σM")
    # K - σM is symmetric positive definite for σ < 0: a symmetric ordering and
    # no pivoting give a third less fill and twice faster solves than the default.
    lu = spla.splu(
        (kff - sigma * mff).tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )
    op_inv = spla.LinearOperator(kff.shape, matvec=lu.solve, dtype=np.float64)
    report(progress, 2, 4, f"Lanczos for {m} modes")
    rng = np.random.default_rng(0)  # deterministic start vector: reproducible bases
    v0 = rng.standard_normal(nfree)
    from tonguevis._blas import single_threaded_blas

    try:
        # ARPACK's vector operations are too small for threaded BLAS: one thread
        # is 3x faster on two cores (and far faster when the machine is busy).
        with single_threaded_blas():
            vals, vecs = spla.eigsh(kff, k=m, M=mff, sigma=sigma, which="LM", OPinv=op_inv, v0=v0)
    except spla.ArpackNoConvergence as exc:  # pragma: no cover - rare
        raise ModelError(f"the eigen-solver did not converge for {m} modes: {exc}") from exc
    order = np.argsort(vals)
    vals, vecs = vals[order], vecs[:, order]
    report(progress, 3, 4, "checking residuals")
    # Mass-normalise (eigsh already returns M-orthonormal vectors; make it exact).
    norms = np.sqrt(np.einsum("ij,ij->j", vecs, mff @ vecs))
    vecs = vecs / norms
    k_phi = kff @ vecs
    resid = np.linalg.norm(k_phi - (mff @ vecs) * vals, axis=0) / np.maximum(np.linalg.norm(k_phi, axis=0), 1e-300)
    if np.any(vals <= sigma) or np.any(~np.isfinite(vals)):
        raise ModelError(f"spurious eigenvalues below the shift σ={sigma}: {vals[vals <= sigma][:5]}")
    if vals[0] <= 1e-8 * max(vals[-1], 1.0):
        raise ModelError(
            "the anchored mesh has a (near) zero-energy mode: the anchors do not hold it "
            f"(λ₁ = {vals[0]:.3g}); use at least three non-collinear anchor nodes"
        )
    if resid.max() > RESIDUAL_TOLERANCE:
        raise ModelError(
            f"modal basis failed its residual check: max ‖Kφ-λMφ‖/‖Kφ‖ = {resid.max():.2e} "
            f"> {RESIDUAL_TOLERANCE:.0e} (mode {int(resid.argmax())})"
        )
    info = {"solve_s": time.perf_counter() - t0, "max_residual": float(resid.max()), "shift": sigma}
    report(progress, 4, 4, "done")
    return vecs, vals, info


def save_basis(basis: ModalBasis, path: Path) -> None:
    """Write the basis as ``.npz`` atomically (temporary file, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)

    def write(tmp):
        with open(tmp, "wb") as fh:
            np.savez(
                fh,
                phi=basis.phi,
                eigenvalues=basis.eigenvalues,
                free_dofs=basis.free_dofs,
                key=np.array(basis.key),
                version=np.array(CACHE_VERSION),
            )

    atomic_write(path, write)


def load_basis(path: Path, key: str | None = None) -> ModalBasis | None:
    """Read a cached basis; ``None`` if absent, unreadable, stale or of another key."""
    path = Path(path)
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            if int(data["version"]) != CACHE_VERSION or (key is not None and str(data["key"]) != key):
                return None
            return ModalBasis(
                phi=np.array(data["phi"]),
                eigenvalues=np.array(data["eigenvalues"]),
                free_dofs=np.array(data["free_dofs"]),
                key=str(data["key"]),
                info={"loaded_from": str(path)},
            )
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        # A crash or a full disk while writing leaves a truncated file: solve again, say so.
        logger.warning("ignoring unreadable modal-basis cache %s (%s): the modes are solved again", path, exc)
        return None
