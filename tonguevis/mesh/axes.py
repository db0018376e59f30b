"""Explicit axis mappings between a file's frame and ours (x anterior, y left, z up).

A mapping is written like ``"-x,-z,-y"``: the new x is minus the old x, the new y
is minus the old z and the new z is minus the old y.  Mappings are always given by
the caller, never guessed.
"""

from __future__ import annotations

import numpy as np

from tonguevis.errors import MeshError

#: Raw ArtiSynth ``tongue3.1`` (x backwards, y down, z lateral) -> ours: a proper
#: rotation (see DATA.md).
ARTISYNTH_AXES = "-x,-z,-y"

_AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


def axes_matrix(axes: str) -> np.ndarray:
    """(3, 3) signed permutation matrix A with ``new = A @ old`` for ``axes``.

    Raises MeshError unless ``axes`` names each of x, y, z exactly once, each with
    an optional sign, separated by commas (e.g. ``"-x,-z,-y"``).
    """
    tokens = [t.strip().lower() for t in str(axes).split(",")]
    if len(tokens) != 3:
        raise MeshError(f"axis mapping {axes!r}: expected three comma-separated axes like '-x,-z,-y'")
    matrix = np.zeros((3, 3))
    used = []
    for row, token in enumerate(tokens):
        sign = -1.0 if token.startswith("-") else 1.0
        name = token.lstrip("+-")
        if name not in _AXIS_INDEX:
            raise MeshError(f"axis mapping {axes!r}: {token!r} is not one of x, y, z with an optional sign")
        used.append(name)
        matrix[row, _AXIS_INDEX[name]] = sign
    if sorted(used) != ["x", "y", "z"]:
        raise MeshError(f"axis mapping {axes!r}: each of x, y, z must appear exactly once")
    return matrix


def apply_axes(points: np.ndarray, tets: np.ndarray, axes: str) -> tuple[np.ndarray, np.ndarray]:
    """Map (n, 3) ``points`` by ``axes``; return new points and tets.

    A mapping that is a reflection (determinant -1) would turn every tet inside
    out, so two vertices of every tet are swapped to keep them positive.
    """
    matrix = axes_matrix(axes)
    new_points = np.asarray(points, dtype=np.float64) @ matrix.T
    new_tets = np.array(tets, dtype=np.int64, copy=True)
    if np.linalg.det(matrix) < 0:
        new_tets[:, [2, 3]] = new_tets[:, [3, 2]]
    return new_points, new_tets
