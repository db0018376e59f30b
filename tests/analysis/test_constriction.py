"""Constriction degree and location against a palate (issue 35): exact distances, signs, arc lengths, edges."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.analysis.constriction import closest_on_triangles, constriction, palate_geometry
from tonguevis.palate import PalateSurface


def _surface(height, x=(-0.04, 0.02), y=(-0.02, 0.02), step=1e-3, **kwargs) -> PalateSurface:
    """A palate z = height(x, y) (m) on a grid, midline y = 0."""
    xs = np.arange(x[0], x[1] + step / 2, step)
    ys = np.arange(y[0], y[1] + step / 2, step)
    gx, gy = np.meshgrid(xs, ys)
    return PalateSurface(xs, ys, height(gx, gy), metadata={"midline_y": 0.0}, **kwargs)


def _dome(x, y):
    return 0.012 - 18.0 * y ** 2 - 4.0 * (x - 0.01) ** 2


def _rotation(degrees: float, axis: int) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(np.radians(degrees) * np.eye(3)[axis]).as_matrix()


def test_the_closest_point_on_a_triangle_beats_every_point_of_it():
    """On the triangle, and no further than any of a dense sample of its points: the minimum (every region)."""
    rng = np.random.default_rng(3)
    n = 80
    a, b, c = (rng.normal(size=(n, 3)) for _ in range(3))
    p = rng.normal(scale=2.0, size=(n, 3))
    closest, region = closest_on_triangles(p, a, b, c)
    assert set(region.tolist()) == set(range(7))  # vertices, edges and insides all visited
    u = np.linspace(0.0, 1.0, 121)
    uu, vv = np.meshgrid(u, u)
    inside = uu + vv <= 1.0
    uu, vv = uu[inside], vv[inside]
    for k in range(n):
        samples = a[k] + uu[:, None] * (b[k] - a[k]) + vv[:, None] * (c[k] - a[k])
        best = np.linalg.norm(samples - p[k], axis=1).min()
        mine = np.linalg.norm(closest[k] - p[k])
        assert mine <= best + 1e-12
        # ... and on the triangle: its barycentric coordinates are within [0, 1]
        m = np.column_stack([b[k] - a[k], c[k] - a[k]])
        coords, *_ = np.linalg.lstsq(m, closest[k] - a[k], rcond=None)
        assert np.all(coords >= -1e-9) and coords.sum() <= 1 + 1e-9
        assert np.linalg.norm(m @ coords - (closest[k] - a[k])) < 1e-9


def test_the_candidate_search_equals_every_face_searched():
    """The KD-tree's candidates give the brute-force minimum over all faces, near and far, in a moved frame."""
    placed = _surface(_dome).transformed(_rotation(20.0, 2) @ _rotation(-8.0, 1), 1.3, np.array([0.01, -0.02, 0.005]))
    rng = np.random.default_rng(7)
    vertices, faces = placed.triangles()
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    points = rng.uniform(lo - 0.02, hi + 0.02, size=(150, 3))
    found = constriction(placed, points)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    for k, p in enumerate(points):
        near, _ = closest_on_triangles(np.tile(p, (len(faces), 1)), a, b, c)
        brute = np.linalg.norm(near - p, axis=1)
        assert abs(found.degree[k]) == pytest.approx(brute.min(), abs=1e-12)
        assert np.linalg.norm(found.closest[k] - p) == pytest.approx(brute.min(), abs=1e-12)
    gap, _ = placed.clearance(points)
    over = np.isfinite(gap)
    assert over.sum() > 20 and np.all(np.sign(found.degree[over]) == np.sign(gap[over]))  # below +, above -


def test_a_flat_and_a_sloping_palate_give_the_figures_by_hand():
    flat = _surface(lambda x, y: np.full_like(x, 0.010))
    points = np.array([[-0.010, 0.0, 0.004],   # 6 mm under the roof, 30 mm behind its front (x = 20 mm)
                       [0.000, 0.003, 0.013],   # 3 mm above it
                       [-0.050, 0.0, 0.010],    # 10 mm behind its back edge, at its height
                       [np.nan, 0.0, 0.0]])
    found = constriction(flat, points)
    assert found.degree[:3] * 1e3 == pytest.approx([6.0, -3.0, 10.0], abs=1e-9)
    assert found.location[:3] * 1e3 == pytest.approx([30.0, 20.0, 60.0], abs=1e-9)
    assert found.at_edge[:3].tolist() == [False, False, True]
    assert np.isnan(found.degree[3]) and np.isnan(found.location[3]) and not found.at_edge[3]
    # z = 10 mm + x / 2: the foot of the perpendicular from the origin is (-4, 0, 8) mm, 10/sqrt(1.25) mm away;
    # along the roof from its front (x = 20 mm) that is 24 mm of x, 24 sqrt(1.25) mm of arc.
    slope = _surface(lambda x, y: 0.010 + 0.5 * x)
    found = constriction(slope, np.zeros((1, 3)))
    assert found.degree[0] == pytest.approx(0.010 / np.sqrt(1.25), abs=1e-12)
    assert found.closest[0] == pytest.approx([-0.004, 0.0, 0.008], abs=1e-12)
    assert found.location[0] == pytest.approx(0.024 * np.sqrt(1.25), abs=1e-12)


def test_figures_scale_and_turn_with_the_palates_frame():
    own = _surface(lambda x, y: 0.010 + 0.5 * x)
    moved = own.transformed(_rotation(25.0, 2), 2.0, np.array([0.003, 0.004, -0.002]))
    point = np.array([[0.0, 0.0, 0.0]])
    there = 2.0 * point @ _rotation(25.0, 2).T + [0.003, 0.004, -0.002]
    mine, theirs = constriction(own, point), constriction(moved, there)
    assert theirs.degree[0] == pytest.approx(2.0 * mine.degree[0], abs=1e-12)
    assert theirs.location[0] == pytest.approx(2.0 * mine.location[0], abs=1e-12)
    geometry = palate_geometry(moved)
    assert geometry is palate_geometry(moved)  # built once per palate
    front = geometry.midline_points()[0]
    assert front == pytest.approx(moved._from_own(np.array([[0.02, 0.0, 0.02]]))[0], abs=1e-12)


def test_a_palate_without_cells_is_an_error():
    from tonguevis.palate import PalateError

    empty = _surface(lambda x, y: np.where(x > 0.0, np.nan, np.nan))
    with pytest.raises(PalateError, match="no surface"):
        constriction(empty, np.zeros((1, 3)))
