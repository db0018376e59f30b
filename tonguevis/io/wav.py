"""WAV audio in and out (stdlib ``wave`` + NumPy; IEEE-float WAV by a small RIFF parser).

Reading gives mono float64 samples nominally in [-1, 1]: integer PCM is
divided by its full scale (8-bit unsigned, 16/24/32-bit signed); several
channels are averaged.  Writing is mono int16 PCM.
"""

from __future__ import annotations

import os
import struct
import wave
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis._files import atomic_write
from tonguevis.io.recording import Audio


def _pcm_to_float(raw: bytes, width: int, channels: int, path) -> np.ndarray:
    frame_bytes = width * channels
    usable = len(raw) - len(raw) % frame_bytes
    raw = raw[:usable]
    if width == 1:
        data = (np.frombuffer(raw, dtype=np.uint8).astype(np.float64) - 128.0) / 128.0
    elif width == 2:
        data = np.frombuffer(raw, dtype="<i2").astype(np.float64) / 32768.0
    elif width == 3:
        b = np.frombuffer(raw, dtype=np.uint8).reshape(-1, 3).astype(np.int32)
        ints = b[:, 0] | (b[:, 1] << 8) | (b[:, 2] << 16)
        ints = np.where(ints >= 1 << 23, ints - (1 << 24), ints)
        data = ints.astype(np.float64) / float(1 << 23)
    elif width == 4:
        data = np.frombuffer(raw, dtype="<i4").astype(np.float64) / float(1 << 31)
    else:
        raise RecordingError(f"unsupported WAV sample width of {width} bytes", path)
    return data.reshape(-1, channels).mean(axis=1)


def _read_float_wav(data: bytes, path) -> Audio:
    """IEEE-float (format 3, or extensible with a float subformat) WAV, which ``wave`` refuses."""
    if len(data) < 12 or data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise RecordingError("not a WAV file (no RIFF/WAVE header)", path)
    pos, fmt, payload = 12, None, None
    while pos + 8 <= len(data):
        cid, size = struct.unpack_from("<4sI", data, pos)
        body = data[pos + 8 : pos + 8 + size]
        if cid == b"fmt " and len(body) >= 16:
            fmt = struct.unpack_from("<HHIIHH", body, 0)
            if fmt[0] == 0xFFFE and len(body) >= 26:
                fmt = (struct.unpack_from("<H", body, 24)[0],) + fmt[1:]
        elif cid == b"data":
            payload = body
        pos += 8 + size + (size & 1)
    if fmt is None or payload is None:
        raise RecordingError("WAV file has no fmt or data chunk", path)
    tag, channels, rate, _, _, bits = fmt
    if tag != 3 or bits not in (32, 64) or channels < 1 or rate <= 0:
        raise RecordingError(f"unsupported WAV encoding (format tag {tag}, {bits} bits)", path)
    dtype = "<f4" if bits == 32 else "<f8"
    frame = channels * bits // 8
    payload = payload[: len(payload) - len(payload) % frame]
    samples = np.frombuffer(payload, dtype=dtype).astype(np.float64).reshape(-1, channels).mean(axis=1)
    return Audio(samples=samples, rate=float(rate))


def read_wav(path: str | os.PathLike) -> Audio:
    """Mono float64 audio from a WAV file (PCM 8/16/24/32-bit or IEEE float)."""
    path = Path(path)
    try:
        with wave.open(str(path), "rb") as w:
            channels, width, rate = w.getnchannels(), w.getsampwidth(), w.getframerate()
            raw = w.readframes(w.getnframes())
    except wave.Error as exc:
        if "unknown format: 3" in str(exc) or "unknown format: 65534" in str(exc):
            return _read_float_wav(path.read_bytes(), path)
        raise RecordingError(f"not a readable WAV file: {exc}", path) from None
    except (EOFError, struct.error) as exc:
        raise RecordingError(f"truncated or malformed WAV file: {exc}", path) from None
    if channels < 1 or rate <= 0:
        raise RecordingError(f"impossible WAV header ({channels} channels, {rate} Hz)", path)
    return Audio(samples=_pcm_to_float(raw, width, channels, path), rate=float(rate))


def write_wav(audio: Audio, path: str | os.PathLike) -> None:
    """Write mono int16 PCM (samples clipped to [-1, 1]) through a temporary file."""
    rate = int(round(audio.rate))
    if rate <= 0:
        raise RecordingError(f"cannot write audio at {audio.rate} Hz", path)
    samples = np.nan_to_num(np.asarray(audio.samples, dtype=np.float64).ravel())
    # Same full scale as the reader (32768) so a write-read round trip is exact to half a step.
    ints = np.clip(np.round(samples * 32768.0), -32768, 32767).astype("<i2")

    def write(tmp: Path) -> None:
        with wave.open(str(tmp), "wb") as w:
            w.setnchannels(1)
            w.setsampwidth(2)
            w.setframerate(rate)
            w.writeframes(ints.tobytes())

    atomic_write(path, write)
