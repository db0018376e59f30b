"""The Midsagittal tab: the replay's midsagittal view (the widget the live window uses) beside the palatogram,
both at the time cursor.  The view draws :class:`tonguevis.render.midsagittal.MidsagittalSection`'s picture
(the tongue's section, the palate traced and estimated, the sensors and their trails, the constriction of each
tongue sensor printed); the palatogram is :func:`tonguevis.analysis.epg.palatogram` of that frame against the
palate the motion was simulated with."""

from __future__ import annotations

import numpy as np
from PySide6.QtWidgets import QHBoxLayout, QWidget

from tonguevis.appstate import AppState, connected
from tonguevis.gui.midsagittal_view import MidsagittalView
from tonguevis.gui.palatogram_view import PalatogramView

from tonguevis._logging import logger


class SectionPanel(QWidget):
    """See the module doc.  ``shown_frame``: the frame drawn (-1: none); ``picture``: its
    :class:`~tonguevis.render.midsagittal.MidsagittalPicture`."""

    def __init__(self, state: AppState, parent=None):
        super().__init__(parent)
        self.state = state
        self.session = None
        self.section = None
        self.layout_epg = None
        self.picture = None
        self.shown_frame = -1
        self.view = MidsagittalView(self, title="midsagittal (anterior →): palate traced —, estimated - -")
        self.palatogram = PalatogramView(self)
        row = QHBoxLayout(self)
        row.setContentsMargins(2, 2, 2, 2)
        row.addWidget(self.view, 3)
        row.addWidget(self.palatogram, 1)
        connected(state.events.time, lambda event: self.show_time(event.value))

    def set_session(self, session) -> None:
        from tonguevis.render.midsagittal import MidsagittalSection

        self.session = session
        self.shown_frame = -1
        self.section = self.layout_epg = self.picture = None
        frames = getattr(session, "frames", None)
        if frames is None:
            self.view.bounds = None
            self.view.lines = ["simulating…" if session is not None else "Open a recording"]
            self.view.segments = self.view.palate = self.view.palate_estimated = np.zeros((0, 2, 2))
            self.view.sensors, self.view.sensor_names, self.view.trails = np.zeros((0, 2)), [], []
            self.view.update()
            self.palatogram.show_contacts(None, "")
            return
        self.section = MidsagittalSection(session)
        motion = frames.motion
        if motion.palate is not None:
            from tonguevis.analysis.epg import epg_layout

            try:
                self.layout_epg = epg_layout(motion.palate)
            except Exception as exc:  # a palate too small for the layout: the rest of the tab still works
                logger.info("no palatogram: %s", exc)
        self.view.set_bounds(self.section.region(), margin=0.08)
        self.show_time(self.state.time, force=True)

    def show_time(self, t: float, force: bool = False) -> None:
        frames = getattr(self.session, "frames", None)
        if frames is None or self.section is None or not (force or self.isVisible()):
            return
        i = frames.frame_at(t)
        if i == self.shown_frame and not force:
            return
        self.shown_frame = i
        picture = self.picture = self.section.at(i)
        view = self.view
        view.segments, view.palate, view.palate_estimated = picture.tongue, picture.traced, picture.estimated
        names = list(picture.sensors)
        view.sensor_names = names
        view.sensors = np.array([picture.sensors[n] for n in names]).reshape(-1, 2)
        view.trails = [picture.trails[n] for n in names]
        view.lines = [f"t = {picture.time_s:.3f} s (frame {i})"] + picture.lines()
        view.update()
        self._show_palatogram(i)

    def _show_palatogram(self, i: int) -> None:
        motion = self.session.frames.motion
        if motion.palate is None:
            self.palatogram.show_contacts(None, "simulated without a palate")
            return
        if self.layout_epg is None:
            self.palatogram.show_contacts(None, "no electrode layout on this palate")
            return
        from tonguevis.analysis.epg import palatogram

        gram = palatogram(motion, [i], layout=self.layout_epg)
        self.palatogram.show_contacts(gram.contacts[0], f"t = {gram.times[0]:.3f} s")

    def showEvent(self, event) -> None:  # noqa: N802 (Qt name)
        super().showEvent(event)
        self.show_time(self.state.time, force=True)
