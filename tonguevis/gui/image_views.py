"""A pyvista plotter drawn as a picture in an ordinary widget: VTK renders off screen.

pyvistaqt's ``QtInteractor`` is a ``QOpenGLWidget``: VTK renders into frame
buffers that Qt then composites with the rest of the window through OpenGL,
and a ``QOpenGLWidget`` turns on OpenGL composition for the *whole* top-level
window.  Without a GPU (Mesa's llvmpipe: Xvfb, VMs, laptops without a
working driver) that composition is drawn pixel by pixel on the CPU every
time any widget repaints: measured on the app at 1624 × 950, repainting the
status bar alone cost 36 ms, and every frame of playback paid ~50 ms of
composition on top of VTK's render.  A native child window that VTK draws
into avoids the composition but still pays VTK's copy of its frame to the
window and the buffer swap (13 of a four-view frame's 22 ms of fixed cost
under llvmpipe).

:class:`ImageInteractor` renders off screen (VTK's own frame buffers, no
window, no swap), reads the frame back (one copy, ~1 ms) and paints it as an
image.  A new frame is rendered when it is asked for (:meth:`~ImageInteractor.request_render`)
and read back at the paint: in between, Mesa rasterises it on its threads while
the GUI thread moves the plots' cursors and labels.  During playback the views
are *pipelined* (:attr:`~ImageInteractor.pipelined`): each frame is read back at
the next frame's request, a whole frame later, so no paint waits for Mesa (the
caller renders each frame for the time it will be shown).  Qt draws the window in
software as if there were no OpenGL at all, ``QWidget.grab`` sees the 3D views,
and the pixels are VTK's, unchanged.
Mouse and keys go to VTK's interactor as in VTK's ``QVTKRenderWindowInteractor``
(whose event handlers it reuses), so the views rotate, pan and zoom as before.

It offers what the app uses of ``QtInteractor``: the pyvista ``BasePlotter``
API (subplots, ``add_mesh``, ``render``, ``screenshot``, ...), ``interactor``
(the widget), ``update()`` to draw the scene again at the next paint, and
``close``.
"""

from __future__ import annotations

import atexit
import contextlib
import weakref

import numpy as np
from PySide6.QtCore import QPoint, Qt, QTimer
from PySide6.QtGui import QImage, QPainter
from PySide6.QtWidgets import QSizePolicy, QWidget
from pyvista.plotting import BasePlotter
from pyvista.plotting.render_window_interactor import RenderWindowInteractor
from vtkmodules.qt.QVTKRenderWindowInteractor import QVTKRenderWindowInteractor
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkCommonCore import vtkUnsignedCharArray
from vtkmodules.vtkRenderingCore import vtkRenderWindow
from vtkmodules.vtkRenderingUI import vtkGenericRenderWindowInteractor


@contextlib.contextmanager
def _no_base_plotter_init():
    """PySide continues the cooperative ``__init__`` chain past QWidget into BasePlotter
    (with no arguments): make that call a no-op while the widget is built."""
    original = BasePlotter.__init__
    BasePlotter.__init__ = lambda self, *a, **k: None
    try:
        yield
    finally:
        BasePlotter.__init__ = original


#: Every ImageInteractor not closed yet: closed at exit while Qt and the X connections are still
#: alive (one left to the garbage collector at interpreter exit, e.g. in a tab whose window was
#: closed without closing its children, tore VTK's X connection down out of order, and Xlib's
#: fatal I/O error then ended the process with status 1).
_OPEN: weakref.WeakSet = weakref.WeakSet()


@atexit.register
def _close_all() -> None:
    for plotter in list(_OPEN):
        with contextlib.suppress(Exception):
            plotter.close()


def _offscreen_render_window():
    """VTK's EGL render window where it exists (no X connection of its own: nothing for the
    window system to tear down out of order), else the platform's own, off screen."""
    try:
        from vtkmodules.vtkRenderingOpenGL2 import vtkEGLRenderWindow

        window = vtkEGLRenderWindow()
    except ImportError:
        window = vtkRenderWindow()
    else:
        if not window.IsA("vtkEGLRenderWindow"):
            window = vtkRenderWindow()
    window.SetOffScreenRendering(1)
    # Nothing to swap off screen, and Mesa's eglSwapBuffers on the pbuffer waits until the frame
    # is rasterised: without it, Render() returns once the frame is submitted, llvmpipe's threads
    # rasterise it while the GUI thread goes on with the rest of the frame (the plots' cursors,
    # the labels), and the read-back at the paint waits only for what is left.
    window.SetSwapBuffers(0)
    return window


class _NoEvents:
    """Stands in for the VTK interactor after close (Qt may still send leave or key events)."""

    def __getattr__(self, _name):
        return lambda *a, **k: None


class ImageInteractor(QVTKRenderWindowInteractor, BasePlotter):
    """pyvista plotter rendering off screen and painted as an image in this widget.

    Keyword arguments go to ``BasePlotter`` (``shape``, ``splitting_position``, ...);
    ``multi_samples``: the render window's multisampling (0, none, is what software
    OpenGL can afford).  ``renders`` counts VTK renders, ``paints`` the widget's paints.
    """

    def __init__(self, parent=None, multi_samples: int = 0, **kwargs):
        # Not QVTKRenderWindowInteractor.__init__: it makes a native window for VTK to draw in.
        with _no_base_plotter_init():
            QWidget.__init__(self, parent)
        # The state QVTKRenderWindowInteractor's mouse and key handlers keep (name-mangled).
        self._ActiveButton = Qt.MouseButton.NoButton
        self._QVTKRenderWindowInteractor__saveX = 0
        self._QVTKRenderWindowInteractor__saveY = 0
        self._QVTKRenderWindowInteractor__saveModifiers = Qt.KeyboardModifier.NoModifier
        self._QVTKRenderWindowInteractor__saveButtons = Qt.MouseButton.NoButton
        self._QVTKRenderWindowInteractor__wheelDelta = 0
        self._RenderWindow = _offscreen_render_window()
        self._RenderWindow.SetMultiSamples(int(multi_samples))
        self._Iren = vtkGenericRenderWindowInteractor()
        self._Iren.SetRenderWindow(self._RenderWindow)
        self.setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent)
        self.setMouseTracking(True)
        self.setFocusPolicy(Qt.FocusPolicy.WheelFocus)
        self.setSizePolicy(QSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding))
        self._Timer = QTimer(self)
        self._Timer.timeout.connect(self.TimerEvent)
        self._Iren.AddObserver("CreateTimerEvent", self.CreateTimer)
        self._Iren.AddObserver("DestroyTimerEvent", self.DestroyTimer)
        self._RenderWindow.AddObserver("CursorChangedEvent", self.CursorChangedEvent)

        BasePlotter.__init__(self, **kwargs)
        self.interactor = self
        self.ren_win = self._RenderWindow
        for renderer in self.renderers:
            self.ren_win.AddRenderer(renderer)
        self._off_screen = False
        self.iren = RenderWindowInteractor(self, interactor=self._Iren)
        self.iren.interactor.RemoveObservers("MouseMoveEvent")
        self.iren.initialize()
        self.enable_trackball_style()
        self._first_time = False  # BasePlotter renders only once this is False
        self._pixels = vtkUnsignedCharArray()
        self._image: QImage | None = None
        self._rendered = False  # rendered since the last read-back (e.g. by the interactor): paint shows that
        self._dirty = False  # something asked to draw the scene anew (the interactor's camera, a resize)
        self._painting = False
        #: While True (playback), a frame is read back at the next :meth:`request_render`, a frame
        #: later, and painted then: the paint never waits for Mesa's rasterising.
        self.pipelined = False
        self._tag = None  # what the caller said the last requested frame is
        #: The tag of the frame in the image painted, a callable told of each newly shown tag,
        #: and one called after each paint.
        self.shown_tag = None
        self.on_shown = None
        self.on_painted = None
        self.renders = self.paints = 0
        self._RenderWindow.AddObserver("EndEvent", self._on_rendered)
        self._resize_render_window()
        _OPEN.add(self)

    # -- pyvista -------------------------------------------------------------------------
    def __getattr__(self, name):
        # QVTKRenderWindowInteractor forwards unknown names to VTK's interactor; pyvista's lazy
        # plugin lookups come last.
        iren = self.__dict__.get("_Iren")
        if iren is not None and not isinstance(iren, _NoEvents) and hasattr(iren, name):
            return getattr(iren, name)
        return BasePlotter.__getattr__(self, name)

    def _check_has_ren_win(self) -> None:
        # Other OpenGL contexts (another plotter, a video export) may be current on this thread.
        if self.render_window is not None:
            self.render_window.MakeCurrent()
        BasePlotter._check_has_ren_win(self)

    def render(self) -> None:
        """Render now and show the result at the next paint (no-op once closed).

        Returns once the frame is submitted: releasing the context flushes it (EGL), and
        Mesa's threads rasterise it until the paint reads it back."""
        if getattr(self, "_closed", False):
            return
        BasePlotter.render(self)
        self._RenderWindow.ReleaseCurrent()

    def screenshot(self, *args, **kwargs):
        """pyvista's screenshot, leaving no context of ours current (see :meth:`_on_rendered`).

        pyvista reads VTK's front buffer, which only the (otherwise switched off) buffer swap
        fills: the scene is rendered once more with the swap on."""
        window = self._RenderWindow
        if window is None:
            return BasePlotter.screenshot(self, *args, **kwargs)
        window.SetSwapBuffers(1)
        try:
            window.Render()
            return BasePlotter.screenshot(self, *args, **kwargs)
        finally:
            window.SetSwapBuffers(0)
            window.ReleaseCurrent()

    def request_render(self, tag=None) -> None:
        """The scene changed: render it now, so that it rasterises while the GUI thread goes on,
        and paint it at the next paint; a render done but not painted yet is stale, and the
        paint renders again instead (one render per paint while the scene keeps changing).

        When :attr:`pipelined`, the frame requested before this one (rasterised meanwhile) is
        read back now and painted next, and this one renders for the next request: every
        request renders, and each frame is painted one request after its own.
        ``tag``: what this frame is (e.g. its time); :attr:`shown_tag` once it is painted."""
        if getattr(self, "_closed", False):
            return
        if self.pipelined:
            self.show_rendered()
            self._tag = tag
            self.render()
            return
        self._tag = tag
        if self._rendered:
            self._rendered = False
            QWidget.update(self)
            return
        self.render()

    def show_rendered(self) -> None:
        """Pipelined: read back the frame rendered last (if not yet) and paint it next."""
        if getattr(self, "_closed", False) or not self._rendered:
            return
        self._read_image()
        self._rendered = False
        QWidget.update(self)

    def set_pipelined(self, pipelined: bool) -> None:
        """Pipeline the frames (playback) or paint each as soon as it is asked for; off, the
        next paint shows the last frame requested."""
        self.pipelined = bool(pipelined)
        if not self.pipelined:
            QWidget.update(self)

    def _on_rendered(self, *_args) -> None:
        # Our EGL context is released after each use (render, read-back, screenshot): left
        # current, it would stop a GLX context on this thread (the video export's off-screen
        # plotter) from being made current.
        self.renders += 1
        self._rendered = True
        self._dirty = False
        if not self._painting and not self.pipelined:
            QWidget.update(self)

    # -- Qt --------------------------------------------------------------------------------
    def paintEngine(self):  # noqa: N802 (Qt name): QVTKRenderWindowInteractor returns None (paint on screen)
        return QWidget.paintEngine(self)

    def set_render_scale(self, scale: float) -> None:
        """Render at ``scale`` (0.5-1) times the widget's pixels and draw the picture scaled up: a
        software rasteriser's time goes with the pixels (the live view trades a little sharpness
        for its latency)."""
        self.render_scale = float(min(max(scale, 0.5), 1.0))
        self._resize_render_window()
        self._rendered, self._dirty = False, True
        QWidget.update(self)

    def _resize_render_window(self) -> None:
        ratio = (self.devicePixelRatioF() or 1.0) * getattr(self, "render_scale", 1.0)
        w, h = max(1, int(round(ratio * self.width()))), max(1, int(round(ratio * self.height())))
        self._RenderWindow.SetDPI(int(round(72 * ratio)))
        self._RenderWindow.SetSize(w, h)
        self._Iren.SetSize(w, h)

    def resizeEvent(self, _event) -> None:  # noqa: N802 (Qt name)
        if getattr(self, "_closed", False):
            return
        self._resize_render_window()
        self._Iren.ConfigureEvent()
        self._rendered = False
        self._dirty = True
        QWidget.update(self)

    def _read_image(self) -> None:
        w, h = self._RenderWindow.GetSize()
        self._RenderWindow.MakeCurrent()
        self._RenderWindow.GetRGBACharPixelData(0, 0, w - 1, h - 1, 0, self._pixels, 0)
        self._RenderWindow.ReleaseCurrent()
        rgba = vtk_to_numpy(self._pixels).reshape(h, w, 4)
        self._rows = np.ascontiguousarray(rgba[::-1])  # VTK's first row is the bottom one
        image = QImage(self._rows.data, w, h, 4 * w, QImage.Format.Format_RGBX8888)
        image.setDevicePixelRatio(w / max(self.width(), 1))
        self._image = image
        if self._tag != self.shown_tag:
            self.shown_tag = self._tag
            if self.on_shown is not None:
                self.on_shown(self._tag)

    def _image_fits(self) -> bool:
        if self._image is None or self._RenderWindow is None:
            return False
        return (self._image.width(), self._image.height()) == tuple(self._RenderWindow.GetSize())

    def paintEvent(self, _event) -> None:  # noqa: N802 (Qt name)
        """Render the scene (unless it was rendered since the last paint) and draw the frame;
        pipelined, draw the frame read back at the last request (the newest rasterises on)."""
        if getattr(self, "_closed", False):
            return
        if not (self.pipelined and not self._dirty and self._image_fits()):
            self._painting = True
            try:
                if not self._rendered or self._dirty:  # e.g. the camera moved since the last render
                    self._RenderWindow.Render()
                self._read_image()
                self._rendered = False
            finally:
                self._painting = False
        self.paints += 1
        painter = QPainter(self)
        if getattr(self, "render_scale", 1.0) != 1.0:  # fewer pixels rendered: drawn scaled to the widget
            painter.drawImage(self.rect(), self._image)
        else:
            painter.drawImage(QPoint(0, 0), self._image)
        painter.end()
        if self.on_painted is not None:
            self.on_painted()

    def Render(self) -> None:  # noqa: N802 (QVTKRenderWindowInteractor's name): a repaint renders
        self._dirty = True
        QWidget.update(self)

    def closeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        if not getattr(self, "_closed", False):
            self.Finalize()
        event.accept()

    def close(self) -> None:
        """Release VTK's render window and context, then the widget (returns None, like QtInteractor.close)."""
        if getattr(self, "_closed", True):
            return
        _OPEN.discard(self)
        BasePlotter.close(self)
        QWidget.close(self)
        self._Iren = _NoEvents()
        self._RenderWindow = None
