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
from tonguevis.sim.newmark import NewmarkSettings, integrate
from tonguevis.sim.plausibility import ABSURD_AMPLIFICATION, ABSURD_VOLUME, plausibility_figures

logger = logging.getLogger("tonguevis")

VOLUME_WARNING = 0.05  # relative volume change past which the motion is flagged as implausible
ABSURD_SHARE = 0.05  # a run with more absurd frames than this is refused rather than returned
#: Default sensor spring, in units of the tongue's own point stiffness at the sensors
#: (see :func:`tonguevis.sim.constrained.point_stiffness`); None holds the sensors exactly (the paper).
DEFAULT_SENSOR_STIFFNESS = 20.0


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
    targets, compliance, schedule = drive_schedule(prep.displacement, recording.rate, basis.eigenvalues, phi_s,
                                                   sensor_stiffness)
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
    misfit = _sensor_misfit(result.q, phi_s, w_s, prep.displacement, warping)
    plausibility, absurd = plausibility_figures(displacements, prep.displacement, volume_change, misfit)
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
    released = schedule["released"]
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
        "dropouts": {"bridged_gaps": int(schedule["bridged"]), "released_frames": int(released.sum()),
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
        targets=rest_nodes[None] + prep.displacement,
        sensor_residual=misfit,
        energy=energy,
        volume_change=volume_change,
        converged=result.converged & ~result.recovered,
        metadata=metadata,
    )


def drive_schedule(displacement: np.ndarray, rate: float, eigenvalues: np.ndarray, phi_s: np.ndarray,
                   sensor_stiffness: float | None):
    """What the integrator is driven with: (targets (F, S, 3), compliance (F, S), info).

    The measured sensor displacements (F, S, 3; NaN = missing) are projected
    frame by frame onto the tongue's own deformations
    (:func:`tonguevis.sim.constrained.compliant_targets`: sensor springs of
    ``sensor_stiffness`` times the point stiffness; None keeps the
    measurements, the paper's hard constraints), which also predicts where a
    missing sensor's node goes.  Dropouts are bridged or handed over to that
    prediction (:mod:`tonguevis.sim.dropouts`).  The dynamic solve then holds
    the acting sensor nodes to these targets with hard multipliers: a spring
    in the dynamic solve itself would lag behind fast speech (the sensor
    node, a mass on a spring with the modes' damping, trailed a real /ta/ by
    up to 7 mm).  info: {"bridged": gaps interpolated, "released": (F, S)
    frames a sensor was missing after bridging}.
    """
    from tonguevis.sim.constrained import compliant_targets, point_stiffness
    from tonguevis.sim.dropouts import blend_targets, bridge_short_gaps, handover

    filled, bridged = bridge_short_gaps(displacement, rate)
    present = np.all(np.isfinite(filled), axis=2)
    base = 0.0 if sensor_stiffness is None else 1.0 / (sensor_stiffness * point_stiffness(eigenvalues, phi_s))
    projected = compliant_targets(eigenvalues, phi_s, filled, np.where(present, base, np.inf))
    trust, acting = handover(present, rate)
    targets = blend_targets(np.where(present[:, :, None], projected, np.nan), projected, trust, acting)
    compliance = np.where(np.all(np.isfinite(targets), axis=2), 0.0, np.inf)
    return targets, compliance, {"bridged": bridged, "released": ~present}


def _sensor_misfit(q, phi_s, w_s, measured, warping):
    """(F, S) distance (m) of each sensor node from its measured displacement (NaN where not measured)."""
    from tonguevis.sim.rotation import rotate_accumulated

    d = np.einsum("scm,fm->fsc", phi_s, q)
    if warping:
        d = rotate_accumulated(np.einsum("scm,fm->fsc", w_s, q), d)
    return np.linalg.norm(d - measured, axis=2)


def _stage(progress: ProgressCallback | None, stage: int, stages: int) -> ProgressCallback | None:
    """Map a sub-task's progress onto one of ``stages`` equal parts."""
    if progress is None:
        return None

    def sub(done: int, total: int, message: str = "") -> None:
        frac = done / total if total else 1.0
        progress(int(1000 * (stage + frac)), 1000 * stages, message)

    return sub
