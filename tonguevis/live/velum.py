"""The velum in the live view: lifted frame by frame by the dorsum, as the replay lifts it.

A speaker's palate placed on the rest (:mod:`tonguevis.sim.speaker_palate`) has a ``lift_shape``: behind the
traced hard palate the soft palate takes a share of a lift.  The replay lifts it per frame by the least amount
that keeps every sensor over the soft palate a coil's half under it, held over a few frames
(:func:`tonguevis.sim.speaker_palate.velum_lift`); live, the same least lift is computed for each frame as it
comes and held for the frames after it (only the past is known), so the palate drawn and the palatogram
measured against follow the dorsum at a /k/ as in the replay.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from tonguevis.sim.speaker_palate import LIFT_HOLD, velum_lift


class LiveVelum:
    """The velum's lift (m) of ``palate`` (a placed PalateSurface with a ``lift_shape``) frame by frame."""

    def __init__(self, palate):
        self.palate = palate
        self._recent: deque = deque(maxlen=LIFT_HOLD + 1)

    def lift(self, sensors: np.ndarray) -> float:
        """The lift (m) for this frame's sensors ((S, 3) m, in the palate's frame, NaN where missing): the
        largest of this frame's least lift and the last :data:`LIFT_HOLD` frames'."""
        self._recent.append(float(velum_lift(self.palate, np.asarray(sensors, dtype=np.float64)[None])[0]))
        return max(self._recent)

    @staticmethod
    def liftable(palate) -> bool:
        """Whether ``palate`` has a velum that lifts (a speaker's palate; not the generic one or a mesh)."""
        return palate is not None and getattr(palate, "lift_shape", None) is not None
