"""Leave-one-sensor-out validation of the domains model (seed 001), beside :mod:`tonguevis.analysis.validation`
for the modal methods.  Analysis over the simulation: it lives here, not in :mod:`tonguevis.sim.domains`."""

from __future__ import annotations

import time

import numpy as np

from tonguevis.analysis.validation_scores import trajectory_scores
from tonguevis.sim.domains import DomainModel

__all__ = ["held_out_domains"]


def held_out_domains(recording, settings=None, model=None, *, cache: bool = True, trajectories: bool = False,
                     **overrides) -> dict:
    """Leave-one-sensor-out with the domains method, as :func:`tonguevis.analysis.validate` does for the modal
    ones (``validate(..., method="domains")`` calls this for its ``model`` predictor): per tongue sensor h, the
    domains seeded at the *other* sensors (the model does not know where h sits) and the centre, driven by them
    as :func:`simulate_domains` drives them, and h's node's trajectory scored against h's measurement.
    ``settings``, ``overrides``: as :func:`tonguevis.sim.simulate` (a
    :class:`~tonguevis.sim.settings.RunSettings`; the method is domains whatever they say).
    Returns {sensor: {"rmse_mm", "corr", "frames", "unconverged_frames", "frames_per_s"}}
    (:func:`tonguevis.analysis.validation_scores.trajectory_scores`); ``keep_volume``: also "kept_rmse_mm" and
    "kept_corr", the same run with the volume kept (:func:`tonguevis.sim.volume.volume_subspace`, the drivers'
    nodes held, h's free); ``trajectories``: also "predicted" (F, 3) m, "converged" (F,) and with
    ``keep_volume`` "kept" (F, 3) m."""
    from tonguevis.errors import SimulationError
    from tonguevis.sim.placement import targets_in_frame
    from tonguevis.sim.settings import RunSettings, build_model, run_settings
    from tonguevis.sim.simulate import drive_schedule

    if settings is not None and not isinstance(settings, RunSettings):  # held_out_domains(recording, model, ...)
        settings, model = model if isinstance(model, RunSettings) else None, settings
    try:
        settings = run_settings(settings, **overrides).replace(method="domains")
    except SimulationError as exc:
        raise SimulationError(str(exc), recording.metadata.get("file")) from None
    sensor_stiffness, tolerance, keep_volume = (settings.sensor_stiffness_value, settings.newton_tolerance,
                                                settings.keep_volume)
    model = model if model is not None else build_model(settings)
    recording = recording.on_uniform_grid()
    model, prep, _ = targets_in_frame(recording, model, settings.frame, settings.landmarks, settings.rest,
                                      settings.smooth_window, tongue_size=settings.tongue_size)
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
        if trajectories:
            out[name].update(predicted=predicted, converged=np.asarray(result.converged, bool))
        if keep_volume:
            from tonguevis.sim.volume import held_nodes, volume_subspace

            extra, c, _ = volume_subspace(model, dm.basis, None, result.q, held_nodes(model, nodes[keep]))
            rows_h = slice(3 * int(nodes[h]), 3 * int(nodes[h]) + 3)
            kept = predicted + c @ extra[rows_h].T
            scores = trajectory_scores(measured[ok], kept[ok])
            out[name].update(kept_rmse_mm=scores["rmse_mm"], kept_corr=scores["corr"])
            if trajectories:
                out[name]["kept"] = kept
    return out
