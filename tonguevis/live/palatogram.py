"""The live palatogram: the electrodes of the palate the simulated tongue touches, a few times a second.

Computed on the simulator's surface (not the display's smoothing) against the palate as the
simulator placed it on the rest; every :data:`EPG_EVERY_S` s of the stream at most (a few ms each:
the clinician reads it, it need not follow every frame).
"""

from __future__ import annotations

import numpy as np

#: s between two palatograms computed.
EPG_EVERY_S = 0.05


class LivePalatogram:
    """The palatogram of ``sim``'s tongue (a rested :class:`~tonguevis.live.simulator.LiveSimulator` with a
    palate): ``layout`` (the palate's electrodes), ``index`` (the model's upper-surface nodes, as indices
    into the simulator's surface), ``triangles`` (of that upper surface).  Raises when the palate has no
    electrode layout or the model no upper surface."""

    def __init__(self, sim):
        from tonguevis.analysis.epg import epg_layout, upper_surface

        nodes, self.triangles = upper_surface(sim.model)
        self.layout = epg_layout(sim.palate)
        self.index = np.searchsorted(sim.surface_nodes, nodes)
        self.palate = sim.palate
        self.last_s = -np.inf

    def contacts(self, step, time_s: float, lift: float = 0.0) -> np.ndarray | None:
        """The electrode contacts of ``step`` (a LiveStep at stream time ``time_s``) when one is due, else None;
        ``lift`` (m): the velum's lift at that frame (the palate measured against as lifted then)."""
        if time_s - self.last_s < EPG_EVERY_S:
            return None
        from tonguevis.analysis.epg import electrode_contacts

        surface = (np.asarray(step.surface, dtype=np.float64) + step.jaw_offset)[self.index]
        self.last_s = time_s
        palate = self.palate.lifted(lift) if lift > 0.0 else self.palate
        return electrode_contacts(surface[None], self.triangles, palate, self.layout)[0]
