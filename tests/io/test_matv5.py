"""Our MAT v5 reader against scipy.io.loadmat (the reference) on valid files, and on damage."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.io

from tests.conftest import shared_file
from tonguevis.io import RecordingError
from tonguevis.io.matv5 import MatStruct, read_mat5


def _same(ours, ref):
    """Compare a read_mat5 value with scipy's (MATLAB dtypes: mat_dtype=True) value."""
    if isinstance(ours, MatStruct):
        assert ref.dtype.names == tuple(ours.fields) and ref.shape == ours.shape
        for element, ref_element in zip(ours, ref.ravel(order="F")):
            for name in ours.fields:
                _same(element[name], ref_element[name])
    elif isinstance(ours, str):
        assert "\n".join(str(x) for x in np.atleast_1d(ref)) == ours
    elif isinstance(ours, list):
        assert ref.dtype == object and ref.size == len(ours)
        for value, ref_value in zip(ours, ref.ravel(order="F")):
            _same(value, ref_value)
    else:
        if ref.size == 0:
            assert ours.size == 0
            return
        assert ours.dtype == ref.dtype and ours.shape == ref.shape
        np.testing.assert_array_equal(ours, ref)


@pytest.mark.filterwarnings("ignore:Casting complex values to real")  # scipy, mat_dtype=True
@pytest.mark.parametrize("compress", [False, True])
def test_equals_scipy_on_many_classes(tmp_path, compress):
    labels = np.zeros((1, 2), dtype=[("LABEL", "O"), ("OFFS", "O")])
    labels[0, 0] = ("sp", np.array([[0.0, 0.2]]))
    labels[0, 1] = ("THE", np.array([[0.2, 0.27]]))
    variables = {
        "double": np.arange(12.0).reshape(3, 4), "single": np.float32([[1.5, -2.5]]),
        "ints": np.int16([[1, -2, 3]]), "u64": np.uint64([[2**40]]), "logical": np.array([[True, False]]),
        "complex": np.array([[1 + 2j, 3 - 4j]]), "text": "The birch canoe", "unicode": "héllo",
        "chars2d": np.array(["ab", "cd"]), "cell": np.array([[np.eye(2), "x"]], dtype=object),
        "cube": np.arange(24.0).reshape(2, 3, 4), "empty": np.zeros((0, 3)), "labels": labels,
    }
    path = tmp_path / "many.mat"
    scipy.io.savemat(str(path), variables, do_compression=compress)
    ours = read_mat5(path)
    ref = scipy.io.loadmat(str(path), squeeze_me=False, struct_as_record=True, mat_dtype=True)
    # loadmat(mat_dtype=True) drops imaginary parts (a scipy quirk): compare complex without it
    plain = scipy.io.loadmat(str(path), squeeze_me=False, struct_as_record=True)
    assert set(ours) == set(variables)
    for name in variables:
        _same(ours[name], plain[name] if name == "complex" else ref[name])


def test_equals_scipy_on_the_real_mview_file():
    path = shared_file("ema", "mview", "F01_B01_S01_R01_N.mat")
    ours = read_mat5(path)
    ref = scipy.io.loadmat(str(path), squeeze_me=False, struct_as_record=True, mat_dtype=True)
    name = "F01_B01_S01_R01_N"
    assert list(ours) == [name]
    _same(ours[name], ref[name])


@pytest.mark.parametrize("damage, message", [
    (lambda d: d[:100], "shorter than its 128-byte header"),
    (lambda d: d[:126] + b"XX" + d[128:], "endian indicator"),
    (lambda d: d[:-20], "cut short|claims|runs past"),
    (lambda d: d[:140] + bytes(b ^ 0x55 for b in d[140:160]) + d[160:], "does not inflate|cut short|claims"),
])
def test_damage_is_a_recording_error(tmp_path, damage, message):
    path = tmp_path / "d.mat"
    scipy.io.savemat(str(path), {"x": np.arange(50.0), "s": "text"}, do_compression=True)
    path.write_bytes(damage(path.read_bytes()))
    with pytest.raises(RecordingError, match=message) as info:
        read_mat5(path)
    assert str(path) in str(info.value)
