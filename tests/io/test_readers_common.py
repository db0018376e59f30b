"""The test every reader must pass (after MNE's ``_test_raw_reader``), on generated examples."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from tests.io.examples import MAKERS
from tonguevis.io import RecordingError, detect_format, read_recording

REQUIRED_METADATA = ("format", "file", "original_unit", "dropped_frames")


@pytest.fixture(params=sorted(MAKERS))
def example(request, tmp_path):
    return MAKERS[request.param](tmp_path)


def check_recording(rec, n_expected=None):
    """Invariants of every Recording a reader returns."""
    assert rec.rate > 0 and np.isfinite(rec.rate)
    assert rec.times.dtype == np.float64 and rec.times.ndim == 1
    n = rec.n_samples
    assert n >= 1
    if n_expected is not None:
        assert n == n_expected
    assert np.all(np.isfinite(rec.times))
    assert np.all(np.diff(rec.times) > 0), "times must increase"
    if n > 2:
        assert np.median(np.diff(rec.times)) == pytest.approx(1.0 / rec.rate, rel=1e-3)
    assert rec.sensors, "at least one sensor"
    for name, xyz in rec.sensors.items():
        assert isinstance(name, str) and name
        assert xyz.shape == (n, 3) and xyz.dtype == np.float64
        # a sample is all-finite or all-NaN: validity is per sample, never half a point
        finite = np.isfinite(xyz)
        assert np.all(finite.all(axis=1) | (~finite).all(axis=1))
    for name, orient in rec.orientations.items():
        assert name in rec.sensors and orient.shape[0] == n
    for key in REQUIRED_METADATA:
        assert key in rec.metadata, key
    if rec.audio is not None:
        # float audio (MVIEW) may exceed [-1, 1]; only shape, type and rate are promised
        assert rec.audio.samples.ndim == 1 and rec.audio.samples.dtype == np.float32 and rec.audio.rate > 0


def test_reader_returns_truth_in_metres(example):
    rec = read_recording(example.path, **example.options)
    check_recording(rec)
    assert rec.metadata["format"] == example.fmt
    assert rec.metadata["file"] == str(example.path)
    assert rec.rate == pytest.approx(example.rate, rel=1e-6)
    # Read without a sensor map, a channel name that could mean two things gets one meaning
    # (MVIEW's TR is the Haskins tongue rear, TBK): sensor_map.resolve_two_meanings.
    meanings = rec.metadata.get("channel_meanings", {})
    assert meanings == ({"TR": "TBK"} if example.fmt == "mview" and "TR" in example.truth else meanings)
    expected = {meanings.get(name, name): truth for name, truth in example.truth.items()}
    assert set(rec.sensors) == set(expected)
    for name, truth in expected.items():
        np.testing.assert_allclose(rec.sensors[name], truth, atol=2e-9, equal_nan=True, err_msg=name)
        assert np.array_equal(rec.valid(name), np.all(np.isfinite(truth), axis=1))
    assert rec.metadata["original_unit"] == "mm"


def test_dispatch_by_content_ignores_the_extension(example, tmp_path):
    if not example.content_dispatch:
        pytest.skip("headerless AG500 files have no signature; only the .pos extension says what they are")
    renamed = tmp_path / "renamed" / "recording.dat"
    renamed.parent.mkdir()
    shutil.copy(example.path, renamed)
    assert detect_format(renamed).name == example.fmt
    assert detect_format(example.path).name == example.fmt


def test_sensor_map_renames_and_rejects_missing_channels(example):
    first = next(iter(example.truth))
    rec = read_recording(example.path, sensor_map={"TD": example.map_value}, **example.options)
    assert "TD" in rec.sensors and first not in rec.sensors
    assert len(rec.sensors) == len(example.truth)  # the others keep their default names
    np.testing.assert_allclose(rec.sensors["TD"], example.truth[first], atol=2e-9, equal_nan=True)
    assert rec.metadata["sensor_map"] == {"TD": example.map_value}
    with pytest.raises(RecordingError, match="NOPE"):
        read_recording(example.path, sensor_map={"TL": "NOPE"}, **example.options)
    # giving a canonical name that an unmapped channel already carries is refused
    other = list(example.truth)[1]
    with pytest.raises(RecordingError, match=f"{other}.*map them too"):
        read_recording(example.path, sensor_map={other: example.map_value}, **example.options)


def test_unknown_option_is_a_recording_error(example):
    with pytest.raises(RecordingError, match="unexpected keyword"):
        read_recording(example.path, no_such_option=1)


def test_empty_file_of_each_extension(example, tmp_path):
    empty = tmp_path / ("empty" + example.path.suffix)
    empty.write_bytes(b"")
    with pytest.raises(RecordingError) as info:
        read_recording(empty)
    assert str(empty) in str(info.value)


TEXT_FORMATS = ["est_ascii", "ndi_wave", "bvh", "csv_wide", "csv_long"]


@pytest.mark.parametrize("kind", TEXT_FORMATS)
def test_truncated_last_line_loses_only_that_line(kind, tmp_path, caplog):
    """A file cut inside its last number drops that sample with a warning; one merely
    missing its final newline keeps everything."""
    example = MAKERS[kind](tmp_path)
    full = read_recording(example.path, **example.options)
    data = example.path.read_bytes()
    per_frame = 3 if kind == "csv_long" else 1  # the long layout has a line per sensor
    example.path.write_bytes(data.rstrip(b"\n"))
    whole = read_recording(example.path, **example.options)
    assert whole.n_samples == full.n_samples
    assert "truncated" not in caplog.text and "cut inside" not in caplog.text
    example.path.write_bytes(data.rstrip()[:-2])
    cut = read_recording(example.path, **example.options)
    assert "dropped" in caplog.text
    if per_frame == 1:
        assert cut.n_samples == full.n_samples - 1
        for name in full.sensors:
            np.testing.assert_array_equal(cut.sensors[name], full.sensors[name][:-1])
    else:  # the last sensor of the last frame becomes missing, the others stay
        assert cut.n_samples == full.n_samples
        last = full.sensor_names[-1]
        assert not cut.valid(last)[-1] and cut.valid(full.sensor_names[0])[-1]
