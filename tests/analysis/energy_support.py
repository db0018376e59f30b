"""A small box 'tongue' for the energy, morph and MDS tests (fast to simulate)."""

from __future__ import annotations

from functools import lru_cache
from types import SimpleNamespace

import numpy as np

from tonguevis.mesh.structured import box_mesh
from tonguevis.paths import DATA_DIR
from tonguevis.sim.model import TongueModel

MODES = 20


@lru_cache(maxsize=1)
def box_tongue() -> TongueModel:
    """A 60 × 40 × 30 mm block, tip at +x, anchored on the back half of its floor.

    Sensors on its top: TT 10 mm behind the tip, TD 30 mm, TL/TR 20 mm behind
    the tip and 8 mm off the midline.
    """
    mesh = box_mesh(6, 4, 3, (0.06, 0.04, 0.03))
    p = mesh.points

    def node(x, y, z):
        return int(np.argmin(np.linalg.norm(p - [x, y, z], axis=1)))

    sensors = {"TT": node(0.05, 0.02, 0.03), "TD": node(0.03, 0.02, 0.03),
               "TL": node(0.04, 0.03, 0.03), "TR": node(0.04, 0.01, 0.03)}
    anchors = np.flatnonzero((p[:, 2] < 1e-9) & (p[:, 0] < 0.025))
    return TongueModel(mesh, SimpleNamespace(sensors=sensors, anchors=anchors))


def demo_file(name: str):
    return DATA_DIR / name


SENSOR_MAP = DATA_DIR / "sensor_map.json"
