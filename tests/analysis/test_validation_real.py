"""Leave-one-sensor-out on the real Haskins recording (TT, TB, TBK) and the paper's ArtiSynth tongue."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tests.conftest import shared_file


@pytest.fixture(scope="module")
def artisynth_model():
    from tonguevis.mesh.axes import ARTISYNTH_AXES
    from tonguevis.mesh.readers import read_mesh
    from tonguevis.sim.model import TongueModel

    mesh = read_mesh(shared_file("artisynth", "tongue3.1.node"), axes=ARTISYNTH_AXES)
    p = mesh.points
    tip = p[:, 0].max()

    def dorsal(behind_tip):  # highest midline node so far behind the tip (the placement rule, simply)
        near = np.flatnonzero((np.abs(p[:, 0] - (tip - behind_tip)) < 3e-3) & (np.abs(p[:, 1]) < 3e-3))
        return int(near[np.argmax(p[near, 2])])

    sensors = {"TT": dorsal(0.01), "TB": dorsal(0.02), "TBK": dorsal(0.045)}
    floor = np.flatnonzero(p[:, 2] < p[:, 2].min() + 2e-3)  # clamp the mesh floor
    return TongueModel(mesh, SimpleNamespace(sensors=sensors, anchors=floor))


def test_haskins_sentence_without_rest(artisynth_model):
    from tonguevis.analysis.validation import validate
    from tonguevis.io import read_recording

    rec = read_recording(shared_file("ema", "mview", "F01_B01_S01_R01_N.mat"), sensor_map="haskins")
    result = validate(rec, artisynth_model, modes=30, landmarks="rule", quasi_static=False)
    r = result.recording
    # 2.6 s of speech with no rest: the stillest window stands in, and says so.
    assert r["rest_interval_from"] == "stillest window"
    assert r["rest_interval_s"][1] - r["rest_interval_s"][0] == pytest.approx(0.2, abs=0.011)
    assert r["midsagittal_alignment"] and r["tongue_sensors"] == ["TT", "TB", "TBK"]
    # Default sensor springs: no frame flagged, a believable shape near the sensors.
    assert r["unconverged_frames"] == 0 and r["sensor_residual_mean_mm"] < 3.0
    p = r["plausibility"]
    assert p["amplification"] < 2.0 and p["volume_change_max_percent"] < 2.0
    for name, s in result.sensors.items():
        assert s["frames"] == rec.n_samples
        assert s["measured_peak_mm"] > 5  # every tongue sensor moved in the sentence
        assert all(np.isfinite(s[f"{m}_rmse_mm"]) for m in ("model", "linear", "kinematic")), name
    # Two drivers: the kinematic baseline is linear along their line; TB lies between TT and TBK.
    assert result.sensors["TB"]["outside_drivers"] is False
    assert result.sensors["TT"]["outside_drivers"] is True
    w = np.array(result.sensors["TB"]["kinematic_weights"])
    assert np.all(w > 0) and w.sum() == pytest.approx(1.0)
