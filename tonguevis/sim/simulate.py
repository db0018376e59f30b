"""From a recording to a :class:`Motion`: preprocess, align, integrate, reconstruct."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np

from tonguevis._progress import ProgressCallback, report
from tonguevis.errors import SimulationError
from tonguevis.io.recording import Recording
from tonguevis.sim.model import TongueModel
from tonguevis.sim.motion import Motion
from tonguevis.sim.newmark import NewmarkSettings, integrate

logger = logging.getLogger("tonguevis")

TONGUE_SENSORS = ("TT", "TB", "TD", "TBK", "TL", "TR")
LATERAL_SENSORS = ("TL", "TR")
VOLUME_WARNING = 0.05  # relative volume change past which the motion is flagged as implausible


@dataclass
class PreparedTargets:
    """Aligned sensor motion ready to drive a model.

    names : S driving sensors; nodes : (S,) their mesh nodes;
    displacement : (F, S, 3) sensor displacement from rest in the model frame (m), NaN = missing;
    transform : the similarity fit recording -> model; ignored : sensors without a node;
    rest_interval : (start_s, end_s); midsagittal : whether the fit kept the midsagittal plane;
    alignment_rms : RMS distance (m) between aligned rest sensors and their nodes before snapping.
    aligned_rest : (S, 3) rest positions of the sensors in the model frame (m).
    """

    names: list[str]
    nodes: np.ndarray
    displacement: np.ndarray
    transform: Any
    ignored: list[str]
    rest_interval: tuple[float, float]
    midsagittal: bool
    alignment_rms: float
    aligned_rest: np.ndarray


def prepare_targets(
    recording: Recording,
    model: TongueModel,
    landmarks: str = "speaker",
    rest_interval: tuple[float, float] | None = None,
    smooth_window: int | None = None,
) -> PreparedTargets:
    """Head and jaw correction, rest pose, similarity fit, sensor-node choice (§3.1).

    landmarks : "rule" keeps the model's placement-rule nodes (comparable
        across speakers, as the paper); "speaker" snaps each sensor to the
        dorsal-surface node nearest its own aligned rest position.
    """
    from tonguevis import preprocess as pp

    file = recording.metadata.get("file")
    if landmarks not in ("rule", "speaker"):
        raise SimulationError(f"landmarks must be 'rule' or 'speaker', got {landmarks!r}", file)
    present = [n for n in TONGUE_SENSORS if n in recording.sensors]
    names = [n for n in present if n in model.landmarks.sensors]
    ignored = [n for n in present if n not in model.landmarks.sensors]
    if ignored:
        logger.warning("sensors %s have no landmark on the model and are ignored", ", ".join(ignored))
    if len(names) < 2:
        raise SimulationError(
            f"too few tongue sensors to drive the model: found {names or 'none'} of "
            f"{', '.join(TONGUE_SENSORS)} (recording sensors: {', '.join(recording.sensor_names)}); "
            "map the channels with a sensor map", file)
    rec = recording
    if rest_interval is None:
        rest_interval = pp.find_rest_interval(rec, sensors=names)
    if sum(n.upper().startswith("REF") for n in rec.sensors) >= 3:
        rec = pp.correct_head(rec, rest_interval=rest_interval)
    if "JAW" in rec.sensors:
        rec = pp.correct_jaw(rec, rest_interval=rest_interval)
    if smooth_window:
        rec = pp.smooth(rec, window=smooth_window, sensors=names)
    rest = pp.rest_pose(rec, rest_interval, sensors=names)
    source = np.array([rest[n] for n in names])
    rule_nodes = np.array([int(model.landmarks.sensors[n]) for n in names])
    target = model.mesh.points[rule_nodes]
    midsagittal = not any(n in LATERAL_SENSORS for n in names)
    if not midsagittal and len(names) < 3:
        raise SimulationError(f"a 3-D alignment needs at least 3 tongue sensors, got {names}", file)
    transform = pp.fit_similarity(source, target, midsagittal=midsagittal)
    aligned_rest = transform.apply(source)
    alignment_rms = float(np.sqrt(np.mean(np.sum((aligned_rest - target) ** 2, axis=1))))
    if landmarks == "speaker":
        candidates = model.dorsal_nodes
        dist = np.linalg.norm(model.mesh.points[candidates][None] - aligned_rest[:, None], axis=2)
        nodes = candidates[np.argmin(dist, axis=1)]
        if len(np.unique(nodes)) < len(nodes):
            raise SimulationError(f"two sensors snapped to the same node ({dict(zip(names, nodes.tolist()))})", file)
    else:
        nodes = rule_nodes
    positions = np.stack([rec.sensors[n] for n in names], axis=1)  # (F, S, 3)
    # Displacement from rest, rotated and scaled into the model frame.
    displacement = transform.scale * (positions - source[None]) @ transform.rotation.T
    return PreparedTargets(
        names, nodes, displacement, transform, ignored, tuple(rest_interval), midsagittal, alignment_rms, aligned_rest
    )


def simulate(
    recording: Recording,
    model: TongueModel | None = None,
    modes: int = 100,
    warping: bool = True,
    landmarks: str = "speaker",
    rest_interval: tuple[float, float] | None = None,
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
        "rest_interval": list(prep.rest_interval),
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
