"""WAV reading (PCM 8/16/24/32-bit, IEEE float, stereo) and the int16 writer."""

from __future__ import annotations

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
