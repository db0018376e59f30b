"""The desktop app (PySide6 + pyvistaqt): the only package of tonguevis that imports Qt.

Start it with ``tonguevis`` / ``tonguevis view``, or from Python with
:func:`tonguevis.gui.app.run_view`.  Every module here is a Qt widget, dialog or
action; what they draw and export comes from Qt-free packages that run headless
(``tonguevis export-video`` renders off screen without Qt): the scene and its
drawing data in :mod:`tonguevis.render` (:mod:`~tonguevis.render.scene`,
:mod:`~tonguevis.render.drawing`, :mod:`~tonguevis.render.frames`,
:mod:`~tonguevis.render.video`, :mod:`~tonguevis.render.paraview`), the steps
(open, simulate, sessions) in :mod:`tonguevis.workflows`.  Views follow one
Qt-free :class:`tonguevis.appstate.AppState`.  ``lint-imports`` (pyproject.toml)
checks that no module outside this package imports Qt, directly or through others.
"""
