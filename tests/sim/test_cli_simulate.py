"""tonguevis simulate: figures on stdout, one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.cli import main
from tonguevis.paths import DATA_DIR
from tonguevis.sim import Motion


def test_simulate_prints_the_figures_and_writes_motion_and_vtk(tmp_path, capsys):
    code = main(["simulate", str(DATA_DIR / "spk2_ka.tsv"), "--quiet", "--out", str(tmp_path),
                 "--sensor-stiffness", "hard", "--vtk-series"])  # the old series on request (--out: motion.npz)
    out = capsys.readouterr().out
    assert code == 0, out
    for what in ("max sensor residual", "max volume change", "energy peak", "drift at the end", "TT->node",
                 "far-field amplification", "held exactly"):
        assert what in out
    residual_mm = float(out.split("max sensor residual: ")[1].split(" mm")[0])
    assert residual_mm < 0.01
    motion = Motion.load(tmp_path / "motion.npz")
    # 100 modes, then the sensor patches' shapes (three local ones per sensor: the sensors on the surface by
    # default, then each sensor's hump but the tip's: three translations and three times six leans)
    from tonguevis.sim.patches import HUMP_TILTS, humped_sensors

    patches = motion.metadata["sensor_patches"]
    assert patches["global_modes"] == 100 and motion.q.shape[1] == 100 + patches["shapes"]
    from tonguevis.sim.settings import RunSettings

    humped = len(humped_sensors(motion.sensor_names)) if RunSettings().humps else 0
    assert patches["shapes"] == 3 * len(motion.sensor_nodes) + 3 * (1 + HUMP_TILTS) * humped
    assert (patches["hump_mm"] is not None) == RunSettings().humps
    assert np.isfinite(motion.q).all()
    assert (tmp_path / "vtk" / "motion.pvd").exists()


def test_simulate_reports_bad_input_in_one_line(tmp_path, capsys):
    bad = tmp_path / "broken.tsv"
    bad.write_text("this is not an EMA export\n")
    assert main(["simulate", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "broken.tsv" in err[0]
    assert main(["simulate", str(DATA_DIR / "spk1_ta.tsv"), "--mesh", str(tmp_path / "none.vtu"), "--quiet"]) == 2
    assert "none.vtu" in capsys.readouterr().err


def test_default_sensor_springs_follow_the_sensors_closely_and_say_so(capsys):
    assert main(["simulate", str(DATA_DIR / "spk2_ka.tsv"), "--quiet", "--no-sensor-patches"]) == 0
    out = capsys.readouterr().out
    assert "sensor springs 20x" in out
    misfit_rms = float(out.split("sensor misfit ")[1].split(" mm RMS")[0])
    amplification = float(out.split("far-field amplification ")[1].split(" ")[0])
    assert 0.0 < misfit_rms < 1.0 and amplification < 2.0
    # the default: the sensor patches close the springs' gap, every sensor on the surface
    assert main(["simulate", str(DATA_DIR / "spk2_ka.tsv"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert float(out.split("sensor misfit ")[1].split(" mm RMS")[0]) < 1e-6


def test_bad_sensor_stiffness_is_a_one_line_error(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["simulate", str(DATA_DIR / "spk2_ka.tsv"), "--quiet", "--sensor-stiffness", "soft"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "soft" in err[-1] and "hard" in err[-1]
