"""Opening a second recording to compare with the first, as a mixin of MainWindow.

The second recording goes into the app model's ``"compare"`` slot; the controller
(:class:`~tonguevis.gui.controller.SimulationController`) simulates it in its own job (the first
one's simulation is not cancelled by it), with the app's run settings; the
:class:`~tonguevis.gui.compare.ComparePanel` follows the model and shows it.
"""

from __future__ import annotations

from PySide6.QtWidgets import QFileDialog

from tonguevis.errors import TonguevisError



class CompareMixin:
    """File ▸ Compare with another recording… / Stop comparing."""

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
        """Show the opened ``session`` as B (see :meth:`open_compare`); the controller simulates it."""
        if layout is not None:
            self.compare_panel.set_layout(layout)
        if time_mode is not None:
            self.compare_panel.set_time_mode(time_mode)
        changes = {}
        if warping is not None:
            changes["warping"] = bool(warping)
        if modes is not None:
            changes["modes"] = int(modes)
        self.controller.compare_changes = changes
        self.state.set_session(session, "compare", self)

    def stop_comparing(self) -> None:
        self.state.set_session(None, "compare", self)

    def _build_compare_panel(self, splitter) -> None:
        """B's panel, hidden until a second recording is open, between A's views and the tabs."""
        from tonguevis.gui.compare import ComparePanel

        self.compare_panel = ComparePanel(self.state, self.view3d, self)
        splitter.insertWidget(1, self.compare_panel)
        splitter.setSizes([900, 450, 600])
