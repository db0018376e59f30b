"""Boundary geometry, context surfaces, element quality and the manifold check,
each against a plain reference."""

from __future__ import annotations

import logging
from collections import defaultdict

import meshio
import numpy as np
import pytest

from tests.conftest import shared_file
from tests.mesh.helpers import box_mesh
from tonguevis.mesh import (
    MeshError,
    TetMesh,
    dorsal_surface_nodes,
    inferior_surface_nodes,
    read_surface,
    tet_quality,
)
from tonguevis.mesh.checks import _check_manifold
from tonguevis.mesh.surfaces import surface_heights


@pytest.fixture
def box():
    points, tets = box_mesh(3, 3, 2, size=(0.03, 0.03, 0.02))
    return TetMesh(points, tets)


def test_surface_heights_match_a_loop_reference(box):
    rng = np.random.default_rng(1)
    xy = rng.uniform(-0.005, 0.035, size=(40, 2))
    fast = surface_heights(box, xy)
    faces = box.boundary_faces()
    for q, (low, high) in zip(xy, fast):
        zs = []
        for f in faces:                                          # reference: one face at a time
            a, b, c = box.points[f]
            m = np.array([[b[0] - a[0], c[0] - a[0]], [b[1] - a[1], c[1] - a[1]]])
            if abs(np.linalg.det(m)) < 1e-18:
                continue
            u, v = np.linalg.solve(m, q - a[:2])
            if u >= -1e-12 and v >= -1e-12 and u + v <= 1 + 1e-12:
                zs.append(a[2] + u * (b[2] - a[2]) + v * (c[2] - a[2]))
        if zs:
            assert low == pytest.approx(min(zs)) and high == pytest.approx(max(zs))
        else:
            assert np.isnan(low) and np.isnan(high)
    inside = (xy >= 0).all(axis=1) & (xy <= 0.03).all(axis=1)
    np.testing.assert_allclose(fast[inside], [[0.0, 0.02]] * inside.sum(), atol=1e-12)


def test_dorsal_and_inferior_nodes_of_a_box(box):
    z = box.points[:, 2]
    np.testing.assert_array_equal(dorsal_surface_nodes(box), np.nonzero(np.isclose(z, z.max()))[0])
    np.testing.assert_array_equal(inferior_surface_nodes(box), np.nonzero(np.isclose(z, z.min()))[0])


def test_dorsal_nodes_exclude_shadowed_upward_faces():
    """A floor under an overhang faces up but is not dorsal (like the mouth floor under the blade)."""
    points, tets = box_mesh(4, 1, 3, size=(0.04, 0.01, 0.03))
    keep = ~((points[tets, 0].mean(axis=1) > 0.02) & (points[tets, 2].mean(axis=1) > 0.01)
             & (points[tets, 2].mean(axis=1) < 0.02))            # a slot under a shelf at the front
    mesh = TetMesh(points, tets[keep])
    used = np.unique(mesh.tets)
    dorsal = dorsal_surface_nodes(mesh)
    assert np.all(np.isclose(mesh.points[dorsal, 2], 0.03))
    slot_floor = used[(mesh.points[used, 0] > 0.021) & np.isclose(mesh.points[used, 2], 0.01)]
    assert slot_floor.size and not set(slot_floor) & set(dorsal)


def test_tet_quality_known_values():
    regular = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)
    corner = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    flat = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, 1e-9]], float)
    t = np.array([[0, 1, 3, 2]])
    assert tet_quality(regular, t)[0] == pytest.approx(1.0)
    assert tet_quality(regular, t[:, [0, 1, 3, 2]])[0] == pytest.approx(-1.0)
    assert tet_quality(corner, np.array([[0, 1, 2, 3]]))[0] == pytest.approx(3 / (3 + np.sqrt(3)) * 2 / np.sqrt(3))
    assert tet_quality(corner * 1e-3 + 5, np.array([[0, 1, 2, 3]]))[0] == pytest.approx(
        tet_quality(corner, np.array([[0, 1, 2, 3]]))[0])
    assert abs(tet_quality(flat, np.array([[0, 1, 2, 3]]))[0]) < 1e-6


def _reference_manifold(tets: np.ndarray) -> bool:
    """Plain-Python check: faces in <= 2 tets, boundary edges in 2 faces, one fan per node."""
    face_count = defaultdict(list)
    for t in tets:
        for f in ((t[1], t[2], t[3]), (t[0], t[3], t[2]), (t[0], t[1], t[3]), (t[0], t[2], t[1])):
            face_count[tuple(sorted(f))].append(f)
    if any(len(v) > 2 for v in face_count.values()):
        return False
    boundary = [v[0] for v in face_count.values() if len(v) == 1]
    edge_faces = defaultdict(list)
    for i, f in enumerate(boundary):
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            edge_faces[tuple(sorted((a, b)))].append(i)
    if any(len(v) != 2 for v in edge_faces.values()):
        return False
    node_faces = defaultdict(set)
    for i, f in enumerate(boundary):
        for v in f:
            node_faces[v].add(i)
    for v, faces in node_faces.items():
        seen, stack = set(), [next(iter(faces))]
        while stack:
            i = stack.pop()
            if i in seen:
                continue
            seen.add(i)
            for e, fs in edge_faces.items():
                if v in e and i in fs:
                    stack.extend(j for j in fs if j != i)
        if seen != faces:
            return False
    return True


def _random_subsets():
    """Tet subsets of a box: half cut by a random plane (mostly manifold), half with
    random tets deleted (mostly not)."""
    points, tets = box_mesh(2, 2, 2)
    centres = points[tets].mean(axis=1)
    rng = np.random.default_rng(7)
    for k in range(24):
        if k % 2 == 0:
            normal = rng.normal(size=3)
            keep = (centres - 0.5) @ normal < rng.uniform(-0.3, 0.3) * np.linalg.norm(normal)
            yield tets[keep] if keep.sum() else tets
        else:
            yield np.delete(tets, rng.choice(len(tets), 1 + k % 5, replace=False), axis=0)


def test_manifold_check_matches_the_reference():
    verdicts = []
    for subset in _random_subsets():
        try:
            _check_manifold(subset, None, 0)
            fast = True
        except MeshError:
            fast = False
        assert fast == _reference_manifold(subset)
        verdicts.append(fast)
    assert 3 <= sum(verdicts) <= len(verdicts) - 3              # both outcomes exercised


def test_read_surface_formats_and_units(tmp_path, caplog):
    points = np.array([[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0]], float)  # mm
    meshio.write(tmp_path / "q.obj", meshio.Mesh(points, [("quad", np.array([[0, 1, 2, 3]]))]))
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        p, t = read_surface(tmp_path / "q.obj")
    assert "millimetres" in caplog.text
    np.testing.assert_allclose(p, points * 1e-3)
    np.testing.assert_array_equal(t, [[0, 1, 2], [0, 2, 3]])
    meshio.write(tmp_path / "t.stl", meshio.Mesh(points * 1e-3, [("triangle", np.array([[0, 1, 2]]))]))
    p, t = read_surface(tmp_path / "t.stl")
    assert t.shape == (1, 3) and np.ptp(p) == pytest.approx(0.01)
    with pytest.raises(MeshError, match="no such surface"):
        read_surface(tmp_path / "absent.stl")
    (tmp_path / "junk.ply").write_text("nonsense")
    with pytest.raises(MeshError, match="junk.ply"):
        read_surface(tmp_path / "junk.ply")


def test_read_artisynth_context_surface():
    points, triangles = read_surface(shared_file("artisynth", "ubcjaw_symmetric.obj"))
    assert 0.05 < np.ptp(points, axis=0).max() < 0.2            # metres
    assert triangles.shape[1] == 3 and triangles.max() < len(points)


def test_boundary_faces_match_a_dict_reference():
    from tonguevis.mesh import boundary_faces
    from tonguevis.mesh.tetmesh import face_keys

    for subset in _random_subsets():
        count = defaultdict(list)
        for t in subset:
            for f in ((t[1], t[2], t[3]), (t[0], t[3], t[2]), (t[0], t[1], t[3]), (t[0], t[2], t[1])):
                count[tuple(sorted(f))].append(f)
        expected = sorted(tuple(int(i) for i in v[0]) for v in count.values() if len(v) == 1)
        assert sorted(tuple(int(i) for i in f) for f in boundary_faces(subset)) == expected
    keys = face_keys(np.array([[3, 1, 2], [2, 3, 1], [1, 2, 4], [2_000_000, 0, 1]]))
    assert keys[0] == keys[1] and len(set(keys.tolist())) == 3
