"""From a recording to a :class:`Motion`: preprocess, align, integrate, reconstruct."""

from __future__ import annotations

import logging

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.io.recording import Recording
from tonguevis.preprocess.rest import RestChoice
from tonguevis.preprocess.targets import TONGUE_SENSORS, PreparedTargets, prepare_targets  # noqa: F401 (re-exported)
from tonguevis.sim.model import TongueModel
from tonguevis.sim.motion import Motion
from tonguevis.errors import SimulationError
from tonguevis.sim.constrained import RUNAWAY_ROTATION
from tonguevis.sim.dropouts import RAMP_STIFFNESS
from tonguevis.sim.newmark import NewmarkSettings, integrate

logger = logging.getLogger("tonguevis")

VOLUME_WARNING = 0.05  # relative volume change past which the motion is flagged as implausible
#: Per frame, beyond these a frame is absurd (no tongue does it): flagged, and a run with
#: more than ABSURD_SHARE of such frames is refused rather than returned.
ABSURD_VOLUME = 0.25
ABSURD_AMPLIFICATION = 10.0
ABSURD_SHARE = 0.05
MOVED_M = 1e-3  # per-frame amplification only where some sensor moved this far from rest
#: Default sensor spring, in units of the tongue's own point stiffness at the sensors
#: (see :func:`tonguevis.sim.constrained.point_stiffness`); None holds the sensors exactly (the paper).
DEFAULT_SENSOR_STIFFNESS = None


def simulate(
    recording: Recording,
    model: TongueModel | None = None,
    modes: int = 100,
    warping: bool = True,
    landmarks: str = "speaker",
    rest_interval: RestChoice | tuple[float, float] | None = None,
    smooth_window: int | None = None,
    tolerance: float = 1e-8,
    sensor_stiffness: float | None | str = "default",
    backend: str = "warp",
    progress: ProgressCallback | None = None,
) -> Motion:
    """Drive ``model`` (default: our shipped tongue) with ``recording``.

    sensor_stiffness : how hard the sensor nodes are pulled onto the sensors,
        in units of the tongue's own stiffness at the sensor nodes (a
        dimensionless multiple, the same on any mesh); None holds them exactly
        (hard Lagrange multipliers, the paper's setting); "default":
        :data:`DEFAULT_SENSOR_STIFFNESS`.
    backend : "warp" runs the frame loop as a warp-lang kernel
        (:mod:`newmark_kernel`), "numpy" the reference (same result to rounding).
    rest_interval : a :class:`RestChoice`, a (start_s, end_s) the user gave,
        or None to choose one (detected, else the stillest window); the choice
        is in ``motion.metadata["rest"]``.

    Sensor dropouts are bridged when short and released/re-engaged smoothly
    when long (:mod:`tonguevis.sim.dropouts`).  Frames whose Newton solve
    ran away keep the previous shape (``metadata["recovered_frames"]``);
    frames no tongue could produce (volume change over 25 %, a node moving 10x
    the furthest sensor) are flagged, and a run with more than 5 % of them is
    refused with SimulationError.  ``metadata["plausibility"]`` holds the
    far-field amplification (largest node displacement over the largest sensor
    displacement), volume change and sensor misfit.
    """
    from tonguevis._backend import check_backend
    from tonguevis.sim.constrained import point_stiffness
    from tonguevis.sim.dropouts import bridge_short_gaps, compliance_schedule, engagement

    check_backend(backend)
    if sensor_stiffness == "default":
        sensor_stiffness = DEFAULT_SENSOR_STIFFNESS
    if sensor_stiffness is not None and not (np.isfinite(sensor_stiffness) and sensor_stiffness > 0):
        raise SimulationError(f"sensor stiffness must be a positive number or None (hard), got {sensor_stiffness!r}",
                              recording.metadata.get("file"))
    model = model or TongueModel.default()
    prep = prepare_targets(recording, model, landmarks, rest_interval, smooth_window)
    basis = model.basis(modes, progress=_stage(progress, 0, 3))
    w_full = model.rotation_matrix(basis)
    dofs = (3 * prep.nodes[:, None] + np.arange(3)).ravel()
    s = len(prep.nodes)
    phi_s = basis.phi[dofs].reshape(s, 3, -1)
    w_s = w_full[dofs].reshape(s, 3, -1)
    settings = NewmarkSettings(
        dt=1.0 / recording.rate, alpha=model.material.alpha, beta=model.material.beta,
        tolerance=tolerance, warping=warping,
    )
    k_ref = point_stiffness(basis.eigenvalues, phi_s)
    base = 0.0 if sensor_stiffness is None else 1.0 / (sensor_stiffness * k_ref)
    displacement, bridged = bridge_short_gaps(prep.displacement, recording.rate)
    weight, source = engagement(np.all(np.isfinite(displacement), axis=2), recording.rate)
    targets = displacement[source, np.arange(s)[None, :]]
    compliance = compliance_schedule(weight, base, RAMP_STIFFNESS * k_ref)
    report(progress, 1, 3, "integrating")
    if backend == "warp":
        from tonguevis.sim.newmark_kernel import integrate_compiled

        result = integrate_compiled(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance)
    else:
        result = integrate(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance,
                           progress=_stage(progress, 1, 3))
    report(progress, 2, 3, "reconstructing the mesh")
    displacements = model.displacements(result.q, warping=warping, backend=backend)
    volume_change = model.volume_change(displacements, backend=backend)
    energy = model.energy(result.q)
    plausibility, absurd = _plausibility(displacements, displacement, volume_change, result.residual)
    times = recording.times
    file = recording.metadata.get("file")
    if not np.all(np.isfinite(result.q)) or len(absurd) > ABSURD_SHARE * len(times):
        first = int(absurd[0]) if len(absurd) else int(np.flatnonzero(~np.all(np.isfinite(result.q), axis=1))[0])
        raise SimulationError(
            f"the model could not follow this recording plausibly: {len(absurd)} of {len(times)} frames "
            f"change the volume by over {100 * ABSURD_VOLUME:.0f} % or move a node over {ABSURD_AMPLIFICATION:g}x "
            f"as far as any sensor (first at t = {times[first]:.2f} s); try more modes (--modes) or the "
            "speaker's sensor layout (--landmarks speaker)", file)
    bad = np.flatnonzero(~result.converged)
    recovered = np.flatnonzero(result.recovered)
    if len(recovered):
        logger.warning("%d of %d frames ran away (non-finite, or a sensor node turned past %.1f rad) and kept the previous shape (first at t = %.2f s)",
                       len(recovered), len(times), RUNAWAY_ROTATION, times[recovered[0]])
    if len(absurd):
        logger.warning("%d frames are implausible (first at t = %.2f s)", len(absurd), times[absurd[0]])
    worst_volume = float(np.abs(volume_change).max()) if len(volume_change) else 0.0
    if worst_volume > VOLUME_WARNING:
        logger.warning(
            "the tongue changes volume by up to %.1f %% to follow the sensors: too few modes (%d) or sensor "
            "nodes far from the speaker's layout make it bend unnaturally", 100 * worst_volume, modes)
    rest_nodes = model.mesh.points[prep.nodes]
    released = ~np.all(np.isfinite(displacement), axis=2)
    metadata = {
        "recording": dict(recording.metadata),
        "landmarks": landmarks,
        "modes": modes,
        "ignored_sensors": prep.ignored,
        "rest": prep.rest.as_dict(),
        "midsagittal_alignment": prep.midsagittal,
        "alignment_scale": prep.transform.scale,
        "alignment_matrix": prep.transform.matrix.tolist(),
        "alignment_rms_m": prep.alignment_rms,
        "sensor_stiffness": sensor_stiffness,
        "sensor_stiffness_n_per_m": None if sensor_stiffness is None else float(sensor_stiffness * k_ref),
        "point_stiffness_n_per_m": k_ref,
        "dropouts": {"bridged_gaps": int(bridged), "released_frames": int(released.sum()),
                     "released_by_sensor": {n: int(released[:, k].sum()) for k, n in enumerate(prep.names)}},
        "unconverged_frames": bad.tolist(),
        "recovered_frames": recovered.tolist(),
        "implausible_frames": absurd.tolist(),
        "plausibility": plausibility,
        "newton_iterations_mean": float(result.iterations.mean()) if len(result.iterations) else 0.0,
    }
    report(progress, 3, 3, "done")
    return Motion(
        times=np.asarray(times, dtype=np.float64),
        q=result.q,
        model=model,
        warping=warping,
        sensor_names=prep.names,
        sensor_nodes=prep.nodes,
        targets=rest_nodes[None] + displacement,
        sensor_residual=result.residual,
        energy=energy,
        volume_change=volume_change,
        converged=result.converged & ~result.recovered,
        metadata=metadata,
    )


def _plausibility(displacements, sensor_displacement, volume_change, residual):
    """Summary figures of a motion and the frames no tongue could produce.

    displacements : (F, n, 3) node displacements; sensor_displacement : (F, S, 3)
    measured sensor displacements (NaN = missing); volume_change (F,);
    residual (F, S) sensor misfit, metres.
    """
    node = np.linalg.norm(displacements, axis=2).max(axis=1)
    with np.errstate(invalid="ignore"):
        sensor = np.nanmax(np.linalg.norm(sensor_displacement, axis=2), axis=1, initial=0.0)
    sensor = np.where(np.isfinite(sensor), sensor, 0.0)
    moved = sensor >= MOVED_M
    per_frame = np.where(moved, node / np.where(moved, sensor, 1.0), np.nan)
    overall = float(node.max() / sensor.max()) if len(node) and sensor.max() > 0 else float("nan")
    absurd = np.flatnonzero((np.abs(volume_change) > ABSURD_VOLUME) | (per_frame > ABSURD_AMPLIFICATION)
                            | ~np.isfinite(volume_change))
    res = residual[np.isfinite(residual)]
    figures = {
        "amplification": overall,
        "amplification_frame_max": float(np.nanmax(per_frame)) if moved.any() else float("nan"),
        "largest_node_displacement_mm": float(1e3 * node.max()) if len(node) else 0.0,
        "largest_sensor_displacement_mm": float(1e3 * sensor.max()) if len(sensor) else 0.0,
        "volume_change_max_percent": float(100 * np.abs(volume_change).max()) if len(volume_change) else 0.0,
        "sensor_misfit_max_mm": float(1e3 * res.max()) if len(res) else 0.0,
        "sensor_misfit_rms_mm": float(1e3 * np.sqrt(np.mean(res ** 2))) if len(res) else 0.0,
    }
    return figures, absurd


def _stage(progress: ProgressCallback | None, stage: int, stages: int) -> ProgressCallback | None:
    """Map a sub-task's progress onto one of ``stages`` equal parts."""
    if progress is None:
        return None

    def sub(done: int, total: int, message: str = "") -> None:
        frac = done / total if total else 1.0
        progress(int(1000 * (stage + frac)), 1000 * stages, message)

    return sub
