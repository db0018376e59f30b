"""WAV reading (PCM 8 to 64-bit, IEEE float, extensible headers, stereo, truncated files) and the int16 writer."""

from __future__ import annotations

import logging
import struct
import wave

import numpy as np
import pytest

from tonguevis.io import Audio, RecordingError
from tonguevis.io.wav import read_wav, write_wav

SIGNAL = 0.6 * np.sin(np.linspace(0, 20, 500))


def _pcm(path, ints: np.ndarray, width: int, channels: int = 1, rate: int = 16000):
    with wave.open(str(path), "wb") as w:
        w.setnchannels(channels)
        w.setsampwidth(width)
        w.setframerate(rate)
        if width == 3:
            raw = np.asarray(ints, dtype="<i4").view(np.uint8).reshape(-1, 4)[:, :3].tobytes()
        else:
            raw = np.asarray(ints).tobytes()
        w.writeframes(raw)


def _riff(path, fmt: bytes, data: bytes, extra: bytes = b"") -> None:
    """A WAV file from its fmt chunk's body and its data bytes (``extra``: chunks before data)."""
    pad = b"\x00" if len(data) % 2 else b""
    body = (b"WAVE" + b"fmt " + struct.pack("<I", len(fmt)) + fmt + extra
            + b"data" + struct.pack("<I", len(data)) + data + pad)
    path.write_bytes(b"RIFF" + struct.pack("<I", len(body)) + body)


def _extensible_fmt(subformat: int, channels: int, rate: int, width: int) -> bytes:
    """WAVE_FORMAT_EXTENSIBLE fmt body: PCM (1) or IEEE float (3) samples of ``width`` bytes."""
    guid = struct.pack("<H", subformat) + b"\x00\x00\x00\x00\x10\x00\x80\x00\x00\xaa\x00\x38\x9b\x71"
    block = channels * width
    return struct.pack("<HHIIHHHHI16s", 0xFFFE, channels, rate, rate * block, block, 8 * width, 22, 8 * width,
                       0, guid)


def _packed(ints: np.ndarray, width: int) -> bytes:
    """Little-endian signed integers stored in ``width`` bytes each."""
    return np.asarray(ints, dtype="<i8").view(np.uint8).reshape(-1, 8)[:, :width].tobytes()


def _float_wav(path, samples: np.ndarray, rate: int = 16000, extensible: bool = False):
    data = samples.astype("<f4").tobytes()
    if extensible:
        fmt = struct.pack("<HHIIHHHHI16s", 0xFFFE, 1, rate, rate * 4, 4, 32, 22, 32, 4,
                          struct.pack("<H", 3) + b"\x00\x00\x00\x00\x10\x00\x80\x00\x00\xaa\x00\x38\x9b\x71")
    else:
        fmt = struct.pack("<HHIIHH", 3, 1, rate, rate * 4, 4, 32)
    body = b"WAVE" + b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", len(data)) + data
    path.write_bytes(b"RIFF" + struct.pack("<I", len(body)) + body)


@pytest.mark.parametrize("width, scale, dtype", [(1, 128, np.uint8), (2, 32768, "<i2"), (3, 1 << 23, "<i4"), (4, 1 << 31, "<i4")])
def test_pcm_widths_scale_to_unit_range(tmp_path, width, scale, dtype):
    ints = np.round(SIGNAL * (scale - 1)).astype(np.int64)
    stored = ints + 128 if width == 1 else ints
    _pcm(tmp_path / "a.wav", stored.astype(dtype), width)
    audio = read_wav(tmp_path / "a.wav")
    assert audio.rate == 16000
    np.testing.assert_allclose(audio.samples, ints / scale, atol=1e-12)
    np.testing.assert_allclose(audio.samples, SIGNAL, atol=1.5 / scale + 1e-9)


def test_stereo_is_averaged(tmp_path):
    left = np.round(SIGNAL * 10000).astype("<i2")
    right = np.zeros_like(left)
    _pcm(tmp_path / "s.wav", np.column_stack([left, right]).ravel(), 2, channels=2)
    np.testing.assert_allclose(read_wav(tmp_path / "s.wav").samples, left / 32768 / 2)


@pytest.mark.parametrize("extensible", [False, True])
def test_float_wav(tmp_path, extensible):
    _float_wav(tmp_path / "f.wav", SIGNAL, extensible=extensible)
    audio = read_wav(tmp_path / "f.wav")
    np.testing.assert_allclose(audio.samples, SIGNAL.astype(np.float32), atol=0)


def test_writer_int16_round_trip_and_clipping(tmp_path):
    samples = np.concatenate([SIGNAL, [1.7, -3.0, np.nan]])
    write_wav(Audio(samples=samples, rate=22050), tmp_path / "w.wav")
    with wave.open(str(tmp_path / "w.wav")) as w:
        assert (w.getnchannels(), w.getsampwidth(), w.getframerate()) == (1, 2, 22050)
    back = read_wav(tmp_path / "w.wav")
    np.testing.assert_allclose(back.samples[:500], SIGNAL, atol=0.5 / 32768 + 1e-12)
    np.testing.assert_allclose(back.samples[500:], [32767 / 32768, -1.0, 0.0])


@pytest.mark.parametrize("width", [3, 5, 6, 8])
def test_extensible_pcm_of_any_width_stereo(tmp_path, width):
    full = 1 << (8 * width - 1)
    left = np.round(SIGNAL * (full - 1)).astype(np.int64)
    right = -left // 2
    frames = np.column_stack([left, right]).ravel()
    _riff(tmp_path / "e.wav", _extensible_fmt(1, 2, 44100, width), _packed(frames, width))
    audio = read_wav(tmp_path / "e.wav")
    assert audio.rate == 44100
    np.testing.assert_allclose(audio.samples, (left + right) / 2 / full, atol=1e-12)


def test_float_written_by_scipy(tmp_path):
    from scipy.io import wavfile

    for dtype in (np.float32, np.float64):
        wavfile.write(tmp_path / "f.wav", 8000, SIGNAL.astype(dtype))
        audio = read_wav(tmp_path / "f.wav")
        assert audio.samples.dtype == np.float32 and audio.rate == 8000  # float32 kept whole, float64 rounded
        np.testing.assert_allclose(audio.samples, SIGNAL.astype(dtype), atol=0 if dtype == np.float32 else 6e-8)


def test_chunks_scipy_skips_are_not_a_warning(tmp_path, caplog):
    ints = np.round(SIGNAL * 10000).astype("<i2")
    bext = b"bext" + struct.pack("<I", 4) + b"abcd"  # Broadcast WAV metadata, as field recorders write it
    _riff(tmp_path / "b.wav", struct.pack("<HHIIHH", 1, 1, 16000, 32000, 2, 16), ints.tobytes(), extra=bext)
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        audio = read_wav(tmp_path / "b.wav")
    np.testing.assert_allclose(audio.samples, ints / 32768)
    assert not caplog.records


def test_truncated_wav_keeps_the_samples_present_with_a_warning(tmp_path, caplog):
    ints = np.round(SIGNAL * 10000).astype("<i2")
    _pcm(tmp_path / "cut.wav", ints, 2)
    whole = (tmp_path / "cut.wav").read_bytes()
    (tmp_path / "cut.wav").write_bytes(whole[: 44 + 2 * 300])  # the copy stopped after 300 samples
    with caplog.at_level(logging.WARNING, logger="tonguevis"):
        audio = read_wav(tmp_path / "cut.wav")
    np.testing.assert_allclose(audio.samples, ints[:300] / 32768)
    assert "cut.wav" in caplog.text and "truncated" in caplog.text and "300 samples" in caplog.text


@pytest.mark.parametrize("keep", [44, 44 + 3 * 100 + 1])
def test_truncated_wav_without_whole_samples_is_a_recording_error(tmp_path, keep):
    """Cut right after the header (no sample at all), or inside a 24-bit sample."""
    _pcm(tmp_path / "t.wav", np.round(SIGNAL * 1000).astype("<i4"), 3)
    whole = (tmp_path / "t.wav").read_bytes()
    (tmp_path / "t.wav").write_bytes(whole[:keep])
    with pytest.raises(RecordingError, match=r"t\.wav.*truncated WAV file"):
        read_wav(tmp_path / "t.wav")


def test_bad_wav_is_a_recording_error(tmp_path):
    bad = tmp_path / "bad.wav"
    bad.write_bytes(b"RIFF\x10\x00\x00\x00WAVEjunk")
    with pytest.raises(RecordingError, match="bad.wav"):
        read_wav(bad)
    _pcm(tmp_path / "t.wav", np.zeros(100, "<i2"), 2)
    cut = tmp_path / "t.wav"
    cut.write_bytes(cut.read_bytes()[:30])
    with pytest.raises(RecordingError, match="t.wav"):
        read_wav(cut)
    mulaw = tmp_path / "mulaw.wav"
    _riff(mulaw, struct.pack("<HHIIHH", 7, 1, 8000, 8000, 1, 8), b"\x01\x02")
    with pytest.raises(RecordingError, match="mulaw.wav"):
        read_wav(mulaw)
    silent = tmp_path / "nochannels.wav"
    _riff(silent, struct.pack("<HHIIHH", 1, 0, 8000, 0, 0, 16), b"\x01\x02")
    with pytest.raises(RecordingError, match="nochannels.wav"):
        read_wav(silent)
