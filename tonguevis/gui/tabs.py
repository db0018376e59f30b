"""The feature tabs (Energy, Morph, Segmentation, Measures) and how they join the main window.

Each feature tab is added here (:func:`add_feature_tabs`).  The tabs talk only to the app model (``window.state``), never to
each other nor to the window:

- Energy hears ``motion`` (a recording of the app simulated: its production curves are
  added) and writes ``add_motions`` (the motions its curves come from) and
  ``set_morph_end`` (a picked frame sent to the morph);
- Morph hears ``motions`` (the recordings its ends can come from) and ``morph_ends``;
- Segmentation follows the primary session (``session`` and ``motion``) and the time;
- Measures follows the primary session and its ``productions``, and writes the time (a double-clicked closure).
"""

from __future__ import annotations

from tonguevis._logging import logger


def add_feature_tabs(window) -> None:
    try:
        from tonguevis.gui.energy_tab import EnergyTab
        from tonguevis.gui.morph_tab import MorphTab
    except ImportError as exc:  # a feature not installed must not stop the app
        logger.warning("energy/morph tabs not available: %s", exc)
        return
    from tonguevis.gui.segmentation_tab import SegmentationTab

    state = window.state
    window.register_tab("Energy", EnergyTab(state))
    window.register_tab("Morph", MorphTab(state))
    window.register_tab("Segmentation", SegmentationTab(state))
    from tonguevis.gui.measures_tab import MeasuresTab

    window.register_tab("Measures", MeasuresTab(state))
