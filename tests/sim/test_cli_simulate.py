"""tonguevis simulate: figures on stdout, one-line errors."""

from __future__ import annotations

import numpy as np

from tonguevis.cli import main
from tonguevis.paths import DATA_DIR
from tonguevis.sim import Motion


def test_simulate_prints_the_figures_and_writes_motion_and_vtk(tmp_path, capsys):
    code = main(["simulate", str(DATA_DIR / "spk2_ka.tsv"), "--modes", "30", "--quiet", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0, out
    for what in ("max sensor residual", "max volume change", "energy peak", "drift at the end", "TT->node"):
        assert what in out
    residual_mm = float(out.split("max sensor residual: ")[1].split(" mm")[0])
    assert residual_mm < 0.01
    motion = Motion.load(tmp_path / "motion.npz")
    assert motion.q.shape[1] == 30 and np.isfinite(motion.q).all()
    assert (tmp_path / "vtk" / "motion.pvd").exists()


def test_simulate_reports_bad_input_in_one_line(tmp_path, capsys):
    bad = tmp_path / "broken.tsv"
    bad.write_text("this is not an EMA export\n")
    assert main(["simulate", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "broken.tsv" in err[0]
    assert main(["simulate", str(DATA_DIR / "spk1_ta.tsv"), "--mesh", str(tmp_path / "none.vtu"), "--quiet"]) == 2
    assert "none.vtu" in capsys.readouterr().err
