"""The shipped tongue: size, quality, landmarks, context surfaces."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.mesh import (
    SENSOR_NAMES,
    context_surface_path,
    find_landmarks,
    load_default_landmarks,
    load_default_mesh,
    read_surface,
    tet_quality,
)


@pytest.fixture(scope="module")
def mesh():
    return load_default_mesh()


def test_size_near_the_papers_mesh(mesh):
    assert 1500 <= mesh.n_nodes <= 2200
    assert 6500 <= mesh.n_tets <= 10000
    assert 80e-6 <= mesh.volume <= 100e-6                       # m³: 80-100 cm³


def test_adult_proportions_in_our_frame(mesh):
    extent = np.ptp(mesh.points, axis=0) * 1e3                  # mm
    assert 70 <= extent[0] <= 82                                # tip to root
    assert 60 <= extent[1] <= 72                                # width at the root
    assert 50 <= extent[2] <= 60                                # floor to dorsum
    tip = mesh.points[np.argmax(mesh.points[:, 0])]
    assert abs(tip[1]) < 2e-3                                   # tip on the midline
    assert tip[2] - mesh.points[:, 2].min() > 0.035             # the blade hangs free


def test_symmetric_about_y0(mesh):
    """Mirrored boundary nodes lie on the boundary surface (not node on node: fTetWild's
    nodes are not symmetric, the shape is)."""
    pv = pytest.importorskip("pyvista")
    from tonguevis.mesh import midline_y

    faces = mesh.boundary_faces()
    surface = pv.PolyData(mesh.points, np.column_stack([np.full(len(faces), 3), faces]).ravel())
    mirrored = pv.PolyData(mesh.points[np.unique(faces)] * [1, -1, 1])
    distance = np.abs(mirrored.compute_implicit_distance(surface)["implicit_distance"])
    assert np.median(distance) < 0.2e-3 and np.percentile(distance, 99) < 1e-3
    assert abs(midline_y(mesh)) < 0.5e-3


def test_tets_positive_and_decent(mesh):
    quality = tet_quality(mesh.points, mesh.tets)
    assert quality.min() > 0.1
    assert np.median(quality) > 0.7


def test_shipped_landmarks_match_the_rule(mesh):
    shipped = load_default_landmarks(mesh)
    found = find_landmarks(mesh)
    assert set(SENSOR_NAMES) <= set(shipped.sensors)
    assert shipped.sensors == found.sensors
    np.testing.assert_array_equal(shipped.anchors, found.anchors)


@pytest.mark.parametrize("name", ["jaw", "palate"])
def test_context_surfaces_in_metres_around_the_tongue(mesh, name):
    points, triangles = read_surface(context_surface_path(name))
    assert triangles.shape[1] == 3 and triangles.max() < len(points)
    assert np.ptp(points, axis=0).max() < 0.15
    centre = mesh.points.mean(axis=0)
    assert np.linalg.norm(points.mean(axis=0)[:2] - centre[:2]) < 0.04


def test_proportions_follow_design_md(mesh):
    """Measured on the shipped mesh like DESIGN.md measured the ArtiSynth tongue:
    blade free for ~18 mm, half-widths, dorsum heights, root (all mm)."""
    from tonguevis.mesh.surfaces import surface_heights

    p = mesh.points * 1e3
    tip, floor = p[:, 0].max(), p[:, 2].min()

    def half_width(s):
        ys = np.arange(0.0, 40.0, 0.25)
        h = surface_heights(mesh, np.column_stack([np.full_like(ys, tip - s), ys]) * 1e-3)
        return ys[~np.isnan(h[:, 0])].max()

    def midline(s):
        low, high = surface_heights(mesh, np.array([[tip - s, 0.0]]) * 1e-3)[0] * 1e3 - floor
        return low, high

    assert 7 <= half_width(2) <= 11
    assert 12 <= half_width(15) <= 16
    assert 21 <= half_width(40) <= 27
    assert 31 <= half_width(65) <= 36
    for s in (5, 10, 15):                                       # the blade hangs free
        low, high = midline(s)
        assert 30 < low < 44 and 48 < high < 55
    for s in (25, 35, 45, 55):                                  # the body reaches the floor
        low, high = midline(s)
        assert low < 8 and 48 <= high <= 57
    assert 20 <= midline(74)[1] <= 32                           # the root falls towards the hyoid
