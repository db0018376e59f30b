"""Leave-one-sensor-out validation: how well does the model predict a sensor it was not told?

For each tongue sensor h of a recording in turn:

1. The recording is prepared once with *all* tongue sensors
   (:func:`tonguevis.preprocess.prepare_targets`): head and jaw correction, rest
   pose, the similarity fit onto the model, and each sensor's node (the
   placement-rule node, or with ``landmarks="speaker"`` the dorsal-surface
   node nearest its aligned rest position).  Using every sensor's *rest*
   position here is fair: rest poses are known before any motion.  Sensor h's
   *motion* never drives anything.
2. The model is driven by the other sensors only, and the displacement of
   h's node is read from the result.  Four predictors:

   * ``model``: the warped modal model, Newmark dynamics (what ``simulate`` runs);
   * ``linear``: the same modes without warping (linear modal dynamics);
   * ``static``: the warped model solved quasi-statically, frame by frame
     (no inertia or damping; :mod:`tonguevis.analysis.quasistatic`);
   * ``kinematic``: no mesh at all, a radial-basis interpolation of the
     driving sensors' displacements over their aligned rest positions
     (:mod:`tonguevis.analysis.kinematic`).

3. Each prediction is compared with h's measured displacement from rest, in
   the model frame (after the same similarity fit), with :func:`trajectory_scores`.

Scoring lives in :mod:`tonguevis.analysis.validation_scores`, the report
tables in :mod:`tonguevis.analysis.validation_report`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

from tonguevis._logging import verbose
from tonguevis._progress import ProgressCallback, report
from tonguevis.analysis.kinematic import interpolation_weights
from tonguevis.analysis.validation_scores import recording_summary, trajectory_scores
from tonguevis.errors import SimulationError
from tonguevis.io.recording import Recording


METHODS = ("model", "linear", "static", "kinematic")

@dataclass
class HeldOutSensor:
    """One held-out sensor.

    name, node : the sensor and its mesh node; drivers : the sensors that drove the model.
    measured : (F, 3) its measured displacement from rest, model frame, metres.
    predicted : method -> (F, 3) predicted displacement of its node (or point), metres.
    converged : method -> (F,) bool, Newton convergence of the driven run (kinematic: all True).
    """

    name: str
    node: int
    drivers: list[str]
    measured: np.ndarray
    predicted: dict[str, np.ndarray] = field(default_factory=dict)
    converged: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class ValidationResult:
    """Scores per held-out sensor, the recording's summary and the settings used.

    ``as_dict()`` is the JSON document: {"sensors": {NAME: scores},
    "settings": {...}, "recording": {...}}.
    """

    sensors: dict[str, dict[str, Any]]
    settings: dict[str, Any]
    recording: dict[str, Any]
    held_out: dict[str, HeldOutSensor]

    def as_dict(self) -> dict[str, Any]:
        return _finite({"sensors": self.sensors, "settings": self.settings, "recording": self.recording})

    def write_json(self, path) -> None:
        """Write :meth:`as_dict` as JSON (temporary file, then rename)."""
        import json

        from tonguevis._files import atomic_write_text

        atomic_write_text(path, json.dumps(self.as_dict(), indent=1, allow_nan=False) + "\n")


@verbose
def validate(
    recording: Recording,
    settings=None,
    model=None,
    *,
    progress: ProgressCallback | None = None,
    quasi_static: bool = True,
    **overrides: Any,
) -> ValidationResult:
    """Leave-one-sensor-out validation of ``model`` (default: the settings' mesh, else the shipped tongue) on
    ``recording``, simulated as ``settings`` (a :class:`~tonguevis.sim.settings.RunSettings`, default everyone's)
    with ``overrides`` (its fields as keywords) describe: the motion with every sensor is
    :func:`tonguevis.sim.simulate`'s, and each held-out run uses the same settings.

    Needs >= 3 tongue sensors with landmarks on the model (each run is driven by >= 2).
    rest : the detected rest by default, else the stillest 0.2 s window (logged; the JSON says which).
    method : the ``model`` predictor's: "warped" (default), "linear" (then equal to the ``linear`` baseline) or
        "domains" (seed 001's model, :func:`tonguevis.analysis.validation_domains.held_out_domains`, seeded at
        the driving sensors); ``linear``, ``static`` and ``kinematic`` are the modal baselines whatever it is.
    sensor_stiffness : every physical predictor's.
    sensor_patches : in each run the patches of the driving sensors only close their gaps, and the held-out
        node moves with the modes and those patches.
    frame, tongue_size : "speaker" (default) scores in the speaker's millimetres (the model placed in the
        speaker at ``tongue_size``), "model" in the generic tongue's (the speaker scaled onto it).
    keep_volume : besides each dynamic method, the same runs with the volume kept
        (:func:`tonguevis.sim.volume.volume_subspace`, the driving sensors' nodes held, the held-out
        node free), scored as ``{method}_kept``; the summary is of the motion with every sensor, kept too.
    rest_fit : the tongue bent onto every rest sensor (the held-out one's rest position too, as the
        interpolation baseline uses it; its motion is what is predicted).
    palate : the motion with every sensor is simulated against it (its contact figures in the summary); the
        held-out runs are kept below it the same way (:func:`tonguevis.sim.simulate.keep_below_palate`).
    """
    from tonguevis.io.sensor_map import how_to_map
    from tonguevis.preprocess.targets import TONGUE_SENSORS, working_tongue_sensors
    from tonguevis.sim.placement import targets_in_frame
    from tonguevis.sim.settings import RunSettings, build_model, run_settings
    from tonguevis.sim.patches import humped_sensors
    from tonguevis.sim.simulate import TOUCH_REACH, contact_context, drive_schedule, held_to_palate, simulate

    file = recording.metadata.get("file")
    if settings is not None and not isinstance(settings, RunSettings):  # validate(recording, model, ...)
        settings, model = model if isinstance(model, RunSettings) else None, settings
    try:
        settings = run_settings(settings, **overrides)
    except SimulationError as exc:
        raise SimulationError(str(exc), file) from None
    modes, landmarks, frame, tolerance = settings.modes, settings.landmarks, settings.frame, settings.newton_tolerance
    sensor_stiffness, keep_volume = settings.sensor_stiffness_value, settings.keep_volume
    model = model if model is not None else build_model(settings)
    recording = recording.on_uniform_grid()  # as simulate: dropped frames back as missing samples
    working = working_tongue_sensors(recording)  # warns about a coil that never worked, once
    dead = [n for n in TONGUE_SENSORS if n in recording.sensors and n not in working]
    if dead:
        recording = recording.with_sensors({k: v for k, v in recording.sensors.items() if k not in dead})
    candidates = [n for n in working if n in model.landmarks.sensors]
    if len(candidates) < 3:
        raise SimulationError(
            f"leave-one-sensor-out needs at least 3 tongue sensors with model landmarks, found "
            f"{candidates or 'none'} (recording sensors: {', '.join(recording.sensor_names)}); "
            + how_to_map(recording), file)
    given = model
    model, prep, fit = targets_in_frame(recording, model, frame, landmarks, settings.rest,
                                        settings.smooth_window, tongue_size=settings.tongue_size,
                                        rest_fit=settings.rest_fit)  # the model in the frame (its rest shape fitted)
    sensor_patches = settings.sensor_patches
    if sensor_patches == "default":  # 3 mm on the generic tongue, as simulate() takes it
        from tonguevis.sim.patches import PATCH_RADIUS

        sensor_patches = PATCH_RADIUS / (fit["scale"] if frame == "speaker" else 1.0)
    names, nodes = prep.names, np.asarray(prep.nodes)
    basis = model.basis(modes)
    w_full = model.rotation_matrix(basis)
    report(progress, 0, 4, "simulating with every sensor")
    motion = simulate(recording, settings.replace(rest=prep.rest), given)
    centres = prep.aligned_rest
    s = len(names)
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    phi_s = basis.phi[dofs].reshape(s, 3, -1)
    w_s = w_full[dofs].reshape(s, 3, -1)
    drive, contact = prep.displacement, None
    if settings.palate is not None:  # as simulate(): sensors touching the palate held to it, the tongue below it
        contact = contact_context(settings.palate, prep, model, basis, recording)
        contact["backend"] = settings.backend
        reach = TOUCH_REACH * (1.0 if frame == "speaker" else fit["scale"])
        drive, _ = held_to_palate(contact, model.mesh.points[nodes], drive, reach, names)
    # Trial h drives with every sensor but h: h's targets are marked missing,
    # which the integrator treats as a sensor that is not there; the other
    # sensors' dropouts are handled as in the simulation.
    schedules = []
    for h in range(s):
        held = drive.copy()
        held[:, h] = np.nan
        schedules.append(drive_schedule(held, recording.rate, basis.eigenvalues, phi_s, sensor_stiffness,
                                        contact=contact))
    trials = np.stack([sch[0] for sch in schedules])  # (S, F, S, 3)
    compliance = np.stack([sch[1] for sch in schedules])  # (S, F, S)
    # Per method and trial: the held-out node's trajectory (F, 3) and the converged flags; each
    # trial's q (F, m) is dropped once its node is reconstructed (a long recording's five trials of
    # q are hundreds of MB a method).
    predicted: dict[str, list] = {}

    def keep_held_out(method: str, runs, warping: bool) -> None:
        out, kept = [], []
        for h, (q, conv) in enumerate(runs):
            run_basis, run_w = basis, w_full
            if contact is not None:  # where inertia carried the tongue into the palate, as simulate() corrects it
                from tonguevis.sim.simulate import keep_below_palate

                q, _ = keep_below_palate(q, contact, schedules[h][2], basis, phi_s, base_compliance)
            if sensor_patches is not None:  # the drivers' patches close their gaps; the held-out one has none
                drivers = [name for k, name in enumerate(prep.names) if k != h]
                run_basis, run_w, q = _patched(model, basis, np.delete(nodes, h), q,
                                               np.delete(prep.displacement, h, axis=1), warping, sensor_patches,
                                               humped_sensors(drivers) if settings.humps else None)
            out.append((_node_trajectory(run_basis, run_w, int(nodes[h]), q, warping), np.asarray(conv, bool)))
            if keep_volume:  # the same run projected, the drivers' nodes held, h's free
                from tonguevis.sim.volume import held_nodes, volume_subspace

                extra, c, _ = volume_subspace(model, run_basis.phi, run_w if warping else None, q,
                                              held_nodes(model, np.delete(nodes, h)))
                kept.append((_node_trajectory(SimpleNamespace(phi=np.hstack([run_basis.phi, extra])),
                                              np.hstack([run_w, np.zeros_like(extra)]), int(nodes[h]),
                                              np.hstack([q, c]), warping), np.asarray(conv, bool)))
        predicted[method] = out
        if keep_volume:
            predicted[f"{method}_kept"] = kept

    from tonguevis.sim.constrained import point_stiffness

    base_compliance = 0.0 if sensor_stiffness is None else 1.0 / (sensor_stiffness * point_stiffness(
        basis.eigenvalues, phi_s))
    for k, (method, warping) in enumerate((("model", settings.warping), ("linear", False))):
        report(progress, 1 + k, 4, f"leave-one-out: {method}")
        if method == "model" and settings.method == "domains":  # seed 001's model, seeded at the drivers
            from tonguevis.analysis.validation_domains import held_out_domains

            runs = held_out_domains(recording, settings.replace(rest=prep.rest), given, trajectories=True)
            predicted["model"] = [(runs[name]["predicted"], runs[name]["converged"]) for name in names]
            if keep_volume:
                predicted["model_kept"] = [(runs[name]["kept"], runs[name]["converged"]) for name in names]
            continue
        keep_held_out(method, _drive_trials(basis, phi_s, w_s, trials, compliance, warping, 1.0 / recording.rate,
                                            model.material, tolerance), warping)
    if quasi_static:
        from tonguevis.analysis.quasistatic import quasi_static as solve_static

        report(progress, 3, 4, "leave-one-out: quasi-static")
        keep_held_out("static", [solve_static(basis.eigenvalues, phi_s, w_s, t, tolerance, compliance=c)[:2]
                                 for t, c in zip(trials, compliance)], True)
    held_out: dict[str, HeldOutSensor] = {}
    scores: dict[str, dict[str, Any]] = {}
    for h, name in enumerate(names):
        keep = np.array([k for k in range(s) if k != h])
        item = HeldOutSensor(name, int(nodes[h]), [names[k] for k in keep], prep.displacement[:, h])
        for method, runs in predicted.items():
            item.predicted[method], item.converged[method] = runs[h]
        weights = interpolation_weights(centres[keep], centres[h][None])[0]
        item.predicted["kinematic"] = np.einsum("n,fnc->fc", weights, prep.displacement[:, keep])
        item.converged["kinematic"] = np.ones(len(recording.times), dtype=bool)
        held_out[name] = item
        scores[name] = _sensor_scores(item)
        # A negative interpolation weight: the held-out sensor lies outside the
        # drivers' hull (exact when the drivers are affinely independent, as
        # for 2 or 3 drivers: the weights are then barycentric coordinates).
        scores[name]["outside_drivers"] = bool(np.any(weights < -1e-9))
        scores[name]["kinematic_weights"] = weights.tolist()
    report(progress, 4, 4, "validated")
    summary = recording_summary(recording, motion, prep, prep.rest.interval, prep.rest.how)
    summary["rest_interval_reason"] = prep.rest.reason
    summary["plausibility"] = dict(motion.metadata.get("plausibility", {}))
    for key in ("recovered_frames", "implausible_frames"):
        summary[key] = list(motion.metadata.get(key, []))
    described = _settings(model, basis, modes, landmarks, quasi_static, tolerance, frame)
    described["method"] = settings.method
    described["sensor_stiffness"] = sensor_stiffness
    described["sensor_stiffness_n_per_m"] = motion.metadata.get("sensor_stiffness_n_per_m")
    if settings.palate is not None:
        described["palate"] = {"contact": motion.metadata.get("contact", {}), "held_out_runs": "kept below it"}
    if settings.rest_fit:
        described["rest_fit"] = fit.get("rest_fit")
    return ValidationResult(scores, described, summary, held_out)


def _sensor_scores(item: HeldOutSensor) -> dict[str, Any]:
    """Scores of every method on the frames where all methods and the measurement are finite."""
    ok = np.all(np.isfinite(item.measured), axis=1)
    for pred in item.predicted.values():
        ok &= np.all(np.isfinite(pred), axis=1)
    out: dict[str, Any] = {"node": item.node, "drivers": item.drivers, "frames": int(ok.sum())}
    measured = item.measured[ok]
    out["measured_std_axes_mm"] = (1e3 * measured.std(axis=0)).tolist() if len(measured) else [np.nan] * 3
    out["measured_peak_mm"] = float(1e3 * np.linalg.norm(measured, axis=1).max()) if len(measured) else np.nan
    for method, pred in item.predicted.items():
        s = trajectory_scores(measured, pred[ok])
        out[f"{method}_rmse_mm"] = s["rmse_mm"]
        out[f"{method}_corr"] = s["corr"]
        out[f"{method}_rmse_axes_mm"] = s["rmse_axes_mm"]
        out[f"{method}_corr_axes"] = s["corr_axes"]
        out[f"{method}_unconverged_frames"] = int(np.sum(~item.converged[method]))
    return out


def _drive_trials(basis, phi_s, w_s, trials, compliance, warping, dt, material, tolerance) -> list:
    """[(q (F, m), converged (F,))] per trial of targets (T, F, S, 3), and compliances (T, F, S)
    at the sensor rows phi_s, w_s (S, 3, m); the compiled integrator runs all trials in one launch."""
    from tonguevis.sim.newmark import NewmarkSettings

    settings = NewmarkSettings(dt=dt, alpha=material.alpha, beta=material.beta, tolerance=tolerance, warping=warping)
    from tonguevis.sim.newmark_kernel import integrate_compiled

    results = integrate_compiled(basis.eigenvalues, phi_s, w_s, trials, settings, compliance=compliance,
                                 rates=False)  # q alone: each trial's q̇ and q̈ would be two more (F, m) arrays
    return [(r.q, r.converged) for r in results]


def _patched(model, basis, drivers: np.ndarray, q: np.ndarray, measured: np.ndarray, warping: bool, radius: float,
             humped: list[int] | None = None):
    """(augmented basis, its W, q with the patch coordinates) of one run: the driving sensors'
    patches (:mod:`tonguevis.sim.patches`) closing the gaps to their measurements (F, S', 3); ``humped``: the
    drivers with a hump (indices; None: no humps)."""
    from tonguevis.sim.patches import augmented_basis, augmented_model, close_sensor_gaps

    augmented = augmented_basis(model, basis, drivers, radius, hump=None if humped is None else "scaled",
                                humped=humped)
    rotation = augmented_model(model, augmented).rotation_matrix(augmented)
    patch = close_sensor_gaps(augmented, rotation, drivers, q, measured, warping)
    return augmented, rotation, np.hstack([q, patch])


def _node_trajectory(basis, w_full, node: int, q: np.ndarray, warping: bool) -> np.ndarray:
    """(F, 3) displacement of one node for modal displacements q (F, m), metres."""
    from tonguevis.sim.rotation import rotate_accumulated

    rows = slice(3 * node, 3 * node + 3)
    d = q @ basis.phi[rows].T
    if not warping:
        return d
    return rotate_accumulated(q @ w_full[rows].T, d)


def _settings(model, basis, modes, landmarks, quasi_static, tolerance, frame: str = "model") -> dict[str, Any]:
    from tonguevis.analysis.validation_scores import MIN_AXIS_STD_MM

    mesh = model.mesh
    return {
        "modes": int(modes),
        "landmarks": landmarks,
        "methods": list(METHODS if quasi_static else [m for m in METHODS if m != "static"]),
        "mesh": {"nodes": int(mesh.n_nodes), "tets": int(mesh.n_tets),
                 "source": str(mesh.metadata.get("file") or mesh.metadata.get("source") or "default"),
                 "anchors": [int(a) for a in model.anchors],
                 "sensor_landmarks": {k: int(v) for k, v in model.landmarks.sensors.items()}},
        "material": model.material.as_dict(),
        "lowest_frequency_hz": float(np.sqrt(max(basis.eigenvalues[0], 0.0)) / (2 * np.pi)),
        "highest_frequency_hz": float(np.sqrt(max(basis.eigenvalues[-1], 0.0)) / (2 * np.pi)),
        "newton_tolerance_m": tolerance,
        "kinematic": "RBFInterpolator, linear kernel + degree-1 polynomial, in the driving sensors' affine hull",
        "frame": frame,
        "units": ("displacements in mm in the speaker's frame (the model placed in the speaker)" if frame == "speaker"
                  else "displacements in mm in the model frame (after the similarity fit)"),
        "correlation": ("per-axis Pearson r of predicted vs measured displacement, averaged over the axes "
                        f"whose measured standard deviation is at least {MIN_AXIS_STD_MM} mm"),
    }


def _finite(obj):
    """The same structure with NaN/inf floats as None (strict JSON) and NumPy scalars as Python."""
    if isinstance(obj, dict):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_finite(v) for v in (obj.tolist() if isinstance(obj, np.ndarray) else obj)]
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj
