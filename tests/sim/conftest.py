"""Fixtures the physics tests share: the shipped tongue and the demo /ka/ of speaker 1."""

from __future__ import annotations

import pytest

from tonguevis.io import read_recording
from tonguevis.paths import DATA_DIR
from tonguevis.sim import TongueModel


@pytest.fixture(scope="module")
def model():
    return TongueModel.default()


@pytest.fixture(scope="module")
def demo():
    return read_recording(DATA_DIR / "spk1_ka.tsv", sensor_map=DATA_DIR / "sensor_map.json")
