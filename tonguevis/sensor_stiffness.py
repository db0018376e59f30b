"""The words for how hard the sensor nodes are pulled onto the sensors, the same in the library and the CLI.

``sensor_stiffness`` is a dimensionless multiple of the tongue's own point
stiffness at the sensor nodes (see :func:`tonguevis.sim.simulate`): a positive
number (or its text, "20"), ``"default"`` (the measured default, 20), or
``"hard"`` / None (hard constraints: the sensor nodes follow the sensors
exactly, the paper's setting).
"""

from __future__ import annotations

import math

from tonguevis.errors import SimulationError

#: The words ``sensor_stiffness`` accepts besides a positive number.
WORDS = ("default", "hard")


def sensor_stiffness_value(value, where=None) -> float | None | str:
    """``value`` as the simulation takes it: a positive float, None (hard) or "default".

    Raises SimulationError naming ``where`` (a file, or None) and the accepted
    words for anything else ("soft", 0, -1, inf, a list ...).
    """
    if value is None:
        return None
    if isinstance(value, str):
        word = value.strip().lower()
        if word == "hard":
            return None
        if word == "default":
            return "default"
        try:
            value = float(word)
        except ValueError:
            raise SimulationError(f"sensor stiffness {value!r} is neither a positive number nor one of "
                                 f"{', '.join(repr(w) for w in WORDS)}", where) from None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise SimulationError(f"sensor stiffness must be a positive number, 'hard' or 'default', got {value!r}",
                             where)
    return float(value)
