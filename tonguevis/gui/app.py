"""Starting the desktop app: the QApplication, the window, and the screenshot mode."""

from __future__ import annotations

import json
import os
import sys
import traceback

from tonguevis._logging import logger


def application():
    from PySide6.QtWidgets import QApplication

    from tonguevis.gui.qt_workarounds import keep_none_alive

    keep_none_alive()  # every window: a long playback makes as many void Qt calls as the live view
    app = QApplication.instance()
    if app is None:
        app = QApplication(sys.argv[:1])
        app.setApplicationName("tonguevis")
        app.setOrganizationName("tonguevis")
    return app


def install_error_hook(window) -> None:
    """Unexpected exceptions in Qt callbacks become a dialog; the app keeps running."""

    def hook(kind, value, tb):
        logger.error("unexpected error:\n%s", "".join(traceback.format_exception(kind, value, tb)))
        try:
            window.show_error("Unexpected error", f"{kind.__name__}: {value}")
        except Exception:  # never let the hook itself raise
            pass

    sys.excepthook = hook


def create_window(file=None, sensor_map=None, mesh=None, modes: int = 100, settings=None, feature_tabs: bool = True,
                  rest=None, audio=None, labels=None, palate=None, frame: str | None = None,
                  options: dict | None = None, sensor_patches="default", rest_fit: bool = False,
                  model_frame: str = "speaker", tongue_size: float | str | None = "adult"):
    """A shown MainWindow that opens ``file`` (default: the demo), with ``rest`` (start_s, end_s) if given,
    and the sound ``audio`` and TextGrid ``labels`` if given (else those found beside the file);
    simulated against ``palate`` (a PalateSurface, a file or "generic"; None: no contact), shown in
    ``frame`` ("head" or "jaw"; default head); ``options``: the reader options (``-O``) of ``file``;
    ``sensor_patches``: as :func:`tonguevis.simulate` (Simulation ▸ Sensors on the surface); ``rest_fit``:
    the tongue bent onto the rest sensors (Simulation ▸ Fit the tongue to the rest sensors); ``model_frame``
    and ``tongue_size``: in whose millimetres and at what size the tongue is simulated (as
    :class:`~tonguevis.workflows.settings.RunSettings` ``frame`` and ``tongue_size``)."""
    from tonguevis.gui.window import MainWindow

    application()
    window = MainWindow(settings=settings, modes=modes, mesh_path=mesh, palate=palate)
    if sensor_patches != window.sensor_patches:
        window.sensor_patches = sensor_patches
        window.patches_action.blockSignals(True)
        window.patches_action.setChecked(sensor_patches is not None)
        window.patches_action.blockSignals(False)
    if rest_fit:
        window.rest_fit_action.blockSignals(True)
        window.rest_fit_action.setChecked(True)
        window.rest_fit_action.blockSignals(False)
        window.state.change_run_settings(window, rest_fit=True)
    if model_frame != window.state.run_settings.frame or tongue_size != window.state.run_settings.tongue_size:
        window.state.change_run_settings(window, frame=model_frame, tongue_size=tongue_size)
        key = window._tongue_size()
        if key is not None:
            window.size_actions[key].setChecked(True)
    if frame is not None:
        window.state.set_reference(frame)
    if feature_tabs:
        from tonguevis.gui.tabs import add_feature_tabs

        add_feature_tabs(window)
    window.show()
    if file is None and rest is None and audio is None and labels is None and not options:
        window.open_demo()  # with the palate given, if any
    else:
        from tonguevis.workflows.session import demo_recording_path

        window.open_recording(file if file is not None else demo_recording_path(), sensor_map=sensor_map, rest=rest,
                              audio=audio, labels=labels, options=options)
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


def run_view(file=None, sensor_map=None, mesh=None, modes: int = 100, screenshot=None, frame: int | None = None,
             rest=None, audio=None, labels=None, palate=None, reference: str | None = None,
             color: str | None = None, compare: dict | None = None, options: dict | None = None,
             sensor_patches="default", rest_fit: bool = False, model_frame: str = "speaker",
             tongue_size: float | str | None = "adult") -> int:
    """``tonguevis view``: run the app; with ``screenshot``, save the window at ``frame``, print the
    rest line and exit.  ``rest``: (start_s, end_s) of the rest interval, None to find it; ``audio``,
    ``labels``: a WAV and a TextGrid, None for those beside the file; ``palate``: simulate against it
    (None: no contact); ``reference``: "head" or "jaw" frame; ``color``: the surface colouring;
    ``compare``: the keyword arguments of :meth:`MainWindow.open_compare` (``path`` ...) for a
    second recording shown with the first (a screenshot waits for both simulations); ``options``: reader
    options (``-O``) of ``file``; ``model_frame``, ``tongue_size``: as :func:`create_window`'s."""
    app = application()
    window = create_window(file, sensor_map, mesh, modes, rest=rest, audio=audio, labels=labels, palate=palate,
                           frame=reference, options=options, sensor_patches=sensor_patches, rest_fit=rest_fit,
                           model_frame=model_frame, tongue_size=tongue_size)
    if compare is not None and window.session is not None:
        if not window.open_compare(**compare) and screenshot is not None:
            window.close()
            from tonguevis.errors import TonguevisError

            raise TonguevisError(window.state.status)  # "<title>: <message naming the file>"
    if color is not None:
        window.state.set_color(color)
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
