"""The tongue simulated frame by frame from a live stream: the replay's model and constraints, causally.

:class:`LiveSimulator` does for one frame at a time what :func:`tonguevis.sim.simulate` does
for a whole recording, with the same functions wherever they are causal:

1. **Rest** (once): a few hundred milliseconds of still frames (:func:`stillest_window` of the
   recent stream, or whatever the clinician pressed "Take rest now" on) become a small
   :class:`~tonguevis.io.recording.Recording`; :func:`tonguevis.sim.placement.targets_in_frame`
   on it, with that whole snippet as the rest interval, gives the placed model, the sensor
   nodes and the rest positions exactly as the replay computes them for the same rest.
2. **Per frame**: head correction (the rigid fit of the head references onto their rest pose,
   :func:`tonguevis.preprocess._rigid.fit_rotations`, as :func:`~tonguevis.preprocess.correction.correct_head`),
   jaw correction (:func:`~tonguevis.preprocess.correction.correct_jaw`'s rule), the displacement
   from rest into the model's frame, the compliant projection of the targets
   (:func:`tonguevis.sim.constrained.compliant_targets`, sensor springs as
   :func:`tonguevis.sim.simulate.drive_schedule` builds them), one step of the compiled
   Newmark frame loop (:class:`tonguevis.sim.newmark_kernel.CompiledIntegrator`, resumable: one
   frame at a time gives the q of one launch), then the surface nodes' positions with modal
   warping (vectorised, preallocated buffers).

What differs from the replay (it cannot see the future): a sensor's short dropout (≤ 0.1 s)
is not bridged by interpolation through the samples after it (:func:`~tonguevis.sim.dropouts.bridge_short_gaps`);
it is released and re-engaged like a long one (:func:`~tonguevis.sim.dropouts.engagement`'s
ramps, computed causally: the same weights wherever nothing was bridged).  Frames the replay
would recover afterwards (implausible shapes, :mod:`tonguevis.sim.plausibility`) are shown as
simulated.  Smoothing (``smooth_window``) is not applied.  With no dropout the node positions
equal the replay's (a test: to 1e-12 m on the demo).

Units: the stream's positions in mm (as :class:`~tonguevis.live.source.LiveFrame` carries them),
everything returned in metres in the speaker frame (the head-corrected device frame, in which
the model is placed) unless the settings say ``frame="model"``.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from tonguevis.errors import TonguevisError

#: Seconds of still stream the rest is taken from (the replay's fallback window is 0.2 s; a
#: clinician's "rest" is a held pose of about half a second).
REST_WINDOW_S = 0.5
#: Seconds of recent frames kept to look for the stillest window in.
REST_SEARCH_S = 3.0


class LiveSimulationError(TonguevisError):
    """The live simulation cannot start or go on (no rest yet, too few tongue sensors, ...)."""


@dataclass
class LiveStep:
    """What one frame gave.

    surface : (k, 3) float32 m, the surface nodes' positions (``LiveSimulator.surface_nodes`` order;
        a view on a buffer the next step overwrites: copy to keep); None when not reconstructed.
    sensor_points : (S, 3) float64 m, the driving sensors' measured positions in the model's frame
        (each sensor's node at rest plus its displacement), NaN where missing.
    corrected : (A, 3) float64 m, every slot head-corrected (the stream's frame, NaN where missing),
        what a sweep saves as its live head correction.
    q : (m,) modal coordinates.  jaw_offset : (3,) m, the jaw's translation from rest (zeros without JAW).
    timings : stage -> seconds ("correct", "drive", "integrate", "reconstruct").
    recovered : the model could not follow this frame (the integrator's linear fallback, as the replay's
        recovered frames: :class:`~tonguevis.sim.newmark.IntegrationResult`).
    """

    surface: np.ndarray | None
    sensor_points: np.ndarray
    corrected: np.ndarray
    q: np.ndarray
    jaw_offset: np.ndarray
    timings: dict = field(default_factory=dict)
    recovered: bool = False


def stillest_window(times: np.ndarray, positions: np.ndarray, duration: float = REST_WINDOW_S) -> slice | None:
    """The frames (a slice) of the ``duration`` s window in which the sensors move least, or None.

    times : (N,) s; positions : (N, S, 3), any unit.  Motion is the largest frame-to-frame step
    over the sensors (a missing sample counts as a large move), as
    :func:`tonguevis.preprocess.rest.stillest_window`; None when fewer frames than the window holds.
    """
    n = len(times)
    if n < 2:
        return None
    dt = float(np.median(np.diff(times)))
    width = max(1, int(round(duration / dt))) if dt > 0 else n
    if n - 1 < width:
        return None
    step = np.linalg.norm(np.diff(positions, axis=0), axis=2).max(axis=1)
    csum = np.concatenate([[0.0], np.cumsum(np.where(np.isfinite(step), step, 1e9))])
    means = (csum[width:] - csum[:-width]) / width
    start = int(np.argmin(means))
    return slice(start, start + width + 1)


class _Engagement:
    """:func:`tonguevis.sim.dropouts.engagement` computed frame by frame (it only looks back)."""

    def __init__(self, n_sensors: int, rate: float):
        from tonguevis.sim.dropouts import RAMP_S

        self.ramp = max(1, int(round(RAMP_S * rate)))
        self.steps = np.arange(1, self.ramp + 1) / (self.ramp + 1)
        self.missing_for = np.zeros(n_sensors, dtype=np.int64)  # frames since the sensor was lost (0: present)
        self.back_for = np.full(n_sensors, -1, dtype=np.int64)  # frames since it came back (-1: never lost)
        self.seen = np.zeros(n_sensors, dtype=bool)  # measured at least once (a gap at the start has no release)
        self.last = np.full((n_sensors, 3), np.nan)

    def __call__(self, displacement: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(weight (S,), anchored targets (S, 3)) for this frame's displacement (S, 3), NaN = missing."""
        valid = np.all(np.isfinite(displacement), axis=1)
        weight = np.zeros(len(valid))
        lost = ~valid
        # A gap: the first frames after the last measurement weaken the spring (only after a measurement).
        self.missing_for = np.where(lost, self.missing_for + 1, 0)
        releasing = lost & self.seen & (self.missing_for <= self.ramp)
        weight[releasing] = 1.0 - self.steps[self.missing_for[releasing] - 1]
        # Back after a gap (also one at the start): the spring grows over the ramp.
        self.back_for = np.where(valid, np.where(self.back_for >= 0, self.back_for + 1, -1), self.back_for)
        self.back_for[lost] = 0  # counts from the first valid frame after this gap
        returning = valid & (self.back_for >= 1) & (self.back_for <= self.ramp)
        weight[valid] = 1.0
        weight[returning] = self.steps[self.back_for[returning] - 1]
        anchored = np.where(valid[:, None], displacement, self.last)
        self.last = np.where(valid[:, None], displacement, self.last)
        self.seen |= valid
        return weight, anchored


def check_live_settings(settings) -> None:
    """LiveSimulationError, naming the setting, for what a frame-by-frame simulation cannot do yet: the domains
    method and the volume kept (both need the whole recording: the domains' nonlinear solve runs at a few hundred
    frames/s, the volume's pressure subspace is built from the motion's own shapes) and the trajectories' smoothing
    (a Savitzky-Golay window looks ahead)."""
    if settings.method == "domains":
        raise LiveSimulationError("the live view simulates with modal warping or the linear modes (--method warped "
                                  "or linear); the domains method runs on whole recordings only (tonguevis simulate)")
    if settings.keep_volume:
        raise LiveSimulationError("--keep-volume needs the whole recording (its pressure shapes come from the "
                                  "motion's own): replay the recording (tonguevis view) to see it")
    if settings.smooth_window is not None:
        raise LiveSimulationError("smoothing the trajectories looks ahead in time: the live view has its own "
                                  "display smoothing instead (the panel's slider)")


class LiveSimulator:
    """The tongue driven by a live stream, one frame at a time (see the module docstring).

    sensor_names : the stream's slot names (S_all; the sensor map's names: TT, TD, ..., REF1, JAW).
    settings : a :class:`~tonguevis.sim.settings.RunSettings` (modes, warping, landmarks,
        sensor stiffness, frame, tongue size; the mesh through ``model``); default the replay's.
    model : the unplaced tongue model (default the settings' mesh, else the shipped tongue).
    rate : the stream's sample rate (Hz); the dynamic solve's step is 1/rate.
    dtype : the surface's float type (float32 to draw; float64 to compare with the replay).

    :meth:`observe` keeps the recent frames (for :meth:`take_rest`); :meth:`set_rest` /
    :meth:`take_rest` build the simulation; :meth:`step` simulates one frame.
    """

    def __init__(self, sensor_names, settings=None, model=None, rate: float = 100.0, dtype=np.float32,
                 tolerance: float | None = None):
        from tonguevis.sim.settings import RunSettings, build_model

        self.settings = settings if settings is not None else RunSettings()
        check_live_settings(self.settings)
        self.sensor_names = [str(n) for n in sensor_names]
        if len(set(self.sensor_names)) != len(self.sensor_names):
            raise LiveSimulationError(f"the stream's slot names repeat: {self.sensor_names}")
        self.source_model = model if model is not None else build_model(self.settings)
        if not (np.isfinite(rate) and rate > 0):
            raise LiveSimulationError(f"the stream's rate must be a positive number of Hz, got {rate!r}")
        self.rate = float(rate)
        self.dtype = np.dtype(dtype)
        self.tolerance = float(tolerance) if tolerance is not None else self.settings.newton_tolerance
        self._recent: deque = deque(maxlen=max(8, int(round(REST_SEARCH_S * self.rate))))
        self.ready = False
        self.frames_done = 0
        self.palate = None  # the settings' palate placed on the rest (a PalateSurface), once the rest is taken

    # ------------------------------------------------------------------ rest
    def observe(self, timestamp_s: float, positions_mm: np.ndarray) -> None:
        """Remember a frame (timestamp s, (S_all, 3) mm) for :meth:`take_rest`."""
        self._recent.append((float(timestamp_s), np.array(positions_mm, dtype=np.float64)))

    def rest_candidate(self, duration: float = REST_WINDOW_S) -> tuple[np.ndarray, np.ndarray] | None:
        """(times (n,), positions (n, S_all, 3) mm) of the stillest ``duration`` s among the recent frames."""
        if len(self._recent) < 2:
            return None
        times = np.array([t for t, _ in self._recent])
        positions = np.stack([p for _, p in self._recent])
        tongue = [k for k, n in enumerate(self.sensor_names) if n in _tongue_names()]
        window = stillest_window(times, positions[:, tongue] if tongue else positions, duration)
        if window is None:
            return None
        return times[window], positions[window]

    def take_rest(self, duration: float = REST_WINDOW_S) -> None:
        """The rest from the stillest ``duration`` s of the recent stream (LiveSimulationError when too few frames)."""
        found = self.rest_candidate(duration)
        if found is None:
            raise LiveSimulationError(f"not enough frames yet to take a rest of {duration:g} s "
                                      f"({len(self._recent)} received)")
        self.set_rest(*found)

    def set_rest(self, times: np.ndarray, positions_mm: np.ndarray) -> None:
        """Build the simulation on the rest frames: times (n,) s, positions (n, S_all, 3) mm (NaN = missing).

        The rest interval is the whole of them: every sensor's rest is its mean over these frames,
        the head's frame the references' mean pose, as the replay with ``rest_interval`` =
        (times[0], times[-1]) computes them.  Raises LiveSimulationError (too few tongue sensors,
        a sensor with no valid sample in the rest, ...).
        """
        from tonguevis.io.recording import Recording
        from tonguevis.preprocess.correction import head_references
        from tonguevis.preprocess.rest import RestChoice
        from tonguevis.sim.constrained import point_stiffness
        from tonguevis.sim.newmark import NewmarkSettings
        from tonguevis.sim.newmark_kernel import CompiledIntegrator
        from tonguevis.sim.placement import targets_in_frame

        times = np.asarray(times, dtype=np.float64)
        positions = np.asarray(positions_mm, dtype=np.float64) / 1000.0
        if positions.ndim != 3 or positions.shape[1:] != (len(self.sensor_names), 3) or len(times) != len(positions):
            raise LiveSimulationError(f"rest frames: expected ({len(times)}, {len(self.sensor_names)}, 3) positions, "
                                      f"got {positions.shape}")
        if len(times) < 2:
            raise LiveSimulationError("a rest needs at least two frames")
        snippet = Recording(rate=self.rate, times=times,
                            sensors={n: positions[:, k] for k, n in enumerate(self.sensor_names)},
                            metadata={"file": "live rest", "format": "live", "frame": "tonguevis"})
        s = self.settings
        rest = RestChoice((float(times[0]), float(times[-1])), "given")
        try:
            model, prep, fit = targets_in_frame(snippet, self.source_model, s.frame, s.landmarks, rest, None,
                                                tongue_size=s.tongue_size, rest_fit=s.rest_fit)
        except TonguevisError as exc:
            raise LiveSimulationError(f"cannot take this rest: {exc}") from exc
        self.model, self.prep, self.fit = model, prep, fit
        self.rest_times = times
        # The per-frame corrections' constants, as prepare_targets computed them on the snippet.
        self.references = head_references(snippet)
        self._ref_index = [self.sensor_names.index(n) for n in self.references]
        if self.references:
            pose = np.stack([positions[:, k] for k in self._ref_index], axis=1)
            self._head_pose = np.array([pose[:, j][np.all(np.isfinite(pose[:, j]), axis=1)].mean(axis=0)
                                        for j in range(len(self.references))])
        self._jaw = self.sensor_names.index("JAW") if "JAW" in self.sensor_names else None
        from tonguevis.preprocess._names import is_reference

        self._rides_jaw = np.array([n != "JAW" and not is_reference(n) for n in self.sensor_names])
        corrected_rest = self._head_correct_many(positions)
        if self._jaw is not None:
            jaw = corrected_rest[:, self._jaw]
            self._jaw_rest = jaw[np.all(np.isfinite(jaw), axis=1)].mean(axis=0)
            corrected_rest = corrected_rest.copy()
            corrected_rest[:, self._rides_jaw] -= (jaw - self._jaw_rest)[:, None]
        self._drive_index = np.array([self.sensor_names.index(n) for n in prep.names])
        # Displacement = scale (p - source) Rᵀ (prepare_targets): source, each driving sensor's mean corrected
        # position over the rest (the rest pose the fit was made from); the transform into the model's frame.
        rest_drive = corrected_rest[:, self._drive_index]
        self._source = np.array([rest_drive[:, j][np.all(np.isfinite(rest_drive[:, j]), axis=1)].mean(axis=0)
                                 for j in range(len(self._drive_index))])
        t = prep.transform
        self._linear = t.scale * t.rotation
        # The model and its constraints (simulate()'s).
        basis = model.basis(s.modes)
        w_full = model.rotation_matrix(basis)
        dofs = (3 * prep.nodes[:, None] + np.arange(3)).ravel()
        n_s = len(prep.nodes)
        self.eigenvalues = basis.eigenvalues
        self.phi_s = basis.phi[dofs].reshape(n_s, 3, -1)
        self.w_s = w_full[dofs].reshape(n_s, 3, -1)
        stiffness = s.sensor_stiffness_value
        self.k_ref = point_stiffness(basis.eigenvalues, self.phi_s)
        self._base = 0.0 if stiffness is None else 1.0 / (stiffness * self.k_ref)
        from tonguevis.sim.dropouts import RAMP_STIFFNESS

        self._ramp_k = RAMP_STIFFNESS * self.k_ref
        self._engagement = _Engagement(n_s, self.rate)
        newmark = NewmarkSettings(dt=1.0 / self.rate, alpha=model.material.alpha, beta=model.material.beta,
                                  tolerance=self.tolerance, warping=s.warping)
        self.integrator = CompiledIntegrator(basis.eigenvalues, self.phi_s, self.w_s, newmark, n_sensors=n_s,
                                             rates=False)
        # Sensors on the surface (the replay's default): each frame's patch coordinates close the gaps the
        # modes leave, frame by frame as simulate() does after the dynamics (tonguevis.sim.patches).
        self._patches = None
        if s.sensor_patches is not None:
            from tonguevis.sim.patches import PATCH_RADIUS, PATCH_REACH, augmented_basis, humped_sensors

            radius = s.sensor_patches
            if radius == "default":
                radius = PATCH_RADIUS * (1.0 / fit["scale"] if s.frame == "speaker" else 1.0)
            basis = augmented_basis(model, basis, prep.nodes, radius, radius * PATCH_REACH / PATCH_RADIUS,
                                    "scaled" if s.humps else None, humped_sensors(prep.names))
            w_full = np.array(model.curl_operator @ basis.phi)
            w_full[:, self.eigenvalues.size:] = 0.0  # the patch shapes ride on the modes' rotation, unwarped
            self._patches = (basis, w_full)
        # Surface reconstruction: the boundary's nodes only, Φᵀ and Wᵀ of their columns, in the drawing dtype.
        faces = np.asarray(model.surface_faces, dtype=np.int64)
        self.surface_nodes = np.unique(faces)
        local = np.full(model.mesh.n_nodes, -1, dtype=np.int64)
        local[self.surface_nodes] = np.arange(len(self.surface_nodes))
        self.surface_faces = local[faces]
        cols = (3 * self.surface_nodes[:, None] + np.arange(3)).ravel()
        self._phi_t = np.ascontiguousarray(basis.phi[cols].T, dtype=self.dtype)
        self._w_t = np.ascontiguousarray(w_full[cols].T, dtype=self.dtype) if s.warping else None
        self.rest_surface = np.asarray(model.mesh.points[self.surface_nodes], dtype=self.dtype)
        k = len(self.surface_nodes)
        self._lin = np.empty(3 * k, dtype=self.dtype)
        self._w = np.empty(3 * k, dtype=self.dtype)
        self._surface = np.empty((k, 3), dtype=self.dtype)
        self.sensor_rest_nodes = model.mesh.points[prep.nodes]
        self.driving_names = list(prep.names)
        self.last_corrected = self._head_correct_many(positions[-1:])[0]  # until the first step
        self.palate = self._placed_palate(snippet)
        self.ready = True
        self.frames_done = 0

    def _placed_palate(self, snippet):
        """The settings' palate placed on this rest as the replay places it (:func:`tonguevis.sim.palate_placement.
        place_palate`: a speaker's palate carried by the rest alignment and made whole from the rest's sensors; the
        generic one with the placed tongue), in the frame the surfaces are given in; None without a palate.  The
        velum stays at rest (the replay lifts it from the whole session's dorsum; live has only the past)."""
        if self.settings.palate is None:
            return None
        from tonguevis.sim.palate_placement import _speech_references, place_palate

        try:
            placed, _, _ = place_palate(self.settings.palate, self.prep, quiet=True, model=self.model,
                                        speech_references=_speech_references(snippet, self.prep, self.settings.palate))
        except TonguevisError as exc:
            raise LiveSimulationError(f"cannot place the palate on this rest: {exc}") from exc
        return placed

    # ------------------------------------------------------------------ per frame
    def _head_correct_many(self, positions: np.ndarray) -> np.ndarray:
        """(N, S_all, 3) m head-corrected (every slot moved by its frame's rigid fit of the references)."""
        if not self.references:
            return positions
        from tonguevis.preprocess._rigid import fit_rotations

        current = positions[:, self._ref_index]
        ok = np.all(np.isfinite(current), axis=(1, 2))
        out = np.full(positions.shape, np.nan)
        if np.any(ok):
            r, _, src_c, tgt_c, _ = fit_rotations(current[ok], np.broadcast_to(self._head_pose, current[ok].shape))
            shift = tgt_c - np.einsum("nij,nj->ni", r, src_c)
            out[ok] = np.einsum("nij,nsj->nsi", r, positions[ok]) + shift[:, None]
        return out

    def step(self, positions_mm: np.ndarray, reconstruct: bool = True) -> LiveStep:
        """Simulate the next frame from its raw positions (S_all, 3) mm (NaN = missing); see :class:`LiveStep`.

        reconstruct : False skips the surface (``surface`` None): a frame simulated (the dynamics need
        every frame at its step) but not drawn, because a newer one came with it."""
        if not self.ready:
            raise LiveSimulationError("no rest yet: take the rest (a still moment) before simulating")
        from tonguevis.sim.constrained import compliant_targets
        from tonguevis.sim.dropouts import spring_compliance

        clock = time.perf_counter
        t0 = clock()
        raw = np.asarray(positions_mm, dtype=np.float64).reshape(len(self.sensor_names), 3) / 1000.0
        corrected = self._head_correct_many(raw[None])[0]
        fixed = corrected
        jaw_offset = np.zeros(3)
        if self._jaw is not None:
            moved = corrected[self._jaw] - self._jaw_rest
            fixed = corrected.copy()
            fixed[self._rides_jaw] -= moved
            jaw_offset = self._linear @ moved if np.all(np.isfinite(moved)) else jaw_offset
        positions = fixed[self._drive_index]
        displacement = (positions - self._source) @ self._linear.T
        t1 = clock()
        weight, anchored = self._engagement(displacement)
        springs = spring_compliance(weight[None], self._base, self._ramp_k)
        projected = compliant_targets(self.eigenvalues, self.phi_s, anchored[None], springs)[0]
        acting = weight > 0
        targets = np.where(acting[:, None], projected, np.nan)
        compliance = np.where(acting, 0.0, np.inf)
        t2 = clock()
        result = self.integrator.advance(targets[None, None], compliance[None, None])[0]
        q = result.q[0]
        t3 = clock()
        shape = q
        if self._patches is not None:
            from tonguevis.sim.patches import close_sensor_gaps

            basis, w_full = self._patches
            # a lost sensor's patch eases out with its spring, from its last measurement (as in the replay)
            shape = np.concatenate([q, close_sensor_gaps(basis, w_full, self.prep.nodes, q[None], anchored[None],
                                                         self.settings.warping, weight=weight[None])[0]])
        surface = self.reconstruct(shape) if reconstruct else None
        t4 = clock()
        self.frames_done += 1
        self.last_corrected = corrected
        return LiveStep(surface, self.sensor_rest_nodes + displacement, corrected, q, jaw_offset,
                        {"correct": t1 - t0, "drive": t2 - t1, "integrate": t3 - t2, "reconstruct": t4 - t3},
                        bool(result.recovered[0]))

    def reconstruct(self, q: np.ndarray) -> np.ndarray:
        """(k, 3) surface node positions (m, ``dtype``) for modal coordinates q (m,; with sensor patches the
        modes' then the patches' coordinates): rest + R̃(Wq) Φq,
        written into a buffer kept between frames (the next call overwrites it)."""
        qd = np.asarray(q, dtype=self.dtype)
        np.matmul(qd, self._phi_t, out=self._lin)
        lin = self._lin.reshape(-1, 3)
        if self._w_t is not None:
            np.matmul(qd, self._w_t, out=self._w)
            w = self._w.reshape(-1, 3)
            # R̃(w) d = d + a (w × d) + b w × (w × d)  (tonguevis.sim.rotation.rotate_accumulated)
            from tonguevis.sim.rotation import rotation_coefficients

            a, b, _, _ = rotation_coefficients(np.sqrt(np.einsum("ij,ij->i", w, w)))
            wd = np.cross(w, lin)
            wwd = np.cross(w, wd)
            np.add(lin, a[:, None].astype(self.dtype) * wd, out=self._surface)
            self._surface += b[:, None].astype(self.dtype) * wwd
            self._surface += self.rest_surface
        else:
            np.add(lin, self.rest_surface, out=self._surface)
        return self._surface

    def sensor_points_in_view(self, step: LiveStep) -> np.ndarray:
        """(S, 3) m, the driving sensors where the view draws them: with the tongue, carried by the jaw."""
        return step.sensor_points + step.jaw_offset

    def tip_position(self, step: LiveStep) -> np.ndarray | None:
        """(3,) m, the tongue tip sensor's (TT, else the first driving sensor's) corrected position in the
        stream's frame (where targets live), None when missing."""
        name = "TT" if "TT" in self.sensor_names else (self.driving_names[0] if self.ready else None)
        if name is None:
            return None
        p = step.corrected[self.sensor_names.index(name)]
        return p.copy() if np.all(np.isfinite(p)) else None


def _tongue_names() -> tuple[str, ...]:
    from tonguevis.preprocess.targets import TONGUE_SENSORS

    return tuple(TONGUE_SENSORS)
