"""Read tetrahedral meshes (TetGen, VTU/VTK, Gmsh, NumPy ``.npz``) into :class:`TetMesh`.

Formats:
- TetGen ``.node`` + ``.ele`` (pass either file or their common stem): 0- or 1-based
  numbering (whatever the ``.node`` file starts with), point attributes, boundary
  markers and ``#`` comments allowed; linear tets only.
- ``.npz`` with arrays ``points`` (n, 3) and ``tets`` (k, 4), read without pickle.
- anything meshio reads that holds ``tetra`` cells (``.vtu``, ``.vtk``, ``.msh``,
  ``.mesh``, ``.xdmf`` ...); other cell blocks (boundary triangles) are ignored.

Units: meshes are kept in metres.  A mesh whose extent exceeds 1 (no tongue is a
metre long) is taken to be in millimetres and converted with a logged warning,
unless ``unit=`` says what the file uses.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tonguevis.errors import MeshError
from tonguevis.mesh.axes import apply_axes
from tonguevis.mesh.checks import checked_tets
from tonguevis.mesh.meshio_read import quiet_meshio_read  # noqa: F401 (re-exported)
from tonguevis.mesh.tetmesh import TetMesh

from tonguevis._logging import logger

#: Metres per unit for the accepted ``unit=`` names.
UNIT_SCALE = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}

_TETGEN_SUFFIXES = (".node", ".ele")


def read_mesh(path: str | os.PathLike, unit: str | None = None, axes: str | None = None) -> TetMesh:
    """Read a tetrahedral mesh file into a validated :class:`TetMesh` (metres, our frame).

    path : TetGen ``.node``/``.ele`` (or their stem), ``.npz``, or a meshio format.
    unit : ``"m"``, ``"cm"`` or ``"mm"``; None guesses: extent > 1 means millimetres.
    axes : explicit axis mapping such as ``"-x,-z,-y"`` (see
        :mod:`tonguevis.mesh.axes`), applied after the unit conversion; or
        ``"auto"``: found from the mesh's shape (:func:`tonguevis.mesh.orientation.find_axes`),
        logged, and MeshError when the shape does not tell; None keeps the file's axes.

    Raises :class:`MeshError` naming the file for anything unreadable or unusable.
    """
    path = Path(path)
    if unit is not None and unit not in UNIT_SCALE:
        raise MeshError(f"unknown unit {unit!r}; expected one of {sorted(UNIT_SCALE)}", path)
    suffix = path.suffix.lower()
    if suffix in _TETGEN_SUFFIXES or (not path.exists() and path.with_suffix(path.suffix + ".node").exists()):
        stem = path.with_suffix("") if suffix in _TETGEN_SUFFIXES else path
        points, tets, id_offset, source = _read_tetgen(stem)
    elif suffix == ".npz":
        points, tets = _read_npz(path)
        id_offset, source = 0, path
    else:
        points, tets = _read_meshio(path)
        id_offset, source = 0, path

    metadata = {"source": str(source), "unit": unit}
    extent = float(np.max(np.ptp(points, axis=0))) if points.size else 0.0
    if unit is None:
        if extent > 1.0:
            logger.warning("%s: extent %.4g is impossible in metres for a tongue; reading as millimetres",
                        source, extent)
            unit = "mm"
            metadata["unit"] = "mm (guessed from the extent)"
        else:
            unit = "m"
    points = points * UNIT_SCALE[unit]

    tets = checked_tets(points, tets, source, id_offset)
    if axes is not None and str(axes).strip().lower() == "auto":
        axes = _found_axes(TetMesh(points, tets, dict(metadata)), source)
        metadata["axes_found"] = True
    if axes is not None:
        points, tets = apply_axes(points, tets, axes)
        metadata["axes"] = axes
    return TetMesh(points, tets, metadata)


def _found_axes(mesh: TetMesh, source) -> str:
    """The axis mapping of ``mesh`` found from its shape; MeshError when the shape does not tell."""
    from tonguevis.mesh.orientation import find_axes

    fit = find_axes(mesh)
    if not fit.decided:
        raise MeshError(f"cannot tell the mesh's axes from its shape (best mapping {fit.axes!r} fits only "
                        f"{fit.margin:.2f} times better than the next); give them, e.g. axes='-x,-z,-y' "
                        "(--mesh-axes=-x,-z,-y), new x anterior, y left, z up", source)
    logger.info("%s: axes %s found from the shape (fits %.1f times better than the next mapping, "
             "%.1f times better than the file's own axes)", source, fit.axes, fit.margin,
             fit.identity_misfit / fit.misfit)
    return fit.axes


def _read_npz(path: Path) -> tuple[np.ndarray, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as data:
            missing = [k for k in ("points", "tets") if k not in data.files]
            if missing:
                raise MeshError(f"missing arrays {missing}; expected 'points' (n, 3) and 'tets' (k, 4), "
                                f"found {data.files}", path)
            points = np.asarray(data["points"], dtype=np.float64)
            tets = np.asarray(data["tets"])
    except MeshError:
        raise
    except (OSError, ValueError, EOFError) as exc:
        raise MeshError(f"not a readable .npz mesh ({exc})", path) from exc
    if not np.issubdtype(tets.dtype, np.integer):
        raise MeshError(f"'tets' must hold integer node indices, found {tets.dtype}", path)
    return points, tets.astype(np.int64)


def _read_meshio(path: Path) -> tuple[np.ndarray, np.ndarray]:
    import meshio

    if not path.exists():
        raise MeshError("no such mesh file", path)
    try:
        mesh = quiet_meshio_read(path)
    except meshio.ReadError as exc:
        raise MeshError(
            f"cannot read as a mesh ({exc}); supported: TetGen .node/.ele, .npz, and meshio "
            f"formats with tetra cells (.vtu, .vtk, .msh, ...)", path) from exc
    except (ValueError, KeyError, IndexError, EOFError, TypeError, AttributeError) as exc:
        raise MeshError(f"malformed mesh file ({type(exc).__name__}: {exc})", path) from exc
    blocks = [c.data for c in mesh.cells if c.type == "tetra"]
    if not blocks:
        found = sorted({c.type for c in mesh.cells})
        raise MeshError(f"no linear tetrahedra ('tetra' cells) in the file; found cell types {found}", path)
    return np.asarray(mesh.points, dtype=np.float64)[:, :3], np.concatenate(blocks).astype(np.int64)


def _tetgen_rows(path: Path) -> list[list[str]]:
    """Non-empty lines of a TetGen file, comments stripped, split into tokens."""
    try:
        text = path.read_text(errors="replace")
    except OSError as exc:
        raise MeshError(f"cannot read TetGen file ({exc.strerror or exc})", path) from exc
    rows = []
    for line in text.splitlines():
        tokens = line.split("#", 1)[0].split()
        if tokens:
            rows.append(tokens)
    if not rows:
        raise MeshError("empty TetGen file (no header line)", path)
    return rows


def _table(rows: list[list[str]], count: int, width: int, path: Path, what: str) -> np.ndarray:
    """(count, width) float array from the first ``width`` tokens of each row."""
    if len(rows) < count:
        raise MeshError(f"truncated: header announces {count} {what} but only {len(rows)} follow", path)
    body = rows[:count]
    short = [i for i, r in enumerate(body) if len(r) < width]
    if short:
        raise MeshError(f"truncated or malformed {what} line {short[0] + 2}: expected at least {width} "
                        f"numbers, found {len(body[short[0]])}", path)
    try:
        return np.array([r[:width] for r in body], dtype=np.float64)
    except ValueError as exc:
        raise MeshError(f"non-numeric value among the {what} ({exc})", path) from exc


def _header(row: list[str], path: Path, names: str) -> list[int]:
    try:
        return [int(float(v)) for v in row]
    except ValueError as exc:
        raise MeshError(f"bad header {' '.join(row)!r}; expected integers ({names})", path) from exc


def _read_tetgen(stem: Path) -> tuple[np.ndarray, np.ndarray, int, Path]:
    node_path, ele_path = stem.with_suffix(stem.suffix + ".node"), stem.with_suffix(stem.suffix + ".ele")
    for p in (node_path, ele_path):
        if not p.exists():
            raise MeshError("TetGen mesh needs both .node and .ele files; this one is missing", p)

    node_rows = _tetgen_rows(node_path)
    header = _header(node_rows[0], node_path, "count, dimension, attributes, markers")
    if len(header) < 2 or header[1] != 3 or header[0] <= 0:
        raise MeshError(f"header {node_rows[0]} must give a positive node count and dimension 3", node_path)
    n_nodes = header[0]
    nodes = _table(node_rows[1:], n_nodes, 4, node_path, "nodes")
    node_ids = nodes[:, 0].astype(np.int64)
    points = nodes[:, 1:4]

    ele_rows = _tetgen_rows(ele_path)
    header = _header(ele_rows[0], ele_path, "count, nodes per tet, attributes")
    if len(header) < 2 or header[0] <= 0:
        raise MeshError(f"header {ele_rows[0]} must give a positive element count", ele_path)
    if header[1] != 4:
        raise MeshError(f"only linear tets are supported: header says {header[1]} nodes per tet", ele_path)
    elements = _table(ele_rows[1:], header[0], 5, ele_path, "elements").astype(np.int64)
    raw_tets = elements[:, 1:5]

    # Map the file's node numbers to rows (usually ids == base + row).
    base = int(node_ids.min())
    if np.array_equal(node_ids, np.arange(base, base + n_nodes)):
        tets = raw_tets - base
    else:
        order = np.argsort(node_ids)
        sorted_ids = node_ids[order]
        if np.any(np.diff(sorted_ids) == 0):
            dup = sorted_ids[:-1][np.diff(sorted_ids) == 0]
            raise MeshError(f"duplicate node numbers {dup[:10].tolist()}", node_path)
        pos = np.clip(np.searchsorted(sorted_ids, raw_tets), 0, n_nodes - 1)
        unknown = sorted_ids[pos] != raw_tets
        if unknown.any():
            bad = np.nonzero(unknown.any(axis=1))[0]
            raise MeshError(f"elements {elements[bad[:10], 0].tolist()} refer to node numbers not in "
                            f"{node_path.name}", ele_path)
        tets = order[pos]
    if tets.min() < 0 or tets.max() >= n_nodes:
        bad = np.nonzero(np.any((tets < 0) | (tets >= n_nodes), axis=1))[0]
        raise MeshError(f"elements {elements[bad[:10], 0].tolist()} refer to node numbers outside "
                        f"{base}..{base + n_nodes - 1}", ele_path)
    return points, tets, base, ele_path
