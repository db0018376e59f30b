"""The desktop app (PySide6 + pyvistaqt): the only package of tonguevis that imports Qt.

Start it with ``tonguevis`` / ``tonguevis view``, or from Python with
:func:`tonguevis.gui.app.run_view`.  Views subscribe to one Qt-free
:class:`tonguevis.appstate.AppState`; science stays in Qt-free modules
(:mod:`session`, :mod:`frames`, :mod:`energy_density`, :mod:`scene`, :mod:`video`).
Feature tabs join through ``MainWindow.register_tab`` (:mod:`tonguevis.gui.tabs`).
"""
