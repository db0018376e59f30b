"""The feature tabs (Energy, Morph, ...) and how they join the main window.

Each feature registers a factory with :func:`tonguevis.gui.window.register_tab_factory`
or is added here; :func:`add_feature_tabs` wires the Energy and Morph tabs to
the window: the app's own simulations feed the Energy tab, motions loaded
there feed the Morph tab, and a frame picked in the Energy tab becomes a morph end.
"""

from __future__ import annotations

import logging

log = logging.getLogger("tonguevis")


def add_feature_tabs(window) -> None:
    try:
        from tonguevis.gui.energy_tab import EnergyTab
        from tonguevis.gui.morph_tab import MorphTab
    except ImportError as exc:  # a feature not installed must not stop the app
        log.warning("energy/morph tabs not available: %s", exc)
        return

    def current_recording():
        session = window.session
        return None if session is None or session.path is None else session.path.stem

    def model_provider():
        from tonguevis.gui.simulation import build_model

        if window.model is None:
            window.model = build_model(window.mesh_path)
        return window.model

    energy = EnergyTab(window.state, current_recording=current_recording, model_provider=model_provider,
                       simulate_options={"modes": window.modes})
    morph = MorphTab(window.state)
    window.register_tab("Energy", energy)
    window.register_tab("Morph", morph)
    energy.motionsLoaded.connect(morph.set_motions)
    energy.morphEndPicked.connect(lambda which, recording, t: morph.set_end(which, recording, t))
    window.energy_tab, window.morph_tab = energy, morph

    def simulated(ok: bool) -> None:
        session = window.session
        if not ok or session is None or session.motion is None or session.production_table is None:
            return
        try:
            energy.add_motion(session.name, session.motion, session.production_table)
        except Exception as exc:  # the main views must not suffer from a tab's problem
            log.warning("energy curves of %s not added: %s", session.name, exc)

    window.simulation_finished.connect(simulated)
    from tonguevis.gui.segmentation_tab import SegmentationTab
    window.segmentation_tab = SegmentationTab(window.state)
    window.register_tab("Segmentation", window.segmentation_tab)
