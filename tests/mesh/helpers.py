"""Tiny generated meshes and file writers for the mesh tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tonguevis.mesh.tetmesh import signed_tet_volumes

# Six tets filling the unit cube (Kuhn subdivision along the 0-7 diagonal).
_KUHN = np.array([[0, 1, 3, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 6, 4, 7], [0, 4, 5, 7], [0, 5, 1, 7]])


def box_mesh(nx: int = 2, ny: int = 2, nz: int = 2, size=(1.0, 1.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """Points (n, 3) and positive tets (6 nx ny nz, 4) of a box of ``size``."""
    gx, gy, gz = (np.linspace(0, s, k + 1) for s, k in zip(size, (nx, ny, nz)))
    X, Y, Z = np.meshgrid(gx, gy, gz, indexing="ij")
    points = np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])
    index = np.arange(points.shape[0]).reshape(nx + 1, ny + 1, nz + 1)
    tets = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                corners = np.array([index[i + a, j + b, k + c] for a in (0, 1) for b in (0, 1) for c in (0, 1)])
                # corner order: bit2 = x, bit1 = y, bit0 = z -> relabel to x + 2y + 4z
                corners = corners[[0, 4, 2, 6, 1, 5, 3, 7]]
                tets.append(corners[_KUHN])
    tets = np.concatenate(tets)
    negative = signed_tet_volumes(points, tets) < 0
    tets[negative] = tets[negative][:, [0, 1, 3, 2]]
    return points, tets


def write_tetgen(stem: Path, points: np.ndarray, tets: np.ndarray, base: int = 0,
                 attributes: bool = False) -> Path:
    """Write ``stem.node`` / ``stem.ele`` with numbering from ``base``; return the .node path."""
    extra = " 1 1" if attributes else " 0 0"
    lines = ["# generated for a test", f"{len(points)} 3{extra}"]
    for i, p in enumerate(points):
        tail = "  0.5  1" if attributes else ""
        lines.append(f"{i + base} {float(p[0])!r} {float(p[1])!r} {float(p[2])!r}{tail}   # node")
    stem.with_suffix(".node").write_text("\n".join(lines) + "\n")
    lines = [f"{len(tets)} 4 {1 if attributes else 0}"]
    for i, t in enumerate(tets):
        tail = " 7" if attributes else ""
        lines.append(f"{i + base} {t[0] + base} {t[1] + base} {t[2] + base} {t[3] + base}{tail}")
    lines.append("# end")
    stem.with_suffix(".ele").write_text("\n".join(lines) + "\n")
    return stem.with_suffix(".node")
