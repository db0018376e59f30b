"""The live view's display smoothing: a first-order low-pass of what is drawn, frame by frame (causal).

It changes only the screen: what a sweep saves stays raw.  Off (time constant 0) by default.
"""

from __future__ import annotations

import numpy as np


class DisplayLowPass:
    """``y += (1 - exp(-dt / time_constant)) (x - y)`` for each drawn quantity (a key: "surface",
    "sensors"...), started at its first value; a value unknown before (NaN) takes the new one at once.

    time_constant : seconds (0: off, values pass through).
    """

    def __init__(self, time_constant: float = 0.0):
        self.time_constant = 0.0
        self._state: dict[str, np.ndarray] = {}
        self.set_time_constant(time_constant)

    def set_time_constant(self, seconds: float) -> None:
        """Smooth with this time constant from now (s; 0: off); starts over from the next values."""
        self.time_constant = max(float(seconds), 0.0)
        self.reset()

    def reset(self) -> None:
        """Forget the past values (a new rest: the drawn quantities change meaning)."""
        self._state.clear()

    def __call__(self, key: str, value: np.ndarray, dt: float) -> np.ndarray:
        """``value`` (any shape, float) smoothed, ``dt`` s after the last one of ``key`` (off: ``value`` itself).
        The result is the filter's state: copy it to keep it past the next call."""
        if self.time_constant <= 0:
            return value
        old = self._state.get(key)
        if old is None or old.shape != value.shape:
            self._state[key] = np.array(value, dtype=np.float64)
            return value
        alpha = 1.0 - np.exp(-max(dt, 0.0) / self.time_constant)
        fresh = np.isfinite(old)
        old[fresh] += alpha * (value[fresh] - old[fresh])
        old[~fresh] = value[~fresh]
        return old
