"""The shared helpers: fast paths against plain references, axes, gaps, re-gridding."""

from __future__ import annotations

import numpy as np
import pytest

from tests.io.synthetic import make_recording
from tonguevis.io import RecordingError
from tonguevis.io._common import (
    dropped_frames, format_rows, parse_axes, parse_number_table, regrid_dropped_frames, rotate_quaternions,
)


def _reference_parse(rows):
    return np.array([[float(c) if c.strip() else np.nan for c in row] for row in rows])


def test_parse_number_table_equals_reference():
    rng = np.random.default_rng(0)
    values = rng.normal(size=(40, 7)) * 10.0 ** rng.integers(-3, 4, size=(40, 7))
    rows = [[f"{v:.6g}" for v in row] for row in values]
    rows[3][2] = ""
    rows[7][0] = "  "  # whitespace-only: the careful path
    rows[9][6] = " 1.5e3 "
    expected = _reference_parse(rows)
    np.testing.assert_array_equal(parse_number_table(rows, "f", 1), expected)
    rows[7][0] = ""  # all-empty cells take the fast path
    np.testing.assert_array_equal(parse_number_table(rows, "f", 1), _reference_parse(rows))


def test_parse_number_table_names_the_bad_cell():
    rows = [["1", "2"], ["3", "x4"]]
    with pytest.raises(RecordingError, match=r"line 11, column 2: value 'x4' is not a number"):
        parse_number_table(rows, "f.tsv", 10)


def test_format_rows_equals_char_mod_reference():
    rng = np.random.default_rng(1)
    table = rng.normal(size=(30, 5)) * 100
    table[2, 3] = np.nan
    table[5, :] = np.nan
    ref = np.char.mod("%.6f", table)
    ref[np.isnan(table)] = ""
    assert format_rows(table, "\t") == ["\t".join(row) for row in ref.tolist()]
    assert format_rows(table, ",", nan="nan")[2].split(",")[3] == "nan"


def test_parse_axes():
    np.testing.assert_array_equal(parse_axes(None), np.eye(3))
    A = parse_axes("-y,x,z")
    np.testing.assert_array_equal(A @ [1.0, 2.0, 3.0], [-2.0, 1.0, 3.0])
    np.testing.assert_array_equal(parse_axes("-yxz"), A)
    np.testing.assert_array_equal(parse_axes(A), A)
    for bad in ("x,y", "x,y,w", "x,x,z", [[1, 0, 0], [0, 2, 0], [0, 0, 1]]):
        with pytest.raises(RecordingError, match="axes"):
            parse_axes(bad)


def test_rotate_quaternions_conjugates_rotations():
    from scipy.spatial.transform import Rotation

    rots = Rotation.random(20, random_state=3)
    q = rots.as_quat()[:, [3, 0, 1, 2]]
    for A in (parse_axes("-y,x,z"), parse_axes("x,-y,z"), parse_axes("z,x,y")):
        out = rotate_quaternions(q, A)
        got = Rotation.from_quat(out[:, [1, 2, 3, 0]]).as_matrix()
        want = A @ rots.as_matrix() @ A.T
        np.testing.assert_allclose(got, want, atol=1e-12)


def test_dropped_frames_and_regrid():
    times = np.array([0.0, 0.01, 0.02, 0.05, 0.06, 0.08])
    assert dropped_frames(times, 100.0) == [(0.02, 2), (0.06, 1)]
    rec = make_recording(n=6, names=("A",), audio_rate=None, with_gaps=False)
    rec.times = times + 0.0003  # clock jitter
    rec.metadata["dropped_frames"] = dropped_frames(rec.times, 100.0)
    regular = regrid_dropped_frames(rec)
    assert regular.n_samples == 9
    np.testing.assert_allclose(np.diff(regular.times), 0.01)
    filled = np.flatnonzero(~regular.valid("A"))
    assert filled.tolist() == [3, 4, 7]
    np.testing.assert_array_equal(regular.sensors["A"][[0, 1, 2, 5, 6, 8]], rec.sensors["A"])
    assert regular.orientations["A"].shape == (9, 4)
    assert regrid_dropped_frames(regular) is regular


def test_recording_on_uniform_grid_fills_the_real_gap():
    from tests.conftest import shared_file
    from tonguevis.io import read_recording

    rec = read_recording(shared_file("ema", "ndi_wave", "Example3.tsv"))
    regular = rec.on_uniform_grid()
    assert regular.n_samples == rec.n_samples + 1
    assert np.all(np.abs(np.diff(regular.times) - 0.01) < 1e-9)
    assert regular.valid_fraction("S0") == pytest.approx(100 / 101)


def test_atomic_write_gives_normal_permissions_and_keeps_the_old_file_on_failure(tmp_path):
    import os

    import pytest

    from tonguevis._files import atomic_write, atomic_write_text

    path = tmp_path / "out.csv"
    atomic_write_text(path, "a\n")
    mask = os.umask(0)
    os.umask(mask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~mask
    with pytest.raises(RuntimeError):
        atomic_write(path, lambda tmp: (tmp.write_text("half"), (_ for _ in ()).throw(RuntimeError("disk full"))))
    assert path.read_text() == "a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]
