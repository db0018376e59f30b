"""PySide6 6.12 on Python < 3.12 drops a reference to None on every void Qt call: the app keeps None alive."""

from __future__ import annotations

import sys

import pytest

pytestmark = [pytest.mark.gui, pytest.mark.timeout(60)]


@pytest.mark.skipif(sys.version_info >= (3, 12), reason="None is immortal from Python 3.12")
def test_the_app_keeps_none_alive_through_a_long_playback(qtbot):
    from tonguevis.gui.app import application

    application()
    assert sys.getrefcount(None) > 2 ** 39  # ~10^12 void calls: centuries of frames at 100 a second
