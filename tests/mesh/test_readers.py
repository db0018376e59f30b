"""read_mesh: formats, numbering, units, axes and every kind of bad input."""

from __future__ import annotations

import logging

import meshio
import numpy as np
import pytest

from tests.mesh.helpers import box_mesh, write_tetgen
from tonguevis.errors import TonguevisError
from tonguevis.mesh import MeshError, apply_axes, axes_matrix, read_mesh


@pytest.fixture
def box():
    return box_mesh(2, 2, 2, size=(0.04, 0.03, 0.02))


def _same_mesh(mesh, points, tets):
    np.testing.assert_allclose(mesh.points, points, atol=1e-12)
    np.testing.assert_array_equal(np.sort(mesh.tets, axis=1), np.sort(tets, axis=1))
    assert np.all(mesh.tet_volumes() > 0)


@pytest.mark.parametrize("base", [0, 1])
@pytest.mark.parametrize("attributes", [False, True])
def test_tetgen_zero_and_one_based(tmp_path, box, base, attributes):
    points, tets = box
    node = write_tetgen(tmp_path / "box", points, tets, base=base, attributes=attributes)
    for path in (node, node.with_suffix(".ele"), tmp_path / "box"):
        _same_mesh(read_mesh(path), points, tets)


def test_tetgen_with_shuffled_node_numbers(tmp_path, box):
    points, tets = box
    ids = np.random.default_rng(0).permutation(len(points)) * 3 + 5     # sparse, unordered numbers
    lines = [f"{len(points)} 3 0 0"] + [f"{ids[i]} {p[0]} {p[1]} {p[2]}" for i, p in enumerate(points)]
    (tmp_path / "m.node").write_text("\n".join(lines) + "\n")
    lines = [f"{len(tets)} 4 0"] + [f"{i} " + " ".join(str(ids[v]) for v in t) for i, t in enumerate(tets)]
    (tmp_path / "m.ele").write_text("\n".join(lines) + "\n")
    _same_mesh(read_mesh(tmp_path / "m.node"), points, tets)


@pytest.mark.parametrize("suffix,fmt", [(".vtu", "vtu"), (".vtk", "vtk"), (".msh", "gmsh22")])
def test_meshio_formats(tmp_path, box, suffix, fmt):
    points, tets = box
    path = tmp_path / f"box{suffix}"
    cells = [("tetra", tets)]
    if fmt == "gmsh22":  # Gmsh files usually carry boundary triangles too: ignored
        cells.append(("triangle", tets[:2, :3]))
    meshio.write(path, meshio.Mesh(points, cells), file_format=fmt)
    _same_mesh(read_mesh(path), points, tets)


def test_npz(tmp_path, box):
    points, tets = box
    np.savez(tmp_path / "box.npz", points=points, tets=tets)
    _same_mesh(read_mesh(tmp_path / "box.npz"), points, tets)


def test_npz_with_pickled_objects_is_refused(tmp_path, box):
    points, tets = box
    np.savez(tmp_path / "evil.npz", points=points, tets=np.array([object()], dtype=object))
    with pytest.raises(MeshError, match="evil.npz"):
        read_mesh(tmp_path / "evil.npz")


def test_npz_missing_arrays(tmp_path, box):
    np.savez(tmp_path / "half.npz", points=box[0])
    with pytest.raises(MeshError, match="tets"):
        read_mesh(tmp_path / "half.npz")


def test_inverted_tets_are_reoriented_with_a_warning(tmp_path, box, caplog):
    points, tets = box
    bad = tets.copy()
    bad[[3, 7]] = bad[[3, 7]][:, [1, 0, 2, 3]]
    write_tetgen(tmp_path / "inv", points, bad)
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        mesh = read_mesh(tmp_path / "inv.node")
    assert "reoriented 2 inverted tets" in caplog.text and "3, 7" in caplog.text
    _same_mesh(mesh, points, tets)


def test_degenerate_tet_is_an_error_naming_it(tmp_path, box):
    points, tets = box
    points = np.vstack([points, [0.01, 0.0, 0.0], [0.02, 0.0, 0.0]])   # on a line through node 0
    flat = np.array([[0, len(points) - 2, len(points) - 1, 1]])        # three collinear corners: zero volume
    tets_bad = np.vstack([tets, flat])
    write_tetgen(tmp_path / "deg", points, tets_bad, base=1)
    with pytest.raises(MeshError, match=r"deg\.ele.*degenerate.*elements %d" % (len(tets) + 1)):
        read_mesh(tmp_path / "deg.node")


def test_repeated_node_is_degenerate(tmp_path, box):
    points, tets = box
    bad = tets.copy()
    bad[5, 3] = bad[5, 0]
    write_tetgen(tmp_path / "rep", points, bad)
    with pytest.raises(MeshError, match="degenerate.*elements 5"):
        read_mesh(tmp_path / "rep.node")


def test_dangling_node_is_an_error_naming_it(tmp_path, box):
    points, tets = box
    write_tetgen(tmp_path / "dang", np.vstack([points, [0.5, 0.5, 0.5]]), tets)
    with pytest.raises(MeshError, match=r"dangling.*nodes %d" % len(points)):
        read_mesh(tmp_path / "dang.node")


def _two_cubes_touching(shared: str):
    """Two unit cubes of tets meeting along an edge or at a corner only (non-manifold)."""
    p1, t1 = box_mesh(1, 1, 1)
    offset = np.array([1.0, 1.0, 0.0]) if shared == "edge" else np.array([1.0, 1.0, 1.0])
    p2 = p1 + offset
    points = np.vstack([p1, p2])
    tets = np.vstack([t1, t1 + len(p1)])
    # merge coincident nodes
    _, first, inverse = np.unique(points.round(9), axis=0, return_index=True, return_inverse=True)
    keep = np.sort(first)
    remap = np.searchsorted(keep, first[inverse.ravel()])
    return points[keep], remap[tets]


@pytest.mark.parametrize("shared,message", [("edge", "do not border exactly two"), ("corner", "pinched")])
def test_non_manifold_boundary_is_an_error(tmp_path, shared, message):
    points, tets = _two_cubes_touching(shared)
    write_tetgen(tmp_path / "nm", points, tets)
    with pytest.raises(MeshError, match=rf"nm\.ele.*non-manifold.*{message}"):
        read_mesh(tmp_path / "nm.node")


def test_face_shared_by_three_tets_is_an_error(tmp_path, box):
    points, tets = box
    # an interior face: the three nodes tet 0 shares with another tet
    other = next(j for j in range(1, len(tets)) if len(set(tets[0]) & set(tets[j])) == 3)
    face = sorted(set(tets[0]) & set(tets[other]))
    apex = points[face].mean(axis=0) + 1e-3 * np.array([1.0, 2.0, 3.0])
    points = np.vstack([points, apex])
    extra = np.array([[*face, len(points) - 1]])
    write_tetgen(tmp_path / "three", points, np.vstack([tets, extra]))
    with pytest.raises(MeshError, match="more than two tets"):
        read_mesh(tmp_path / "three.node")


def test_millimetres_are_converted_with_a_warning(tmp_path, box, caplog):
    points, tets = box
    np.savez(tmp_path / "mm.npz", points=points * 1e3, tets=tets)
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        mesh = read_mesh(tmp_path / "mm.npz")
    assert "millimetres" in caplog.text
    np.testing.assert_allclose(mesh.points, points)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        explicit = read_mesh(tmp_path / "mm.npz", unit="mm")
    assert caplog.text == ""
    np.testing.assert_allclose(explicit.points, points)
    assert np.allclose(read_mesh(tmp_path / "mm.npz", unit="m").points, points * 1e3)
    with pytest.raises(MeshError, match="unknown unit"):
        read_mesh(tmp_path / "mm.npz", unit="inch")


@pytest.mark.parametrize("which,text,match", [
    ("node", "10 3 0 0\n0 0 0 0\n1 1 0 0\n", "truncated: header announces 10 nodes"),
    ("node", "27 3 0 0\n" + "0 0.0 0.0\n" * 27, "truncated or malformed nodes line 2"),
    ("node", "", "empty"),
    ("node", "abc 3\n", "bad header"),
    ("node", "27 2 0 0\n", "dimension 3"),
    ("ele", "48 4 0\n0 1 2 3 4\n", "truncated: header announces 48 elements"),
    ("ele", "48 10 0\n", "only linear tets"),
])
def test_truncated_or_malformed_tetgen(tmp_path, box, which, text, match):
    node = write_tetgen(tmp_path / "t", *box)
    node.with_suffix("." + which).write_text(text)
    with pytest.raises(MeshError, match=rf"t\.{which}.*{match}|{match}.*t\.{which}") as info:
        read_mesh(node)
    assert isinstance(info.value, TonguevisError)


def test_tet_referring_to_missing_node(tmp_path, box):
    points, tets = box
    bad = tets.copy()
    bad[2, 1] = 99
    write_tetgen(tmp_path / "miss", points, bad)
    with pytest.raises(MeshError, match="elements \\[2\\]"):
        read_mesh(tmp_path / "miss.node")


def test_missing_companion_and_unknown_files(tmp_path, box):
    node = write_tetgen(tmp_path / "lonely", *box)
    node.with_suffix(".ele").unlink()
    with pytest.raises(MeshError, match="lonely.ele.*missing"):
        read_mesh(node)
    (tmp_path / "junk.vtu").write_text("not xml at all")
    with pytest.raises(MeshError, match="junk.vtu"):
        read_mesh(tmp_path / "junk.vtu")
    with pytest.raises(MeshError, match="no such mesh file"):
        read_mesh(tmp_path / "absent.vtu")
    meshio.write(tmp_path / "tri.vtu", meshio.Mesh(box[0], [("triangle", box[1][:, :3])]))
    with pytest.raises(MeshError, match="no linear tetrahedra"):
        read_mesh(tmp_path / "tri.vtu")


def test_axes_matrix_and_mapping(box):
    A = axes_matrix("-x,-z,-y")
    np.testing.assert_array_equal(A @ [1.0, 2.0, 3.0], [-1.0, -3.0, -2.0])
    assert np.isclose(np.linalg.det(A), 1.0)
    points, tets = box
    for axes in ("-x,-z,-y", "y,x,z", "x,y,-z", "+z, x, y"):
        new_points, new_tets = apply_axes(points, tets, axes)
        np.testing.assert_allclose(new_points, points @ axes_matrix(axes).T)
        volumes = np.einsum("ij,ij->i", new_points[new_tets[:, 1]] - new_points[new_tets[:, 0]],
                            np.cross(new_points[new_tets[:, 2]] - new_points[new_tets[:, 0]],
                                     new_points[new_tets[:, 3]] - new_points[new_tets[:, 0]]))
        assert np.all(volumes > 0)                              # reflections keep tets positive
    for bad in ("x,y", "x,x,z", "x,y,w", ""):
        with pytest.raises(MeshError, match="axis mapping"):
            axes_matrix(bad)


def test_read_mesh_applies_axes(tmp_path, box):
    points, tets = box
    np.savez(tmp_path / "b.npz", points=points, tets=tets)
    mesh = read_mesh(tmp_path / "b.npz", axes="-x,-z,-y")
    np.testing.assert_allclose(mesh.points, points * [-1, -1, -1] @ np.array([[1, 0, 0], [0, 0, 1], [0, 1, 0]]).T)
    assert np.isclose(mesh.volume, 0.04 * 0.03 * 0.02)
