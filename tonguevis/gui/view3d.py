"""The 3D views (main + top/front/lateral) as a Qt widget, linked to the AppState."""

from __future__ import annotations

import logging

import numpy as np
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QPushButton, QVBoxLayout, QWidget

from tonguevis.appstate import COLOR_MODES, AppState, interval_at
from tonguevis.gui.frames import SCALARS
from tonguevis.gui.scene import TongueScene

log = logging.getLogger("tonguevis")
COLOUR_LABELS = {"displacement": "displacement magnitude", "energy": "elastic energy density",
                 "plain": "plain"}


def context_surfaces() -> dict:
    """Jaw and palate surfaces shipped in meshes/ (empty if absent or unreadable)."""
    import pyvista as pv

    from tonguevis.paths import MESH_DIR

    out = {}
    try:
        from tonguevis.mesh import read_surface
    except ImportError:
        return out
    for name in ("jaw", "palate"):
        for path in sorted(MESH_DIR.glob(f"{name}.*")):
            try:
                points, faces = _as_points_faces(read_surface(path))
            except Exception as exc:  # context is optional: never block the app on it
                log.warning("context surface %s not shown: %s", path, exc)
                continue
            from tonguevis.gui.scene import faces_to_vtk

            out[name] = pv.PolyData(np.asarray(points, dtype=np.float32), faces_to_vtk(faces))
            break
    return out


def _as_points_faces(surface):
    if isinstance(surface, tuple):
        return surface[0], surface[1]
    for names in (("points", "faces"), ("vertices", "faces"), ("points", "triangles")):
        if all(hasattr(surface, n) for n in names):
            return getattr(surface, names[0]), getattr(surface, names[1])
    raise TypeError(f"unknown surface type {type(surface).__name__}")


def surface_faces(model) -> np.ndarray:
    faces = getattr(model, "surface_faces", None)
    if callable(faces):
        faces = faces()
    return np.asarray(faces if faces is not None else model.mesh.boundary_faces())


def scene_titles() -> dict[str, str]:
    return {name: f"{label}\n({unit})" for name, (label, unit) in SCALARS.items()}


def frame_text(frames, i: int, productions) -> str:
    t = frames.times[i]
    text = f"t = {t:.3f} s   frame {i + 1}/{frames.n_frames}"
    production = interval_at(productions, t)
    if production is not None:
        text += f"   production {productions.index(production) + 1}"
    residual = getattr(frames.motion, "sensor_residual", None)
    if residual is not None and len(residual):
        text += f"\nsensor residual max {1e3 * float(np.nanmax(residual[i])):.2f} mm"
    return text


class View3D(QWidget):
    def __init__(self, state: AppState, parent=None):
        super().__init__(parent)
        from pyvistaqt import QtInteractor

        self.state = state
        self.session = None
        self.frame = -1
        self.renders = 0
        # No multisampling: under software OpenGL (Xvfb, VMs) 8x MSAA costs most of each frame.
        self.plotter = QtInteractor(self, shape="1|3", splitting_position=0.72, auto_update=False, multi_samples=0)
        self.scene = TongueScene(self.plotter)
        self.colour = QComboBox()
        for mode in COLOR_MODES:
            self.colour.addItem(COLOUR_LABELS[mode], mode)
        self.reset = QPushButton("Reset camera")
        self.message = QLabel("")
        bar = QHBoxLayout()
        bar.addWidget(QLabel("Colour by"))
        bar.addWidget(self.colour)
        bar.addWidget(self.reset)
        bar.addWidget(self.message, 1)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addLayout(bar)
        layout.addWidget(self.plotter.interactor, 1)
        self.colour.currentIndexChanged.connect(lambda _i: state.set_color(self.colour.currentData(), self))
        self.reset.clicked.connect(self.reset_camera)
        self.cursor_time = state.time
        state.subscribe("time", self._on_time)
        state.subscribe("color", self._on_colour)

    def set_session(self, session) -> None:
        self.session = session
        self.frame = -1
        frames = getattr(session, "frames", None)
        if frames is None:
            self.message.setText("simulating…" if session is not None else "")
            return
        model = frames.motion.model
        self.scene.build(frames.points[0], surface_faces(model), len(frames.motion.sensor_names),
                         context_surfaces(), clim=frames.clim, titles=scene_titles())
        self.scene.set_mode(self.state.color)
        self.message.setText(f"{model.mesh.n_nodes} nodes, {frames.motion.q.shape[1]} modes, "
                             f"sensors {', '.join(frames.motion.sensor_names)}")
        self.show_time(self.state.time)

    def _on_time(self, event) -> None:
        self.show_time(event.value)

    def show_time(self, t: float) -> None:
        self.cursor_time = t
        frames = getattr(self.session, "frames", None)
        if frames is None:
            return
        i = frames.frame_at(t)
        if i == self.frame:
            return
        self.frame = i
        mode = self.state.color
        scalars = frames.scalars[mode][i] if mode in frames.scalars else None
        self.scene.update(frames.points[i], scalars, frames.sensor_points[i], frames.targets[i],
                          frame_text(frames, i, self.session.productions), render=False)
        # One render per frame: the widget's paint renders the scene (pyvistaqt's paintGL
        # always renders), so asking for a repaint instead of render() avoids a second one.
        self.plotter.interactor.update()
        self.renders += 1

    def _on_colour(self, event) -> None:
        index = self.colour.findData(event.value)
        if index != self.colour.currentIndex():
            self.colour.setCurrentIndex(index)
        self.scene.set_mode(event.value)
        self.frame = -1
        self.show_time(self.state.time)

    def set_context_visible(self, visible: bool) -> None:
        self.scene.set_context_visible(visible)
        self.plotter.interactor.update()

    def reset_camera(self) -> None:
        self.scene.reset_cameras()
        self.plotter.render()

    def close_view(self) -> None:
        self.plotter.close()
