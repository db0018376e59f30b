"""The plane section of a triangle surface (the live view's midsagittal outline)."""

import numpy as np

from tonguevis.analysis.section import plane_section


def test_a_cube_cut_in_the_middle_is_a_square():
    from tonguevis.mesh.structured import box_mesh

    mesh = box_mesh(3, 3, 3, size=(0.02, 0.04, 0.01), origin=(0.0, 0.0, 0.0))
    faces = mesh.boundary_faces()
    segments = plane_section(mesh.points, faces, 0.015)  # between two node layers
    length = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1).sum()
    assert np.isclose(length, 2 * (0.02 + 0.01))  # the 20 x 10 mm square's perimeter
    xz = segments.reshape(-1, 2)
    assert np.allclose(xz.min(axis=0), 0.0) and np.allclose(xz.max(axis=0), (0.02, 0.01))
    assert len(plane_section(mesh.points, faces, 0.05)) == 0  # beside the box
