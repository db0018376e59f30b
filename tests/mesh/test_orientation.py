"""A mesh's axes found from its shape (tonguevis.mesh.orientation), and refused when it lies turned."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import shared_file
from tests.mesh.helpers import box_mesh
from tonguevis.mesh import ARTISYNTH_AXES, MeshError, TetMesh, apply_axes, axes_matrix, load_default_mesh, read_mesh
from tonguevis.mesh.orientation import find_axes, proper_axis_mappings


@pytest.fixture(scope="module")
def ours():
    return load_default_mesh()


def test_the_24_proper_mappings_are_distinct_rotations():
    mappings = proper_axis_mappings()
    assert len(mappings) == 24 and mappings[0] == "x,y,z"
    matrices = {axes_matrix(m).tobytes() for m in mappings}
    assert len(matrices) == 24
    assert all(np.linalg.det(axes_matrix(m)) == pytest.approx(1.0) for m in mappings)


@pytest.mark.parametrize("turn", ["x,y,z", "-x,-z,-y", "z,x,y", "-y,x,z", "x,-y,-z"])
def test_our_tongue_turned_any_way_is_turned_back(ours, turn):
    """Turned, moved and scaled to millimetres, the shipped tongue's mapping back is found."""
    points, tets = apply_axes(ours.points * 1000.0 + [40.0, -70.0, 12.0], ours.tets, turn)
    fit = find_axes(TetMesh(points, tets))
    assert fit.decided and fit.margin > 1.5
    np.testing.assert_array_equal(axes_matrix(fit.axes), axes_matrix(turn).T)  # the inverse turn
    assert fit.in_our_frame == (turn == "x,y,z")


def test_a_box_does_not_tell_its_axes():
    points, tets = box_mesh(3, 3, 3, size=(0.05, 0.05, 0.05))
    fit = find_axes(TetMesh(points, tets))
    assert not fit.decided


def test_auto_axes_refused_when_the_shape_does_not_tell(tmp_path):
    from tests.mesh.helpers import write_tetgen

    points, tets = box_mesh(3, 3, 3, size=(0.05, 0.05, 0.05))
    path = write_tetgen(tmp_path / "cube", points, tets)
    with pytest.raises(MeshError, match=r"cube.*cannot tell the mesh's axes.*--mesh-axes"):
        read_mesh(path, axes="auto")


def test_the_artisynth_tongue_in_its_own_frame_is_found_and_turned():
    """Raw tongue3.1 (x backwards, y down, z lateral): the mapping of DATA.md is found."""
    path = shared_file("artisynth", "tongue3.1.node")
    fit = find_axes(read_mesh(path))
    assert fit.axes == ARTISYNTH_AXES and fit.decided and not fit.in_our_frame
    auto = read_mesh(path, axes="auto")
    given = read_mesh(path, axes=ARTISYNTH_AXES)
    assert auto.metadata["axes"] == ARTISYNTH_AXES and auto.metadata["axes_found"]
    np.testing.assert_array_equal(auto.points, given.points)
    np.testing.assert_array_equal(auto.tets, given.tets)


def test_a_model_of_a_turned_mesh_is_refused_with_the_axes_to_give():
    """Landmarks on a mesh on its side would put the sensors on its flank: ask for the axes instead."""
    from tonguevis.sim.model import TongueModel

    path = shared_file("artisynth", "tongue3.1.node")
    with pytest.raises(MeshError, match=r"tongue3\.1.*not lie in our frame.*'-x,-z,-y'.*--mesh-axes=-x,-z,-y"):
        TongueModel.from_mesh(path)
    model = TongueModel.from_mesh(path, axes="auto")
    assert abs(model.landmarks.metadata["midline_y_m"]) < 1e-3  # the midline found: the mesh's z = 0
    assert model.mesh.points[model.landmarks.sensors["TT"], 0] > model.mesh.points[model.landmarks.sensors["TD"], 0]
