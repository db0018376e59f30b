"""Carstens AG500 / AG501 ``.pos`` files (read).

Both hold little-endian float32 frames of 7 values per channel: x, y, z (mm),
phi, theta (degrees), rms, extra.

* AG501 (and later AG500 software) files start with a text header:
  ``AG50xDATA_V00n`` (n = 1, 2 or 3), the header length in bytes (8 digits),
  ``NumberOfChannels=``, ``SamplingFrequencyHz=``, padding; data follow at
  that byte offset.
* Old AG500 files are headerless.  Give ``channels=`` (and ``rate=``, default
  200 Hz, the AG500's rate).  Without ``channels`` the reader assumes the
  AG500's 12 channels when the file size is a whole number of 12-channel
  frames and asks for ``channels=`` otherwise.

Sensors are named ``CH1`` ... counted from 1; positions stay in the
articulograph's frame (the file does not say how the head sat in it) unless
``axes=`` maps it to ours (x anterior, y left, z up).  Orientations are (N, 2)
phi, theta in degrees in the device frame; ``metadata['rms']`` holds the
(N, channels) fit residuals.  NaN samples stay NaN.  Frame k is at k / rate s.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io._common import parse_axes, read_bytes
from tonguevis.io.recording import Recording
from tonguevis.io.registry import RecordingFormat, register_format

from tonguevis._logging import logger

MAGIC = b"AG50xDATA_V00"
VALUES_PER_CHANNEL = 7
AG500_CHANNELS = 12
AG500_RATE = 200.0
MAX_CHANNELS = 64


def sniff(head: bytes, path: Path) -> bool:
    return head.startswith(MAGIC)


def channel_name(value) -> str:
    """Carstens channel number counted from 1 (5 or "5") -> "CH5"."""
    return f"CH{int(value)}"


def _parse_header(data: bytes, path) -> tuple[int, int, float, int]:
    """(version, header bytes, channels, rate) of an AG50x text header."""
    lines = data[:512].split(b"\n")
    if len(lines) < 5:
        raise RecordingError("AG50x header is cut short (needs 4 lines)", path)
    m = re.fullmatch(rb"AG50xDATA_V00([1-9])\r?", lines[0])
    if not m:
        raise RecordingError(f"bad AG50x magic line {lines[0][:20]!r}", path)
    version = int(m.group(1))
    if version > 3:
        raise RecordingError(f"unknown AG50x version V00{version} (known: V001-V003)", path)
    try:
        header_bytes = int(lines[1].strip())
    except ValueError:
        raise RecordingError(f"AG50x header length {lines[1][:20]!r} is not a number", path) from None
    fields = {}
    for line in lines[2:4]:
        key, _, value = line.strip().partition(b"=")
        fields[key.decode("latin-1")] = value
    try:
        channels = int(fields["NumberOfChannels"])
        rate = float(fields["SamplingFrequencyHz"])
    except (KeyError, ValueError):
        raise RecordingError(
            "AG50x header lacks a numeric NumberOfChannels= or SamplingFrequencyHz= line", path
        ) from None
    if not 1 <= channels <= MAX_CHANNELS:
        raise RecordingError(f"impossible NumberOfChannels={channels}", path)
    if not (0 < rate < 100_000):
        raise RecordingError(f"impossible SamplingFrequencyHz={rate}", path)
    if not (sum(len(x) + 1 for x in lines[:4]) <= header_bytes <= len(data)):
        raise RecordingError(
            f"AG50x header length {header_bytes} is impossible for a file of {len(data)} bytes", path
        )
    return version, header_bytes, channels, rate


def read_carstens(path, channels: int | None = None, rate: float | None = None, axes=None) -> Recording:
    """Read an AG500 (headerless) or AG501 (V001-V003 header) ``.pos`` file; see the module docstring."""
    path = Path(path)
    data = read_bytes(path)
    if not data:
        raise RecordingError("empty file", path)
    if data.startswith(MAGIC[:5]):
        version, offset, n_channels, header_rate = _parse_header(data, path)
        if channels is not None and int(channels) != n_channels:
            raise RecordingError(f"channels={channels} contradicts the header's NumberOfChannels={n_channels}", path)
        rate = header_rate if rate is None else float(rate)
        kind = f"AG50x V00{version}"
    else:
        offset, kind = 0, "AG500 headerless"
        rate = AG500_RATE if rate is None else float(rate)
        if channels is None:
            frame = AG500_CHANNELS * VALUES_PER_CHANNEL * 4
            if len(data) % frame:
                raise RecordingError(
                    f"headerless Carstens file of {len(data)} bytes is not a whole number of "
                    f"{AG500_CHANNELS}-channel frames; pass channels= (the number of channels recorded)",
                    path,
                )
            n_channels = AG500_CHANNELS
        else:
            n_channels = int(channels)
            if not 1 <= n_channels <= MAX_CHANNELS:
                raise RecordingError(f"impossible channels={channels}", path)
    if not np.isfinite(rate) or rate <= 0:
        raise RecordingError(f"impossible sample rate {rate} Hz", path)
    frame_bytes = n_channels * VALUES_PER_CHANNEL * 4
    body = data[offset:]
    n_frames, partial = divmod(len(body), frame_bytes)
    if n_frames == 0:
        raise RecordingError(f"no complete frame ({len(body)} data bytes, a frame has {frame_bytes})", path)
    if partial:
        logger.warning("%s: dropped a partial last frame of %d bytes (file truncated?)", path, partial)
    with np.errstate(invalid="ignore"):  # signalling-NaN payloads in damaged files
        values = np.frombuffer(body[: n_frames * frame_bytes], dtype="<f4").astype(np.float64)
    values = values.reshape(n_frames, n_channels, VALUES_PER_CHANNEL)
    A = parse_axes(axes, path)
    xyz = values[:, :, :3] * 0.001
    bad = ~np.all(np.isfinite(xyz), axis=2)
    xyz[bad] = np.nan
    xyz = xyz @ A.T
    sensors = {channel_name(c + 1): xyz[:, c].copy() for c in range(n_channels)}
    angles = values[:, :, 3:5].copy()
    angles[bad] = np.nan
    orientations = {channel_name(c + 1): angles[:, c] for c in range(n_channels)}
    metadata = {
        "format": "carstens",
        "carstens_kind": kind,
        "file": str(path),
        "original_unit": "mm",
        "frame": "device" if axes is None else "tonguevis",
        "axes": A.tolist(),
        "orientation_kind": "carstens_phi_theta_deg",
        "rms": values[:, :, 5].copy(),
        "dropped_frames": [],
        "truncated": bool(partial),
    }
    times = np.arange(n_frames) / rate
    return Recording(rate=rate, times=times, sensors=sensors, orientations=orientations, metadata=metadata)


register_format(RecordingFormat(
    name="carstens",
    description="Carstens AG500 (headerless; channels=) and AG501 AG50xDATA_V001-V003 .pos",
    extensions=(".pos",),
    sniff=sniff,
    read=read_carstens,
    channel_name=channel_name,
))
