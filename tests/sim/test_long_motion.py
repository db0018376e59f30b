"""Long recordings: figures chunk by chunk, frames on demand, the ParaView export in one file.

The chunked paths are checked against the plain whole-array computations they
replace, on the demo /ta/ (short: the 30-minute case is only benchmarked,
scripts/bench_long.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from tonguevis.paths import DATA_DIR


@pytest.fixture(scope="module")
def demo():
    """The demo /ta/ under the paper's hard constraints: it goes 2 mm into the generic palate."""
    from tonguevis.io import read_recording
    from tonguevis.preprocess.targets import prepare_targets
    from tonguevis.sim import TongueModel, simulate

    rec = read_recording(DATA_DIR / "spk1_ta.tsv")
    model = TongueModel.default()
    # the checks below rebuild it in this frame, from the modes alone
    motion = simulate(rec, model, sensor_stiffness=None, frame="model", sensor_patches=None)
    return model, motion, prepare_targets(rec, model)


def _reference_contact(displacements, points, candidates, palate, offset, exclude, faces):
    """The plain whole-array penetration and contact area (as simulate computed them before chunks)."""
    from tonguevis.sim.contact import penetration

    pen = penetration(displacements, points, candidates, palate, offset, exclude)
    n_frames = len(displacements)
    gap = np.full((n_frames, len(points)), np.inf)
    g, _ = palate.clearance((points[candidates][None] + displacements[:, candidates] + offset[:, None]).reshape(-1, 3))
    gap[:, candidates] = np.where(np.isfinite(g), g, np.inf).reshape(n_frames, -1)
    share = np.zeros(len(points))  # each node's third of the rest surface triangles it belongs to
    for tri in faces:
        a, b, c = points[tri]
        share[tri] += 0.5 * np.linalg.norm(np.cross(b - a, c - a)) / 3.0
    return pen, np.array([share[gap[f] < 3e-4].sum() for f in range(n_frames)])


@pytest.mark.parametrize("workers", [1, 3])  # one thread, and chunks taken by several
def test_chunked_figures_equal_the_whole_array(demo, workers):
    from tonguevis.palate import generic_palate
    from tonguevis.sim.figures import ContactProbe, frame_figures
    from tonguevis.sim.plausibility import plausibility_figures, plausibility_from_largest

    model, motion, prep = demo
    full = motion.displacements()
    candidates = np.asarray(model.dorsal_nodes)
    rng = np.random.default_rng(3)
    conflicts = np.column_stack([rng.integers(0, motion.n_frames, 40), rng.integers(0, len(motion.sensor_nodes), 40)])
    near = rng.random((len(candidates), len(motion.sensor_nodes))) < 0.2
    probe = ContactProbe(model.mesh.points, candidates, generic_palate(), prep.jaw_offset, model.surface_faces,
                         conflicts, near)
    chunked = frame_figures(model, motion.q, motion.warping, "numpy", contact=probe, chunk=7,
                            workers=workers)  # 7 does not divide F; the compiled path: test_contact_fast.py

    assert np.allclose(chunked.volume_change, model.volume_change(full), rtol=0, atol=1e-13)
    exclude = np.zeros((motion.n_frames, len(candidates)), dtype=bool)
    for f, s in conflicts:
        exclude[f] |= near[:, s]
    pen, area = _reference_contact(full, model.mesh.points, candidates, probe.palate, prep.jaw_offset, exclude,
                                   model.surface_faces)
    assert pen.max() > 1e-3 and (area > 0).sum() > 10  # the test has contact to compare
    assert np.allclose(chunked.penetration, pen, rtol=0, atol=1e-13)
    assert np.allclose(chunked.contact_area, area, rtol=1e-12, atol=1e-18)

    measured = motion.targets - model.mesh.points[motion.sensor_nodes][None]
    # the far field counted on the surface (what is drawn): the reference takes the surface columns
    surface = model.surface_nodes
    assert np.allclose(chunked.largest_displacement, np.linalg.norm(full[:, surface], axis=2).max(axis=1),
                       rtol=1e-13, atol=0)
    reference, absurd = plausibility_figures(full[:, surface], measured, chunked.volume_change,
                                             motion.sensor_residual)
    fast, fast_absurd = plausibility_from_largest(chunked.largest_displacement, measured, chunked.volume_change,
                                                  motion.sensor_residual)
    assert fast == pytest.approx(reference, rel=1e-12, nan_ok=True) and np.array_equal(absurd, fast_absurd)


@pytest.mark.parametrize("warping", [True, False])
def test_compiled_figures_without_contact_equal_the_whole_array(demo, warping):
    """Without a palate frame_figures warps, measures and drops each frame in one compiled pass
    (kernels.surface_figures, from float32 products): the volume change and largest surface
    displacement of the whole array reconstructed and measured in NumPy, to 1e-8."""
    from tonguevis.sim.figures import frame_figures

    model, motion, _ = demo
    full = model.displacements(motion.q, warping=warping, backend="numpy")
    surface = model.surface_nodes
    for workers in (1, 3):
        fused = frame_figures(model, motion.q, warping, "warp", chunk=7, workers=workers)
        assert np.allclose(fused.volume_change, model.volume_change(full, backend="numpy"), rtol=0, atol=1e-8)
        assert np.allclose(fused.largest_displacement, np.linalg.norm(full[:, surface], axis=2).max(axis=1),
                           rtol=1e-5, atol=1e-8)
    plain = frame_figures(model, motion.q, warping, "numpy")  # the NumPy reconstruction, chunk by chunk
    assert np.allclose(fused.volume_change, plain.volume_change, rtol=0, atol=1e-8)
    assert np.abs(fused.volume_change).max() > 1e-4  # the tongue does change volume: something to compare


def test_simulate_reports_the_whole_array_figures(demo):
    from tonguevis.sim.plausibility import plausibility_figures

    model, motion, _ = demo
    full = motion.displacements()
    # simulate measures from float32 products (see sim.figures): 1e-8 of the float64 whole array
    assert np.allclose(motion.volume_change, model.volume_change(full), rtol=0, atol=1e-8)
    measured = motion.targets - model.mesh.points[motion.sensor_nodes][None]
    reference, _ = plausibility_figures(full[:, model.surface_nodes], measured, motion.volume_change,
                                        motion.sensor_residual)
    assert motion.metadata["plausibility"] == pytest.approx(reference, rel=1e-6, nan_ok=True)


def test_frames_on_demand_equal_the_whole_array(demo):
    model, motion, _ = demo
    full = motion.displacements()
    assert np.array_equal(motion.displacement(123), motion.displacements(slice(123, 124))[0])
    assert np.allclose(motion.displacement(123), full[123], rtol=0, atol=1e-15)
    assert np.allclose(motion.displacements(slice(100, 400, 7)), full[100:400:7], rtol=0, atol=1e-15)
    seen = []
    for idx, chunk in motion.iter_displacements(chunk=100):
        assert chunk.shape == (len(idx), model.mesh.n_nodes, 3) and len(idx) <= 100
        assert np.allclose(chunk, full[idx], rtol=0, atol=1e-15)
        seen.append(idx)
    assert np.array_equal(np.concatenate(seen), np.arange(motion.n_frames))
    surface = np.unique(model.surface_faces)
    for idx, chunk in motion.iter_displacements(chunk=64, frames=slice(5, None, 3), nodes=surface, dtype=np.float32):
        assert chunk.dtype == np.float32 and chunk.shape[1] == len(surface)
        assert np.allclose(chunk, full[idx][:, surface], rtol=1e-5, atol=1e-9)
    with pytest.raises(ValueError, match="chunk"):
        next(motion.iter_displacements(chunk=0))


def test_compiled_integration_without_the_rates_gives_the_same_q(demo):
    """simulate() keeps q alone (rates=False): q̇ and q̈ of every frame were two more arrays of q's size."""
    from tonguevis.sim.newmark import NewmarkSettings
    from tonguevis.sim.newmark_kernel import integrate_compiled
    from tonguevis.sim.simulate import drive_schedule

    model, motion, prep = demo
    basis = model.basis(motion.q.shape[1])
    dofs = (3 * prep.nodes[:, None] + np.arange(3)).ravel()
    s = len(prep.nodes)
    phi_s, w_s = basis.phi[dofs].reshape(s, 3, -1), model.rotation_matrix(basis)[dofs].reshape(s, 3, -1)
    targets, compliance, _ = drive_schedule(prep.displacement[:400], 100.0, basis.eigenvalues, phi_s, None)
    settings = NewmarkSettings(dt=0.01, alpha=model.material.alpha, beta=model.material.beta)
    push = np.zeros((400, basis.phi.shape[1]))
    push[150:160, 0] = 1e-3
    for external in (None, push):
        full = integrate_compiled(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance,
                                  external=external)
        lean = integrate_compiled(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance,
                                  external=external, rates=False)
        assert lean.qd is None and lean.qdd is None and full.qd.shape == full.q.shape
        assert np.array_equal(lean.q, full.q) and np.array_equal(lean.converged, full.converged)


def test_static_projection_in_batches_of_frames_equals_one_batch(demo, monkeypatch):
    import tonguevis.sim.constrained as constrained

    model, motion, prep = demo
    basis = model.basis(motion.q.shape[1])
    dofs = (3 * prep.nodes[:, None] + np.arange(3)).ravel()
    phi_s = basis.phi[dofs].reshape(len(prep.nodes), 3, -1)
    targets = prep.displacement.copy()
    targets[300:340, 1] = np.nan  # a sensor missing for a while
    springs = np.full(targets.shape[:2], 1e-3)
    springs[500:520, 0] = np.inf  # one not acting
    one = [constrained.compliant_shapes(basis.eigenvalues, phi_s, targets, springs),
           constrained.compliant_targets(basis.eigenvalues, phi_s, targets, springs)]
    monkeypatch.setattr(constrained, "FRAMES_PER_SOLVE", 97)
    many = [constrained.compliant_shapes(basis.eigenvalues, phi_s, targets, springs),
            constrained.compliant_targets(basis.eigenvalues, phi_s, targets, springs)]
    for a, b in zip(one, many):
        assert np.allclose(a, b, rtol=1e-12, atol=1e-15) and np.isfinite(a).all()  # rounding of the products


def test_paraview_export_is_one_time_series_meshio_reads(demo, tmp_path):
    import h5py
    import meshio

    from tonguevis.sim.xdmf import DISPLACEMENT_QUANTUM, write_xdmf

    model, motion, _ = demo
    short = _cut(motion, 0, 60)
    path = write_xdmf(short, tmp_path / "motion.xdmf")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["motion.h5", "motion.xdmf"]  # no partial files left
    jaw = np.zeros((short.n_frames, 3)) if short.jaw_offset is None else short.jaw_offset
    with meshio.xdmf.TimeSeriesReader(path) as reader:
        points, cells = reader.read_points_cells()
        assert reader.num_steps == short.n_frames
        assert np.allclose(points, model.mesh.points) and cells[0].type == "tetra"
        assert np.array_equal(cells[0].data, model.mesh.tets)
        for k in (0, 17, short.n_frames - 1):
            t, point_data, _ = reader.read_data(k)
            assert t == pytest.approx(short.times[k])
            expected = short.displacement(k) + jaw[k]  # the head frame: the jaw carries the tongue
            error = np.abs(point_data["displacement"] - expected)
            assert error.max() <= 0.5 * DISPLACEMENT_QUANTUM * (1 + 1e-3) and error.max() > 0  # rounded, no more
            stored = point_data["displacement"] / DISPLACEMENT_QUANTUM
            assert np.array_equal(stored, np.round(stored))  # on the grid: the low bits are free for deflate
    with h5py.File(path.with_suffix(".h5")) as h5:  # compressed, and a plain HDF5 reader undoes it
        dataset = h5["displacement/000017"]
        assert dataset.compression == "gzip" and dataset.shuffle
        assert dataset.id.get_storage_size() < 0.75 * dataset.size * 4


def test_paraview_export_of_the_surface_every_third_frame(demo, tmp_path):
    import h5py
    import meshio

    from tonguevis.sim.xdmf import write_xdmf

    model, motion, _ = demo
    short = _cut(motion, 100, 200)
    surface = np.unique(model.surface_faces)
    path = write_xdmf(short, tmp_path / "surface", surface_only=True, stride=3, frame="jaw", chunk=8,
                      extra_fields=lambda idx: {"frame_number": np.repeat(idx[:, None], len(surface), axis=1)})
    assert path.name == "surface.xdmf"
    with meshio.xdmf.TimeSeriesReader(path) as reader:
        points, cells = reader.read_points_cells()
        assert reader.num_steps == len(range(0, short.n_frames, 3)) == 34
        assert cells[0].type == "triangle" and np.array_equal(surface[cells[0].data], model.surface_faces)
        assert np.allclose(points, model.mesh.points[surface])
        t, point_data, _ = reader.read_data(5)
        assert t == pytest.approx(short.times[15])
        assert np.allclose(point_data["displacement"], short.displacement(15)[surface], rtol=0, atol=2e-6)
        assert np.all(point_data["frame_number"] == 15)
    with h5py.File(path.with_suffix(".h5")) as h5:
        assert np.array_equal(h5["frames"][()], np.arange(0, short.n_frames, 3))
        assert "jaw frame" in h5.attrs["frame_of_reference"]


def test_cli_writes_motion_npz_by_default_and_exports_on_request(tmp_path, capsys):
    from tonguevis.cli import main
    from tonguevis.sim import Motion

    recording = str(DATA_DIR / "spk2_ka.tsv")
    assert main(["simulate", recording, "--quiet", "--out", str(tmp_path / "a")]) == 0
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["motion.npz"]
    motion = Motion.load(tmp_path / "a" / "motion.npz")
    assert main(["simulate", recording, "--quiet", "--out", str(tmp_path / "b"), "--paraview",
                 "--surface-only", "--frame-stride", "10", "--vtk-series"]) == 0
    assert "motion.xdmf" in capsys.readouterr().out
    import meshio

    with meshio.xdmf.TimeSeriesReader(tmp_path / "b" / "motion.xdmf") as reader:
        assert reader.num_steps == len(range(0, motion.n_frames, 10))
    assert len(list((tmp_path / "b" / "vtk").glob("*.vtu"))) == len(range(0, motion.n_frames, 10))
    assert main(["simulate", recording, "--quiet", "--paraview"]) == 2
    assert "--out" in capsys.readouterr().err


def _cut(motion, start, stop):
    """The frames start..stop-1 of ``motion`` (a short motion for the export tests)."""
    from dataclasses import replace

    keep = slice(start, stop)
    return replace(motion, times=motion.times[keep], q=motion.q[keep], targets=motion.targets[keep],
                   sensor_residual=motion.sensor_residual[keep], energy=motion.energy[keep],
                   volume_change=motion.volume_change[keep], converged=motion.converged[keep],
                   jaw_offset=None if motion.jaw_offset is None else motion.jaw_offset[keep])


def test_volume_from_the_surface_nodes_alone_equals_the_whole_mesh(demo):
    model, motion, _ = demo
    full = motion.displacements(slice(0, 300))
    surface = model.surface_nodes
    assert len(surface) < 0.6 * model.mesh.n_nodes  # the inside is left out
    for backend in ("numpy", "warp"):
        assert np.allclose(model.volume_change(full[:, surface], backend=backend, nodes=surface),
                           model.volume_change(full, backend=backend), rtol=0, atol=1e-14)
    with pytest.raises(ValueError, match="every surface node"):
        model.volume_change(full[:, surface[1:]], nodes=surface[1:])
