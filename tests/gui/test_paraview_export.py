"""The app's ParaView export: one XDMF + HDF5 time series, displacement and energy density per frame."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tests.gui.fakes import FakeModel, box_mesh, fake_motion, fake_recording


@pytest.mark.parametrize("surface_only", [False, True])
def test_paraview_export_holds_what_the_app_shows(tmp_path, surface_only):
    import meshio

    from tonguevis.render.energy_density import EnergyDensity
    from tonguevis.render.paraview import export_paraview

    model = FakeModel(box_mesh())
    motion = fake_motion(model, fake_recording(duration=1.0))
    session = SimpleNamespace(motion=motion, path=None)
    path = export_paraview(session, tmp_path / "out.xdmf", surface_only=surface_only, stride=4)
    u = model.displacements(motion.q)
    energy = EnergyDensity(model.mesh.points, model.mesh.tets, 6912.0, 0.49).nodal(u)
    nodes = np.unique(model.surface_faces) if surface_only else np.arange(model.mesh.n_nodes)
    with meshio.xdmf.TimeSeriesReader(path) as reader:
        points, cells = reader.read_points_cells()
        assert reader.num_steps == len(range(0, motion.n_frames, 4))
        assert cells[0].type == ("triangle" if surface_only else "tetra")
        for k in (0, reader.num_steps - 1):
            t, data, _ = reader.read_data(k)
            i = 4 * k
            assert t == pytest.approx(motion.times[i])
            assert np.allclose(data["displacement"], u[i, nodes], rtol=0, atol=2e-6)  # rounded to 2^-18 m
            assert np.allclose(data["energy_density"], energy[i, nodes], rtol=1e-4, atol=1e-6 * energy.max())


def test_nothing_to_export_before_the_simulation(tmp_path):
    from tonguevis.render.paraview import export_paraview
    from tonguevis.errors import ExportError

    with pytest.raises(ExportError, match="not been simulated"):
        export_paraview(SimpleNamespace(motion=None, path=None), tmp_path / "x.xdmf")
    assert not list(tmp_path.iterdir())
