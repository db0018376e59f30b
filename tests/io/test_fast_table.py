"""The NDI Wave reader's fast path (pyarrow) against its careful path (Python, line by line).

Every file is read twice, once as the reader does it and once with the fast path
switched off: both must give the same recording bit for bit (or the same error
naming the file), and the fast path must really have been taken where it applies.
"""

from __future__ import annotations

import logging
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import SHARED_DATA
from tests.io.synthetic import make_recording
from tonguevis.io import RecordingError, write_recording
from tonguevis.io import ndi_wave
from tonguevis.io.fast_table import plain_table

DEMO = Path(__file__).resolve().parents[2] / "data" / "spk1_ta.tsv"


def read_both(path: Path, caplog):
    """(outcome with the fast path, outcome without it, whether the fast path read it); an outcome is
    ("ok", recording, warnings) or ("error", message)."""
    def outcome():
        caplog.clear()
        try:
            rec = ndi_wave.read_ndi_wave(path)
        except RecordingError as exc:
            return ("error", str(exc))
        return ("ok", rec, [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING])

    careful_calls = []
    real_fast, real_careful = ndi_wave.plain_table, ndi_wave._read_table_carefully

    def spying(data, path):
        careful_calls.append(path)
        return real_careful(data, path)

    ndi_wave._read_table_carefully = spying
    try:
        fast = outcome()
        taken = not careful_calls
        ndi_wave.plain_table = lambda *args: None
        careful = outcome()
        assert careful_calls  # the reference really is the careful path
    finally:
        ndi_wave.plain_table, ndi_wave._read_table_carefully = real_fast, real_careful
    return fast, careful, taken


def assert_same(a, b) -> None:
    assert a[0] == b[0], (a, b)
    if a[0] == "error":
        assert a[1] == b[1]
        return
    ra, rb = a[1], b[1]
    assert a[2] == b[2]  # the same warnings (the dropped last line, with its number)
    assert ra.rate == rb.rate and ra.sensor_names == rb.sensor_names
    np.testing.assert_array_equal(ra.times.view(np.int64), rb.times.view(np.int64))
    for name in ra.sensor_names:
        for table_a, table_b in ((ra.sensors, rb.sensors), (ra.orientations, rb.orientations)):
            if name in table_a or name in table_b:
                # bitwise, NaN patterns included
                np.testing.assert_array_equal(table_a[name].view(np.int64), table_b[name].view(np.int64))
    meta_a, meta_b = dict(ra.metadata), dict(rb.metadata)
    for key in ("ndi_status", "meas_id"):
        np.testing.assert_array_equal(meta_a.pop(key), meta_b.pop(key))
    assert meta_a == meta_b


def written(tmp_path: Path) -> bytes:
    """A small export with a three-frame dropout (empty fields, status 119)."""
    rec = make_recording(n=60, names=("S0", "S3", "S5"), audio_rate=None)
    out = tmp_path / "w.tsv"
    write_recording(rec, out)
    return out.read_bytes()


def test_demo_and_real_export_read_the_same_and_fast(tmp_path, caplog):
    files = [DEMO] + [p for p in [SHARED_DATA / "ema" / "ndi_wave" / "Example3.tsv"] if p.exists()]
    for path in files:
        fast, careful, taken = read_both(path, caplog)
        assert taken, path
        assert fast[0] == "ok"
        assert_same(fast, careful)


def _lines(data: bytes) -> list[bytes]:
    return data.split(b"\n")[:-1]


VARIANTS = {
    # name: (how the written file changes, whether the fast path should take it)
    "as written": (lambda d: d, True),
    "CRLF": (lambda d: d.replace(b"\n", b"\r\n"), True),
    "BOM": (lambda d: b"\xef\xbb\xbf" + d, True),
    "no final newline": (lambda d: d[:-1], True),
    "cut inside the last number": (lambda d: d[:-3], True),
    "cut inside the last number, CRLF": (lambda d: d.replace(b"\n", b"\r\n")[:-3], True),
    "blank lines": (lambda d: b"\n".join(_lines(d)[:3] + [b""] + _lines(d)[3:]) + b"\n\n\n", True),
    "blank lines after the header": (lambda d: b"\n".join(_lines(d)[:1] + [b"", b""] + _lines(d)[1:]) + b"\n", True),
    "trailing tabs": (lambda d: b"\n".join(line + b"\t" for line in _lines(d)) + b"\n", True),
    "trailing tabs on rows only": (lambda d: b"\n".join(_lines(d)[:1] + [line + b"\t\t" for line in _lines(d)[1:]])
                                   + b"\n", True),
    "exponents and signs": (lambda d: d.replace(b"\t0.500000", b"\t5e-1").replace(b"\t1.", b"\t+1."), True),
    "a line of tabs only": (lambda d: b"\n".join(_lines(d)[:4] + [b"\t" * _lines(d)[1].count(b"\t")]
                                                 + _lines(d)[4:]) + b"\n", False),
    "lone CR line ends": (lambda d: d.replace(b"\n", b"\r"), False),
    "nan written out": (lambda d: d.replace(b"\t\t", b"\tnan\t", 1), False),
    "spaces around numbers": (lambda d: d.replace(b"\t55.000000", b"\t 55.000000 ", 3), False),
    "a bad number": (lambda d: d.replace(b"55.000000", b"5.5.5", 1), False),
    "a short row": (lambda d: b"\n".join(_lines(d)[:5] + [_lines(d)[5][:30]] + _lines(d)[6:]) + b"\n", False),
    "a short last row": (lambda d: d[: d.rstrip(b"\n").rfind(b"\t")] + b"\n", False),
    "a long row with data": (lambda d: b"\n".join(_lines(d)[:5] + [_lines(d)[5] + b"\t1.0"] + _lines(d)[6:]) + b"\n",
                             False),
    "time going back": (lambda d: b"\n".join(_lines(d)[:2] + [_lines(d)[3], _lines(d)[2]] + _lines(d)[4:]) + b"\n",
                        True),
    "Latin-1 header": (lambda d: d.replace(b"AudioTime[s]", b"AudioTime[s] \xe9", 1), False),
    "header only": (lambda d: _lines(d)[0] + b"\n", False),
    "one row, cut (nothing above to judge it by: kept)": (lambda d: b"\n".join(_lines(d)[:2])[:-3], True),
}


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_variants_read_the_same_either_way(tmp_path, caplog, variant):
    change, fast_expected = VARIANTS[variant]
    path = tmp_path / "v.tsv"
    path.write_bytes(change(written(tmp_path)))
    fast, careful, taken = read_both(path, caplog)
    assert taken == fast_expected
    assert_same(fast, careful)
    if fast[0] == "error":
        assert str(path) in fast[1]


def test_truncated_file_drops_the_same_line_with_its_number(tmp_path, caplog):
    path = tmp_path / "cut.tsv"
    data = written(tmp_path)
    path.write_bytes(data[:-3])
    fast, careful, taken = read_both(path, caplog)
    assert taken and fast[0] == "ok"
    assert fast[1].metadata["truncated"] is True
    assert f"incomplete last line {len(_lines(data))}" in fast[2][0]
    assert_same(fast, careful)


def test_the_fast_table_equals_the_careful_numbers(tmp_path):
    data = written(tmp_path)
    table = plain_table(data)
    header, careful, first_line, truncated = ndi_wave._read_table_carefully(data, tmp_path / "w.tsv")
    assert first_line == table.first_data_line == 2 and not truncated
    np.testing.assert_array_equal(table.values.view(np.int64), careful.view(np.int64))
    assert np.isnan(careful).any()  # the dropout's empty cells are in both


FUZZ = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                       HealthCheck.function_scoped_fixture],
                derandomize=True)


@FUZZ
@given(flips=st.lists(st.tuples(st.floats(0.0, 1.0), st.sampled_from(b"0123456789.+-eE\t\r\nx ")), min_size=1,
                      max_size=4),
       cut=st.floats(0.5, 1.0))
def test_mutated_files_read_the_same_either_way(caplog, flips, cut):
    with tempfile.TemporaryDirectory() as folder:
        data = bytearray(written(Path(folder)))
        data = data[: max(1, int(cut * len(data)))]
        for where, value in flips:
            data[min(int(where * len(data)), len(data) - 1)] = value
        path = Path(folder) / "m.tsv"
        path.write_bytes(bytes(data))
        fast, careful, _ = read_both(path, caplog)
        assert_same(fast, careful)
