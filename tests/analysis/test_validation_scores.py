"""Scores and the ``tonguevis validate`` command (the rest fallback: tests/preprocess/test_rest.py)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tonguevis.analysis.validation_scores import return_to_rest_frame, trajectory_scores


def _pearson(a, b):
    """Textbook Pearson r, one sample at a time (the reference)."""
    n = len(a)
    ma, mb = sum(a) / n, sum(b) / n
    cov = sum((x - ma) * (y - mb) for x, y in zip(a, b))
    va = sum((x - ma) ** 2 for x in a)
    vb = sum((y - mb) ** 2 for y in b)
    return cov / math.sqrt(va * vb)


def test_trajectory_scores_match_plain_formulas():
    rng = np.random.default_rng(5)
    t = np.linspace(0, 2, 201)
    measured = np.stack([3e-3 * np.sin(5 * t), 2e-4 * rng.normal(size=t.size), 4e-3 * np.cos(3 * t)], axis=1)
    predicted = measured * [0.8, 0.0, 1.1] + 1e-3 * rng.normal(size=measured.shape) * [1, 1, 1]
    s = trajectory_scores(measured, predicted)
    squared = [sum((p - m) ** 2 for p, m in zip(pr, me)) for pr, me in zip(predicted, measured)]
    assert s["rmse_mm"] == pytest.approx(1e3 * math.sqrt(sum(squared) / len(squared)), rel=1e-12)
    for axis in range(3):
        col = [(p[axis] - m[axis]) ** 2 for p, m in zip(predicted, measured)]
        assert s["rmse_axes_mm"][axis] == pytest.approx(1e3 * math.sqrt(sum(col) / len(col)), rel=1e-12)
        assert s["corr_axes"][axis] == pytest.approx(_pearson(measured[:, axis], predicted[:, axis]), abs=1e-12)
    # y moved 0.2 mm (< 1 mm): left out of the mean correlation.
    assert s["corr"] == pytest.approx((s["corr_axes"][0] + s["corr_axes"][2]) / 2, abs=1e-12)


def test_a_constant_prediction_has_zero_correlation():
    t = np.linspace(0, 1, 50)
    measured = np.stack([2e-3 * t, 3e-3 * t**2, -2e-3 * t], axis=1)
    s = trajectory_scores(measured, np.zeros_like(measured))
    assert s["corr_axes"] == [0.0, 0.0, 0.0] and s["corr"] == 0.0
    assert s["rmse_mm"] == pytest.approx(1e3 * np.sqrt(np.mean(np.sum(measured**2, axis=1))))


def test_proportional_trajectories_correlate_within_plus_minus_one():
    """p = c m + offset has r = sign(c) exactly up to rounding, and never beyond ±1.

    The plain quotient Σmp / (|m||p|) comes out as 1.0000000000000002 for
    about a third of such axes; the JSON promises -1 <= r <= 1.
    """
    rng = np.random.default_rng(0)
    for _ in range(100):
        measured = 1e-3 * rng.normal(size=(50, 3))
        for c in (0.3, 1.0, 2.7, -1.9):
            s = trajectory_scores(measured, c * measured + 0.01)
            r = np.array(s["corr_axes"])
            assert np.all((-1.0 <= r) & (r <= 1.0)), (c, r.tolist())
            np.testing.assert_allclose(r, np.sign(c), rtol=0, atol=1e-14)
            assert -1.0 <= s["corr"] <= 1.0


def test_return_to_rest_is_the_last_still_frame_after_moving():
    disp = np.zeros((10, 2, 3))
    disp[3:6, 0, 2] = 0.005  # 5 mm up, then back
    disp[8, 1, 0] = 0.0004  # 0.4 mm: still "at rest"
    disp[9, 1, 0] = 0.0008  # 0.8 mm: not at rest
    assert return_to_rest_frame(disp) == 8
    assert return_to_rest_frame(np.zeros((5, 2, 3))) is None
    disp[6:, 0, 2] = np.nan
    assert return_to_rest_frame(disp) is None


# ---------------------------------------------------------------------------- CLI


@pytest.fixture
def cli_setup(monkeypatch):
    """The CLI on the small box model of test_validation (the default mesh is too big for a test)."""
    from types import SimpleNamespace

    import tonguevis.cli.validate as command
    from tests.analysis.test_validation import DRIVERS, VIRTUAL, _generated
    from tonguevis.mesh.structured import box_mesh
    from tonguevis.sim.model import TongueModel

    mesh = box_mesh(6, 4, 2, size=(0.06, 0.03, 0.02))
    p = mesh.points
    sensors = {n: int(np.argmin(np.linalg.norm(p - [x, y, 0.02], axis=1))) for n, (x, y) in {**DRIVERS, **VIRTUAL}.items()}
    model = TongueModel(mesh, SimpleNamespace(sensors=sensors, anchors=np.flatnonzero(p[:, 0] < 1e-9)))
    monkeypatch.setattr(command, "load_model_args", lambda args: model)
    return model, _generated


def test_cli_writes_the_json_and_the_report(cli_setup, tmp_path, capsys):
    from tonguevis.cli import main
    from tonguevis.io import write_recording

    model, generated = cli_setup
    rec = generated(model, "linear", n_frames=60)
    path = tmp_path / "rec.csv"
    write_recording(rec, path)
    out, md = tmp_path / "v.json", tmp_path / "v.md"
    code = main(["validate", str(path), "--modes", "30", "--landmarks", "rule", "--rest", "0", "0.2",
                 "--json", str(out), "--md", str(md), "--quiet", "--no-static",
                 "--sensor-stiffness", "hard"])
    assert code == 0
    doc = json.loads(out.read_text())
    assert set(doc["sensors"]) == {"TT", "TB", "TD", "TL", "TR"}
    assert doc["sensors"]["TB"]["linear_rmse_mm"] < 1e-3  # CSV rounding only
    assert "static_rmse_mm" not in doc["sensors"]["TB"]
    report = md.read_text()
    assert "| TB |" in report and "kinematic RBF" in report
    assert "wrote" in capsys.readouterr().out


def test_cli_errors_on_bad_input(cli_setup, tmp_path, capsys):
    from tonguevis.cli import main
    from tonguevis.io import write_recording

    model, generated = cli_setup
    out = tmp_path / "v.json"
    assert main(["validate", str(tmp_path / "missing.tsv"), "--json", str(out)]) == 2
    assert "missing.tsv" in capsys.readouterr().err
    rec = generated(model, "linear", n_frames=40)
    two = tmp_path / "two.csv"
    write_recording(rec.with_sensors({k: rec.sensors[k] for k in ("TT", "TD")}), two)
    assert main(["validate", str(two), "--json", str(out), "--rest", "0", "0.2", "--quiet"]) == 2
    assert "at least 3 tongue sensors" in capsys.readouterr().err
    assert main(["validate", str(two), "--json", str(out), "--rest", "0.5", "0.2"]) == 2
    err = capsys.readouterr().err
    assert "the end must come after the start" in err and "two.csv" in err
    assert not out.exists()
