"""The QApplication every window of tonguevis shares, and the hook that turns an unexpected error into a dialog."""

from __future__ import annotations

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
