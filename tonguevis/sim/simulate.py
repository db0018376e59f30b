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
from tonguevis.sim.newmark import NewmarkSettings, integrate

logger = logging.getLogger("tonguevis")

VOLUME_WARNING = 0.05  # relative volume change past which the motion is flagged as implausible


def simulate(
    recording: Recording,
    model: TongueModel | None = None,
    modes: int = 100,
    warping: bool = True,
    landmarks: str = "speaker",
    rest_interval: RestChoice | tuple[float, float] | None = None,
    smooth_window: int | None = None,
    tolerance: float = 1e-8,
    compiled: bool = True,
    progress: ProgressCallback | None = None,
) -> Motion:
    """Drive ``model`` (default: our shipped tongue) with ``recording``.

    Returns a :class:`Motion` whose sensor nodes follow the aligned sensor
    displacements (warped positions when ``warping``) to ``tolerance`` metres.
    Frames where Newton did not converge are flagged in ``motion.converged``
    and logged, never silently returned as converged.  ``compiled`` runs the
    frame loop as a warp-lang kernel (:mod:`newmark_warp`); ``False`` runs the
    NumPy reference, which gives the same result to rounding.
    ``rest_interval``: a :class:`RestChoice`, a (start_s, end_s) the user gave,
    or None to choose one (detected, else the stillest window); the choice is
    in ``motion.metadata["rest"]`` = {"interval": [start_s, end_s], "how": ...}.
    """
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
    report(progress, 1, 3, "integrating")
    if compiled:
        from tonguevis.sim.newmark_warp import integrate_warp

        result = integrate_warp(basis.eigenvalues, phi_s, w_s, prep.displacement, settings)
    else:
        result = integrate(basis.eigenvalues, phi_s, w_s, prep.displacement, settings, progress=_stage(progress, 1, 3))
    report(progress, 2, 3, "reconstructing the mesh")
    displacements = model.displacements(result.q, warping=warping)
    volume_change = model.volume_change(displacements)
    energy = model.energy(result.q)
    bad = np.flatnonzero(~result.converged)
    if len(bad):
        logger.warning(
            "%d of %d frames did not converge (first at t = %.2f s)", len(bad), len(result.q),
            recording.times[bad[0]])
    worst_volume = float(np.abs(volume_change).max()) if len(volume_change) else 0.0
    if worst_volume > VOLUME_WARNING:
        logger.warning(
            "the tongue changes volume by up to %.1f %% to follow the sensors: too few modes (%d) or sensor "
            "nodes far from the speaker's layout make it bend unnaturally", 100 * worst_volume, modes)
    rest_nodes = model.mesh.points[prep.nodes]
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
        "unconverged_frames": bad.tolist(),
        "newton_iterations_mean": float(result.iterations.mean()) if len(result.iterations) else 0.0,
    }
    report(progress, 3, 3, "done")
    return Motion(
        times=np.asarray(recording.times, dtype=np.float64),
        q=result.q,
        model=model,
        warping=warping,
        sensor_names=prep.names,
        sensor_nodes=prep.nodes,
        targets=rest_nodes[None] + prep.displacement,
        sensor_residual=result.residual,
        energy=energy,
        volume_change=volume_change,
        converged=result.converged,
        metadata=metadata,
    )


def _stage(progress: ProgressCallback | None, stage: int, stages: int) -> ProgressCallback | None:
    """Map a sub-task's progress onto one of ``stages`` equal parts."""
    if progress is None:
        return None

    def sub(done: int, total: int, message: str = "") -> None:
        frac = done / total if total else 1.0
        progress(int(1000 * (stage + frac)), 1000 * stages, message)

    return sub
