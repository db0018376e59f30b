"""The app's simulations follow its model: :class:`SimulationController`.

A recording opened (``state.set_session``), a run setting changed (``state.change_run_settings``: a menu, a
script, the mesh opened), a rest given (:meth:`SimulationController.resimulate`): the controller simulates the
recordings concerned in the job runner (:func:`tonguevis.gui.worker.run_job`) with the app model's
:class:`~tonguevis.sim.settings.RunSettings`, and sets each motion on its session back on the GUI thread
(``state.set_motion``).  No menu, panel or dialog calls a simulation itself: they write the model.
"""

from __future__ import annotations

from PySide6.QtCore import QObject

from tonguevis.appstate import connected

#: The sessions the controller keeps simulated: the recording the views show and the one compared with it.
ROLES = ("primary", "compare")


class SimulationController(QObject):
    """Keeps the primary and compared sessions of ``window.state`` simulated as its run settings say.

    ``window`` gives the job runner its parent, its dialogs and the signals scripts wait for
    (``simulation_finished``, ``compare_finished``); ``jobs[role]`` is the latest job of each role (running or
    done; None once stopped).
    A run setting tried for one simulation only (:meth:`try_settings`, e.g. a palate loaded: it becomes the
    app's once it simulated) is written to the model by the controller itself, which then does not simulate
    again.
    """

    def __init__(self, window) -> None:
        super().__init__(window)
        self.window = window
        self.state = window.state
        self.jobs: dict = {role: None for role in ROLES}
        #: B's own settings changes (``tonguevis view --compare-linear``: B without warping), over the app's
        self.compare_changes: dict = {}
        connected(self.state.events.run_settings, self._settings_changed)
        connected(self.state.events.session, self._session_changed)

    # -- what the model says ------------------------------------------------------------
    def _settings_changed(self, event) -> None:
        if event.source is self:
            return  # written after its own simulation succeeded: already shown
        for role in ROLES:
            session = self.state.session_of(role)
            if session is not None:
                self.simulate(role)

    def _session_changed(self, event) -> None:
        if event.key not in ROLES:
            return
        if event.value is None:
            self.stop(event.key)
        elif event.value.motion is None:
            self.simulate(event.key)

    # -- simulating -------------------------------------------------------------------------
    def resimulate(self, role: str = "primary") -> None:
        """Simulate the session of ``role`` again (its rest given anew, say)."""
        if self.state.session_of(role) is not None:
            self.simulate(role)

    def try_settings(self, **changes) -> None:
        """Simulate the primary session with the app's settings and ``changes``; the changes become the app's
        when it succeeds (a palate that does not fit this recording is said, and the app keeps its own)."""
        self.simulate("primary", changes)

    def stop(self, role: str) -> None:
        job, self.jobs[role] = self.jobs.get(role), None
        if job is not None:
            job.stop()

    def settings_for(self, role: str, session, changes: dict | None = None):
        """The :class:`RunSettings` ``role``'s ``session`` is simulated with: the app's, ``changes``, its rest."""
        settings = self.state.run_settings
        if role == "compare" and self.compare_changes:
            settings = settings.replace(**self.compare_changes)
        return settings.replace(**(changes or {}), rest=session.given_rest)

    def simulate(self, role: str = "primary", changes: dict | None = None) -> None:
        """Simulate the session of ``role`` in a job (the previous job of that role is stopped first)."""
        from tonguevis.gui.worker import JobReactions, run_job
        from tonguevis.workflows.simulation import simulate_motion

        session = self.state.session_of(role)
        if session is None:
            return
        self.stop(role)
        window = self.window
        settings = self.settings_for(role, session, changes)
        model = self.state.tongue_model  # read here, on the GUI thread
        recording = session.recording
        primary = self.state.session_of("primary")
        onto = getattr(getattr(primary, "motion", None), "model", None) if role == "compare" else None
        palate = settings.palate

        def work(progress, partial):
            return simulate_motion(recording, settings, model, progress=progress, onto=onto,
                                   preview=partial if role == "primary" else None)

        def explain(message: str) -> str:
            if palate is None:
                return message
            kept = "" if session.motion is None else " The views keep the previous simulation."
            return message + (f"\n\n(simulated against the {palate_name(palate)}: File ▸ No palate simulates "
                              f"without contact.{kept})")

        finished = window.simulation_finished if role == "primary" else window.compare_finished
        against = "" if palate is None else f" against the {palate_name(palate)}"
        which = "" if role == "primary" else " (B)"
        self.state.set_status(f"simulating {session.name}{which} with {settings.modes} modes{against}…", self)
        self.jobs[role] = run_job(window, "Simulation" if role == "primary" else "Simulation of the compared recording",
                                  work, lambda result: self._simulated(role, session, result, settings, changes),
                                  JobReactions(on_failed=lambda _message: finished.emit(False),
                                               on_cancelled=lambda: finished.emit(False),
                                               on_partial=lambda result: self._preview(session, result),
                                               status=lambda text: self.state.set_status(text, self),
                                               explain=explain, path=session.path),
                                  label=f"Simulating {session.name}{which}…")

    def _preview(self, session, result) -> None:
        """A long recording's first seconds, simulated (on the GUI thread): shown while the rest simulates
        in the background (the job's dialog closes; its progress goes on in the status bar)."""
        if self.state.role_of(session) != "primary":
            return  # a newer recording was opened meanwhile
        result.apply(session)
        self.state.set_motion(session, self)
        shown = result.motion.metadata["preview"]
        self.state.set_status(
            f"{session.name}: showing the first {result.motion.times[-1] - result.motion.times[0]:.0f} s "
            f"({shown['frames']} of {shown['of']} frames) while the rest simulates; opening another recording "
            f"stops it", self)

    def _simulated(self, role: str, session, result, settings, changes) -> None:
        """The job's result, on the GUI thread: the model kept, the motion set on the session and announced."""
        state = self.state
        if state.tongue_model is None and state.mesh_path == settings.mesh:
            state.set_tongue_model(result.model, settings.mesh, self)  # built by the job: kept for the next
        if state.session_of(role) is not session:
            return  # a newer recording was opened meanwhile
        if changes:  # tried for this simulation: the app's from now on (no second simulation: source is self)
            state.change_run_settings(self, **changes)
        result.apply(session)
        state.set_motion(session, self)
        motion = session.motion
        if role == "primary":
            state.set_status(
                f"{session.name}: {motion.n_frames} frames simulated, "
                f"{int((~motion.converged).sum())} not converged; press Space to play"
                + "".join(f"; {note}" for note in session.notes), self)
            self.window.simulation_finished.emit(True)
        else:
            linear = not settings.warping
            state.set_status(f"compared recording {session.name}: {motion.n_frames} frames simulated"
                             + (" (linear)" if linear else ""), self)
            self.window.compare_finished.emit(True)

    def shutdown(self) -> None:
        for role in ROLES:
            self.stop(role)


def palate_name(palate) -> str:
    """How the status line and dialogs name a palate setting."""
    from tonguevis.render.drawing import palate_label

    return "none (no contact)" if palate is None else palate_label(palate)
