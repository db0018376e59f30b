"""A live stream's rest: the simulator placed on a still moment of the frames seen so far.

Three ways (:func:`simulator_on_rest`): the stillest half second of the recent frames (the
session's own, after its first :data:`~tonguevis.live.session.AUTO_REST_S` s), an interval the user
gave (``--rest START,END``, seconds from the stream's first frame), or the last half second (the
clinician's "Take rest now").  Positions in mm as the stream carries them, times in seconds.
"""

from __future__ import annotations

import numpy as np

from tonguevis.live.simulator import REST_WINDOW_S, LiveSimulationError, LiveSimulator


def simulator_on_rest(recent: list, names: list[str], settings, model=None, *, stillest: bool = False,
                      interval: tuple[float, float] | None = None, clock0: float = 0.0) -> LiveSimulator:
    """A :class:`LiveSimulator` of the slots ``names`` on the rest taken from ``recent`` ([(time s, (S, 3) mm)],
    oldest first, at least two): its stillest :data:`REST_WINDOW_S` s, else ``interval`` (start_s, end_s after
    ``clock0``, the stream's first time stamp), else its last :data:`REST_WINDOW_S` s.  model : the unplaced
    tongue model (None: the settings', built).  The rate is the frames' median.  Raises
    :class:`LiveSimulationError` (or another TonguevisError, a ValueError) when the rest cannot be taken."""
    times = np.array([t for t, _ in recent])
    dt = float(np.median(np.diff(times)))
    sim = LiveSimulator(names, settings, model=model, rate=round(1.0 / dt, 3) if dt > 0 else 100.0)
    if stillest:
        for t, p in recent:
            sim.observe(t, p)
        sim.take_rest(REST_WINDOW_S)
        return sim
    if interval is not None:
        start, end = clock0 + interval[0], clock0 + interval[1]
        inside = (times >= start - 1e-9) & (times <= end + 1e-9)
        if inside.sum() < 2:
            raise LiveSimulationError(f"the rest {interval[0]:g}-{interval[1]:g} s (--rest) holds "
                                      f"{int(inside.sum())} frame(s) of the stream; give a longer one")
    else:
        inside = times >= times[-1] - REST_WINDOW_S
    sim.set_rest(times[inside], np.stack([p for (_, p), keep in zip(recent, inside) if keep]))
    return sim
