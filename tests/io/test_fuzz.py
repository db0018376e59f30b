"""Fuzzing every reader with truncations and byte flips (hypothesis).

Whatever the bytes, ``read_recording`` returns a valid Recording or raises
RecordingError naming the file: never IndexError, KeyError, struct.error ...
Seeds are the generated examples of every format and the real third-party
files (read in place; the mutated copies live in a temporary folder only).
"""

from __future__ import annotations

import logging
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import SHARED_DATA
from tests.io.examples import MAKERS
from tests.io.test_readers_common import check_recording
from tonguevis.io import RecordingError, read_recording

REAL_FILES = [
    ("ndi_wave", "Example3.tsv", {}),
    ("carstens", "artk_ag501.pos", {}),
    ("carstens", "artk_ag500.pos", {}),
    ("carstens", "rticulate_0025.pos", {}),
    ("carstens", "artk_ag501.bvh", {}),
    ("est_track", "artk_esttrack.txt", {}),
    ("est_track", "artk_esttrack.bin", {}),
    ("mview", "F01_B01_S01_R01_N.mat", {}),
]

mutations = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0.0, 1.0)),
    st.tuples(st.just("flip"), st.lists(st.tuples(st.floats(0.0, 1.0), st.integers(0, 255)), min_size=1, max_size=4)),
    st.tuples(st.just("both"), st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.integers(0, 255))),
)


def mutate(data: bytes, mutation) -> bytes:
    kind, arg = mutation
    if not data:
        return data
    if kind == "truncate":
        return data[: int(arg * len(data))]
    if kind == "flip":
        out = bytearray(data)
        for where, value in arg:
            out[min(int(where * len(out)), len(out) - 1)] = value
        return bytes(out)
    cut, where, value = arg
    out = bytearray(data[: max(1, int(cut * len(data)))])
    out[min(int(where * len(out)), len(out) - 1)] = value
    return bytes(out)


def read_mutated(name: str, data: bytes, options: dict) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / name
        path.write_bytes(data)
        try:
            rec = read_recording(path, **options)
        except RecordingError as exc:
            assert str(path) in str(exc), f"error does not name the file: {exc}"
            return
        check_recording(rec)


FUZZ = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                derandomize=True)


@pytest.fixture(autouse=True)
def _quiet_warnings(caplog):
    caplog.set_level(logging.ERROR, logger="tonguevis")


@pytest.mark.parametrize("kind", sorted(MAKERS))
def test_fuzz_generated_examples(kind):
    with tempfile.TemporaryDirectory() as folder:
        example = MAKERS[kind](Path(folder))
        data = example.path.read_bytes()
        name = example.path.name

    @FUZZ
    @given(mutation=mutations)
    def run(mutation):
        read_mutated(name, mutate(data, mutation), example.options)

    run()


@pytest.mark.parametrize("folder, name, options", REAL_FILES, ids=[r[1] for r in REAL_FILES])
def test_fuzz_real_files(folder, name, options):
    path = SHARED_DATA / "ema" / folder / name
    if not path.exists():
        pytest.skip(f"third-party test data not available: {path}")
    data = path.read_bytes()

    @FUZZ
    @given(mutation=mutations)
    def run(mutation):
        read_mutated(name, mutate(data, mutation), options)

    run()
