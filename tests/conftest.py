"""Shared fixtures: where the third-party test data lives, small meshes."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(autouse=True, scope="session")
def _isolated_cache(tmp_path_factory):
    """Modal-basis caches of the tests go to a private folder, not ~/.cache."""
    if "TONGUEVIS_CACHE" not in os.environ:
        os.environ["TONGUEVIS_CACHE"] = str(tmp_path_factory.mktemp("cache"))
    yield


@pytest.fixture(autouse=True)
def _warnings_said_afresh():
    """Each test hears the warnings of its own runs: warn_once's memory is the process's, not the test's."""
    from tonguevis._logging import forget_warnings

    forget_warnings()
    yield


def shared_file(*parts: str) -> Path:
    """Path of a file in ../shared/data, or skip the test with the reason."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"third-party test data not available: {path} (needs ../shared beside the repo)")
    return path


@pytest.fixture
def shared():
    """``shared('ema', 'mview', 'F01...mat')`` -> Path, skipping when absent."""
    return shared_file


#: The OSN12 palate traces (Opti-Speech): midsagittal, coronal, scribble.
OSN12_TRACES = ("002_OSN12_Palate_MidSagital_HR.tsv", "003_OSN12_Palate_Coronal_HR.tsv",
                "004_OSN12_Palate_Scribble_HR.tsv")


@pytest.fixture(scope="session")
def osn12_palate(tmp_path_factory):
    """The OSN12 speaker's palate, fitted by ``tonguevis palate`` from the three traces (skips without them)."""
    from tonguevis.cli import main

    traces = [str(shared_file("ema", "optispeech", name)) for name in OSN12_TRACES]
    out = tmp_path_factory.mktemp("palate") / "osn12.stl"
    assert main(["palate", *traces, "--out", str(out)]) == 0
    return out
