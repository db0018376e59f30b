"""Opening a second recording to compare with the first, as a mixin of MainWindow.

The second recording goes into the app model's ``"compare"`` slot and is simulated by
its own job (the first one's simulation is not cancelled by it); the
:class:`~tonguevis.gui.compare.ComparePanel` follows the model and shows it.
"""

from __future__ import annotations

from PySide6.QtWidgets import QFileDialog

from tonguevis.errors import TonguevisError
from tonguevis.appstate import connected



class CompareMixin:
    """File ▸ Compare with another recording… / Stop comparing."""

    compare_job = None

    def ask_compare(self) -> None:
        path, _ = QFileDialog.getOpenFileName(self, "Compare with another EMA recording", str(self._last_folder()))
        if path:
            self.open_compare(path)

    def open_compare(self, path, sensor_map=None, warping: bool | None = None, modes: int | None = None,
                     layout: str | None = None, time_mode: str | None = None) -> bool:
        """Open ``path`` as the recording B compared with the one open (A), and simulate it.

        ``warping``/``modes``: B's model settings (default: the window's), so one recording
        can be compared with itself under another model (``warping=False``: linear).
        ``layout`` ("side" or "ghost") and ``time_mode`` ("production" or "absolute") set the panel.
        """
        from tonguevis.workflows.session import load_session, needs_sensor_map

        try:
            session = load_session(path, sensor_map=sensor_map)
        except (TonguevisError, OSError) as exc:
            self.show_error("Cannot open the recording to compare", str(exc), path)
            return False
        if needs_sensor_map(session.recording):
            self.show_error("Cannot compare", "no channel of this recording is a known tongue sensor: open it on "
                            "its own first to map its channels, or give a sensor map (tonguevis view A --compare B "
                            "--compare-sensors MAP)", path)
            return False
        self.compare_session(session, warping, modes, layout, time_mode)
        return True

    def compare_session(self, session, warping: bool | None = None, modes: int | None = None,
                        layout: str | None = None, time_mode: str | None = None) -> None:
        """Show the opened ``session`` as B (see :meth:`open_compare`) and simulate it."""
        if layout is not None:
            self.compare_panel.set_layout(layout)
        if time_mode is not None:
            self.compare_panel.set_time_mode(time_mode)
        settings = {"warping": self.warping if warping is None else bool(warping),
                    "modes": self.modes if modes is None else int(modes)}
        self.state.set_session(session, "compare", self)
        self._simulate_compare(session, settings)

    def stop_comparing(self) -> None:
        self.state.set_session(None, "compare", self)

    def _compare_closed(self, event) -> None:
        """B closed (the menu, the panel's button, a script): its simulation is not wanted any more."""
        if event.key == "compare" and event.value is None and self.compare_job is not None:
            self.compare_job.stop()
            self.compare_job = None

    def _simulate_compare(self, session, settings: dict) -> None:
        from tonguevis.workflows.simulation import simulate_motion
        from tonguevis.gui.worker import run_job

        if self.compare_job is not None:
            self.compare_job.stop()
        model = self.state.tongue_model
        recording = session.recording
        run = self.state.run_settings.replace(modes=settings["modes"], warping=settings["warping"],
                                              rest=session.given_rest)

        primary = self.state.session_of("primary")
        onto = getattr(getattr(primary, "motion", None), "model", None)  # B drawn on A's placed tongue

        def work(progress):
            return simulate_motion(recording, run, model, progress=progress, onto=onto)

        def done(result) -> None:
            if self.state.session_of("compare") is not session:
                return  # another recording to compare was opened meanwhile
            result.apply(session)
            self.state.set_motion(session, self)
            motion = session.motion
            self.state.set_status(f"compared recording {session.name}: {motion.n_frames} frames simulated"
                                  + ("" if settings["warping"] else " (linear)"), self)
            self.compare_finished.emit(True)

        self.compare_job = run_job(self, "Simulation of the compared recording", work, done,
                                   label=f"Simulating {session.name} (B)…", path=session.path,
                                   on_failed=lambda _message: self.compare_finished.emit(False),
                                   on_cancelled=lambda: self.compare_finished.emit(False),
                                   status=lambda text: self.state.set_status(text, self))

    def _build_compare_panel(self, splitter) -> None:
        """B's panel, hidden until a second recording is open, between A's views and the tabs."""
        from tonguevis.gui.compare import ComparePanel

        self.compare_panel = ComparePanel(self.state, self.view3d, self)
        splitter.insertWidget(1, self.compare_panel)
        splitter.setSizes([900, 450, 600])
        connected(self.state.events.session, self._compare_closed)
