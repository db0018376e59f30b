"""``tonguevis segment``: a demo recording simulated on a small block, segmented, written."""

from __future__ import annotations

import numpy as np
import pytest

from tests.analysis.segmentation_support import box_model
from tonguevis.analysis.segmentation import SegmentationResult
from tonguevis.paths import DATA_DIR

RECORDING = DATA_DIR / "spk1_ta.tsv"


@pytest.fixture
def block(monkeypatch):
    from tonguevis.cli import segment as segment_cli

    model = box_model()
    monkeypatch.setattr(segment_cli, "load_model", lambda mesh, axes: model)
    return model


def _run(*arguments):
    from tonguevis.cli import main

    return main(["segment", str(RECORDING), "--modes", "20", "--landmarks", "rule", "--quiet",
                 *arguments])


def test_production_autoseeded_to_a_count_writes_vtu_png_npz(block, tmp_path, capsys):
    import meshio

    pytest.importorskip("pyvista", reason="the PNG is rendered with pyvista (the gui extra)")

    vtu, png, npz = tmp_path / "s.vtu", tmp_path / "s.png", tmp_path / "s.npz"
    code = _run("--production", "2", "--mode-kind", "constraint", "--seeds", "3", "--out", str(vtu),
                "--png", str(png), "--save", str(npz))
    out = capsys.readouterr().out
    assert code == 0, out
    result = SegmentationResult.load(npz)
    assert result.n_partitions == 3 and result.mode == "constraint"
    assert result.n_frames > 5  # a whole production, energy-weighted
    np.testing.assert_allclose(result.frame_weights.sum(), 1.0)
    # the anchors are constrained: the fit equals the target there (zero: anchors do not move)
    approximation = result.nodal_approximation()
    np.testing.assert_allclose(approximation[:, block.anchors], result.target[:, block.anchors], atol=1e-15)
    mesh = meshio.read(vtu)
    assert sorted(np.unique(mesh.cell_data["partition"][0])) == [0, 1, 2]
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 10_000
    assert "3 partitions with constraint modes" in out and f"{100 * result.relative_error:.2f} %" in out


def test_single_frame_with_seed_tets(block, tmp_path, capsys):
    vtu, npz = tmp_path / "s.vtu", tmp_path / "s.npz"
    code = _run("--time", "12.9", "--mode-kind", "rigid", "--seed-tets", f"0,{block.mesh.n_tets - 1}",
                "--out", str(vtu), "--save", str(npz))
    assert code == 0, capsys.readouterr()
    result = SegmentationResult.load(npz)
    assert result.n_frames == 1 and result.frame_times[0] == pytest.approx(12.9, abs=0.006)
    assert result.seeds.tolist() == [0, block.mesh.n_tets - 1] and result.mode == "rigid"


def test_bad_arguments_are_one_line_errors(block, tmp_path, capsys):
    code = _run("--seeds", "many", "--out", str(tmp_path / "s.vtu"))
    assert code == 2 and "--seeds wants 'auto' or a partition count" in capsys.readouterr().err
    code = _run("--production", "99", "--out", str(tmp_path / "s.vtu"))
    err = capsys.readouterr().err
    assert code == 2 and "production 99" in err and "spk1_ta.tsv" in err
    assert not (tmp_path / "s.vtu").exists()
