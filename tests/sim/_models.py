"""Small models shared by the physics tests."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from tonguevis.mesh.structured import box_mesh
from tonguevis.sim.material import Material
from tonguevis.sim.model import TongueModel


def bar_model(nx=12, n=2, length=0.12, height=0.02, sensors=("TT",), poisson=0.3) -> TongueModel:
    """A bar clamped at x = 0 with sensors on its top: TT at the free end, TD in the middle, TL/TR at 3/4."""
    mesh = box_mesh(nx, n, n, (length, height, height))
    clamped = np.flatnonzero(mesh.points[:, 0] < 1e-12)
    spots = {
        "TT": [length, height / 2, height],
        "TD": [length / 2, height / 2, height],
        "TL": [0.75 * length, height, height],
        "TR": [0.75 * length, 0.0, height],
    }
    nodes = {s: int(np.argmin(np.linalg.norm(mesh.points - spots[s], axis=1))) for s in sensors}
    return TongueModel(mesh, SimpleNamespace(sensors=nodes, anchors=clamped), Material(young=6912.0, poisson=poisson))


def sensor_rows(model: TongueModel, nodes, m: int):
    """(eigenvalues, phi_s, w_s) for the given sensor nodes."""
    basis = model.basis(m, cache=False)
    w = model.rotation_matrix(basis)
    dofs = (3 * np.asarray(nodes)[:, None] + np.arange(3)).ravel()
    s = len(nodes)
    return basis.eigenvalues, basis.phi[dofs].reshape(s, 3, -1), w[dofs].reshape(s, 3, -1)
