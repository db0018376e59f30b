"""Leave-one-sensor-out validation of the domains model (seed 001), beside :mod:`tonguevis.analysis.validation`
for the modal methods.  Analysis over the simulation: it lives here, not in :mod:`tonguevis.sim.domains`."""

from __future__ import annotations

import time

import numpy as np

from tonguevis.analysis.validation_scores import trajectory_scores
from tonguevis.sim.domains import DomainModel
from tonguevis.sim.model import TongueModel

__all__ = ["held_out_domains"]


def held_out_domains(recording, model=None, landmarks: str = "speaker", rest=None,
                     sensor_stiffness: float | None | str = "default", frame: str = "speaker",
                     tongue_size: float | str | None = None, tolerance: float = 1e-7, cache: bool = True,
                     keep_volume: bool = False) -> dict:
    """Leave-one-sensor-out with the domains method, as :func:`tonguevis.analysis.validate` does for the modal
    ones (which takes no method): per tongue sensor h, the domains seeded at the *other* sensors (the model
    does not know where h sits) and the centre, driven by them as :func:`simulate_domains` drives them, and
    h's node's trajectory scored against h's measurement.  Returns {sensor: {"rmse_mm", "corr", "frames",
    "unconverged_frames", "frames_per_s"}} (:func:`tonguevis.analysis.validation_scores.trajectory_scores`);
    ``keep_volume``: also "kept_rmse_mm" and "kept_corr", the same run with the volume kept
    (:func:`tonguevis.sim.volume.volume_subspace`, the drivers' nodes held, h's free)."""
    from tonguevis.sensor_stiffness import sensor_stiffness_value
    from tonguevis.sim.placement import targets_in_frame
    from tonguevis.sim.simulate import DEFAULT_SENSOR_STIFFNESS, drive_schedule

    sensor_stiffness = sensor_stiffness_value(sensor_stiffness, recording.metadata.get("file"))
    if sensor_stiffness == "default":
        sensor_stiffness = DEFAULT_SENSOR_STIFFNESS
    recording = recording.on_uniform_grid()
    model, prep, _ = targets_in_frame(recording, model or TongueModel.default(), frame, landmarks, rest,
                                      tongue_size=tongue_size)
    nodes = np.asarray(prep.nodes)
    out = {}
    for h, name in enumerate(prep.names):
        keep = np.delete(np.arange(len(nodes)), h)
        dm = DomainModel(model, nodes[keep], cache=cache)
        rows = dm.rows(nodes[keep])
        targets, _, _ = drive_schedule(prep.displacement[:, keep], recording.rate, dm.eigenvalues, rows,
                                       sensor_stiffness)
        t0 = time.perf_counter()
        result = dm.integrate(targets, 1.0 / recording.rate, model.material.alpha, model.material.beta, tolerance)
        elapsed = time.perf_counter() - t0
        predicted = np.einsum("cr,fr->fc", dm.rows([nodes[h]])[0], result.q)
        measured = prep.displacement[:, h]
        ok = np.all(np.isfinite(measured), axis=1)
        scores = trajectory_scores(measured[ok], predicted[ok])
        out[name] = {"rmse_mm": scores["rmse_mm"], "corr": scores["corr"], "frames": int(ok.sum()),
                     "unconverged_frames": int(np.sum(~result.converged)),
                     "frames_per_s": len(targets) / elapsed if elapsed > 0 else float("inf")}
        if keep_volume:
            from tonguevis.sim.volume import held_nodes, volume_subspace

            extra, c, _ = volume_subspace(model, dm.basis, None, result.q, held_nodes(model, nodes[keep]))
            rows_h = slice(3 * int(nodes[h]), 3 * int(nodes[h]) + 3)
            kept = predicted + c @ extra[rows_h].T
            scores = trajectory_scores(measured[ok], kept[ok])
            out[name].update(kept_rmse_mm=scores["rmse_mm"], kept_corr=scores["corr"])
    return out
