"""The model placed in the speaker (tonguevis.sim.placement): derived modes, the same motion in the speaker's units."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tests.sim._models import bar_model
from tests.sim.test_simulate import SENSORS, _recording
from tonguevis.preprocess.alignment import SimilarityTransform
from tonguevis.sim import Motion, simulate
from tonguevis.sim.modal import free_dofs_for, solve_modes
from tonguevis.sim.placement import PlacedModel, placed_basis

MOVE = SimilarityTransform(1.8, Rotation.from_rotvec([0.3, -0.5, 0.7]).as_matrix(), np.array([0.01, -0.02, 0.03]))


def _solved(model, m):
    """(phi (3n, m), eigenvalues) by a direct eigen-solve of ``model``'s own K and M."""
    free = free_dofs_for(model.mesh.n_nodes, model.anchors)
    phi_free, vals, _ = solve_modes(model.stiffness, model.mass, free, m)
    phi = np.zeros((3 * model.mesh.n_nodes, m))
    phi[free] = phi_free
    return phi, vals


def _same_modes(derived, solved, vals, mass):
    """The same modes: C = Φ_solvedᵀ M Φ_derived is orthogonal and couples only equal eigenvalues (the bar's
    square section makes pairs of equal ones, whose modes are any rotation within the pair)."""
    c = solved.T @ (mass @ derived)
    np.testing.assert_allclose(c.T @ c, np.eye(len(vals)), atol=1e-7)
    apart = ~np.isclose(vals[:, None], vals[None, :], rtol=1e-6)
    assert np.abs(c[apart]).max() < 1e-7
    assert apart.sum() > 0.8 * apart.size  # most eigenvalues distinct: the check has teeth


@pytest.mark.parametrize("keep_frequencies", [True, False])
def test_the_placed_basis_is_the_eigen_solve_of_the_moved_mesh(keep_frequencies):
    model = bar_model(nx=6, sensors=SENSORS)
    m = 12
    placed = PlacedModel(model, MOVE, keep_frequencies)
    derived = placed.basis(m, cache=False)
    phi, vals = _solved(placed, m)  # K and M assembled on the moved mesh, with its density
    np.testing.assert_allclose(derived.eigenvalues, vals, rtol=1e-8)
    _same_modes(derived.phi, phi, vals, placed.mass)
    source = model.basis(m, cache=False).eigenvalues
    if keep_frequencies:  # the moved tongue vibrates as the model does
        np.testing.assert_allclose(vals, source, rtol=1e-8)
    else:  # same tissue, c times larger: c times slower
        np.testing.assert_allclose(vals, source / MOVE.scale ** 2, rtol=1e-8)
    # Modal warping's W = CΦ of the moved mesh (its own curl operator): the same rotations (turned by the
    # move) per modal displacement of the same shape, i.e. W' = Q_b W / √(f c⁵), which is how
    # PlacedModel.rotation_matrix derives it from the source's
    w = model.rotation_matrix(model.basis(m, cache=False))
    w_own = np.asarray(placed.curl_operator @ derived.phi)
    n = model.mesh.n_nodes
    turned = np.einsum("ij,njm->nim", MOVE.rotation, w.reshape(n, 3, m)).reshape(3 * n, m)
    factor = np.sqrt(placed.density_factor * MOVE.scale ** 3) * MOVE.scale
    np.testing.assert_allclose(w_own * factor, turned, atol=1e-9 * np.abs(w).max())
    np.testing.assert_allclose(placed.rotation_matrix(derived), w_own, rtol=0, atol=1e-12 * np.abs(w_own).max())
    # The point stiffness at the sensors (the sensor springs' unit): a body c times larger of the same E is
    # c times stiffer per metre at a point, whatever its density, so the springs' multiple means the same.
    from tonguevis.sim.constrained import point_stiffness

    nodes = np.array(list(model.landmarks.sensors.values()))
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    k = point_stiffness(source, model.basis(m, cache=False).phi[dofs].reshape(len(nodes), 3, m))
    k_moved = point_stiffness(derived.eigenvalues, derived.phi[dofs].reshape(len(nodes), 3, m))
    assert k_moved == pytest.approx(MOVE.scale * k, rel=1e-9)


def test_placed_basis_pure_rotation_and_scale_formula():
    """placed_basis on its own: Q_b φ / √(f c³), λ / (f c²)."""
    model = bar_model(nx=4)
    basis = model.basis(5, cache=False)
    out = placed_basis(basis, MOVE.rotation, 2.0, 0.5)
    np.testing.assert_allclose(out.eigenvalues, basis.eigenvalues / 2.0)
    node = 7
    np.testing.assert_allclose(out.phi[3 * node:3 * node + 3], MOVE.rotation @ basis.phi[3 * node:3 * node + 3] / 2.0)


@pytest.fixture(scope="module")
def model():
    return bar_model(sensors=SENSORS)


@pytest.mark.parametrize("patches", [None, "default"])
def test_a_speaker_frame_motion_is_the_model_frame_one_seen_through_the_fit(model, patches):
    recording = _recording(model, jaw_m=0.004)
    options = dict(modes=20, landmarks="speaker", backend="numpy", sensor_patches=patches)
    # tongue_size=None: placed by the inverse of the rest alignment itself
    in_model = simulate(recording, model, frame="model", **options)
    in_speaker = simulate(recording, model, frame="speaker", tongue_size=None, **options)
    fit = in_speaker.metadata["fit"]
    back = SimilarityTransform(fit["scale"], np.array(fit["rotation"]), np.array(fit["translation_m"])).inverse()
    assert isinstance(in_speaker.model, PlacedModel) or isinstance(in_speaker.model.base_model, PlacedModel)
    assert in_speaker.metadata["frame"] == "speaker" and in_model.metadata["frame"] == "model"
    assert fit["scale"] == pytest.approx(1.15, rel=1e-6)  # the synthetic speaker is 1/1.15 of the model
    np.testing.assert_array_equal(in_speaker.sensor_nodes, in_model.sensor_nodes)
    extent = np.ptp(in_speaker.model.mesh.points, axis=0).max()
    for frame in (0, 250, 280, len(recording.times) - 1):
        expected = back.apply(in_model.deformed_points(frame))
        np.testing.assert_allclose(in_speaker.deformed_points(frame), expected, atol=1e-9 * extent)
    np.testing.assert_allclose(in_speaker.volume_change, in_model.volume_change, atol=1e-10)
    # the same strain in a body 1/s times larger of the same Young's modulus: 1/s³ times the energy
    np.testing.assert_allclose(in_speaker.energy, in_model.energy / fit["scale"] ** 3, rtol=1e-6,
                               atol=1e-9 * in_model.energy.max() / fit["scale"] ** 3)
    np.testing.assert_allclose(in_speaker.sensor_residual, in_model.sensor_residual / fit["scale"], atol=1e-10)
    for key in ("amplification", "volume_change_max_percent"):
        assert in_speaker.metadata["plausibility"][key] == pytest.approx(in_model.metadata["plausibility"][key],
                                                                         rel=1e-6, abs=1e-9)
    # The targets are the speaker's own sensors (jaw-corrected): TT rose 15 mm on the model, 15 / 1.15 in the speaker.
    tt = in_speaker.sensor_names.index("TT")
    rise = np.linalg.norm(in_speaker.targets[:, tt] - in_speaker.targets[0, tt], axis=1).max()
    assert rise == pytest.approx(0.015 / 1.15, rel=1e-6)


@pytest.mark.parametrize("size", [None, 1.0])
def test_the_fit_is_in_the_metadata_and_the_motion_reloads_in_its_frame(model, tmp_path, size):
    recording = _recording(model)
    motion = simulate(recording, model, modes=20, backend="numpy", tongue_size=size)
    fit = motion.metadata["fit"]
    assert motion.metadata["frame"] == "speaker"
    for key in ("scale", "rotation", "translation_m", "residual_rms_mm", "residual_max_mm"):
        assert key in fit
    assert fit["residual_max_mm"] >= fit["residual_rms_mm"] >= 0
    path = tmp_path / "m.npz"
    motion.save(path)
    loaded = Motion.load(path)
    assert isinstance(loaded.model, PlacedModel)
    np.testing.assert_array_equal(loaded.model.mesh.points, motion.model.mesh.points)  # bit for bit: same results
    np.testing.assert_allclose(loaded.deformed_points(300), motion.deformed_points(300), atol=1e-12)
    assert loaded.metadata["fit"]["scale"] == pytest.approx(fit["scale"])


def test_morphing_across_frames_carries_the_shape_onto_the_source_tongue(model):
    """A speaker-frame motion morphed to the model-frame one of the same recording: the target's q, carried
    onto the placed model, is the source's own (the same shape), so the morph does not change it."""
    from tonguevis.analysis.morph import morph_between

    recording = _recording(model)
    options = dict(modes=20, backend="numpy", sensor_patches=None)  # the modal shapes alone, in either frame
    in_speaker = simulate(recording, model, tongue_size=None, **options)
    in_model = simulate(recording, model, frame="model", **options)
    morph = morph_between(in_speaker, 2.5, in_model, 2.5)
    assert morph.model is in_speaker.model
    # equal to the Newton tolerance (1e-8 m on the sensors), not bit for bit: the two runs stop their iterations apart
    np.testing.assert_allclose(morph.q_target, morph.q_source, rtol=1e-6, atol=1e-6 * np.abs(morph.q_source).max())


def test_the_demo_runs_in_the_speakers_millimetres():
    """The shipped demo: the model placed in the speaker (its tongue scaled by 1/s), the fit said, the
    generic palate placed with it, and the summary saying the frame."""
    from tonguevis.cli.simulate import summary
    from tonguevis.io import read_recording
    from tonguevis.paths import DATA_DIR
    from tonguevis.sim import TongueModel

    model = TongueModel.default()
    recording = read_recording(DATA_DIR / "spk1_ta.tsv")
    motion = simulate(recording, model, modes=40, palate="generic")
    fit = motion.metadata["fit"]
    scale = fit["scale"]
    assert motion.metadata["frame"] == "speaker" and fit["fitted_to"] == "rule nodes"
    assert 0.5 < scale < 2 and scale != 1.0  # placed as the rest alignment scales it (the default)
    assert motion.model.rest_volume == pytest.approx(model.rest_volume / scale ** 3, rel=1e-9)
    assert fit["residual_max_mm"] < 10
    # the generic palate moved with the model: the same clearance over the placed tongue's nodes
    placed_gap, _ = motion.palate.clearance(motion.model.mesh.points[model.dorsal_nodes])
    from tonguevis.palate import generic_palate

    model_gap, _ = generic_palate().clearance(model.mesh.points[model.dorsal_nodes])
    ok = np.isfinite(model_gap)
    assert ok.sum() > 20
    np.testing.assert_allclose(placed_gap[ok] * scale, model_gap[ok], atol=1e-9)
    assert any(line.startswith("frame: the speaker's") for line in summary(motion))
    sized = simulate(recording, model, modes=40, tongue_size=1.0)
    assert sized.metadata["fit"]["fitted_to"] == "upper surface"
    assert sized.model.rest_volume == pytest.approx(model.rest_volume, rel=1e-9)


def test_the_surface_fit_places_the_model_at_the_size_given(model):
    """The synthetic speaker is the bar at 1/1.15 of its size: told so, the surface fit puts every rest sensor
    on its own node exactly; at the model's own size the tongue keeps its volume and the
    sensors sit near its upper surface, the residual said."""
    recording = _recording(model)
    told = simulate(recording, model, modes=20, backend="numpy", tongue_size=1 / 1.15)
    assert told.metadata["fit"]["fitted_to"] == "upper surface"
    assert told.metadata["fit"]["residual_max_mm"] < 1e-3  # micrometres: the rest pose is a mean over a window
    assert told.model.rest_volume == pytest.approx(model.rest_volume / 1.15 ** 3, rel=1e-9)
    generic = simulate(recording, model, modes=20, backend="numpy", tongue_size=1.0)
    fit = generic.metadata["fit"]
    assert generic.model.rest_volume == pytest.approx(model.rest_volume, rel=1e-9)
    assert 0.1 < fit["residual_max_mm"] < 10  # 15 % too large: the sensors cannot all sit on nodes
    assert fit["tongue_size"] == 1.0
    with pytest.raises(Exception, match="tongue size"):
        simulate(recording, model, modes=20, backend="numpy", tongue_size=-1.0)


def test_a_motion_carried_onto_another_placement_is_the_same_deformation(model):
    """Carried onto the unplaced model, a speaker-frame motion (placed by the alignment) is the model-frame one;
    a comparison of two speakers' motions carries B onto A's tongue, so a per-node difference exists."""
    from tonguevis.analysis.compare import Comparison
    from tonguevis.sim.placement import carried

    recording = _recording(model)
    options = dict(modes=20, backend="numpy", sensor_patches=None)  # the modal shapes alone, in either frame
    in_speaker = simulate(recording, model, tongue_size=None, **options)
    in_model = simulate(recording, model, frame="model", **options)
    back = carried(in_speaker, model)
    assert back.model is model
    extent = np.ptp(model.mesh.points, axis=0).max()
    for frame in (0, 250, 280):
        np.testing.assert_allclose(back.deformed_points(frame), in_model.deformed_points(frame), atol=1e-7 * extent)
    np.testing.assert_allclose(back.targets, in_model.targets, atol=1e-9)
    np.testing.assert_allclose(back.energy, in_model.energy, rtol=1e-4, atol=1e-4 * in_model.energy.max())
    other = simulate(_recording(model, raise_m=0.01), model, tongue_size=None, **options)  # another fit
    assert not np.allclose(other.model.mesh.points, in_speaker.model.mesh.points)
    comparison = Comparison(in_speaker, other, "absolute")
    assert comparison.same_mesh
    assert np.isfinite(comparison.difference(250, 250)).all()


def test_an_implausible_placed_size_is_warned_about(model, caplog):
    """The synthetic speaker is 1/1.15 of the bar: placed by the alignment, fine; a speaker whose rest sensors
    lie twice as far apart makes an 8x tongue, which is said, with the option that keeps the model's size."""
    import logging

    from tests.sim.test_simulate import Recording

    recording = _recording(model)
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        simulate(recording, model, modes=20, backend="numpy", tongue_size=None)  # the alignment's size
    assert "times the generic one's volume" not in caplog.text and "times its volume" not in caplog.text
    wide = Recording(rate=recording.rate, times=recording.times,
                     sensors={k: 2.3 * v for k, v in recording.sensors.items()}, metadata=dict(recording.metadata))
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        motion = simulate(wide, model, modes=20, backend="numpy", tongue_size=None)
    assert "8.0 times the generic one's volume" in caplog.text and "--tongue-size 1" in caplog.text and "tongue_size=1" in caplog.text
    assert motion.metadata["fit"]["model_volume_cm3"] == pytest.approx(8 * 1e6 * model.rest_volume, rel=1e-6)


def test_the_adult_size_keeps_an_adult_alignment_and_replaces_one_no_adult_has(model, caplog):
    """tongue_size="adult" (the front ends' default): the synthetic speaker's alignment (1.15x smaller, within
    half to twice the volume) is kept, the very motion tongue_size=None makes; a speaker whose rest sensors
    lie 2.3 times as far apart (an 8x tongue) gets the generic size, the sensors fitted onto its surface,
    said once with the option that keeps the alignment's size."""
    import logging

    from tests.sim.test_simulate import Recording
    from tonguevis.sim.placement import describe_fit, size_note

    recording = _recording(model)
    kept = simulate(recording, model, modes=20, backend="numpy", tongue_size="adult")
    aligned = simulate(recording, model, modes=20, backend="numpy", tongue_size=None)
    assert kept.metadata["fit"]["size_from"] == "alignment"
    np.testing.assert_array_equal(kept.q, aligned.q)
    np.testing.assert_array_equal(kept.model.mesh.points, aligned.model.mesh.points)
    wide = Recording(rate=recording.rate, times=recording.times,
                     sensors={k: 2.3 * v for k, v in recording.sensors.items()}, metadata=dict(recording.metadata))
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        adult = simulate(wide, model, modes=20, backend="numpy", tongue_size="adult")
    fit = adult.metadata["fit"]
    assert fit["size_from"] == "adult norm" and fit["fitted_to"] == "upper surface" and fit["tongue_size"] == 1.0
    assert adult.model.rest_volume == pytest.approx(model.rest_volume, rel=1e-9)
    assert "8.0 times its volume" in caplog.text and "--tongue-size alignment" in caplog.text
    assert "the generic adult size" in describe_fit(fit)
    assert size_note(fit).startswith("tongue at the generic adult size: the rest sensors' spread would make it 8.0 times")
    assert size_note(kept.metadata["fit"]) == ""
    generic = simulate(wide, model, modes=20, backend="numpy", tongue_size=1.0)  # the same as asking for 1
    np.testing.assert_array_equal(adult.q, generic.q)
    assert generic.metadata["fit"]["size_from"] == "given"
    with pytest.raises(Exception, match="tongue size"):
        simulate(recording, model, modes=20, backend="numpy", tongue_size="large")


def test_a_loaded_motion_draws_the_palate_where_its_simulation_placed_it(tmp_path):
    """A motion saved and loaded has no palate of its own: the views place the speaker's palate again, and the
    generic roof joined behind it follows the tongue.  Placed by the alignment, the motion records the size
    the alignment implied; placing it again must not take that for a size asked for (a surface fit: another
    placement, the roof joined elsewhere)."""
    from tonguevis.palate import PalateSurface
    from tonguevis.sim import TongueModel
    from tonguevis.workflows import open_recording
    from tonguevis.workflows.simulation import shown_palate

    rec = open_recording("data/spk1_ta.tsv")
    tongue = np.concatenate([v for k, v in rec.sensors.items() if k in ("TT", "TB", "TD", "TL", "TR")])
    tongue = tongue[np.all(np.isfinite(tongue), axis=1)]
    x = np.arange(tongue[:, 0].min() - 0.01, tongue[:, 0].max() + 0.01, 1e-3)
    y = np.arange(tongue[:, 1].min() - 0.01, tongue[:, 1].max() + 0.01, 1e-3)
    roof = PalateSurface(x, y, np.full((len(y), len(x)), tongue[:, 2].max() + 2e-3), metadata={"source": "flat roof"})
    model = TongueModel.default()
    motion = simulate(rec, model, modes=20, palate=roof, tongue_size=None)
    assert motion.metadata["fit"]["fitted_to"] == "rule nodes"
    motion.save(tmp_path / "m.npz")
    loaded = Motion.load(tmp_path / "m.npz")
    assert getattr(loaded, "palate", None) is None
    simulated, again = (shown_palate(rec, m, model, roof) for m in (motion, loaded))
    assert len(again.points) == len(simulated.points)
    np.testing.assert_allclose(again.points, simulated.points, atol=1e-9)
