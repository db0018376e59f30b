"""Simulating a recording with seed 001's StVK on quadratic domains (:mod:`tonguevis.sim.domains` holds the
model): :func:`simulate_domains`, what ``simulate(recording, method="domains")`` runs."""

from __future__ import annotations

import time

import numpy as np

from tonguevis.sim.domains import FAST_TOLERANCE, SCHEMES, DomainModel, domains_model
from tonguevis.sim.drive import drive_schedule
from tonguevis.sim.motion_builder import MotionBuilder


def simulate_domains(recording, settings=None, model=None, *, progress=None, cache: bool = True,
                     cubature: bool = False, scheme: str = "newton", **overrides):
    """:func:`tonguevis.sim.simulate` with ``method="domains"`` (``settings`` and ``overrides`` as there; the
    method is domains whatever they say): the same preparation (rest, alignment, frame),
    the same sensor constraints (the compliant projection of :func:`~tonguevis.sim.simulate.drive_schedule`
    with this model's own linear stiffness, dropouts bridged and handed over, then held hard), the reduced
    StVK of :class:`DomainModel` integrated by :meth:`DomainModel.integrate`, and the same :class:`Motion`
    (plausibility, misfit, recovered and implausible frames, every metadata key of the modal methods)
    with ``metadata["method"] = "domains"`` and ``metadata["domains"]`` (seeds, DOFs, weights' source).
    ``motion.q`` holds z (F, r), ``motion.model`` the :func:`domains_model` copy (u = B z) and
    ``motion.energy`` the StVK energy of each frame (J).  No palate yet (SimulationError), and the
    time step is the recording's (backward Euler, unconditionally stable).
    cubature : the force and tangent from a few hundred weighted tets (:mod:`tonguevis.sim.cubature`,
    cached; its force error on shapes it was not built from in ``metadata["domains"]["cubature"]``) instead
    of every tet: about 20 times less work per force.
    scheme : the frame loop. "newton" (default): :meth:`DomainModel.integrate_fast`, Newton to 1 µm with the
    exact force compiled; "linearised": one force call a frame (its cost in accuracy in
    scripts/bench_domains.py); "reference": :meth:`DomainModel.integrate`, the NumPy force, to 0.1 µm
    (what the others are checked against).  ``backend="numpy"`` takes the NumPy force in any scheme
    (``tolerance`` is the reference's; the fast schemes take at least :data:`FAST_TOLERANCE`).
    """
    from tonguevis._progress import report
    from tonguevis.errors import SimulationError
    from tonguevis.sim.constrained import point_stiffness
    from tonguevis.sim.figures import frame_figures
    from tonguevis.sim.placement import targets_in_frame
    from tonguevis.sim.settings import RunSettings, build_model, run_settings

    file = recording.metadata.get("file")
    if settings is not None and not isinstance(settings, RunSettings):  # simulate_domains(recording, model, ...)
        settings, model = model if isinstance(model, RunSettings) else None, settings
    try:
        settings = run_settings(settings, **overrides).replace(method="domains")
    except SimulationError as exc:
        raise SimulationError(str(exc), file) from None
    if scheme not in SCHEMES:
        raise ValueError(f"scheme must be one of {', '.join(map(repr, SCHEMES))}, got {scheme!r}")
    if settings.palate is not None:
        raise SimulationError("the domains method has no palate contact yet: simulate it with method='warped' or "
                              "without the palate", file)
    sensor_stiffness, backend, tolerance = settings.sensor_stiffness_value, settings.backend, settings.newton_tolerance
    model = model if model is not None else build_model(settings)
    recording = recording.on_uniform_grid()
    model, prep, fit = targets_in_frame(recording, model, settings.frame, settings.landmarks, settings.rest,
                                        settings.smooth_window, tongue_size=settings.tongue_size)
    report(progress, 0, 3, "building the quadratic domains")
    t0 = time.perf_counter()
    dm = DomainModel(model, prep.nodes, cache=cache,
                     backend="numpy" if scheme == "reference" or backend == "numpy" else "warp")
    build_s = time.perf_counter() - t0
    cub_info = None
    if cubature:
        from tonguevis.sim.cubature import cubature_for, training_poses

        cub = cubature_for(dm, cache=cache)
        cub_info = {"tets": int(len(cub.tets)), "training_force_error": cub.training_error,
                    "force_error_other_shapes": cub.relative_error(training_poses(dm, count=6, seed=99))}
        dm.use_cubature(cub)
    dmodel = domains_model(model, dm)
    basis = dmodel.basis(dm.n_dofs)
    phi_s = dm.rows(prep.nodes)
    w_s = np.zeros_like(phi_s)
    k_ref = point_stiffness(dm.eigenvalues, phi_s)
    targets, compliance, schedule = drive_schedule(prep.displacement, recording.rate, dm.eigenvalues, phi_s,
                                                   sensor_stiffness)
    report(progress, 1, 3, "integrating")
    t0 = time.perf_counter()
    if scheme == "reference":
        result = dm.integrate(targets, 1.0 / recording.rate, model.material.alpha, model.material.beta, tolerance)
        energy = None
    else:
        result, energy = dm.integrate_fast(targets, 1.0 / recording.rate, model.material.alpha,
                                           model.material.beta, max(tolerance, FAST_TOLERANCE),
                                           linearised=scheme == "linearised")
    loop_s = time.perf_counter() - t0
    report(progress, 2, 3, "measuring the frames")
    figures = frame_figures(dmodel, result.q, False, backend)
    run = MotionBuilder(settings.replace(modes=dm.n_dofs), dmodel, recording, prep, basis, (phi_s, w_s),
               (targets, compliance, schedule), k_ref, None)
    run.fit = fit
    motion = run.motion(result, figures, len(targets))
    motion.energy = dm.energies(motion.q) if energy is None else energy
    motion.metadata["method"] = "domains"
    motion.metadata["domains"] = {
        "seeds": dm.domains.seeds.tolist(), "dofs": int(dm.n_dofs), "domains": int(len(dm.domains.seeds)),
        "weights": "material-aware (seed 001 §7; domain boundary not held, see tonguevis.sim.domains)",
        "integrator": "backward Euler, reduced StVK " + ("by cubature" if cubature else "over every tet"),
        "scheme": scheme, "force": "cubature" if cubature else ("compiled" if dm.backend == "warp" else "numpy"),
        "force_calls": int(result.iterations.sum()),
        "cubature": cub_info,
        "build_s": build_s, "loop_s": loop_s, "frames_per_s": len(targets) / loop_s if loop_s > 0 else float("inf"),
        "unconverged_frames": int(np.sum(~result.converged)),
    }
    report(progress, 3, 3, "done")
    return motion
