"""WAV audio in and out, through :mod:`scipy.io.wavfile`.

Reading gives mono samples (float32 in the Audio) nominally in [-1, 1]: integer PCM of any
width (8-bit unsigned, 16 to 64-bit signed, WAVE_FORMAT_EXTENSIBLE too) is
divided by its container's full scale, IEEE float is taken as is; several
channels are averaged.  A file cut short keeps the samples present, with a
warning; one that cannot be read raises :class:`RecordingError` naming it.
Writing is mono int16 PCM (:func:`write_wav`), or any number of IEEE float32 channels
(:func:`write_wav_channels`: the EMA beside the sound, as ``tonguevis export-wav`` writes it).
"""

from __future__ import annotations

import logging
import os
import struct
import warnings
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis._files import atomic_write
from tonguevis.io.recording import Audio

from tonguevis._logging import logger

#: What scipy raises on a file it cannot parse (a cut header, zero channels, a frame cut in half).
_PARSE_ERRORS = (ValueError, struct.error, EOFError, ZeroDivisionError, OverflowError, IndexError)


def _announced_size(path: Path) -> int | None:
    """Bytes the RIFF header says the file has (None when there is no RIFF header)."""
    with open(path, "rb") as f:
        head = f.read(8)
    if len(head) < 8 or head[:4] not in (b"RIFF", b"RIFX"):
        return None
    return struct.unpack("<I" if head[:4] == b"RIFF" else ">I", head[4:])[0] + 8


def _truncation(path: Path) -> str | None:
    """'N of the M bytes its header announces' when the file is shorter than its header says."""
    announced, size = _announced_size(path), path.stat().st_size
    if announced is None or size >= announced:
        return None
    return f"{size} of the {announced} bytes its header announces"


def _to_unit_float(data: np.ndarray, path) -> np.ndarray:
    """Samples as float64 in [-1, 1] (integer PCM divided by its container's full scale)."""
    kind = data.dtype.kind
    if kind == "u":  # 8-bit PCM is unsigned around 128
        half = float(1 << (8 * data.dtype.itemsize - 1))
        return (data.astype(np.float64) - half) / half
    if kind == "i":  # scipy left-justifies 24/40/48/56-bit samples in int32/int64
        return data.astype(np.float64) / float(1 << (8 * data.dtype.itemsize - 1))
    if kind == "f":
        return data.astype(np.float64)
    raise RecordingError(f"unsupported WAV sample type {data.dtype}", path)


def read_wav(path: str | os.PathLike) -> Audio:
    """Mono float64 audio from a WAV file (integer PCM of any width or IEEE float)."""
    from scipy.io import wavfile

    path = Path(path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", wavfile.WavFileWarning)
        try:
            rate, data = wavfile.read(path, mmap=False)
        except _PARSE_ERRORS as exc:
            cut = _truncation(path)
            if cut is not None:
                raise RecordingError(f"truncated WAV file ({cut}): {exc}", path) from None
            raise RecordingError(f"not a readable WAV file: {exc}", path) from None
    cut = _truncation(path)  # decided from the sizes, not from the wording of scipy's warning
    for warning in caught:
        if not issubclass(warning.category, wavfile.WavFileWarning):
            warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
        elif cut is None:  # said once below when the file is cut short
            # A chunk scipy skips (bext, iXML, ...) loses nothing; anything else odd is worth a warning.
            level = logging.INFO if "not understood" in str(warning.message) else logging.WARNING
            logger.log(level, "%s: %s", path, warning.message)
    if rate <= 0:
        raise RecordingError(f"impossible WAV header ({rate} Hz)", path)
    samples = _to_unit_float(data, path)
    if samples.ndim == 2:
        samples = samples.mean(axis=1)
    if cut is not None:
        if len(samples) == 0:
            raise RecordingError(f"truncated WAV file ({cut}): no complete sample", path)
        logger.warning("%s: truncated WAV file (%s); using the %d samples present", path, cut, len(samples))
    return Audio(samples=samples, rate=float(rate))


def write_wav(audio: Audio, path: str | os.PathLike) -> None:
    """Write mono int16 PCM (samples clipped to [-1, 1]) through a temporary file."""
    from scipy.io import wavfile

    rate = int(round(audio.rate))
    if rate <= 0:
        raise RecordingError(f"cannot write audio at {audio.rate} Hz", path)
    samples = np.nan_to_num(np.asarray(audio.samples, dtype=np.float64).ravel())
    # Same full scale as the reader (32768) so a write-read round trip is exact to half a step.
    ints = np.clip(np.round(samples * 32768.0), -32768, 32767).astype("<i2")
    atomic_write(path, lambda tmp: wavfile.write(tmp, rate, ints))


def write_wav_channels(channels: np.ndarray, rate: float, path: str | os.PathLike) -> None:
    """Write (n, c) samples as a c-channel IEEE float32 WAV (values as they are, not clipped: Praat and
    scipy read them back unchanged) through a temporary file."""
    from scipy.io import wavfile

    rate_hz = int(round(rate))
    data = np.asarray(channels, dtype="<f4")
    if rate_hz <= 0 or abs(rate_hz - rate) > 1e-6 * rate:
        raise RecordingError(f"cannot write a WAV at {rate} Hz (a whole number of samples per second)", path)
    if data.ndim != 2 or data.shape[1] < 1:
        raise RecordingError(f"a multichannel WAV needs (samples, channels) data, got shape {data.shape}", path)
    if not np.isfinite(data).all():
        raise RecordingError("a WAV cannot hold NaN or infinite samples (fill the gaps first)", path)
    atomic_write(path, lambda tmp: wavfile.write(tmp, rate_hz, data))
