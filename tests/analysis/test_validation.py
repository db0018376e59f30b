"""Leave-one-sensor-out validation on synthetic cases with known answers."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from tonguevis.analysis.kinematic import interpolation_weights
from tonguevis.analysis.quasistatic import linear_static, quasi_static
from tonguevis.analysis.validation import validate
from tonguevis.io.recording import Recording
from tonguevis.mesh.structured import box_mesh
from tonguevis.sim.model import TongueModel
from tonguevis.sim.newmark import NewmarkSettings, integrate

MODES = 30
RATE = 100.0
REST = (0.0, 0.2)
# A 60 x 30 x 20 mm block clamped at x = 0; sensors on its top face (z = 20 mm).
DRIVERS = {"TT": (0.06, 0.015), "TD": (0.03, 0.015), "TL": (0.04, 0.0225), "TR": (0.04, 0.0075)}
VIRTUAL = {"TB": (0.05, 0.015)}


@pytest.fixture(scope="module")
def box_model():
    mesh = box_mesh(6, 4, 2, size=(0.06, 0.03, 0.02))
    p = mesh.points

    def node(x, y):
        return int(np.argmin(np.linalg.norm(p - [x, y, 0.02], axis=1)))

    sensors = {name: node(*xy) for name, xy in {**DRIVERS, **VIRTUAL}.items()}
    anchors = np.flatnonzero(p[:, 0] < 1e-9)
    return TongueModel(mesh, SimpleNamespace(sensors=sensors, anchors=anchors))


def _driver_targets(n_frames: int) -> np.ndarray:
    """(F, 4, 3) smooth driving displacements (m): rest for 0.3 s, then a tip raise and a sideways sway."""
    t = np.arange(n_frames) / RATE
    ramp = np.clip((t - 0.3) / 0.4, 0.0, 1.0)
    wave = np.sin(2 * np.pi * 2.0 * np.clip(t - 0.3, 0.0, None))
    tt = np.stack([0.002 * wave, 0.001 * ramp, 0.006 * ramp + 0.002 * wave], axis=1)
    td = np.stack([0.001 * ramp, 0.0 * t, 0.002 * ramp - 0.001 * wave], axis=1)
    tl = np.stack([0.0015 * wave, 0.0015 * ramp, 0.003 * ramp], axis=1)
    tr = np.stack([0.0015 * wave, 0.0005 * ramp, 0.004 * ramp], axis=1)
    return np.stack([tt, td, tl, tr], axis=1)


def _recording_from(model, displacements: np.ndarray, names) -> Recording:
    """A recording whose sensors sit on their landmark nodes and move by ``displacements`` (F, S, 3)."""
    nodes = [model.landmarks.sensors[n] for n in names]
    rest = model.mesh.points[nodes]
    sensors = {n: rest[k] + displacements[:, k] for k, n in enumerate(names)}
    times = np.arange(len(displacements)) / RATE
    return Recording(rate=RATE, times=times, sensors=sensors, metadata={"file": "synthetic", "format": "test"})


def _generated(model, how: str, n_frames: int = 90) -> Recording:
    """Drive the model with TT, TD, TL, TR; record the virtual sensor TB at its node too."""
    basis = model.basis(MODES)
    w_full = model.rotation_matrix(basis)
    names = list(DRIVERS)
    nodes = np.array([model.landmarks.sensors[n] for n in names])
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    phi_s = basis.phi[dofs].reshape(len(nodes), 3, -1)
    w_s = w_full[dofs].reshape(len(nodes), 3, -1)
    targets = _driver_targets(n_frames)
    if how == "static":
        q, converged, _ = quasi_static(basis.eigenvalues, phi_s, w_s, targets)
    else:
        settings = NewmarkSettings(dt=1 / RATE, alpha=model.material.alpha, beta=model.material.beta,
                                   warping=how == "model")
        result = integrate(basis.eigenvalues, phi_s, w_s, targets, settings)
        q, converged = result.q, result.converged
    assert converged.all()
    disp = model.displacements(q, warping=how != "linear")
    all_names = names + list(VIRTUAL)
    every = np.stack([disp[:, model.landmarks.sensors[n]] for n in all_names], axis=1)
    return _recording_from(model, every, all_names)


@pytest.mark.parametrize("how", ["model", "linear", "static"])
def test_a_virtual_sensor_driven_by_the_same_sensors_is_predicted_exactly(box_model, how):
    """TB was recorded from the model driven by TT, TD, TL, TR: holding it out drives with exactly those."""
    rec = _generated(box_model, how)
    result = validate(rec, box_model, modes=MODES, landmarks="rule", rest=REST, sensor_stiffness=None)
    tb = result.sensors["TB"]
    assert tb["drivers"] == ["TT", "TD", "TL", "TR"]
    assert result.held_out["TB"].node == box_model.landmarks.sensors["TB"]
    assert tb["measured_peak_mm"] > 3.0  # it really moved
    assert tb[f"{how}_rmse_mm"] < 1e-5
    assert tb[f"{how}_corr"] > 1 - 1e-9
    # The other predictors are different models, so they cannot be exact here.
    others = [m for m in ("model", "linear", "static", "kinematic") if m != how]
    assert min(tb[f"{m}_rmse_mm"] for m in others if not {m, how} <= {"model", "static"}) > 1e-3
    # Holding out a driver changes the drive: no longer exact.
    assert result.sensors["TT"][f"{how}_rmse_mm"] > 0.05


def test_kinematic_baseline_is_exact_on_an_affine_motion(box_model):
    """All sensors on the top face moved by one affine field: interpolating the others gives it exactly."""
    names = ["TT", "TB", "TD", "TL", "TR"]
    rest = box_model.mesh.points[[box_model.landmarks.sensors[n] for n in names]]
    t = np.arange(60) / RATE
    s = np.clip((t - 0.25) / 0.3, 0, 1)[:, None, None]
    gradient = np.array([[0.05, 0.02, 0.0], [-0.03, 0.04, 0.0], [0.1, -0.05, 0.0]])
    shift = np.array([0.001, -0.0005, 0.002])
    disp = s * ((rest - rest.mean(axis=0)) @ gradient.T + shift)[None]
    rec = _recording_from(box_model, disp, names)
    result = validate(rec, box_model, modes=MODES, landmarks="rule", rest=REST, sensor_stiffness=None, quasi_static=False)
    for name in names:
        assert result.sensors[name]["kinematic_rmse_mm"] < 1e-9, name
        np.testing.assert_allclose(result.held_out[name].predicted["kinematic"],
                                   result.held_out[name].measured, atol=1e-12)
    assert "static_rmse_mm" not in result.sensors["TT"]


def test_the_json_has_what_it_promises(box_model, tmp_path):
    rec = _generated(box_model, "model", n_frames=70)
    result = validate(rec, box_model, modes=MODES, landmarks="rule", rest=REST, sensor_stiffness=None)
    path = tmp_path / "v.json"
    result.write_json(path)
    doc = json.loads(path.read_text())
    assert set(doc) == {"sensors", "settings", "recording"}
    assert set(doc["sensors"]) == {"TT", "TB", "TD", "TL", "TR"}
    for scores in doc["sensors"].values():
        for method in ("model", "linear", "static", "kinematic"):
            assert isinstance(scores[f"{method}_rmse_mm"], float)
            assert -1.0 <= scores[f"{method}_corr"] <= 1.0
            assert len(scores[f"{method}_rmse_axes_mm"]) == 3 and len(scores[f"{method}_corr_axes"]) == 3
            assert scores[f"{method}_unconverged_frames"] == 0
        assert scores["frames"] == rec.n_samples
    assert doc["sensors"]["TT"]["outside_drivers"] is True  # the tip lies beyond TB, TD, TL, TR
    assert sum(doc["sensors"]["TT"]["kinematic_weights"]) == pytest.approx(1.0)
    settings = doc["settings"]
    assert settings["modes"] == MODES and settings["landmarks"] == "rule"
    assert settings["mesh"]["nodes"] == box_model.mesh.n_nodes
    r = doc["recording"]
    assert r["rest_interval_from"] == "given" and r["rest_interval_s"] == list(REST)
    assert r["tongue_sensors"] == ["TT", "TB", "TD", "TL", "TR"]
    assert r["volume_change_max_pct"] >= r["volume_change_mean_pct"] > 0
    assert r["sensor_residual_max_mm"] < 1e-4
    assert r["unconverged_frames"] == 0
    assert abs(r["alignment_scale"] - 1.0) < 1e-9 and r["alignment_rms_mm"] < 1e-9
    # The JSON figures are the held-out trajectories' own RMSE.
    item = result.held_out["TD"]
    err = item.predicted["linear"] - item.measured
    assert doc["sensors"]["TD"]["linear_rmse_mm"] == pytest.approx(1e3 * np.sqrt(np.mean(np.sum(err**2, axis=1))))


def test_too_few_tongue_sensors_is_an_error(box_model):
    from tonguevis.errors import SimulationError

    rec = _generated(box_model, "linear", n_frames=40)
    rec = rec.with_sensors({k: rec.sensors[k] for k in ("TT", "TD")})
    with pytest.raises(SimulationError, match="at least 3 tongue sensors"):
        validate(rec, box_model, modes=MODES, landmarks="rule", rest=REST, sensor_stiffness=None)


def test_quasi_static_solves_the_static_problem(box_model):
    """Small targets: the warped solve equals the linear closed form; large: equilibrium Λq ∈ range(Gᵀ)."""
    from tonguevis.sim.rotation import accumulated_rotation_matrix, rotate_accumulated

    basis = box_model.basis(MODES)
    w_full = box_model.rotation_matrix(basis)
    nodes = np.array([box_model.landmarks.sensors[n] for n in DRIVERS])
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    phi_s = basis.phi[dofs].reshape(4, 3, -1)
    w_s = w_full[dofs].reshape(4, 3, -1)
    targets = _driver_targets(80)
    tiny = 1e-6 * targets
    q_small, ok, _ = quasi_static(basis.eigenvalues, phi_s, w_s, tiny, tolerance=1e-14)
    assert ok.all()
    q_lin = linear_static(basis.eigenvalues, phi_s, tiny)
    np.testing.assert_allclose(q_small, q_lin, atol=1e-4 * np.abs(q_lin).max())
    # A plain reference for the closed form: the minimum-norm solution of Λ^½ q.
    lam = basis.eigenvalues
    ref = np.linalg.pinv(phi_s.reshape(12, -1) / np.sqrt(lam)) @ tiny[50].ravel() / np.sqrt(lam)
    np.testing.assert_allclose(q_lin[50], ref, rtol=1e-8, atol=1e-12 * np.abs(ref).max())

    q, ok, _ = quasi_static(basis.eigenvalues, phi_s, w_s, targets)
    assert ok.all()
    i = int(np.argmax(np.abs(targets).sum(axis=(1, 2))))
    f = rotate_accumulated(w_s @ q[i], phi_s @ q[i])
    np.testing.assert_allclose(f, targets[i], atol=1e-8)
    g = np.einsum("sij,sjm->sim", accumulated_rotation_matrix(w_s @ q[i]), phi_s).reshape(12, -1)
    force = lam * q[i]
    mult = np.linalg.lstsq(g.T, force, rcond=None)[0]
    assert np.linalg.norm(g.T @ mult - force) < 1e-8 * np.linalg.norm(force)
    assert np.abs(q[i] - q_lin[i] * 1e6).max() > 1e-3 * np.abs(q[i]).max()  # warping mattered here


def test_interpolation_weights_reproduce_affine_fields():
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(3, 3)), rng.normal(size=3)
    centres = rng.normal(size=(6, 3))
    queries = rng.normal(size=(4, 3))
    w = interpolation_weights(centres, queries)
    np.testing.assert_allclose(w @ (centres @ a.T + b), queries @ a.T + b, atol=1e-12)
    # Three centres: exact on the plane through them (barycentric), constant across it.
    tri = rng.normal(size=(3, 3))
    normal = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    normal /= np.linalg.norm(normal)
    inside = tri.T @ np.array([0.2, 0.5, 0.3])
    w = interpolation_weights(tri, np.stack([inside, inside + 0.7 * normal]))
    np.testing.assert_allclose(w[0], [0.2, 0.5, 0.3], atol=1e-12)
    np.testing.assert_allclose(w[1], w[0], atol=1e-12)
    # Two centres: linear interpolation and extrapolation along their line.
    pair = rng.normal(size=(2, 3))
    w = interpolation_weights(pair, [pair[0] + 1.5 * (pair[1] - pair[0])])
    np.testing.assert_allclose(w, [[-0.5, 1.5]], atol=1e-12)


def test_drift_is_measured_after_the_sensors_return_to_rest(box_model):
    """A raise and back: at the last frame at rest the static shape is rest, so both drift figures agree."""
    names = ["TT", "TB", "TD", "TL", "TR"]
    t = np.arange(100) / RATE
    bump = np.where((t > 0.3) & (t < 0.7), np.sin(np.pi * (t - 0.3) / 0.4) ** 2, 0.0)
    disp = np.zeros((len(t), 5, 3))
    disp[:, 0, 2] = 0.006 * bump  # the tip goes up 6 mm and comes back
    disp[:, 1, 2] = 0.003 * bump
    rec = _recording_from(box_model, disp, names)
    result = validate(rec, box_model, modes=MODES, landmarks="rule", rest=REST, sensor_stiffness=None, quasi_static=False)
    r = result.recording
    assert r["drift_time_s"] == pytest.approx(t[-1])
    assert r["drift_sensor_offset_mm"] < 1e-9
    assert r["drift_beyond_static_mm"] == pytest.approx(r["drift_mm"], abs=1e-9)
    # The damped model has settled 0.3 s after the sensors came back: well under the 6 mm raise.
    assert r["drift_mm"] < 0.1


def test_a_long_recording_is_advised_to_skip_the_quasi_static_baseline():
    from types import SimpleNamespace

    from tonguevis.cli.validate import LONG_FOR_STATIC_S, long_static_advice

    def recording(seconds):
        times = np.arange(0.0, seconds, 0.01)
        return SimpleNamespace(times=times, n_samples=len(times), metadata={"file": "long.tsv"})

    advice = long_static_advice(recording(3 * LONG_FOR_STATIC_S), no_static=False)
    assert advice is not None and "--no-static" in advice and "long.tsv" in advice
    assert long_static_advice(recording(3 * LONG_FOR_STATIC_S), no_static=True) is None
    assert long_static_advice(recording(0.5 * LONG_FOR_STATIC_S), no_static=False) is None
