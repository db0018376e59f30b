#!/usr/bin/env python
"""Screenshots of the desktop app for the README and docs (real window, real simulation).

Writes docs/images/app.png (the demo /ta/ recording in mid-syllable, coloured by
displacement), docs/images/app_energy.png (same frame, energy density, modal
q(t) tab) and docs/images/app_palate.png (speaker 3's synthetic /ta/ simulated
against the shipped generic palate, in the head frame, coloured by the distance
to the palate at the frame where the tongue comes closest to it, Palate tab).
Needs a display: run under ``xvfb-run -a -s "-screen 0 1600x1000x24"``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=REPO / "data" / "spk1_ta.tsv")
    parser.add_argument("--out", type=Path, default=REPO / "docs" / "images")
    parser.add_argument("--time", type=float, default=5.62, help="time shown, seconds (default: a /t/ release)")
    parser.add_argument("--modes", type=int, default=100)
    parser.add_argument("--palate-recording", type=Path, default=REPO / "data" / "spk3_ta.tsv",
                        help="recording shown against the generic palate (default: speaker 3's /ta/, whose tip "
                             "reaches the alveolar ridge)")
    args = parser.parse_args()

    from PySide6.QtCore import QSettings

    from tonguevis.gui.app import application
    from tonguevis.gui.tabs import add_feature_tabs
    from tonguevis.gui.window import MainWindow
    from tonguevis.sim.settings import RunSettings

    app = application()
    window = MainWindow(preferences=QSettings("/tmp/tonguevis-screenshots.ini", QSettings.Format.IniFormat),
                        run_settings=RunSettings(modes=args.modes))
    add_feature_tabs(window)
    window.resize(1600, 960)
    window.show()
    from PySide6.QtCore import QTimer

    args.out.mkdir(parents=True, exist_ok=True)
    status = {"code": 1}

    def first() -> None:
        window.export_screenshot(args.out / "app.png")
        window.state.set_color("energy")
        window.tabs.setCurrentWidget(window.modal_tab)
        QTimer.singleShot(1000, second)

    def second() -> None:
        window.export_screenshot(args.out / "app_energy.png")
        window.simulation_finished.disconnect(finished)
        window.simulation_finished.connect(against_palate)
        window.palate = "generic"  # File ▸ Use the generic palate: contact on
        window.open_recording(args.palate_recording)

    def against_palate(ok: bool) -> None:
        if not ok:
            print("simulation failed:", window.statusBar().currentMessage(), file=sys.stderr)
            app.quit()
            return
        window.state.set_reference("head")
        window.state.set_color("contact")
        window.tabs.setCurrentWidget(window.palate_panel)
        window.state.set_time(float(closest_frame_time(window.session)))
        QTimer.singleShot(1500, third)

    def third() -> None:
        window.export_screenshot(args.out / "app_palate.png")
        print(f"wrote {args.out / 'app.png'}, {args.out / 'app_energy.png'} and {args.out / 'app_palate.png'}")
        print(window.frame_status.text())
        status["code"] = 0
        app.quit()

    def finished(ok: bool) -> None:
        if not ok:
            print("simulation failed:", window.statusBar().currentMessage(), file=sys.stderr)
            app.quit()
            return
        window.state.set_time(args.time)
        QTimer.singleShot(1000, first)  # everything inside the event loop: plots and GL settle

    window.simulation_finished.connect(finished)
    window.open_recording(args.recording)
    app.exec()
    window.close()
    return status["code"]


def closest_frame_time(session) -> float:
    """The time at which the tongue's upper surface comes closest to the palate (head frame)."""
    import numpy as np

    from tonguevis.render.drawing import contact_at

    closest = [contact_at(session, i)["closest_mm"] for i in range(session.frames.n_frames)]
    closest = np.array([np.inf if c is None else c for c in closest])
    return session.frames.times[int(np.argmin(closest))]


if __name__ == "__main__":
    sys.exit(main())
