"""Qt-free helpers of the app: energy density, per-frame drawing data, normals, audio, sessions."""

from __future__ import annotations

import numpy as np
import pytest

from tests.gui.fakes import FakeModel, box_mesh, fake_motion, fake_recording
from tonguevis.render.energy_density import EnergyDensity
from tonguevis.sim.assembly import assemble_stiffness


@pytest.fixture(scope="module")
def fake():
    model = FakeModel(box_mesh())
    recording = fake_recording(duration=1.0)
    return model, recording, fake_motion(model, recording)


def test_energy_density_integrates_to_half_u_K_u():
    mesh = box_mesh()
    density = EnergyDensity(mesh.points, mesh.tets, 6912.0, 0.49)
    K = assemble_stiffness(mesh.points, mesh.tets, 6912.0, 0.49)
    rng = np.random.default_rng(1)
    u = 1e-3 * rng.standard_normal((3, mesh.n_nodes, 3))
    expected = [0.5 * ui.ravel() @ (K @ ui.ravel()) for ui in u]
    assert np.allclose(density.total(u), expected, rtol=1e-10)


def test_rigid_motion_has_no_energy_density():
    mesh = box_mesh()
    density = EnergyDensity(mesh.points, mesh.tets, 6912.0, 0.49)
    theta = np.array([0.01, -0.02, 0.005])
    u = np.cross(theta, mesh.points) + [0.001, 0.002, -0.003]
    assert np.abs(density.element(u)).max() < 1e-9 * density.element(1e-3 * mesh.points).max()


def test_strain_operator_path_equals_direct_formula():
    mesh = box_mesh()
    density = EnergyDensity(mesh.points, mesh.tets, 6912.0, 0.49)
    u = 1e-3 * np.random.default_rng(2).standard_normal((2, mesh.n_nodes, 3))
    strains = (density.strain_operator() @ u.reshape(2, -1).T).T
    assert np.allclose(density.from_strains(strains), density.element(u), rtol=1e-10, atol=0)


def test_nodal_average_is_volume_weighted_mean():
    mesh = box_mesh(2, 1, 1)
    density = EnergyDensity(mesh.points, mesh.tets, 6912.0, 0.49)
    values = np.arange(mesh.n_tets, dtype=float)
    nodal = density.to_nodes(values)
    for node in range(mesh.n_nodes):  # plain reference
        around = np.any(mesh.tets == node, axis=1)
        w = density.volumes[around]
        assert nodal[node] == pytest.approx((w * values[around]).sum() / w.sum())


def test_motion_frames_match_the_motion(fake):
    from tonguevis.render.frames import MotionFrames

    model, _, motion = fake
    frames = MotionFrames(motion, block=7)  # blocks that do not divide the frame count
    u = model.displacements(motion.q)
    drawn = frames.nodes
    assert set(np.unique(model.surface_faces)) <= set(drawn) and set(motion.sensor_nodes) <= set(drawn)
    density = EnergyDensity(model.mesh.points, model.mesh.tets, 6912.0, 0.49)
    energy = density.nodal(u)
    for i in (0, 6, 7, 50, frames.n_frames - 1, 3):
        assert np.allclose(frames.points[i][drawn], (model.mesh.points + u[i])[drawn], atol=1e-6)
        assert np.allclose(frames.scalars["displacement"][i][drawn], 1e3 * np.linalg.norm(u[i], axis=1)[drawn],
                           rtol=1e-5, atol=1e-6)
        assert np.allclose(frames.scalars["energy"][i][drawn], energy[i][drawn], rtol=1e-4,
                           atol=1e-6 * frames.clim["energy"][1])
        assert np.allclose(frames.sensor_points[i], frames.points[i][motion.sensor_nodes])
    inside = np.setdiff1d(np.arange(model.mesh.n_nodes), drawn)
    assert len(inside) and np.allclose(frames.points[5][inside], model.mesh.points[inside])  # not drawn: at rest
    assert np.allclose(frames.points[2:9:3], frames.points[[2, 5, 8]])
    assert frames.points[:, motion.sensor_nodes].shape == (frames.n_frames, len(motion.sensor_nodes), 3)
    assert frames.clim["displacement"][1] <= 1e3 * np.linalg.norm(u, axis=2).max()
    assert frames.frame_at(motion.times[5] + 0.004) == 5
    assert frames.frame_at(-10) == 0 and frames.frame_at(1e9) == frames.n_frames - 1
    whole = frames.whole_mesh()
    assert np.allclose(whole.points[50], model.mesh.points + u[50], atol=1e-6)
    assert np.allclose(whole.scalars["energy"][50], energy[50], rtol=1e-4, atol=1e-6 * frames.clim["energy"][1])


def test_motion_frames_cache_stays_bounded_and_colours_come_from_a_sample(fake):
    from tonguevis.render.frames import MotionFrames

    model, _, motion = fake
    frames = MotionFrames(motion, block=8, cache_frames=32, colour_frames=20)
    assert frames.cached_frames == 0  # nothing precomputed
    for i in range(frames.n_frames):  # play every frame through, then seek around
        frames.points[i], frames.scalars["energy"][i]
        assert frames.cached_frames <= 32
    for i in np.random.default_rng(0).integers(0, frames.n_frames, 50):
        frames.scalars["displacement"][int(i)]
        assert frames.cached_frames <= 32
    sample = np.unique(np.round(np.linspace(0, frames.n_frames - 1, 20)).astype(int))
    u = model.displacements(motion.q[sample])[:, frames.nodes]
    expected = np.percentile(1e3 * np.linalg.norm(u, axis=2), 99.5)
    assert frames.clim["displacement"] == (0.0, pytest.approx(expected, rel=1e-5))


def test_vertex_normals_point_out_of_a_box():
    from tonguevis.render.surface_geometry import VertexNormals

    mesh = box_mesh()
    faces = mesh.boundary_faces()
    normals = VertexNormals(faces, mesh.n_nodes)(mesh.points)
    on_surface = np.unique(faces)
    centre = mesh.points.mean(axis=0)
    outward = np.einsum("ij,ij->i", normals[on_surface], mesh.points[on_surface] - centre)
    assert np.all(outward > 0)
    assert np.allclose(np.linalg.norm(normals[on_surface], axis=1), 1, atol=1e-6)


def test_pcm16_slice_and_slow_down():
    from tonguevis.gui.playback import pcm16

    rate = 1000.0
    samples = np.linspace(-1, 1, 2000)
    pcm = np.frombuffer(pcm16(samples, rate, 0.5, 1.0, 0.0, 1.0), dtype="<i2")
    assert len(pcm) == 500 and pcm[0] == int(samples[500] * 32767)
    slow = np.frombuffer(pcm16(samples, rate, 0.5, 1.0, 0.0, 0.5), dtype="<i2")
    assert len(slow) == 1000  # half speed: twice the samples, same start and end values
    assert abs(int(slow[0]) - int(pcm[0])) <= 1 and abs(int(slow[-2]) - int(pcm[-1])) <= 40


def test_waveform_envelope_matches_a_loop():
    from tonguevis.gui.audio_panel import envelope

    samples = np.random.default_rng(3).standard_normal(10_007)
    times, low, high = envelope(samples, 1000.0, 2.0, bins=100)
    per = 100
    for b in (0, 37, 99):
        block = samples[b * per:(b + 1) * per]
        assert low[b] == block.min() and high[b] == block.max()
        assert times[b] == pytest.approx(2.0 + (b + 0.5) * per / 1000.0)


def test_spectrogram_of_long_sound_is_scipys_columns_spread_over_it():
    from scipy.signal import spectrogram

    from tonguevis.gui.audio_panel import bounded_spectrogram, window_power

    samples = np.random.default_rng(4).standard_normal(16000 * 3)
    f, t, power = spectrogram(samples, fs=16000, nperseg=256, noverlap=128)
    assert np.allclose(window_power(samples, np.arange(len(t)) * 128, 16000, 256), power, rtol=1e-9)
    f2, t2, p2 = bounded_spectrogram(samples, 16000, 256, columns=len(t))  # short: scipy's own
    assert np.array_equal(p2, power) and np.array_equal(t2, t)
    f3, t3, p3 = bounded_spectrogram(samples, 16000, 256, columns=50)  # long: 50 columns spread evenly
    assert p3.shape == (len(f), 50) and np.allclose(f3, f)
    assert t3[0] == pytest.approx(t[0]) and t3[-1] == pytest.approx((len(samples) - 128) / 16000)


def test_video_frame_times():
    from tonguevis.render.video import frame_times

    t = frame_times(1.0, 2.0, 25)
    assert len(t) == 25 and t[0] == 1.0 and t[-1] < 2.0


def test_session_signals_units_and_derivatives(fake):
    from tonguevis.workflows.session import Session

    _, recording, _ = fake
    session = Session(recording)
    position = session.signals("position")
    assert list(position) == ["TT", "TD", "JAW"]
    assert np.allclose(position["TT"], 1e3 * recording.sensors["TT"])
    velocity = session.signals("velocity")["TT"][:, 2]
    # z = 0.05 + 0.005 cos(4πt): velocity -0.005·4π sin(4πt) m/s, in mm/s.
    t = recording.times
    inner = slice(10, -10)
    assert np.allclose(velocity[inner], -1e3 * 0.005 * 4 * np.pi * np.sin(4 * np.pi * t)[inner], atol=0.5)
    with pytest.raises(ValueError):
        session.signals("jerk")


def test_sensor_map_needed_only_without_tongue_names(fake):
    from tonguevis.gui.dialogs import guess_role
    from tonguevis.workflows.session import needs_sensor_map, remap_session, Session

    _, recording, _ = fake
    assert not needs_sensor_map(recording)
    unnamed = recording.renamed({"TT": "S1", "TD": "S2", "JAW": "S5"})
    assert needs_sensor_map(unnamed)
    remapped = remap_session(Session(unnamed), {"TT": "S1", "TD": "S2"})
    assert set(remapped.recording.sensor_names) == {"TT", "TD", "S5"}
    assert guess_role("tongue_tip") == "TT" and guess_role("S3") == "(not used)"


def test_production_intervals_from_objects_and_pairs():
    from types import SimpleNamespace

    from tonguevis.workflows.session import production_intervals

    assert production_intervals([SimpleNamespace(start=2, end=3), (0.5, 1.0)]) == [(0.5, 1.0), (2.0, 3.0)]
    assert production_intervals(None) == []


def test_draw_frame_in_the_head_and_the_jaw_frame(fake):
    """Head frame: tongue, sensors and jaw moved by the jaw's translation, palate fixed; jaw frame: the reverse.
    The distance to a flat palate is the vertical gap in both."""
    from dataclasses import replace
    from types import SimpleNamespace

    from tonguevis.render.drawing import draw_frame, generic_shown, speaker_palate
    from tonguevis.render.frames import MotionFrames
    from tonguevis.palate import PalateSurface

    model, _, still = fake
    n = still.n_frames
    motion = replace(still, jaw_offset=np.column_stack([np.zeros(n), np.zeros(n), -0.004 * np.sin(np.linspace(0, np.pi, n))]))
    frames = MotionFrames(motion)
    x = np.linspace(-0.1, 0.2, 301)  # wider than the box can swing
    y = np.linspace(-0.1, 0.15, 251)
    roof = PalateSurface(x, y, np.full((len(y), len(x)), 0.05), metadata={"frame": "model"})
    session = SimpleNamespace(frames=frames, shown_palate=speaker_palate(roof, "roof"), productions=[])
    i = n // 2
    off = motion.jaw_offset[i]
    head = draw_frame(session, i, "head", "contact")
    np.testing.assert_allclose(head.points, frames.points[i] + off, atol=1e-7)
    np.testing.assert_allclose(head.sensor_points, frames.sensor_points[i] + off, atol=1e-7)
    np.testing.assert_allclose(head.context_offsets["jaw"], off, atol=1e-7)
    np.testing.assert_allclose(head.context_offsets["palate"], 0.0, atol=1e-12)
    np.testing.assert_allclose(head.scalars, 50.0 - 1e3 * head.points[:, 2], atol=1e-3)
    assert head.caption.startswith("head frame")
    jaw = draw_frame(session, i, "jaw", "contact")
    np.testing.assert_allclose(jaw.points, frames.points[i], atol=1e-7)
    np.testing.assert_allclose(jaw.context_offsets["jaw"], 0.0, atol=1e-12)
    np.testing.assert_allclose(jaw.context_offsets["palate"], -off, atol=1e-7)
    np.testing.assert_allclose(jaw.scalars, head.scalars)  # contact is between tongue and palate
    assert jaw.caption.startswith("jaw frame")
    assert np.array_equal(draw_frame(session, i, "jaw", "energy").scalars, frames.scalars["energy"][i])
    session.frames = MotionFrames(still)  # no jaw sensor: the frames coincide and say so
    assert draw_frame(session, i, "head", "plain").caption == "head frame = jaw frame (no jaw motion recorded)"
    if generic_shown() is not None:  # the shipped palate, drawn from its own mesh
        assert generic_shown().generic and generic_shown().label == "generic palate"


def test_midline_profile_runs_from_the_tip_back_along_the_mid_plane():
    from tonguevis.analysis.section import MIDLINE_BIN_MM, MidlineProfile

    model = FakeModel(box_mesh(8, 4, 3, size=(0.07, 0.04, 0.03)))
    model.dorsal_nodes = np.flatnonzero(np.isclose(model.mesh.points[:, 2], 0.03))
    profile = MidlineProfile(model)
    pts = model.mesh.points[profile.nodes]
    assert np.allclose(pts[:, 1], 0.02) and np.allclose(pts[:, 2], 0.03)  # the top's mid-line
    assert np.all(np.diff(profile.position_mm) > 0)
    assert profile.position_mm[0] == pytest.approx(0.5 * MIDLINE_BIN_MM)  # the tip (x = 70 mm) first
    assert profile.position_mm[-1] == pytest.approx(70 + 0.5 * MIDLINE_BIN_MM)
