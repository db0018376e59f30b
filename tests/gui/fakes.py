"""Small stand-ins for the physics, to test the GUI's own logic quickly.

The real TongueModel and simulate() are exercised by the end-to-end tests;
these build a tiny box-shaped model with a smooth analytic "modal basis" so
tests of drawing code need neither eigen-solves nor the demo corpus.
"""

from __future__ import annotations

import numpy as np

from tonguevis.io.recording import Audio, Recording
from tonguevis.mesh.tetmesh import TetMesh
from tonguevis.sim.material import Material
from tonguevis.sim.motion import Motion

def box_mesh(nx: int = 4, ny: int = 3, nz: int = 3, size=(0.06, 0.04, 0.03)) -> TetMesh:
    """A conforming box of (nx × ny × nz) cubes split into positive tets, metres."""
    from tonguevis.mesh.structured import box_mesh as structured_box

    return structured_box(nx, ny, nz, size=size)


class Landmarks:
    def __init__(self, sensors):
        self.sensors = sensors


class FakeBasis:
    def __init__(self, phi):
        self.phi = phi


class FakeModel:
    """A TongueModel look-alike: ``displacement(s)(q, warping)`` from an analytic basis."""

    def __init__(self, mesh: TetMesh, modes: int = 6):
        self.mesh = mesh
        self.material = Material()
        p = mesh.points / mesh.points.max(axis=0)
        basis = []
        for k in range(modes):
            field = np.zeros_like(p)
            field[:, (k % 3)] = np.sin((k + 1) * np.pi * p[:, 0] / 2) * (1 + p[:, 2])
            basis.append(field.ravel())
        self.phi = np.array(basis).T * 0.01  # (3n, m)
        far = np.argmax(p[:, 0] + p[:, 2])
        mid = np.argmin(np.linalg.norm(p - [0.5, 0.5, 1.0], axis=1))
        self.landmarks = Landmarks({"TT": int(far), "TD": int(mid)})

    def basis(self, m):
        return FakeBasis(self.phi[:, :m])

    @property
    def surface_faces(self):
        return self.mesh.boundary_faces()

    def displacement(self, q, warping=True):
        return (self.phi @ q).reshape(-1, 3)

    def displacements(self, q, warping=True, dtype=np.float64, nodes=None):
        q = np.atleast_2d(q)
        u = np.einsum("dm,fm->fd", self.phi, q).reshape(len(q), -1, 3).astype(dtype)
        return u if nodes is None else u[:, nodes]


def fake_recording(duration: float = 2.0, rate: float = 100.0, audio_rate: int = 8000,
                   names=("TT", "TD", "JAW")) -> Recording:
    times = np.arange(int(duration * rate)) / rate
    sensors = {}
    for k, name in enumerate(names):
        phase = 2 * np.pi * 2.0 * times + k
        sensors[name] = np.column_stack([0.01 * k + 0.002 * np.sin(phase), 0.0 * times,
                                         0.05 + 0.005 * np.cos(phase)])
    t_audio = np.arange(int(duration * audio_rate)) / audio_rate
    samples = 0.5 * np.sin(2 * np.pi * 220 * t_audio) * (np.sin(2 * np.pi * 2 * t_audio) > 0)
    return Recording(rate, times, sensors, audio=Audio(samples, float(audio_rate)),
                     metadata={"format": "fake", "file": "fake"})


def fake_motion(model: FakeModel, recording: Recording) -> Motion:
    times = recording.times
    m = model.phi.shape[1]
    q = np.sin(2 * np.pi * np.outer(times, np.arange(1, m + 1)) / 2.0)
    names = list(model.landmarks.sensors)
    nodes = np.array([model.landmarks.sensors[n] for n in names])
    deformed = model.mesh.points[None] + model.displacements(q)
    targets = deformed[:, nodes] + 0.001
    return Motion(times=times, q=q, model=model, warping=False, sensor_names=names, sensor_nodes=nodes,
                  targets=targets, sensor_residual=np.full((len(times), len(names)), np.sqrt(3) * 1e-3),
                  energy=np.zeros(len(times)), volume_change=np.zeros(len(times)),
                  converged=np.ones(len(times), bool))
