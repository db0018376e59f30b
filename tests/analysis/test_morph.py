"""Morphing (§6.4): blend direction, exact ends, fused kernel = reference, eq. (14), CDF colours, CLI."""

from __future__ import annotations

import numpy as np
import pytest

from tests.analysis.energy_support import MODES, box_tongue
from tonguevis.analysis.morph import (
    Morph,
    MorphError,
    cdf_colour,
    element_difference,
    morph_between,
    morph_displacements_reference,
    play_schedule,
)
from tonguevis.sim.motion import Motion


def _q(seed, scale=4e-3):
    """Modal displacements big enough for rotations of tenths of a radian on the box."""
    rng = np.random.default_rng(seed)
    return rng.normal(size=MODES) * scale / (1 + np.arange(MODES))


@pytest.fixture(scope="module")
def morph():
    return Morph(box_tongue(), _q(1), _q(2))


def test_rotations_are_large_enough_to_matter(morph):
    model = box_tongue()
    w = (model.rotation_matrix(model.basis(MODES)) @ morph.q_source).reshape(-1, 3)
    assert np.linalg.norm(w, axis=1).max() > 0.2  # rad: warping differs visibly from linear here
    linear = model.displacement(morph.q_source, warping=False)
    assert np.abs(morph.source_displacement - linear).max() > 1e-3


def test_ends_equal_source_and_target(morph):
    model = box_tongue()
    np.testing.assert_allclose(morph.displacement(0.0), model.displacement(_q(1)), rtol=0, atol=1e-15)
    np.testing.assert_allclose(morph.displacement(1.0), model.displacement(_q(2)), rtol=0, atol=1e-15)
    np.testing.assert_allclose(morph.points(1.0), model.mesh.points + model.displacement(_q(2)), atol=1e-15)
    # Which end is which: q(t) = (1 - t) q_source + t q_target.
    np.testing.assert_allclose(morph.blend(0.25), 0.75 * _q(1) + 0.25 * _q(2))


def test_fused_kernel_equals_blend_then_reconstruct(morph):
    ts = np.linspace(0, 1, 9)
    ref = morph_displacements_reference(box_tongue(), _q(1), _q(2), ts)
    np.testing.assert_allclose(morph.displacements(ts), ref, rtol=0, atol=1e-14)
    f32 = morph.displacements(ts, dtype=np.float32)
    assert f32.dtype == np.float32
    np.testing.assert_allclose(f32, ref, rtol=0, atol=1e-6 * np.abs(ref).max())
    # The middle is neither end, and not the average of the warped ends (rotation is recomputed).
    mid = morph.displacement(0.5)
    avg = 0.5 * (morph.source_displacement + morph.target_displacement)
    assert np.abs(mid - avg).max() > 1e-5


def test_linear_morph_is_linear_blend():
    model = box_tongue()
    lin = Morph(model, _q(1), _q(2), warping=False)
    expected = model.displacement(0.3 * _q(1) + 0.7 * _q(2), warping=False)
    np.testing.assert_allclose(lin.displacement(0.7), expected, atol=1e-15)


def test_element_difference_is_eq_14(morph):
    mesh = box_tongue().mesh
    a, b = morph.source_displacement, morph.target_displacement
    expected = []
    for tet in mesh.tets:
        x = mesh.points[tet]
        volume = abs(np.linalg.det(np.stack([x[1] - x[0], x[2] - x[0], x[3] - x[0]]))) / 6
        expected.append(np.sum((a[tet] - b[tet]) ** 2) / volume)
    np.testing.assert_allclose(morph.element_difference, expected, rtol=1e-12)
    np.testing.assert_allclose(element_difference(mesh.points, mesh.tets, a, a), 0.0)


def test_cdf_colours_are_uniform_and_ordered(morph):
    # Heavy-tailed distinct values (like element differences): colours exactly (k + 1/2)/n, a flat histogram.
    values = np.random.default_rng(5).lognormal(0, 2, 1000)
    colour = cdf_colour(values)
    np.testing.assert_allclose(np.sort(colour), (np.arange(1000) + 0.5) / 1000)
    assert np.all(np.diff(colour[np.argsort(values)]) > 0)
    raw, _ = np.histogram(values / values.max(), bins=10, range=(0, 1))
    assert raw.max() > 500  # the raw values crowd the bottom of a linear scale
    # On the morph's elements: flat up to ties (symmetric elements of the box share a difference).
    diff, colour = morph.element_difference, morph.element_colour
    _, tie_sizes = np.unique(diff, return_counts=True)
    counts, _ = np.histogram(colour, bins=10, range=(0, 1))
    assert counts.max() - counts.min() <= 2 * tie_sizes.max()
    assert np.all(np.diff(colour[np.argsort(diff, kind="stable")]) >= 0)
    # Ties share a colour.
    np.testing.assert_allclose(cdf_colour([3.0, 1.0, 3.0, 2.0]), [0.75, 0.125, 0.75, 0.375])


def test_play_schedule_goes_there_and_back():
    ts = play_schedule(5)
    np.testing.assert_allclose(ts, [0, 0.25, 0.5, 0.75, 1, 0.75, 0.5, 0.25, 0])
    np.testing.assert_allclose(play_schedule(3, back=False), [0, 0.5, 1])
    with pytest.raises(MorphError):
        play_schedule(1)


def _motion(model, qs, t0=0.0):
    f = len(qs)
    return Motion(times=t0 + 0.01 * np.arange(f), q=np.asarray(qs), model=model, warping=True,
                  sensor_names=[], sensor_nodes=np.zeros(0, int), targets=np.zeros((f, 0, 3)),
                  sensor_residual=np.zeros((f, 0)), energy=model.energy(np.asarray(qs)),
                  volume_change=np.zeros(f), converged=np.ones(f, bool))


def test_morph_between_motions_picks_frames_and_checks_models():
    model = box_tongue()
    a = _motion(model, [_q(1) * k for k in range(5)])
    b = _motion(model, [_q(2) * k for k in range(5)], t0=1.0)
    m = morph_between(a, 0.031, b, 1.02)
    assert (m.source_frame, m.target_frame) == (3, 2)
    np.testing.assert_allclose(m.q_source, 3 * _q(1))
    np.testing.assert_allclose(m.q_target, 2 * _q(2))
    with pytest.raises(MorphError, match="outside"):
        morph_between(a, 2.0, b, 1.0)
    from types import SimpleNamespace

    from tonguevis.mesh.structured import box_mesh
    from tonguevis.sim.model import TongueModel

    other = TongueModel(box_mesh(6, 4, 3, (0.05, 0.04, 0.03)), SimpleNamespace(
        sensors=model.landmarks.sensors, anchors=model.anchors))
    c = Motion(times=np.zeros(1), q=_q(2)[None], model=other, warping=True, sensor_names=[],
               sensor_nodes=np.zeros(0, int), targets=np.zeros((1, 0, 3)), sensor_residual=np.zeros((1, 0)),
               energy=np.zeros(1), volume_change=np.zeros(1), converged=np.ones(1, bool))
    with pytest.raises(MorphError, match="different tongue models"):
        morph_between(a, 0.0, c, 0.0)
    with pytest.raises(MorphError, match="modes"):
        Morph(model, _q(1), _q(2)[:-1])


@pytest.fixture(scope="module")
def saved_motions(tmp_path_factory):
    folder = tmp_path_factory.mktemp("motions")
    model = box_tongue()
    a = _motion(model, [_q(1) * k / 4 for k in range(5)])
    b = _motion(model, [_q(2) * k / 4 for k in range(5)])
    a.save(folder / "a.npz")
    b.save(folder / "b.npz")
    return folder


def test_cli_morph_png(saved_motions, tmp_path, capsys):
    from tonguevis.cli import main

    out = tmp_path / "m.png"
    code = main(["morph", f"{saved_motions / 'a.npz'}@0.04", f"{saved_motions / 'b.npz'}@0.03", "--out", str(out),
                 "--difference", "node_mean"])
    assert code == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    assert "source (t = 0): a @ 0.04 s" in text and "target (t = 1): b @ 0.03 s" in text
    assert "element difference (node_mean)" in text and "m²" in text
    assert out.read_bytes()[:4] == b"\x89PNG" and out.stat().st_size > 20_000


def test_cli_morph_mp4(saved_motions, tmp_path, capsys):
    from tonguevis.cli import main

    out = tmp_path / "m.mp4"
    code = main(["morph", f"{saved_motions / 'a.npz'}@0.04", f"{saved_motions / 'b.npz'}@0.04", "--out", str(out),
                 "--frames", "6", "--quiet"])
    assert code == 0, capsys.readouterr().err
    data = out.read_bytes()
    assert data[4:8] == b"ftyp" and len(data) > 5_000


def test_cli_morph_bad_arguments(saved_motions, tmp_path, capsys):
    from tonguevis.cli import main

    code = main(["morph", f"{saved_motions / 'a.npz'}@0.04", f"{saved_motions / 'b.npz'}@0.04",
                 "--out", str(tmp_path / "m.gif")])
    assert code == 2 and ".mp4 or .png" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["morph", "a.npz", "b.npz@1", "--out", str(tmp_path / "m.png")])


def test_cdf_colour_equals_rank_reference_with_ties():
    from scipy.stats import rankdata

    rng = np.random.default_rng(11)
    for _ in range(100):
        values = rng.integers(0, 15, rng.integers(1, 50)).astype(float)
        np.testing.assert_allclose(cdf_colour(values), (rankdata(values) - 0.5) / len(values))


def test_cli_morph_simulates_a_recording_once(tmp_path, monkeypatch, capsys):
    from tonguevis.cli import main
    from tonguevis.cli import morph as morph_cli
    from tonguevis.paths import DATA_DIR

    monkeypatch.setattr(morph_cli, "load_model", lambda args: box_tongue())
    calls = []
    real = morph_cli._motion
    monkeypatch.setattr(morph_cli, "_motion", lambda *a: calls.append(a[0]) or real(*a))
    out = tmp_path / "m.png"
    rec = DATA_DIR / "spk1_la.tsv"
    code = main(["morph", f"{rec}@5.55", f"{rec}@5.70", "--out", str(out), "--modes", str(MODES),
                 "--landmarks", "rule", "--quiet"])
    assert code == 0, capsys.readouterr().err
    assert calls == [rec]
    text = capsys.readouterr().out
    assert "spk1_la @ 5.55 s" in text and "spk1_la @ 5.70 s" in text
    assert out.stat().st_size > 20_000


def test_node_mean_difference_ignores_element_size(morph):
    model = box_tongue()
    mesh = model.mesh
    a, b = morph.source_displacement, morph.target_displacement
    node = Morph(model, _q(1), _q(2), difference="node_mean")
    expected = [np.mean(np.sum((a[tet] - b[tet]) ** 2, axis=1)) for tet in mesh.tets]
    np.testing.assert_allclose(node.element_difference, expected, rtol=1e-12)
    assert node.difference_unit == "m²" and morph.difference_unit == "1/m"
    # A uniform translation between the ends gives every element the same node_mean difference,
    # but eq. (14) then still ranks elements by their size.
    shift = np.tile([1e-3, 0.0, 0.0], (mesh.n_nodes, 1))
    same = element_difference(mesh.points, mesh.tets, a + shift, a, kind="node_mean")
    np.testing.assert_allclose(same, 1e-6)
    eq14 = element_difference(mesh.points, mesh.tets, a + shift, a)
    volumes = np.abs(np.linalg.det(mesh.points[mesh.tets[:, 1:]] - mesh.points[mesh.tets[:, :1]])) / 6
    np.testing.assert_allclose(eq14, 4e-6 / volumes, rtol=1e-10)
    with pytest.raises(MorphError, match="unknown element difference"):
        Morph(model, _q(1), _q(2), difference="hausdorff")
