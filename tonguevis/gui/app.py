"""Starting the desktop app: the QApplication, the window, and the screenshot mode."""

from __future__ import annotations

import json
import os
import sys

from tonguevis.gui.application import application, install_error_hook  # noqa: F401 (re-exported)


def create_window(file=None, settings=None, *, reading: dict | None = None, preferences=None,
                  feature_tabs: bool = True, reference: str | None = None):
    """A shown MainWindow that opens ``file`` (default: the demo) and simulates it as ``settings`` (a
    :class:`~tonguevis.sim.settings.RunSettings`, default everyone's; its ``rest`` is the recording's rest when
    given, its ``palate`` the contact) describe.  ``reading``: :func:`~tonguevis.workflows.open_recording`'s
    keywords (``sensor_map``, ``audio``, ``labels`` and reader options, ``-O``); ``preferences``: a QSettings
    (recent files); ``reference``: "head" or "jaw" (the views' frame; default head)."""
    from tonguevis.gui.window import MainWindow
    from tonguevis.sim.settings import RunSettings

    application()
    settings = settings if settings is not None else RunSettings()
    rest, settings = settings.rest, settings.replace(rest=None)  # the rest is the recording's, not every one's
    window = MainWindow(preferences=preferences, run_settings=settings)
    if reference is not None:
        window.state.set_reference(reference)
    if feature_tabs:
        from tonguevis.gui.tabs import add_feature_tabs

        add_feature_tabs(window)
    window.show()
    reading = dict(reading or {})
    if file is None and rest is None and not reading:
        window.open_demo()  # with the palate given, if any
    else:
        from tonguevis.workflows.session import demo_recording_path

        sensor_map, audio, labels = (reading.pop(key, None) for key in ("sensor_map", "audio", "labels"))
        window.open_recording(file if file is not None else demo_recording_path(), sensor_map=sensor_map, rest=rest,
                              audio=audio, labels=labels, options=reading)
    return window


def opening_problem(window, file):
    """What stopped ``window`` opening ``file``, as the error a headless run ends with.

    Without a screen to answer it, the sensor-mapping dialog becomes an error that
    says how to give the map on the command line.
    """
    from tonguevis.errors import RecordingError, TonguevisError
    from tonguevis.gui.dialogs import SensorMapDialog
    from tonguevis.workflows.session import TONGUE_NAMES

    dialog = window.last_dialog
    if isinstance(dialog, SensorMapDialog):
        channels = list(dialog.boxes)
        example = json.dumps(dict(zip(("TT", "TD"), channels)))
        return RecordingError(
            f"no channel is a known tongue sensor ({', '.join(TONGUE_NAMES)}); the channels are "
            f"{', '.join(channels)}. Give a sensor map with --sensors: a preset (paper, haskins, mngu0) "
            f"or a JSON file of name -> channel such as {example} "
            "(a sensor_map.json beside the file is used when there is one)", file)
    return TonguevisError(" ".join(dialog.text().split()))


def run_view(file=None, settings=None, *, reading: dict | None = None, screenshot=None, frame: int | None = None,
             look: dict | None = None, compare: dict | None = None) -> int:
    """``tonguevis view``: run the app on ``file`` simulated as ``settings`` (see :func:`create_window`, as
    ``reading``); with ``screenshot``, save the window at ``frame``, print the rest line and exit.
    ``look``: {"reference": "head"|"jaw", "color": a colouring}; ``compare``: the keyword arguments of
    :meth:`MainWindow.open_compare` (``path`` ...) for a second recording shown with the first (a screenshot
    waits for both simulations)."""
    look = look or {}
    app = application()
    window = create_window(file, settings, reading=reading, reference=look.get("reference"))
    if compare is not None and window.session is not None:
        if not window.open_compare(**compare) and screenshot is not None:
            window.close()
            from tonguevis.errors import TonguevisError

            raise TonguevisError(window.state.status)  # "<title>: <message naming the file>"
    if look.get("color") is not None:
        window.state.set_color(look["color"])
    if screenshot is None:
        install_error_hook(window)
        return app.exec()
    status = {"code": 1}

    def shoot(ok: bool) -> None:
        from PySide6.QtCore import QTimer

        if not ok:
            message = window.state.status
            print(f"tonguevis view: no screenshot, the simulation did not finish: {message}", file=sys.stderr)
            app.exit(2)
            return
        frames = window.session.frames
        index = min(max(int(frame if frame is not None else frames.n_frames // 2), 0), frames.n_frames - 1)
        window.state.set_time(float(frames.times[index]))

        def save() -> None:
            window.export_screenshot(os.fspath(screenshot))
            print(f"{window.session.rest.describe()}\nwrote {screenshot}")
            status["code"] = 0
            window.close()
            app.exit(0)

        QTimer.singleShot(600, save)  # let the plots draw at their final size

    if window.session is None and window.last_dialog is not None:
        problem = opening_problem(window, file)
        window.close()
        raise problem  # the CLI prints it as one line and exits with status 2
    if compare is None:
        window.simulation_finished.connect(shoot)
    else:  # both recordings simulated (or one failed) before the picture
        outcomes: dict[str, bool] = {}

        def finished(role: str, ok: bool) -> None:
            outcomes[role] = ok
            if len(outcomes) == 2 or not ok:
                if not outcomes.get("primary", True) or not outcomes.get("compare", True):
                    shoot(False)
                elif len(outcomes) == 2:
                    shoot(True)

        window.simulation_finished.connect(lambda ok: finished("primary", ok))
        window.compare_finished.connect(lambda ok: finished("compare", ok))
    code = app.exec()
    return code if code else status["code"]
