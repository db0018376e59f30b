"""From a recording to a :class:`Motion`: preprocess, align, integrate, reconstruct."""

from __future__ import annotations


import numpy as np

from tonguevis._memory import release_freed_memory
from tonguevis._progress import ProgressCallback, report
from tonguevis.io.recording import Recording
from tonguevis.preprocess.rest import RestChoice
from tonguevis.preprocess.targets import TONGUE_SENSORS, PreparedTargets, prepare_targets  # noqa: F401 (re-exported)
from tonguevis.sim.model import TongueModel
from tonguevis.sim.motion import Motion
from tonguevis.errors import SimulationError
from tonguevis.sim.constrained import RUNAWAY_ROTATION
from tonguevis.sim.figures import frame_figures
from tonguevis.sim.newmark import NewmarkSettings, integrate
from tonguevis.sim.plausibility import ABSURD_AMPLIFICATION, ABSURD_VOLUME, plausibility_from_largest, raise_spread
from tonguevis.sim.rest_fit import rest_fitted_model_of

from tonguevis._logging import logger, verbose

VOLUME_WARNING = 0.05  # relative volume change past which the motion is flagged as implausible
ABSURD_SHARE = 0.05  # a run with more absurd frames than this is refused rather than returned
RECOVERED_SHARE = 0.10  # ... or with more recovered frames than this: it is no longer the model's motion
#: Default sensor spring, in units of the tongue's own point stiffness at the sensors
#: (see :func:`tonguevis.sim.constrained.point_stiffness`); None holds the sensors exactly (the paper).
DEFAULT_SENSOR_STIFFNESS = 20.0


@verbose
def simulate(
    recording: Recording,
    model: TongueModel | None = None,
    modes: int = 100,
    warping: bool = True,
    landmarks: str = "speaker",
    rest: RestChoice | tuple[float, float] | None = None,
    smooth_window: int | None = None,
    tolerance: float = 1e-8,
    sensor_stiffness: float | None | str = "default",
    backend: str = "warp",
    palate=None,
    progress: ProgressCallback | None = None,
    preview=None,
    preview_seconds: float = 20.0,
    sensor_patches: float | None | str = None,
    frame: str = "speaker",
    tongue_size: float | str | None = None,
    method: str | None = None,
    rest_interval: RestChoice | tuple[float, float] | None = None,
    keep_volume: bool = False,
    rest_fit: bool = False,
) -> Motion:
    """Drive ``model`` (default: our shipped tongue) with ``recording``.

    rest_fit : the placed tongue bent so that every sensor node sits on its rest sensor before the
        simulation (:mod:`tonguevis.sim.rest_fit`: the model's own static response, the anchors held;
        ``metadata["fit"]["rest_fit"]`` gives how far it moved).  Not with ``method="domains"`` yet.

    keep_volume : the volume kept (seed 001 §8): each frame's displacement projected onto the volume-preserving
        shapes of a pressure subspace with the sensor nodes held (:func:`tonguevis.sim.volume.keep_volume`;
        ``metadata["keep_volume"]`` says its key frames and the volume change before and after).  Any method.
        The preview, if any, is shown before the projection.

    rest_interval : the old name of ``rest`` (every front end says ``rest``), kept for one release
        with a DeprecationWarning.

    method : "warped" (modal warping), "linear" (modal, no warping) or "domains" (seed 001's
        StVK on quadratic domains, :func:`tonguevis.sim.domains.simulate_domains`); None
        (default): ``warping`` decides between the first two.

    sensor_stiffness : how hard the sensor nodes are pulled onto the sensors,
        in units of the tongue's own stiffness at the sensor nodes (a
        dimensionless multiple, the same on any mesh); None holds them exactly
        (hard Lagrange multipliers, the paper's setting); "default":
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
        the surface after the dynamics); "default": :data:`~tonguevis.sim.patches.PATCH_RADIUS`
        (3 mm on the model, fading out by 5 mm); None (default): the modes alone (the sensors then
        sit up to a few mm off the surface on real recordings).

    frame : "speaker" (default): the model placed in the speaker by the inverse of the rest
        alignment (:mod:`tonguevis.sim.placement`), so the motion, its figures, the palate and
        every view are in the speaker's head-corrected frame and millimetres; "model": the
        paper's way, the speaker scaled and turned onto the generic tongue (figures in the
        model's millimetres).  The two are the same motion seen through the alignment (lengths
        differ by its scale) when ``tongue_size`` is None; ``metadata["frame"]`` and
        ``metadata["fit"]`` say which and how well.
    tongue_size : in the speaker frame, None (default): the size the rest alignment implies (1/s: the
        model-frame motion exactly, in the speaker's units; 4.4-6.6 times the generic volume on the
        Opti-Speech speaker, whose coils sit further apart than the paper's rule, which is said);
        a number: the speaker's tongue as that multiple of the model's (1: the generic adult tongue),
        the rest sensors fitted onto its upper surface (:func:`tonguevis.sim.placement.surface_fit`);
        "adult" (the front ends' default): the alignment's size when it is an adult tongue's, else 1.

    preview : called once, from the simulating thread, with the :class:`Motion` of the first
        ``preview_seconds`` s (a little more: whole segments) as soon as they are final, before
        the rest is simulated (``metadata["preview"]``: frames shown and of how many); its frames
        equal the whole motion's.  Only on the compiled backend without a palate (the frame loop
        and the figures then run side by side, :mod:`tonguevis.sim.pipeline`); else not called.
    """
    from tonguevis._backend import check_backend
    from tonguevis.sim.constrained import point_stiffness

    from tonguevis.sensor_stiffness import sensor_stiffness_value

    check_backend(backend)
    if rest_interval is not None:
        import warnings

        warnings.warn("simulate(rest_interval=) is now simulate(rest=)", DeprecationWarning, stacklevel=3)
        rest = rest if rest is not None else rest_interval
    warping = method_warping(method, warping, recording.metadata.get("file"))
    if method == "domains":  # seed 001's StVK on quadratic domains (tonguevis.sim.domains)
        from tonguevis.sim.domains import simulate_domains

        if rest_fit:
            raise SimulationError("the domains method cannot fit the rest shape yet: simulate it without "
                                  "rest_fit (--fit-rest), or with method 'warped'", recording.metadata.get("file"))
        motion = simulate_domains(recording, model, landmarks, rest, smooth_window,
                                  sensor_stiffness=sensor_stiffness, backend=backend, palate=palate,
                                  progress=progress, frame=frame, tongue_size=tongue_size)
        return _kept(motion, backend) if keep_volume else motion
    sensor_stiffness = sensor_stiffness_value(sensor_stiffness, recording.metadata.get("file"))  # the CLI's words too
    if sensor_stiffness == "default":
        sensor_stiffness = DEFAULT_SENSOR_STIFFNESS
    if sensor_stiffness is not None and not (np.isfinite(sensor_stiffness) and sensor_stiffness > 0):
        raise SimulationError(f"sensor stiffness must be a positive number or None (hard), got {sensor_stiffness!r}",
                              recording.metadata.get("file"))
    model = model or TongueModel.default()
    # Frames the recorder dropped come back as missing samples: every step is 1/rate apart.
    recording = recording.on_uniform_grid()
    from tonguevis.sim.placement import targets_in_frame

    model, prep, fit = targets_in_frame(recording, model, frame, landmarks, rest, smooth_window,
                                        tongue_size=tongue_size, rest_fit=rest_fit)
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
    contact = None
    if palate is not None:
        contact = _contact_context(palate, prep, model, basis, recording)
        contact["backend"] = backend  # its clearances and solves: compiled, or the NumPy reference
    drive = prep.displacement  # what the tongue follows; the sensors are drawn and scored where measured
    if contact is not None:
        reach = TOUCH_REACH * (1.0 if frame == "speaker" else fit["scale"])  # the speaker's mm in this frame
        drive, contact["held_to_palate"] = held_to_palate(contact, model.mesh.points[prep.nodes], drive, reach,
                                                          prep.names)
    targets, compliance, schedule = drive_schedule(drive, recording.rate, basis.eigenvalues, phi_s,
                                                   sensor_stiffness, contact=contact)
    release_freed_memory()  # the preparation's temporaries: 150 MB kept for 30 minutes otherwise
    report(progress, 1, 3, "integrating")
    run = _Run(model, recording, prep, basis, phi_s, w_s, targets, compliance, schedule, warping, backend, modes,
               landmarks, sensor_stiffness, k_ref, contact)
    run.fit = fit
    run.drive = drive
    from tonguevis.sim.patches import PATCH_RADIUS, PATCH_REACH

    length = 1.0 / fit["scale"] if frame == "speaker" else 1.0  # the model's millimetres in this frame
    if sensor_patches == "default":
        sensor_patches = PATCH_RADIUS * length
    if sensor_patches is not None:
        if not (np.isfinite(sensor_patches) and sensor_patches > 0):
            raise SimulationError(f"the sensor patches' radius must be a positive number of metres or None, got "
                                  f"{sensor_patches!r}", recording.metadata.get("file"))
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

        done = integrate_and_measure(run.model, basis.eigenvalues, phi_s, w_s, targets, settings, compliance, warping,
                                     progress=_stage(progress, 1, 3, span=2), on_segment=offer,
                                     extend=run.patch_coordinates if run.patches else None)
        result, figures = done.result, done.figures
    else:
        if backend == "warp":
            from tonguevis.sim.newmark_kernel import integrate_compiled

            result = integrate_compiled(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance,
                                        external=schedule.get("external"), rates=False)  # q̇, q̈ unused: q alone
        else:
            result = integrate(basis.eigenvalues, phi_s, w_s, targets, settings, compliance=compliance,
                               external=schedule.get("external"), progress=_stage(progress, 1, 3))
        if contact is not None:
            base = 0.0 if sensor_stiffness is None else 1.0 / (sensor_stiffness * k_ref)
            result.q, corrected = _keep_below_palate(result.q, contact, schedule, basis, phi_s, base)
            schedule["corrected_frames"] = corrected
        if run.patches:
            result.q = np.hstack([result.q, run.patch_coordinates(result.q, 0, len(result.q))])
        report(progress, 2, 3, "reconstructing the mesh")
        # Chunk by chunk: the full-mesh displacement of every frame is never held at once.
        figures = frame_figures(run.model, result.q, warping, backend, None if contact is None else
                                _contact_probe(contact, schedule, run.model), progress=_stage(progress, 2, 3))
    motion = run.motion(result, figures, len(targets))
    if keep_volume:
        motion = _kept(motion, backend)
    release_freed_memory()
    report(progress, 3, 3, "done")
    return motion


def _kept(motion: Motion, backend: str) -> Motion:
    """``motion`` with the volume kept (:func:`tonguevis.sim.volume.keep_volume`), said once in the log."""
    from tonguevis.sim.volume import keep_volume

    kept = keep_volume(motion, backend=backend)
    info = kept.metadata["keep_volume"]
    logger.info("volume kept: largest change %.3f %% -> %.4f %% (pressure subspace of %d shapes)",
                100 * info["volume_change_max_before"], 100 * info["volume_change_max_after"],
                info["subspace_size"])
    return kept


#: simulate(method=...): "warped" (modal warping), "linear" (modal, no warping), "domains"
#: (seed 001's StVK on quadratic domains, tonguevis.sim.domains).
METHODS = ("warped", "linear", "domains")


def method_warping(method: str | None, warping: bool, file=None) -> bool:
    """The ``warping`` a modal ``method`` means (None: ``warping`` as given); SimulationError for an unknown one."""
    if method is None:
        return warping
    if method not in METHODS:
        raise SimulationError(f"unknown simulation method {method!r}; choose one of {', '.join(METHODS)}", file)
    return method == "warped"


class _Run:
    """One simulation's inputs, to make its :class:`Motion` from the integration and the figures, for every
    frame or (a preview) for the first ones only, the same way."""

    def __init__(self, model, recording, prep, basis, phi_s, w_s, targets, compliance, schedule, warping, backend,
                 modes, landmarks, sensor_stiffness, k_ref, contact):
        self.model, self.recording, self.prep, self.basis = model, recording, prep, basis
        self.phi_s, self.w_s, self.targets, self.compliance, self.schedule = phi_s, w_s, targets, compliance, schedule
        self.warping, self.backend, self.modes, self.landmarks = warping, backend, modes, landmarks
        self.sensor_stiffness, self.k_ref, self.contact = sensor_stiffness, k_ref, contact
        self.previewed = False
        self.patches: dict | None = None
        self.drive = prep.displacement  # (F, S, 3) m: what the sensor nodes follow (held_to_palate)

    def prepare_patches(self, radius: float, reach: float) -> None:
        """Use the sensor patches (:mod:`tonguevis.sim.patches`) of ``radius`` fading out by ``reach`` (m): the
        run's model, basis and sensor rows become the augmented ones (the frame loop keeps the modes alone)."""
        from tonguevis.sim.patches import augmented_basis, augmented_model

        self.global_rows = (self.basis, self.phi_s)  # what the frame loop (and a recovery) solves with
        basis = augmented_basis(self.model, self.basis, self.prep.nodes, radius, reach)
        self.model = augmented_model(self.model, basis)
        self.rotation = self.model.rotation_matrix(basis)
        dofs = (3 * np.asarray(self.prep.nodes)[:, None] + np.arange(3)).ravel()
        s = len(self.prep.nodes)
        self.basis, self.phi_s, self.w_s = basis, basis.phi[dofs].reshape(s, 3, -1), self.rotation[dofs].reshape(s, 3, -1)
        self.patches = {"radius_mm": 1e3 * radius, "reach_mm": 1e3 * basis.info["patch_reach_m"],
                        "shapes": int(basis.n_modes - basis.info["global_modes"]),
                        "nodes": basis.info["patch_nodes"], "global_modes": int(basis.info["global_modes"])}

    def patch_coordinates(self, q: np.ndarray, start: int, end: int) -> np.ndarray:
        """(end - start, p) patch coordinates closing the sensors' gaps in frames start..end-1 whose
        modal coordinates (from the frame loop) are ``q`` (end - start, m)."""
        from tonguevis.sim.patches import close_sensor_gaps

        frames = slice(start, end)
        return close_sensor_gaps(self.basis, self.rotation, self.prep.nodes, q, self._patch_targets(frames),
                                 self.warping, weight=self.schedule["weight"][frames])

    def _patch_targets(self, frames) -> np.ndarray:
        """(F, S, 3) m for ``frames`` (a slice or indices): where the patches put the sensor nodes: the sensors
        followed (``drive``), a sensor lost for good held at its last measurement while its spring lets go
        (the springs' anchors)."""
        drive = self.drive[frames]
        anchored = self.schedule.get("anchored")
        if anchored is None:
            return drive
        return np.where(np.isnan(drive), anchored[frames], drive)

    def motion(self, result, figures, n: int) -> Motion:
        """The :class:`Motion` of frames 0..n-1 (``n`` = all: the simulation's result, made from ``result``
        and ``figures`` in place; fewer: a preview on copies, ``metadata["preview"]`` saying how many frames
        of how many, nothing logged).  Frames no tongue could produce are recovered; too many of them
        (or a non-finite q) raise SimulationError naming the file."""
        model, prep, basis, warping, backend = self.model, self.prep, self.basis, self.warping, self.backend
        phi_s, w_s, schedule, contact = self.phi_s, self.w_s, self.schedule, self.contact
        total = len(self.targets)
        whole = n == total
        cut = slice(0, n)
        q = result.q if whole else result.q[cut].copy()
        converged, recovered = result.converged[cut], result.recovered[cut].copy()
        iterations = result.iterations[cut]
        volume_change = figures.volume_change if whole else figures.volume_change[cut].copy()
        largest = figures.largest_displacement if whole else figures.largest_displacement[cut].copy()
        measured = prep.displacement[cut]
        energy = model.energy(q)
        misfit = _sensor_misfit(q, phi_s, w_s, measured, warping)
        plausibility, absurd = plausibility_from_largest(largest, measured, volume_change, misfit)
        if len(absurd):
            # Frames no tongue could produce (volume, or a node far beyond every sensor): the static shape for
            # the same targets instead, when that one is sane; flagged as recovered either way.
            from tonguevis.sim.constrained import compliant_shapes
            from tonguevis.sim.patches import close_sensor_gaps

            if self.patches:  # the modes' static shape, then the patches on it
                modes, rows = self.global_rows
                fixed = compliant_shapes(modes.eigenvalues, rows, self.targets[absurd], self.compliance[absurd])
                fixed = np.hstack([fixed, close_sensor_gaps(basis, self.rotation, prep.nodes, fixed,
                                                            self._patch_targets(absurd), warping,
                                                            weight=self.schedule["weight"][absurd])])
            else:
                fixed = compliant_shapes(basis.eigenvalues, phi_s, self.targets[absurd], self.compliance[absurd])
            sub = frame_figures(model, fixed, warping, backend)
            sane = np.isfinite(sub.volume_change) & (np.abs(sub.volume_change) <= ABSURD_VOLUME)
            frames = absurd[sane]
            q[frames] = fixed[sane]
            recovered[frames] = True
            volume_change[frames] = sub.volume_change[sane]
            largest[frames] = sub.largest_displacement[sane]
            misfit = _sensor_misfit(q, phi_s, w_s, measured, warping)
            plausibility, absurd = plausibility_from_largest(largest, measured, volume_change, misfit)
            energy = model.energy(q)
        times = self.recording.times[cut]
        file = self.recording.metadata.get("file")
        n_recovered = int(recovered.sum())
        if (not np.all(np.isfinite(q)) or len(absurd) > ABSURD_SHARE * len(times)
                or n_recovered > RECOVERED_SHARE * len(times)):
            bad_frames = np.union1d(absurd, np.flatnonzero(recovered | ~np.all(np.isfinite(q), axis=1)))
            raise SimulationError(
                f"the model could not follow this recording plausibly: {len(absurd)} of {len(times)} frames change "
                f"the volume by over {100 * ABSURD_VOLUME:.0f} % or move a node over {ABSURD_AMPLIFICATION:g}x as far "
                f"as any sensor, {n_recovered} had to be recovered (first at t = {times[bad_frames[0]]:.2f} s); try "
                f"more modes (--modes, now {self.modes}) or the speaker's sensor layout (--landmarks speaker)"
                + (", or without the rest shape fitted (no --fit-rest): its new modes may be the ones that ran away"
                   if rest_fitted_model_of(model) is not None else ""), file)
        bad = np.flatnonzero(~converged)
        recovered_frames = np.flatnonzero(recovered)
        if whole:
            _log_doubts(recovered_frames, absurd, volume_change, times, self.modes)
        released = schedule["released"][cut]
        contact_figures, penetration, contact_area = {}, None, None
        if contact is not None:
            penetration, contact_area = figures.penetration, figures.contact_area
            sensors = model.mesh.points[prep.nodes][None] + measured  # as drawn: each on its node's rest
            contact_figures = _contact_report(penetration, contact_area, contact, schedule, times,
                                              _sensor_depth(contact, sensors, cut), prep.names)
        stiffness = self.sensor_stiffness
        metadata = {
            "recording": dict(self.recording.metadata),
            "landmarks": self.landmarks,
            "modes": self.modes,
            "ignored_sensors": prep.ignored,
            "rest": prep.rest.as_dict(),
            "midsagittal_alignment": prep.midsagittal,
            "frame": self.fit["frame"],
            "fit": self.fit,
            "alignment_scale": self.fit["rule_node_scale"],  # the rest sensors onto the rule nodes, either frame
            "alignment_matrix": self.fit["matrix"],
            "alignment_rms_m": prep.alignment_rms,  # in the frame's metres
            "sensor_stiffness": stiffness,
            "sensor_stiffness_n_per_m": None if stiffness is None else float(stiffness * self.k_ref),
            "point_stiffness_n_per_m": self.k_ref,
            "dropouts": {"bridged_gaps": int(schedule["bridged"]), "released_frames": int(released.sum()),
                         "released_by_sensor": {n: int(released[:, k].sum()) for k, n in enumerate(prep.names)}},
            "unconverged_frames": bad.tolist(),
            "recovered_frames": recovered_frames.tolist(),
            "implausible_frames": absurd.tolist(),
            "plausibility": plausibility,
            **({"contact": contact_figures} if contact is not None else {}),
            "newton_iterations_mean": float(iterations.mean()) if len(iterations) else 0.0,
            **({"sensor_patches": self.patches} if self.patches else {}),
            **({} if whole else {"preview": {"frames": int(n), "of": int(total)}}),
        }
        rest_nodes = model.mesh.points[prep.nodes]
        return Motion(
            times=np.asarray(times, dtype=np.float64),
            q=q,
            model=model,
            warping=warping,
            sensor_names=prep.names,
            sensor_nodes=prep.nodes,
            targets=rest_nodes[None] + measured,
            sensor_residual=misfit,
            energy=energy,
            volume_change=volume_change,
            converged=converged & ~recovered,
            penetration=penetration,
            contact_area=contact_area,
            jaw_offset=None if prep.jaw_offset is None else prep.jaw_offset[cut],
            metadata=metadata,
            palate=None if contact is None else contact["palate"],
        )


def _log_doubts(recovered: np.ndarray, absurd: np.ndarray, volume_change: np.ndarray, times: np.ndarray,
                modes: int) -> None:
    """Warn about recovered and implausible frames and a large volume change (once, for the whole run)."""
    if len(recovered):
        logger.warning("%d of %d frames ran away (non-finite, a sensor node turned past %.1f rad, or a shape no "
                       "tongue makes) and were recovered (first at t = %.2f s)",
                       len(recovered), len(times), RUNAWAY_ROTATION, times[recovered[0]])
    if len(absurd):
        logger.warning("%d frames are implausible (first at t = %.2f s)", len(absurd), times[absurd[0]])
    worst_volume = float(np.abs(volume_change).max()) if len(volume_change) else 0.0
    if worst_volume > VOLUME_WARNING:
        logger.warning(
            "the tongue changes volume by up to %.1f %% to follow the sensors: too few modes (%d) or sensor "
            "nodes far from the speaker's layout make it bend unnaturally", 100 * worst_volume, modes)

def drive_schedule(displacement: np.ndarray, rate: float, eigenvalues: np.ndarray, phi_s: np.ndarray,
                   sensor_stiffness: float | None, contact: dict | None = None):
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
    frames a sensor was missing after bridging}.  With ``contact`` (from
    :func:`_contact_context`) the projection keeps the tongue below the palate
    (:func:`tonguevis.sim.contact.solve_contact`) and info adds the contact
    forces ("external", (F, m) modal) for the dynamic solve, "active" and "conflicts".
    """
    from tonguevis.sim.constrained import compliant_targets, point_stiffness
    from tonguevis.sim.dropouts import RAMP_STIFFNESS, bridge_short_gaps, engagement, spring_compliance

    filled, bridged = bridge_short_gaps(displacement, rate)
    present = np.all(np.isfinite(filled), axis=2)
    k_ref = point_stiffness(eigenvalues, phi_s)
    base = 0.0 if sensor_stiffness is None else 1.0 / (sensor_stiffness * k_ref)
    weight, source = engagement(present, rate)
    anchored = filled[source, np.arange(filled.shape[1])[None, :]]  # a released sensor: its last measurement
    springs = spring_compliance(weight, base, RAMP_STIFFNESS * k_ref)
    info = {"bridged": bridged, "released": ~present, "weight": weight, "anchored": anchored}
    if contact is None:
        projected = compliant_targets(eigenvalues, phi_s, anchored, springs)
    else:
        from tonguevis.sim.contact import solve_contact

        solved = solve_contact(eigenvalues, contact["phi_nodes"], phi_s, anchored, springs, contact["points"],
                               contact["sensor_nodes"], contact["candidates"], contact["palate"],
                               contact["jaw_offset"], backend=contact.get("backend", "warp"))
        projected = solved.pop("targets")
        info.update(solved)
    acting = weight > 0
    targets = np.where(acting[:, :, None], projected, np.nan)
    compliance = np.where(acting, 0.0, np.inf)
    return targets, compliance, info


def place_palate(palate, prep: PreparedTargets, quiet: bool = False, model: TongueModel | None = None,
                 speech_references: dict | None = None):
    """The palate in the model frame, where the contact solve and the app's views use it: (surface, raised by m).

    palate : a :class:`~tonguevis.palate.PalateSurface`, a palate file or "generic"
    (:func:`tonguevis.palate.load_palate`).  A speaker's palate (the recording's frame,
    from ``tonguevis palate``) is carried onto the model by the recording's alignment
    ``prep.transform``, then raised where the tongue sensors went above it
    (:func:`_register_palate`) and, on the shipped tongue (``model`` None or it), joined to the
    generic palate behind and beside it (:func:`tonguevis.palate.joined_palate`); one whose
    metadata say ``frame == "model"`` (the generic one) is used as is.

    speech_references : the speech's head references where its head correction holds them
    (:func:`tonguevis.preprocess.correction.reference_pose`); a palate fitted from traces with the
    same references (``metadata["head_references"]``) is first carried into the speech's head
    frame by them (:func:`_by_head_references`), so only what they cannot tell is left to the raise.
    """
    from tonguevis.palate import load_palate

    from tonguevis.sim.placement import in_model_frame

    palate = load_palate(palate)
    if palate.metadata.get("frame") == "model":  # the generic palate: placed with the model
        return palate if model is None else in_model_frame(palate, model), 0.0
    from tonguevis.palate import generic_palate, joined_palate

    palate = _by_head_references(palate, speech_references, quiet)
    t = prep.transform
    placed, shift = _register_palate(palate.transformed(t.rotation, t.scale, t.translation), prep, quiet=quiet)
    if model is not None and not shipped_tongue(model):  # the generic palate is our tongue's roof, not this mesh's
        return placed, shift
    # A traced palate covers the front of the roof: the generic one, moved to meet it, completes it.
    generic = generic_palate() if model is None else in_model_frame(generic_palate(), model)
    return joined_palate(placed, generic), shift


def _by_head_references(palate, speech_references: dict | None, quiet: bool = False):
    """``palate`` carried from its traces' head frame into the speech's by the head references both
    recorded (a rigid fit; said once with the references and the residual); as it is otherwise."""
    from tonguevis.preprocess.correction import register_references

    traced = palate.metadata.get("head_references")
    if not traced or not speech_references:
        return palate
    fit = register_references({n: np.asarray(v, dtype=float) for n, v in traced.items()}, speech_references)
    if fit is None:
        if not quiet:
            logger.warning("the palate's head references (%s) and the speech's (%s) share fewer than 3: not "
                           "registered by them", ", ".join(traced), ", ".join(speech_references))
        return palate
    rotation, translation, residual, names = fit
    moved = palate.transformed(rotation, 1.0, translation)
    moved.metadata["head_registration"] = {"references": names, "residual_mm": 1e3 * residual,
                                          "moved_mm": 1e3 * float(np.linalg.norm(translation))}
    if not quiet:
        logger.info("palate registered into the speech's head frame by the head references %s (moved %.1f mm, "
                    "residual %.2f mm)", ", ".join(names), 1e3 * float(np.linalg.norm(translation)), 1e3 * residual)
    return moved


def _speech_references(recording: Recording, prep: PreparedTargets, palate) -> dict:
    """The speech's head references in its head-corrected frame, when the palate has references to meet."""
    from tonguevis.palate import load_palate
    from tonguevis.preprocess.correction import head_corrected, reference_pose

    if not load_palate(palate).metadata.get("head_references"):
        return {}
    return reference_pose(head_corrected(recording, rest_interval=prep.rest_interval))


def shipped_tongue(model: TongueModel) -> bool:
    """Whether ``model`` is on the shipped tongue mesh (the one the generic palate belongs to), also
    placed in a speaker (:mod:`tonguevis.sim.placement`)."""
    from pathlib import Path

    from tonguevis.mesh.default import default_mesh_path
    from tonguevis.sim.placement import source_model

    model = source_model(model)

    source = model.mesh.metadata.get("source")
    try:
        return source is not None and Path(source).resolve() == default_mesh_path().resolve()
    except OSError:
        return False


def placed_palate(recording: Recording, palate, model: TongueModel | None = None, landmarks: str = "speaker",
                  rest: RestChoice | tuple[float, float] | None = None, smooth_window: int | None = None,
                  frame: str = "speaker", tongue_size: float | str | None = None):
    """The palate as :func:`simulate` places it for ``recording`` on ``model`` (unplaced, as given to
    :func:`simulate`): (surface in the motion's ``frame``, raised by m).

    For drawing a motion against its palate: pass the motion's landmarks, rest and frame
    (``motion.metadata["landmarks"]``, :func:`tonguevis.workflows.rest_of`,
    ``motion.metadata.get("frame", "model")``: motions saved before the speaker frame are in the
    model's; ``motion.metadata["fit"]["tongue_size"]``) so the alignment is the one the simulation used.
    """
    from tonguevis.sim.placement import targets_in_frame

    framed, prep, _ = targets_in_frame(recording, model or TongueModel.default(), frame, landmarks, rest,
                                       smooth_window, tongue_size=tongue_size)
    return place_palate(palate, prep, quiet=True, model=framed,  # the simulation said it once
                        speech_references=_speech_references(recording, prep, palate))


def _contact_context(palate, prep, model, basis, recording) -> dict:
    """What the contact solve needs: the palate in the model frame, candidate nodes and their modes."""
    palate, shift = place_palate(palate, prep, model=model,
                                 speech_references=_speech_references(recording, prep, palate))
    candidates = np.asarray(model.dorsal_nodes)
    gap, _ = palate.clearance(model.mesh.points[candidates])
    inside = np.nanmean(gap < -1e-3) if np.isfinite(gap).any() else 0.0
    if inside > 0.2:
        raise SimulationError(
            f"the palate cuts through the tongue at rest ({100 * inside:.0f} % of its upper surface more than 1 mm "
            f"inside it, up to {-1e3 * np.nanmin(gap):.0f} mm): is it this speaker's palate, from this session?",
            recording.metadata.get("file"))
    dofs = (3 * candidates[:, None] + np.arange(3)).ravel()
    return {"palate": palate, "candidates": candidates, "points": model.mesh.points,
            "phi_nodes": basis.phi[dofs].reshape(len(candidates), 3, -1), "sensor_nodes": np.asarray(prep.nodes),
            "jaw_offset": prep.jaw_offset if prep.jaw_offset is not None else np.zeros((recording.n_samples, 3)),
            "registration_shift_m": shift}


def _keep_below_palate(q, contact, schedule, basis, phi_s, compliance: float):
    """The dynamic shapes projected out of the palate where inertia carried them in (see contact.correct_frames)."""
    from tonguevis.sim.contact import CONFLICT_RADIUS, correct_frames

    cand, pts = contact["candidates"], contact["points"]
    near = np.linalg.norm(pts[cand][:, None] - pts[contact["sensor_nodes"]][None], axis=2) < CONFLICT_RADIUS
    allowed = np.ones((len(q), len(cand)), dtype=bool)
    for f, s in schedule["conflicts"]:
        allowed[f] &= ~near[:, s]
    return correct_frames(basis.eigenvalues, contact["phi_nodes"], phi_s, q, pts, cand, contact["palate"],
                          contact["jaw_offset"], allowed, compliance=compliance,
                          backend=contact.get("backend", "warp"))


def _contact_probe(contact, schedule, model):
    """What :func:`tonguevis.sim.figures.frame_figures` needs to measure contact, per chunk of frames.

    Every candidate node counts, also those around a sensor above the palate (the tongue drawn
    there is inside it): the figures say what the geometry is."""
    from tonguevis.sim.figures import ContactProbe

    cand, pts = contact["candidates"], contact["points"]
    return ContactProbe(pts, cand, contact["palate"], contact["jaw_offset"], model.surface_faces,
                        np.zeros((0, 2), dtype=np.int64), np.zeros((len(cand), 0), dtype=bool))


#: m (the speaker's): a sensor this close under the palate is taken to touch it.  The coil and its glue
#: lie between tongue and palate (an NDI Wave sensor is about 1 mm thick with its glue) and the Wave's
#: stated accuracy is 0.5 mm: a coil measured within 1 mm of the palate at a closure is pressed on it,
#: with the tongue around it touching.  Without this, of the frames with a sensor that close to the
#: speaker's palate, 7 of 387 (/ta/ 009) and 2 of 753 (/ka/ 006) showed no contact.
TOUCH_REACH = 1e-3


def held_to_palate(contact: dict, rest: np.ndarray, displacement: np.ndarray, reach: float,
                   names) -> tuple[np.ndarray, dict]:
    """The sensor displacements the tongue follows: those of a sensor within ``reach`` (m) below the
    palate moved up onto it, along the palate's normal; and what was moved, for the metadata.

    rest : (S, 3) the sensor nodes' rest positions (m, the simulation's frame).
    displacement : (F, S, 3) m, the measured sensors' displacements (NaN where not measured).
    Returns ((F, S, 3) displacements, {"reach_mm", "frames": {name: frames held}, "largest_move_mm"}).
    Sensors above the palate, far below it or outside its footprint are left as measured.
    """
    frames, sensors = displacement.shape[:2]
    where = rest[None] + displacement + contact["jaw_offset"][:frames, None]
    gap, normal = contact["palate"].clearance(where.reshape(-1, 3))
    gap, normal = gap.reshape(frames, sensors), normal.reshape(frames, sensors, 3)
    near = np.isfinite(gap) & (gap > 0) & (gap <= reach)
    held = displacement.copy()
    held[near] -= normal[near] * gap[near][:, None]  # the normal points down, away from the palate
    info = {"reach_mm": 1e3 * reach,
            "frames": {name: int(near[:, k].sum()) for k, name in enumerate(names) if near[:, k].any()},
            "largest_move_mm": float(1e3 * gap[near].max()) if near.any() else 0.0}
    return held, info


def _sensor_depth(contact, sensors: np.ndarray, cut: slice) -> np.ndarray:
    """(F, S) how far (m, >= 0) each sensor (F, S, 3, model frame, jaw's frame) lies above the palate;
    0 below it, NaN where not measured or no palate lies above."""
    offset = contact["jaw_offset"][cut]
    gap, _ = contact["palate"].clearance((sensors + offset[:, None]).reshape(-1, 3))
    gap = gap.reshape(sensors.shape[:2])
    return np.where(np.isfinite(gap), np.maximum(0.0, -gap), np.nan)


def _contact_report(pen, contact_area, contact, schedule, times, sensor_depth, names):
    """The contact figures for metadata, from the per-frame penetration (m) of the tongue's nodes,
    its contact area (m²) and the depth (F, S) m of each sensor above the palate.

    They say what the geometry says: a sensor above the palate is penetration (the tongue follows
    the sensor there), and a frame is in contact when the tongue touches, enters or presses on the
    palate, whatever made it."""
    above = np.nan_to_num(sensor_depth) > 0
    deepest_sensor = float(np.nanmax(sensor_depth)) if np.isfinite(sensor_depth).any() else 0.0
    touching = (contact_area > 0) | (pen > 0) | (schedule["active"][:len(pen)] > 0)  # touching, inside or pressed
    conflicts = sorted({s for _, s in schedule["conflicts"]})
    figures = {
        "penetration_max_mm": float(1e3 * max(pen.max() if len(pen) else 0.0, deepest_sensor)),
        "tongue_penetration_max_mm": float(1e3 * pen.max()) if len(pen) else 0.0,
        "sensor_penetration_max_mm": 1e3 * deepest_sensor,
        "sensors_above_palate": {name: {"frames": int(above[:, k].sum()),
                                        "deepest_mm": float(1e3 * np.nanmax(sensor_depth[:, k]))}
                                 for k, name in enumerate(names) if above[:, k].any()},
        "frames_in_contact": int(touching.sum()),
        "frames_with_contact_forces": int(np.sum(schedule["active"] > 0)),
        "frames_corrected_after_the_dynamics": int(len(schedule.get("corrected_frames", []))),
        "contact_area_max_mm2": float(1e6 * contact_area.max()) if len(contact_area) else 0.0,
        "conflicts": {"frames": len({f for f, _ in schedule["conflicts"]}),
                      "by_sensor_index": {int(s): sum(1 for _, t in schedule["conflicts"] if t == s) for s in conflicts},
                      "first_s": float(times[schedule["conflicts"][0][0]]) if schedule["conflicts"] else None},
        "palate": {k: v for k, v in contact["palate"].metadata.items()
                   if k in ("rms_m", "source", "frame", "kept", "joined", "min_bend_radius_m", "bend_radius_m",
                            "head_registration", "raise_by_sensor_mm")},
        "palate_raised_mm": float(1e3 * contact.get("registration_shift_m", 0.0)),
        **({"sensors_held_to_palate": contact["held_to_palate"]} if "held_to_palate" in contact else {}),
    }
    return figures


def _register_palate(palate, prep, percentile: float = 1.0, quiet: bool = False):
    """The palate raised, if need be, until the tongue sensors stay below it; (palate, shift in m).

    A palate traced in another sitting than the speech (no head references to
    relate the two, as in Opti-Speech exports) can sit millimetres too low: on
    the real /ta/ and /ka/ the dorsum sensor read 5-11 mm above the traced
    palate, which no tongue does.  The sensors' positions over the whole
    recording (head frame) are the evidence: the palate is moved up along
    the model's z until all but ``percentile`` % of them are below it.

    What each sensor alone would call for (its own ``percentile``, in mm; sensors with under 5 % of their
    samples under the palate left out) goes into the palate's ``metadata["raise_by_sensor_mm"]``: a
    raise set by one sensor while another needs far less (on OSN12: TD 9.6 mm, TT 1.8 mm) is a tilt
    between the sittings or a soft palate the dorsum lifts, which a rigid raise cannot undo and which
    leaves the front of the roof too high for the tip.
    """
    head = prep.aligned_rest[None] + prep.displacement + prep.jaw_offset[:, None]
    gap, _ = palate.clearance(head.reshape(-1, 3))
    gap = gap.reshape(head.shape[:2])
    needs = {}
    for k, name in enumerate(prep.names):
        own = gap[:, k][np.isfinite(gap[:, k])]
        if len(own) >= 0.05 * len(gap) and len(own):
            needs[name] = round(1e3 * max(0.0, -float(np.percentile(own, percentile))), 2)
    gap = gap[np.isfinite(gap)]
    if len(gap) == 0:
        return palate, 0.0
    shift = max(0.0, -float(np.percentile(gap, percentile)))
    if shift > 0:
        if not quiet:
            logger.warning("the palate lies %.1f mm below where the tongue sensors went: raised by that much "
                           "(traced in another sitting?)%s", 1e3 * shift, raise_spread(needs))
        palate = palate.transformed(np.eye(3), 1.0, np.array([0.0, 0.0, shift]))
    palate.metadata["raise_by_sensor_mm"] = needs
    return palate, shift


def _sensor_misfit(q, phi_s, w_s, measured, warping):
    """(F, S) distance (m) of each sensor node from its measured displacement (NaN where not measured)."""
    from tonguevis.sim.rotation import rotate_accumulated

    out = np.empty(measured.shape[:2])
    for start in range(0, len(q), 16384):  # in blocks: the rotation's temporaries of every frame at once were 0.2 GB
        block = slice(start, start + 16384)
        d = np.einsum("scm,fm->fsc", phi_s, q[block])
        if warping:
            d = rotate_accumulated(np.einsum("scm,fm->fsc", w_s, q[block]), d)
        out[block] = np.linalg.norm(d - measured[block], axis=2)
    return out


def _stage(progress: ProgressCallback | None, stage: int, stages: int, span: int = 1) -> ProgressCallback | None:
    """Map a sub-task's progress onto ``span`` of ``stages`` equal parts, from part ``stage`` on."""
    if progress is None:
        return None

    def sub(done: int, total: int, message: str = "") -> None:
        frac = done / total if total else 1.0
        progress(int(1000 * (stage + span * frac)), 1000 * stages, message)

    return sub
