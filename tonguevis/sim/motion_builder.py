"""From a frame loop's result to a :class:`~tonguevis.sim.motion.Motion`: :class:`MotionBuilder`, shared by the
modal methods (:func:`tonguevis.sim.simulate.simulate`) and the domains (:func:`tonguevis.sim.domains_run.simulate_domains`):
frames no tongue could produce recovered or refused, the plausibility figures, the contact report, the metadata."""

from __future__ import annotations

import numpy as np

from tonguevis._logging import logger
from tonguevis.errors import SimulationError
from tonguevis.sim.figures import frame_figures
from tonguevis.sim.motion import Motion
from tonguevis.sim.constrained import RUNAWAY_ROTATION
from tonguevis.sim.palate_placement import contact_report, sensor_depth
from tonguevis.sim.plausibility import ABSURD_AMPLIFICATION, ABSURD_VOLUME, plausibility_from_largest
from tonguevis.sim.rest_fit import rest_fitted_model_of
from tonguevis.sim.settings import RunSettings

VOLUME_WARNING = 0.05  # relative volume change past which the motion is flagged as implausible
ABSURD_SHARE = 0.05  # a run with more absurd frames than this is refused rather than returned
RECOVERED_SHARE = 0.10  # ... or with more recovered frames than this: it is no longer the model's motion


class MotionBuilder:
    """One simulation's inputs, to make its :class:`Motion` from the integration and the figures, for every
    frame or (a preview) for the first ones only, the same way."""

    def __init__(self, settings: RunSettings, model, recording, prep, basis, rows, drive, k_ref, contact):
        """``rows``: (phi_s, w_s), the sensor nodes' rows of the basis and of the rotation matrix;
        ``drive``: (targets, compliance, schedule) of :func:`drive_schedule`."""
        self.settings = settings
        self.model, self.recording, self.prep, self.basis = model, recording, prep, basis
        (self.phi_s, self.w_s), (self.targets, self.compliance, self.schedule) = rows, drive
        self.warping, self.backend, self.modes = settings.warping, settings.backend, settings.modes
        self.landmarks, self.sensor_stiffness = settings.landmarks, settings.sensor_stiffness_value
        self.k_ref, self.contact = k_ref, contact
        self.previewed = False
        self.patches: dict | None = None
        self.drive = prep.displacement  # (F, S, 3) m: what the sensor nodes follow (held_to_palate)

    def prepare_patches(self, radius: float, reach: float) -> None:
        """Use the sensor patches (:mod:`tonguevis.sim.patches`) of ``radius`` fading out by ``reach`` (m): the
        run's model, basis and sensor rows become the augmented ones (the frame loop keeps the modes alone)."""
        from tonguevis.sim.patches import augmented_basis, augmented_model, humped_sensors

        self.global_rows = (self.basis, self.phi_s)  # what the frame loop (and a recovery) solves with
        basis = augmented_basis(self.model, self.basis, self.prep.nodes, radius, reach,
                                "scaled" if self.settings.humps else None, humped_sensors(self.prep.names))
        self.model = augmented_model(self.model, basis)
        self.rotation = self.model.rotation_matrix(basis)
        dofs = (3 * np.asarray(self.prep.nodes)[:, None] + np.arange(3)).ravel()
        s = len(self.prep.nodes)
        self.basis, self.phi_s, self.w_s = basis, basis.phi[dofs].reshape(s, 3, -1), self.rotation[dofs].reshape(s, 3, -1)
        self.patches = {"radius_mm": 1e3 * radius, "reach_mm": 1e3 * basis.info["patch_reach_m"],
                        "shapes": int(basis.n_modes - basis.info["global_modes"]),
                        "nodes": basis.info["patch_nodes"], "global_modes": int(basis.info["global_modes"]),
                        "hump_mm": None if basis.info["hump_m"] is None else [1e3 * v for v in basis.info["hump_m"]],
                        "humped": basis.info["humped"], "unit_at_node": basis.info["unit_at_node"]}

    def patch_coordinates(self, q: np.ndarray, start: int, end: int, local_only: bool = False) -> np.ndarray:
        """(end - start, p) patch coordinates closing the sensors' gaps in frames start..end-1 whose
        modal coordinates (from the frame loop) are ``q`` (end - start, m); ``local_only``: the humps at rest."""
        from tonguevis.sim.patches import close_sensor_gaps

        frames = slice(start, end)
        return close_sensor_gaps(self.basis, self.rotation, self.prep.nodes, q, self._patch_targets(frames),
                                 self.warping, weight=self.schedule["weight"][frames], local_only=local_only)

    def _patch_targets(self, frames) -> np.ndarray:
        """(F, S, 3) m for ``frames`` (a slice or indices): where the patches put the sensor nodes: the sensors
        followed (``drive``), a sensor lost for good held at its last measurement while its spring lets go
        (the springs' anchors)."""
        drive = self.drive[frames]
        anchored = self.schedule.get("anchored")
        if anchored is None:
            return drive
        return np.where(np.isnan(drive), anchored[frames], drive)

    def _contact_places(self, q, contact_area, contact, warping) -> dict:
        """Where the tongue touches the palate (:func:`tonguevis.sim.palate_regions.place_of`): at the frame of the
        largest contact area ("largest_contact_where") and, during each closure (its nucleus, where the pull
        holds: :meth:`_closure_place`), where the region pressed for the closure (the tip and blade; the dorsum) touches: the place said most ("closures_where", with
        "closures_touching": at how many closures that region touches).  Not the whole tongue's contact there:
        at a /t/ the sides and back of the tongue touch too, over a larger area, and "the closures touch (back)"
        said of a /t/ misled."""
        from tonguevis.sim.contact import TOUCH, node_areas
        from tonguevis.sim.palate_regions import palate_frame, place_of

        model, palate = self.model, contact["palate"]
        frame = palate_frame(palate)
        cand = np.asarray(contact["candidates"])
        all_areas = node_areas(model.mesh.points, np.asarray(model.surface_faces))
        lift = contact.get("lift")

        def place(f: int, nodes: np.ndarray) -> str:
            u = model.displacements(q[f:f + 1], warping=warping, nodes=nodes)[0]
            points = model.mesh.points[nodes] + u + contact["jaw_offset"][f, :3]
            at = palate.lifted(float(lift[f])) if lift is not None else palate
            gap = at.clearance(points)[0]
            touching = np.isfinite(gap) & (gap < TOUCH)
            return place_of(frame, points[touching], all_areas[nodes][touching])

        out: dict = {}
        if len(contact_area) and np.max(contact_area) > 0:
            out["largest_contact_where"] = place(int(np.argmax(contact_area)), cand)
        closures = contact.get("closures") or {}
        middles = closures.get("maximum_constriction_frames", [])
        spans = closures.get("closure_frames") or [[f, f] for f in middles]  # older motions: the peak alone
        spans = [(f0, min(f1, len(q) - 1)) for (f0, f1), f in zip(spans, middles) if f < len(q)]
        pressed = np.asarray(closures.get("nodes", []), dtype=np.int64)
        if spans and len(pressed):
            places = [self._closure_place(place, pressed, f0, f1) for f0, f1 in spans]
            named = [p for p in places if p]
            out["closures_touching"] = len(named)
            out["closures_where"] = max(set(named), key=named.count) if named else ""
        return out

    @staticmethod
    def _closure_place(place, pressed: np.ndarray, first: int, last: int) -> str:
        """Where the pressed region touches during a closure (its frames first..last, the nucleus the pull holds):
        at the first frame it does, "" when it does not.  One frame (the maximum constriction) said "the tip
        touches at 2 of 5" on the shared /ta/ 009 where the tip touched at 4 within three frames of it."""
        for f in range(first, last + 1):
            where = place(f, pressed)
            if where:
                return where
        return ""

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
            contact_figures = contact_report(penetration, contact_area, contact, schedule, times,
                                              sensor_depth(contact, sensors, cut), prep.names)
            contact_figures.update(self._contact_places(q, contact_area, contact, warping))
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
            velum_lift=None if contact is None or contact.get("lift") is None else contact["lift"][cut].copy(),
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
