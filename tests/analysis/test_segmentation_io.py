"""Segmentation results on disk (npz, VTU), input checking, progress and cancelling."""

from __future__ import annotations

import numpy as np
import pytest

from tests.analysis.segmentation_support import bar_mesh, bent_bar_displacement, tet_containing_x
from tonguevis.analysis.segmentation import SegmentationError, SegmentationResult, SegmentationTarget, segment
from tonguevis.errors import Cancelled, TonguevisError
from tonguevis.mesh.tetmesh import TetMesh


@pytest.fixture(scope="module")
def small_result():
    points, tets = bar_mesh(8, 2, 2, length=0.08)
    frames = np.stack([bent_bar_displacement(points, 0.03, 0.05, a) for a in (0.1, 0.3, 0.2)])
    target = SegmentationTarget.sequence(frames, np.array([1.0, 3.0, 2.0]), np.array([0.0, 0.01, 0.02]))
    seeds = [tet_containing_x(points, tets, x) for x in (0.0, 0.08)]
    return TetMesh(points, tets), target, segment(TetMesh(points, tets), target, "rigid", seeds=seeds)


def test_save_load_round_trip(tmp_path, small_result):
    _, _, result = small_result
    result.metadata["note"] = "bar"
    path = result.save(tmp_path / "seg.npz")
    loaded = SegmentationResult.load(path)
    assert loaded.mode == "rigid" and loaded.n_partitions == result.n_partitions
    for name in ("labels", "seeds", "approximation", "split_nodes", "split_tets", "element_errors",
                 "partition_errors", "target", "frame_weights", "history"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(result, name))
    assert loaded.global_error == result.global_error and loaded.relative_error == result.relative_error
    assert loaded.metadata["note"] == "bar"
    assert not list(tmp_path.glob("*.tmp"))


def test_load_rejects_other_and_broken_files(tmp_path, small_result):
    _, _, result = small_result
    other = tmp_path / "other.npz"
    np.savez(other, x=np.arange(3))
    with pytest.raises(SegmentationError, match="other.npz.*not a tonguevis segmentation"):
        SegmentationResult.load(other)
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not a zip file")
    with pytest.raises(SegmentationError, match="garbage.npz"):
        SegmentationResult.load(garbage)
    # a file whose arrays disagree with each other
    path = result.save(tmp_path / "seg.npz")
    with np.load(path, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["labels"] = arrays["labels"][:-1]
    broken = tmp_path / "broken.npz"
    np.savez(broken, **arrays)
    with pytest.raises(SegmentationError, match="broken.npz.*per-tet arrays"):
        SegmentationResult.load(broken)


def test_partition_rows_add_up(small_result):
    mesh, _, result = small_result
    rows = result.partition_rows()
    assert [r["partition"] for r in rows] == list(range(result.n_partitions))
    assert sum(r["tets"] for r in rows) == mesh.n_tets
    assert sum(r["volume_cm3"] for r in rows) == pytest.approx(1e6 * mesh.volume)
    for row in rows:
        assert (row["rms_error_mm"] / 1000) ** 2 == pytest.approx(result.partition_errors[row["partition"]])
        assert result.labels[row["seed"]] == row["partition"]
    # the left seed's partition lies left of the right one's
    assert rows[0]["centroid_m"][0] < rows[1]["centroid_m"][0]


def test_vtu_export_has_the_fields(tmp_path, small_result):
    import meshio

    mesh, target, result = small_result
    path = result.to_vtu(tmp_path / "seg.vtu")
    back = meshio.read(path)
    assert back.cells_dict["tetra"].shape == (mesh.n_tets, 4)
    np.testing.assert_array_equal(back.cell_data["partition"][0], result.labels)
    np.testing.assert_allclose(back.cell_data["element_error"][0], result.element_errors)
    # split mesh: one copy per partition of each interface node, carrying that partition's fit
    assert len(back.points) == len(result.split_nodes) > mesh.n_nodes
    peak = result.peak_frame
    assert peak == 1
    np.testing.assert_allclose(back.point_data["approximation"], result.approximation[peak])
    np.testing.assert_allclose(back.point_data["target"], target.displacements[peak][result.split_nodes])
    np.testing.assert_allclose(result.approximated_points(peak), back.points + back.point_data["approximation"])
    np.testing.assert_allclose(result.target_points(0), mesh.points + target.displacements[0])
    joined = result.to_meshio(frame=0, split=False)
    assert len(joined.points) == mesh.n_nodes
    with pytest.raises(SegmentationError, match="frame 7"):
        result.to_vtu(tmp_path / "x.vtu", frame=7)


def test_bad_input_is_reported(small_result):
    mesh, target, _ = small_result
    with pytest.raises(SegmentationError, match="mode"):
        segment(mesh, target, "elastic", seeds=[0])
    with pytest.raises(SegmentationError, match="outside"):
        segment(mesh, target, "rigid", seeds=[0, mesh.n_tets])
    with pytest.raises(SegmentationError, match="overlap"):
        segment(mesh, target, "rigid", seeds=[[0, 1], [1, 2]])
    with pytest.raises(SegmentationError, match="nodes"):
        segment(TetMesh(mesh.points[:-1], mesh.tets[:5]), target, "rigid", seeds=[0])
    with pytest.raises(SegmentationError, match="threshold"):
        segment(mesh, target, "rigid", seeds="auto", threshold=5.0)
    with pytest.raises(SegmentationError, match="NaN"):
        SegmentationTarget.frame(np.full((4, 3), np.nan))
    with pytest.raises(SegmentationError, match="no elastic energy"):
        SegmentationTarget.sequence(target.displacements, np.zeros(3))
    assert issubclass(SegmentationError, TonguevisError)


def test_progress_reports_and_cancels(small_result):
    mesh, target, _ = small_result
    calls = []
    segment(mesh, target, "constraint", seeds="auto", n_partitions=2, constrained_nodes=[],
            progress=lambda done, total, message: calls.append((done, total, message)))
    assert calls and all(0 <= d <= t for d, t, _ in calls)
    assert any("autoseeding" in m for _, _, m in calls)
    assert calls[-1][0] == calls[-1][1]

    def cancel_soon(done, total, message):
        if done > 5:
            raise Cancelled()

    with pytest.raises(Cancelled):
        segment(mesh, target, "constraint", seeds=[0, mesh.n_tets - 1], constrained_nodes=[], progress=cancel_soon)


@pytest.mark.parametrize("mode", ["rigid", "constraint"])
def test_a_part_no_seed_can_reach_gets_its_own_partition(mode):
    points, tets = bar_mesh(4, 2, 2, length=0.04)
    far = points + [0.1, 0.0, 0.0]  # a second, separate bar
    both = TetMesh(np.vstack([points, far]), np.vstack([tets, tets + len(points)]))
    u = np.vstack([bent_bar_displacement(points, 0.01, 0.03, 0.2), bent_bar_displacement(far, 0.11, 0.13, 0.3)])
    target = SegmentationTarget.frame(u)
    result = segment(both, target, mode, seeds=[0], constrained_nodes=[])
    assert result.n_partitions == 2
    assert np.all(result.labels[: len(tets)] == 0) and np.all(result.labels[len(tets):] == 1)
    assert result.seeds.tolist() == [0, len(tets)]
    auto = segment(both, target, mode, seeds="auto", n_partitions=2, threshold=None, constrained_nodes=[])
    assert auto.n_partitions == 2 and len(np.unique(auto.labels[: len(tets)])) == 1
