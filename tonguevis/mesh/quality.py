"""Element quality of linear tetrahedra."""

from __future__ import annotations

import numpy as np

from tonguevis.mesh.tetmesh import TET_FACES, signed_tet_volumes


def tet_quality(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """(k,) normalised radius ratio 3 r_in / r_circ: 1 for a regular tet, 0 when flat.

    Negative for inverted tets.  Computed for all tets at once.
    """
    p = np.asarray(points, dtype=np.float64)[tets]              # (k, 4, 3)
    volume = signed_tet_volumes(points, tets)
    corners = p[:, TET_FACES]                                   # (k, 4 faces, 3 corners, 3)
    face_areas = 0.5 * np.linalg.norm(
        np.cross(corners[:, :, 1] - corners[:, :, 0], corners[:, :, 2] - corners[:, :, 0]), axis=-1)
    r_in = 3.0 * np.abs(volume) / face_areas.sum(axis=1)
    # Circumradius from the edge products: 24 V R = sqrt((aA+bB+cC)(aA+bB-cC)(aA-bB+cC)(-aA+bB+cC))
    d = lambda i, j: np.linalg.norm(p[:, i] - p[:, j], axis=1)  # noqa: E731
    aa, bb, cc = d(0, 1) * d(2, 3), d(0, 2) * d(1, 3), d(0, 3) * d(1, 2)
    product = (aa + bb + cc) * (aa + bb - cc) * (aa - bb + cc) * (-aa + bb + cc)
    r_circ = np.sqrt(np.clip(product, 0.0, None)) / np.maximum(24.0 * np.abs(volume), 1e-300)
    return np.sign(volume) * 3.0 * r_in / np.maximum(r_circ, 1e-300)
