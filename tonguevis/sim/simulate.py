"""From a recording to a :class:`Motion`: preprocess, align, integrate, reconstruct."""

from __future__ import annotations


import numpy as np

from tonguevis._memory import release_freed_memory
from tonguevis._progress import ProgressCallback, report
from tonguevis.io.recording import Recording
from tonguevis.preprocess.targets import TONGUE_SENSORS, PreparedTargets, prepare_targets  # noqa: F401 (re-exported)
from tonguevis.sim.model import TongueModel
from tonguevis.sim.motion import Motion
from tonguevis.errors import SimulationError
from tonguevis.sim.figures import frame_figures
from tonguevis.sim.newmark import NewmarkSettings, integrate
from tonguevis.sim.drive import drive_schedule
from tonguevis.sim.motion_builder import MotionBuilder
from tonguevis.sim.palate_placement import (TOUCH_REACH, _by_head_references,  # noqa: F401 (re-exported)
                                            contact_context, contact_probe, held_to_palate, keep_below_palate,
                                            place_palate, placed_palate)
from tonguevis.sim.settings import (DEFAULT_SENSOR_STIFFNESS, METHODS, RunSettings,  # noqa: F401 (re-exported)
                                     build_model, run_settings)

from tonguevis._logging import logger, verbose



@verbose
def simulate(
    recording: Recording,
    settings: RunSettings | TongueModel | None = None,
    model: TongueModel | None = None,
    *,
    progress: ProgressCallback | None = None,
    preview=None,
    preview_seconds: float = 20.0,
    **overrides,
) -> Motion:
    """Drive ``model`` (default: the settings' mesh, else our shipped tongue) with ``recording``, as
    ``settings`` (a :class:`~tonguevis.sim.settings.RunSettings`; default: everyone's defaults, so
    ``simulate(recording)`` simulates as ``tonguevis simulate FILE`` does) describe, with any of its fields
    given as keywords overriding it (``simulate(recording, settings, modes=60)``).  The model may also come
    second (``simulate(recording, model, modes=60)``, as before the settings).

    The fields, in brief (:class:`~tonguevis.sim.settings.RunSettings` says more):

    rest_fit : the placed tongue bent so that every sensor node sits on its rest sensor before the
        simulation (:mod:`tonguevis.sim.rest_fit`: the model's own static response, the anchors held;
        ``metadata["fit"]["rest_fit"]`` gives how far it moved).  Not with ``method="domains"`` yet.

    keep_volume : the volume kept (seed 001 §8): each frame's displacement projected onto the volume-preserving
        shapes of a pressure subspace with the sensor nodes held (:func:`tonguevis.sim.volume.keep_volume`;
        ``metadata["keep_volume"]`` says its key frames and the volume change before and after).  Any method.
        The preview, if any, is shown before the projection.

    rest_interval : the old name of ``rest`` (every front end says ``rest``), kept for one release
        with a DeprecationWarning.

    method : "warped" (modal warping, default), "linear" (modal, no warping) or "domains" (seed 001's
        StVK on quadratic domains, :func:`tonguevis.sim.domains_run.simulate_domains`); ``warping=False``
        alone means "linear".

    sensor_stiffness : how hard the sensor nodes are pulled onto the sensors,
        in units of the tongue's own stiffness at the sensor nodes (a
        dimensionless multiple, the same on any mesh); None holds them exactly
        (hard Lagrange multipliers, the paper's setting); "default" (default):
        :data:`DEFAULT_SENSOR_STIFFNESS`.
    backend : "warp" runs the frame loop as a warp-lang kernel
        (:mod:`newmark_kernel`), "numpy" the reference (same result to rounding).
    rest : a :class:`RestChoice`, a (start_s, end_s) the user gave,
        or None to choose one (detected, else the stillest window); the choice
        is in ``motion.metadata["rest"]``.

    Sensor dropouts are bridged when short and released/re-engaged smoothly
    when long (:mod:`tonguevis.sim.dropouts`).  Frames whose Newton solve
    ran away keep the previous shape (``metadata["recovered_frames"]``);
    frames no tongue could produce (volume change over 25 %, a node moving 10x
    the furthest sensor) are flagged, and a run with more than 5 % of them is
    refused with SimulationError.  ``metadata["plausibility"]`` holds the
    far-field amplification (largest surface node displacement over the largest sensor
    displacement), volume change and sensor misfit.

    palate : None, a :class:`~tonguevis.palate.PalateSurface` or a palate file
        (``tonguevis palate``), in the recording's frame: the tongue surface is
        kept below it (:mod:`tonguevis.sim.contact`), and ``motion.penetration``
        and ``motion.contact_area`` report, per frame, the deepest node inside
        it and the area in contact; sensors above it win and are listed in
        ``metadata["contact"]["conflicts"]``.

    sensor_patches : radius (m) of the sensor patches (:mod:`tonguevis.sim.patches`: the tongue's own
        local deformation under each sensor, closing the gap between every measured sensor and
        the surface after the dynamics); "default" (default): :data:`~tonguevis.sim.patches.PATCH_RADIUS`
        (3 mm on the model, fading out by 5 mm); None: the modes alone (the sensors then
        sit up to a few mm off the surface on real recordings).

    frame : "speaker" (default): the model placed in the speaker by the inverse of the rest
        alignment (:mod:`tonguevis.sim.placement`), so the motion, its figures, the palate and
        every view are in the speaker's head-corrected frame and millimetres; "model": the
        paper's way, the speaker scaled and turned onto the generic tongue (figures in the
        model's millimetres).  The two are the same motion seen through the alignment (lengths
        differ by its scale) when ``tongue_size`` is None; ``metadata["frame"]`` and
        ``metadata["fit"]`` say which and how well.
    tongue_size : in the speaker frame, None: the size the rest alignment implies (1/s: the
        model-frame motion exactly, in the speaker's units; 4.4-6.6 times the generic volume on the
        Opti-Speech speaker, whose coils sit further apart than the paper's rule, which is said);
        a number: the speaker's tongue as that multiple of the model's (1: the generic adult tongue),
        the rest sensors fitted onto its upper surface (:func:`tonguevis.sim.placement.surface_fit`);
        "adult" (default): the alignment's size when it is an adult tongue's, else 1.

    preview : called once, from the simulating thread, with the :class:`Motion` of the first
        ``preview_seconds`` s (a little more: whole segments) as soon as they are final, before
        the rest is simulated (``metadata["preview"]``: frames shown and of how many); its frames
        equal the whole motion's.  Only on the compiled backend without a palate (the frame loop
        and the figures then run side by side, :mod:`tonguevis.sim.pipeline`); else not called.
    """
    from tonguevis._backend import check_backend

    file = recording.metadata.get("file")
    if settings is not None and not isinstance(settings, RunSettings):  # simulate(recording, model, ...)
        settings, model = model if isinstance(model, RunSettings) else None, settings
    if "rest_interval" in overrides:
        import warnings

        warnings.warn("simulate(rest_interval=) is now simulate(rest=)", DeprecationWarning, stacklevel=3)
        given = overrides.pop("rest_interval")
        overrides.setdefault("rest", given)
    try:
        settings = run_settings(settings, **overrides)
    except SimulationError as exc:  # say which recording the bad setting was for
        raise SimulationError(str(exc), file) from None
    check_backend(settings.backend)
    if model is None:
        model = build_model(settings)
    if settings.method == "domains":  # seed 001's StVK on quadratic domains (tonguevis.sim.domains)
        from tonguevis.sim.domains_run import simulate_domains

        if settings.rest_fit:
            raise SimulationError("the domains method cannot fit the rest shape yet: simulate it without "
                                  "rest_fit (--fit-rest), or with method 'warped'", file)
        motion = simulate_domains(recording, settings, model, progress=progress)
        return _kept(motion, settings.backend) if settings.keep_volume else motion
    # Frames the recorder dropped come back as missing samples: every step is 1/rate apart.
    recording = recording.on_uniform_grid()
    placed = placed_at_rest(recording, model, settings, progress)
    if not (settings.closures and settings.palate is not None):
        return _simulate_modal(recording, settings, placed, progress, preview, preview_seconds)
    contact = placed[4]
    try:
        return _simulate_modal(recording, settings, (*placed[:4], dict(contact)), progress, preview, preview_seconds)
    except SimulationError as exc:
        if "plausibly" not in str(exc):
            raise
        # The closures' pulls are phonetic knowledge added to the sensors: where a coarse or odd model cannot
        # take them, the recording is still simulated as the sensors alone drive it, and that is said.
        try:
            motion = _simulate_modal(recording, settings.replace(closures=False), placed, progress, preview,
                                     preview_seconds)
        except SimulationError:
            raise exc from None
    logger.warning("%s: the model ran away pressing the tongue on the palate at the closures; simulated without "
                   "the closures' pulls (as --no-closures): the sensors and the contact alone", file)
    motion.metadata.setdefault("contact", {})["closures_dropped"] = "the model ran away with them"
    return motion


def _simulate_modal(recording, settings, placed, progress, preview, preview_seconds):
    """:func:`simulate`'s modal methods (warped, linear) on resolved ``settings``, the recording on its uniform grid
    and ``placed`` as :func:`placed_at_rest` gave it (model, prep, fit, basis, contact)."""
    from tonguevis.sim.constrained import point_stiffness

    sensor_stiffness, backend, frame = settings.sensor_stiffness_value, settings.backend, settings.frame
    model, prep, fit, basis, contact = placed
    w_full = model.rotation_matrix(basis)
    dofs = (3 * prep.nodes[:, None] + np.arange(3)).ravel()
    s = len(prep.nodes)
    phi_s = basis.phi[dofs].reshape(s, 3, -1)
    w_s = w_full[dofs].reshape(s, 3, -1)
    warping = settings.warping
    newmark = NewmarkSettings(
        dt=1.0 / recording.rate, alpha=model.material.alpha, beta=model.material.beta,
        tolerance=settings.newton_tolerance, warping=warping,
    )
    k_ref = point_stiffness(basis.eigenvalues, phi_s)
    drive = prep.displacement  # what the tongue follows; the sensors are drawn and scored where measured
    # What the projection pulls on: the sensors, then (with a palate) the closures' pulls (forces, not held).
    held_rows, held_drive = (phi_s, w_s), drive
    if contact is not None:
        reach = TOUCH_REACH * (1.0 if frame == "speaker" else fit["scale"])  # the speaker's mm in this frame
        drive, contact["held_to_palate"] = held_to_palate(contact, model.mesh.points[prep.nodes], drive, reach,
                                                          prep.names)
        if settings.closures:
            held_rows, held_drive = _with_closures(recording, prep, model, (basis, w_full), contact, held_rows,
                                                   drive)
    targets, compliance, schedule = drive_schedule(held_drive, recording.rate, basis.eigenvalues, held_rows[0],
                                                   sensor_stiffness, contact=contact,
                                                   pulls=held_drive.shape[1] - drive.shape[1])
    release_freed_memory()  # the preparation's temporaries: 150 MB kept for 30 minutes otherwise
    report(progress, 1, 3, "integrating")
    run = MotionBuilder(settings, model, recording, prep, basis, (phi_s, w_s), (targets, compliance, schedule), k_ref,
                        contact)
    run.fit = fit
    run.drive = drive
    from tonguevis.sim.patches import PATCH_RADIUS, PATCH_REACH

    length = 1.0 / fit["scale"] if frame == "speaker" else 1.0  # the model's millimetres in this frame
    sensor_patches = settings.sensor_patches
    if sensor_patches == "default":
        sensor_patches = PATCH_RADIUS * length
    if sensor_patches is not None:
        run.prepare_patches(sensor_patches, sensor_patches * PATCH_REACH / PATCH_RADIUS)
    if backend == "warp" and contact is None:
        from tonguevis.sim.pipeline import integrate_and_measure

        # The frame loop and the figures side by side; the first stretch offered as a preview once it is final.
        wanted = min(len(targets), max(1, int(round(preview_seconds * recording.rate))))

        def offer(progressive) -> None:
            if preview is not None and not run.previewed and wanted <= progressive.done < len(targets):
                run.previewed = True
                try:
                    shown = run.motion(progressive.result, progressive.figures, progressive.done)
                except SimulationError as exc:  # the whole run will say it; no preview then
                    logger.info("no preview of the first %d frames: %s", progressive.done, exc)
                    return
                preview(shown)

        done = integrate_and_measure(run.model, basis.eigenvalues, phi_s, w_s, targets, newmark, compliance, warping,
                                     progress=_stage(progress, 1, 3, span=2), on_segment=offer,
                                     extend=run.patch_coordinates if run.patches else None)
        result, figures = done.result, done.figures
    else:
        if backend == "warp":
            from tonguevis.sim.newmark_kernel import integrate_compiled

            result = integrate_compiled(basis.eigenvalues, phi_s, w_s, targets, newmark, compliance=compliance,
                                        external=schedule.get("external"), rates=False)  # q̇, q̈ unused: q alone
        else:
            result = integrate(basis.eigenvalues, phi_s, w_s, targets, newmark, compliance=compliance,
                               external=schedule.get("external"), progress=_stage(progress, 1, 3))
        if "pull_targets" in schedule:
            result.q = static_at_closures(result.q, basis.eigenvalues, held_rows[0], targets, schedule)
        if contact is not None:
            base = 0.0 if sensor_stiffness is None else 1.0 / (sensor_stiffness * k_ref)
            cand_dofs = (3 * np.asarray(contact["candidates"])[:, None] + np.arange(3)).ravel()
            result.q, corrected = keep_below_palate(result.q, contact, schedule, basis, phi_s, base,
                                                    run.rotation[cand_dofs, :basis.n_modes] if warping else None)
            schedule["corrected_frames"] = run.schedule["corrected_frames"] = corrected
        if run.patches and contact is not None and run.basis.info.get("hump_m") is not None:
            from tonguevis.sim.patch_contact import humps_under_palate

            result.q = humps_under_palate(run, result.q, contact, schedule)
        elif run.patches:
            result.q = np.hstack([result.q, run.patch_coordinates(result.q, 0, len(result.q))])
        report(progress, 2, 3, "reconstructing the mesh")
        # Chunk by chunk: the full-mesh displacement of every frame is never held at once.
        figures = frame_figures(run.model, result.q, warping, backend, None if contact is None else
                                contact_probe(contact, schedule, run.model), progress=_stage(progress, 2, 3))
    motion = run.motion(result, figures, len(targets))
    if settings.keep_volume:
        motion = _kept(motion, backend)
    release_freed_memory()
    report(progress, 3, 3, "done")
    return motion


def _with_closures(recording, prep, model, modes, contact, rows, drive):
    """((rows of Φ, rows of W), drive (F, S + V, 3)): the sensors' ``rows`` (Φ_s, W_s) and, after them, the
    closures' pulls, ``modes`` the (basis, full W)
    (:func:`tonguevis.sim.closures.closure_contacts`, :func:`drive_schedule`'s ``pulls``);
    ``contact["sensor_nodes"]`` and ``contact["closures"]`` say them.  As given when the recording shows no
    closure."""
    from tonguevis.sim.closures import closure_contacts

    closures = closure_contacts(recording, prep, model, contact)
    if closures is None:
        return rows, drive
    (basis, w_full), (phi_s, w_s) = modes, rows
    dofs = (3 * closures.nodes[:, None] + np.arange(3)).ravel()
    v = len(closures.nodes)
    phi_v = basis.phi[dofs].reshape(v, 3, -1)
    w_v = w_full[dofs].reshape(v, 3, -1)
    contact["sensor_nodes"] = np.concatenate([np.asarray(prep.nodes), closures.nodes])
    contact["closures"] = closures.info
    return ((np.concatenate([phi_s, phi_v]), np.concatenate([w_s, w_v])),
            np.concatenate([drive, closures.displacement], axis=1))


def static_at_closures(q: np.ndarray, eigenvalues: np.ndarray, rows: np.ndarray, targets: np.ndarray,
                       schedule: dict) -> np.ndarray:
    """(F, m) the dynamic shapes ``q`` with, where a closure's pull acts, the static shape that holds the
    sensors at their targets and the pulled nodes where the projection put them, blended in by the pull's
    engagement (its weight: 0 to 1 over the ramp into a closure, 1 through it, back to 0 after).

    A force on free nodes lags in the dynamics (a few frames of closure went by before the tip rose onto the
    palate on the real /ta/); at a closure the tongue is pressed and nearly still (the maximum constriction is
    a speed minimum), where the static shape is the dynamic one's limit.  rows : (S + V, 3, m) the sensors' and
    the pulls' rows; targets : (F, S, 3) the sensors'."""
    from tonguevis.sim.constrained import compliant_shapes

    weight = schedule["pull_weight"].max(axis=1)
    frames = np.flatnonzero(weight > 0)
    if len(frames) == 0:
        return q
    both = np.concatenate([targets[frames], schedule["pull_targets"][frames]], axis=1)
    acting = np.all(np.isfinite(both), axis=2)
    static = compliant_shapes(eigenvalues, rows, both, np.where(acting, 0.0, np.inf))
    out = np.array(q, copy=True)
    w = weight[frames, None]
    out[frames] = (1.0 - w) * q[frames] + w * static
    return out


def placed_at_rest(recording: Recording, model: TongueModel, settings: RunSettings, progress=None):
    """(model placed in the settings' frame, prepared targets, fit, modal basis, contact context or None) of a
    recording on the uniform grid.

    With a palate and no rest given, the rest candidates are tried in order (the rest every front end finds,
    then the next stillest windows: :func:`tonguevis.preprocess.rest.rest_candidates`) until one whose tongue
    the palate does not cut through (:class:`~tonguevis.sim.palate_placement.PalateCutsTheRest`: the tongue
    pressed up into the vault there); the rest taken says why in its reason.  None left, or a rest given
    that the palate cuts: SimulationError naming the file, the stillest candidates and ``--rest``."""
    from tonguevis.preprocess.rest import HOW_TO_GIVE_REST, RestChoice, rest_candidates, say_stillest
    from tonguevis.preprocess.targets import driving_sensors
    from tonguevis.sim.palate_placement import PalateCutsTheRest
    from tonguevis.sim.placement import targets_in_frame

    palate = settings.palate
    rests = [settings.rest]
    if palate is not None and settings.rest is None:
        rests = rest_candidates(recording, driving_sensors(recording, model)) or [None]
    cut = []
    for k, rest in enumerate(rests):
        placed, prep, fit = targets_in_frame(recording, model, settings.frame, settings.landmarks, rest,
                                             settings.smooth_window, tongue_size=settings.tongue_size,
                                             rest_fit=settings.rest_fit)
        if k == 0:  # the modes once (a placed model's are the source's, moved; a fitted one solves its own)
            report(progress, 0, 3, "modal basis")
        basis = placed.basis(settings.modes, progress=_stage(progress, 0, 3))
        if palate is None:
            return placed, prep, fit, basis, None
        try:
            contact = contact_context(palate, prep, placed, basis, recording)
        except PalateCutsTheRest as exc:
            cut.append((prep.rest, exc))
            continue
        contact["backend"] = settings.backend  # its clearances and solves: compiled, or the NumPy reference
        if not cut and settings.rest is None and prep.rest.how == "stillest window":
            say_stillest(recording, prep.rest)  # as choose_rest_interval says it without a palate
        if cut:
            why = (f"the palate cuts through the tongue at the stiller rest{'s' if len(cut) > 1 else ''} "
                   + ", ".join(f"{r.interval[0]:.2f}-{r.interval[1]:.2f} s" for r, _ in cut)
                   + " (the tongue pressed up into the vault)")
            prep.rest = RestChoice(prep.rest.interval, prep.rest.how, why)
            logger.warning("%s: rest %.2f-%.2f s: %s", recording.metadata.get("file", "the recording"),
                           *prep.rest.interval, why)
        return placed, prep, fit, basis, contact
    tried = ", ".join(f"{r.interval[0]:.2f}-{r.interval[1]:.2f} s" for r, _ in cut)
    first = str(cut[0][1]).split(": ", 1)[-1] if cut else ""
    raise SimulationError(
        (f"{first}; " if settings.rest is not None else
         f"the palate cuts through the tongue at every still stretch tried ({tried}); ")
        + "is it this speaker's palate, from this session?  If it is, "
        + HOW_TO_GIVE_REST.replace("give one", "give a rest where the tongue is down, not pressed into the vault,"),
        recording.metadata.get("file"))


def _kept(motion: Motion, backend: str) -> Motion:
    """``motion`` with the volume kept (:func:`tonguevis.sim.volume.keep_volume`), said once in the log."""
    from tonguevis.sim.volume import keep_volume

    kept = keep_volume(motion, backend=backend)
    info = kept.metadata["keep_volume"]
    logger.info("volume kept: largest change %.3f %% -> %.4f %% (pressure subspace of %d shapes)",
                100 * info["volume_change_max_before"], 100 * info["volume_change_max_after"],
                info["subspace_size"])
    return kept




def _stage(progress: ProgressCallback | None, stage: int, stages: int, span: int = 1) -> ProgressCallback | None:
    """Map a sub-task's progress onto ``span`` of ``stages`` equal parts, from part ``stage`` on."""
    if progress is None:
        return None

    def sub(done: int, total: int, message: str = "") -> None:
        frac = done / total if total else 1.0
        progress(int(1000 * (stage + span * frac)), 1000 * stages, message)

    return sub
