"""Edinburgh Speech Tools EST_Track files, ascii and binary (mngu0, MOCHA-TIMIT ``.ema``).

Header: ``EST_File Track`` then ``Key value`` lines (``DataType ascii|binary``,
``ByteOrder 01`` little-endian / ``10`` big-endian, ``NumFrames``,
``NumChannels``, ``BreaksPresent``, ``Channel_<i> <name>`` ...) up to
``EST_Header_End``.  Each frame: time (s), a break flag when
``BreaksPresent true`` (0 = no data in that frame), then the channels; binary
files store them as float32.

Channels are grouped into coils by the name before the last underscore
(``T1_px`` -> coil ``T1``), which names the sensor.  Position channels end in
x/y/z (``_X``, ``_px``, ``_posx`` ...), orientation channels in phi/theta or
ox/oy/oz; the rest (rms, extra ...) go to ``metadata['extra_channels']``.
Coils with only x and y (2-D midsagittal data such as MOCHA-TIMIT) get z = 0 and
are listed in ``metadata['two_dimensional']``.  The files do not record the
length unit: ``unit=`` (default ``"mm"``, mngu0's) says it; positions stay in
the articulograph's frame unless ``axes=`` maps them to ours.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io._common import (
    check_times, dropped_frames, estimate_rate, parse_axes, parse_number_table, read_bytes,
    unit_scale, unterminated_row_complete,
)
from tonguevis.io.recording import Recording
from tonguevis.io.registry import RecordingFormat, register_format

from tonguevis._logging import logger

HEADER_END = b"EST_Header_End"
MAX_CHANNELS = 100_000
_POSITION = {"x": 0, "y": 1, "z": 2, "px": 0, "py": 1, "pz": 2, "posx": 0, "posy": 1, "posz": 2}
_ORIENTATION = ("phi", "theta", "ox", "oy", "oz")


def sniff(head: bytes, path: Path) -> bool:
    return head.startswith(b"EST_File Track")


def channel_name(value) -> str:
    """An EST coil number (3) -> the artk/Carstens-style prefix "Ch3"; names pass through."""
    return f"Ch{int(value)}"


def _header(data: bytes, path) -> tuple[dict[str, str], dict[int, str], int]:
    """(key -> value, channel index -> name, byte offset of the data)."""
    end = data.find(HEADER_END)
    if end < 0:
        raise RecordingError("no EST_Header_End line: header cut short or not an EST_Track file", path)
    newline = data.find(b"\n", end)
    offset = len(data) if newline < 0 else newline + 1
    try:
        text = data[:end].decode("ascii")
    except UnicodeDecodeError:
        raise RecordingError("EST header contains non-ASCII bytes", path) from None
    lines = text.splitlines()
    if not lines or lines[0].split() != ["EST_File", "Track"]:
        raise RecordingError("first line is not 'EST_File Track'", path)
    keys, channels = {}, {}
    for line in lines[1:]:
        key, _, value = line.strip().partition(" ")
        if not key:
            continue
        m = re.fullmatch(r"Channel_(\d+)", key)
        if m:
            channels[int(m.group(1))] = value.strip()
        else:
            keys[key] = value.strip()
    return keys, channels, offset


def _int_key(keys: dict, name: str, path, default=None) -> int:
    if name not in keys:
        if default is not None:
            return default
        raise RecordingError(f"EST header lacks {name}", path)
    try:
        value = int(keys[name])
    except ValueError:
        raise RecordingError(f"EST header {name} {keys[name]!r} is not an integer", path) from None
    if value < 0:
        raise RecordingError(f"impossible EST header value {name} {value}", path)
    return value


def _ascii_frames(data: bytes, offset: int, width: int, path) -> np.ndarray:
    lines = data[offset:].decode("ascii", errors="replace").splitlines()
    first_line = data[:offset].count(b"\n") + 1
    rows, numbers = [], []
    for i, line in enumerate(lines):
        if line.strip():
            rows.append(line.split())
            numbers.append(first_line + i)
    ended = data.endswith((b"\n", b"\r"))
    if rows and len(rows[-1]) < width:
        logger.warning("%s: dropped the incomplete last line %d (file truncated?)", path, numbers[-1])
        rows.pop()
    for row, line_no in zip(rows, numbers):
        if len(row) != width:
            raise RecordingError(f"line {line_no} has {len(row)} fields, expected {width}", path)
    if not ended and rows and not unterminated_row_complete(rows[-1], rows[-2] if len(rows) > 1 else None):
        logger.warning("%s: dropped the unterminated last line %d, cut inside a number", path, numbers[len(rows) - 1])
        rows.pop()
    return parse_number_table(rows, path, numbers[0] if numbers else first_line).reshape(len(rows), width)


def read_est_track(path, unit: str = "mm", axes=None) -> Recording:
    """Read an EST_Track file (ascii or binary); see the module docstring."""
    path = Path(path)
    data = read_bytes(path)
    if not data:
        raise RecordingError("empty file", path)
    keys, names, offset = _header(data, path)
    n_frames = _int_key(keys, "NumFrames", path)
    n_channels = _int_key(keys, "NumChannels", path)
    n_aux = _int_key(keys, "NumAuxChannels", path, default=0)
    if not 1 <= n_channels <= MAX_CHANNELS:
        raise RecordingError(f"impossible NumChannels {n_channels}", path)
    if sorted(names) != list(range(n_channels)):
        raise RecordingError(f"Channel_<i> names do not cover 0..{n_channels - 1}", path)
    breaks = keys.get("BreaksPresent", "false").lower() == "true"
    width = 1 + int(breaks) + n_channels
    kind = keys.get("DataType", "ascii").lower()
    scale = unit_scale(unit, path)
    if kind == "binary":
        if n_aux:
            raise RecordingError("binary EST_Track with auxiliary channels is not supported", path)
        order = keys.get("ByteOrder", "01")
        if order not in ("01", "10"):
            raise RecordingError(f"unknown ByteOrder {order!r} (expected 01 or 10)", path)
        dtype = "<f4" if order == "01" else ">f4"
        body = data[offset:]
        got, partial = divmod(len(body), 4 * width)
        if partial:
            logger.warning("%s: dropped a partial last frame of %d bytes (file truncated?)", path, partial)
        with np.errstate(invalid="ignore"):  # signalling-NaN payloads in damaged files
            table = np.frombuffer(body[: got * 4 * width], dtype=dtype).astype(np.float64).reshape(got, width)
    elif kind == "ascii":
        table = _ascii_frames(data, offset, width + n_aux, path)[:, :width]
    else:
        raise RecordingError(f"unknown DataType {kind!r} (expected ascii or binary)", path)
    if table.shape[0] == 0:
        raise RecordingError("no complete frame after the header", path)
    if table.shape[0] > n_frames:
        raise RecordingError(f"{table.shape[0]} frames but the header says NumFrames {n_frames}", path)
    if table.shape[0] < n_frames:
        logger.warning("%s: %d of the %d frames the header announces are present", path, table.shape[0], n_frames)
    times = table[:, 0]
    check_times(times, path, "EST frame time")
    values = table[:, 1 + int(breaks):].copy()
    if breaks:
        values[table[:, 1] == 0] = np.nan
    rate = estimate_rate(times, default=_float_key(keys, path), path=path)
    A = parse_axes(axes, path)
    coils: dict[str, dict] = {}
    extra = {}
    for index in range(n_channels):
        name = names[index]
        coil, _, suffix = name.rpartition("_")
        suffix_l = suffix.lower()
        if coil and suffix_l in _POSITION:
            coils.setdefault(coil, {"pos": {}, "orient": {}})["pos"][_POSITION[suffix_l]] = index
        elif coil and suffix_l in _ORIENTATION:
            coils.setdefault(coil, {"pos": {}, "orient": {}})["orient"][suffix_l] = index
        else:
            extra[name] = values[:, index].copy()
    sensors, orientations, two_d = {}, {}, []
    for coil, parts in coils.items():
        pos = parts["pos"]
        if 0 not in pos or 1 not in pos:
            for key, idx in list(pos.items()) + list(parts["orient"].items()):
                extra[names[idx]] = values[:, idx].copy()
            continue
        xyz = np.zeros((len(times), 3))
        for axis, idx in pos.items():
            xyz[:, axis] = values[:, idx] * scale
        if 2 not in pos:
            two_d.append(coil)
        xyz[~np.all(np.isfinite(xyz), axis=1)] = np.nan
        sensors[coil] = xyz @ A.T
        if parts["orient"]:
            orientations[coil] = np.column_stack([values[:, i] for i in parts["orient"].values()])
    if not sensors:
        raise RecordingError("no coil has x and y position channels (names like T1_px or Ch1_X)", path)
    metadata = {
        "format": "est_track",
        "file": str(path),
        "original_unit": unit,
        "est_data_type": kind,
        "frame": "device" if axes is None else "tonguevis",
        "axes": A.tolist(),
        "orientation_kind": "est_channels",
        "orientation_channels": {c: list(p["orient"]) for c, p in coils.items() if c in sensors},
        "extra_channels": extra,
        "two_dimensional": two_d,
        "dropped_frames": dropped_frames(times, rate),
    }
    return Recording(rate=rate, times=times.copy(), sensors=sensors, orientations=orientations, metadata=metadata)


def _float_key(keys: dict, path) -> float | None:
    """A rate from the header's ``Sample_Rate`` or ``SampleRate`` when present (else None)."""
    for key in ("Sample_Rate", "SampleRate", "sample_rate"):
        if key in keys:
            try:
                value = float(keys[key])
            except ValueError:
                raise RecordingError(f"EST header {key} {keys[key]!r} is not a number", path) from None
            if value > 0 and np.isfinite(value):
                return value
    return None


register_format(RecordingFormat(
    name="est_track",
    description="Edinburgh Speech Tools EST_Track, ascii or binary (mngu0, MOCHA-TIMIT .ema)",
    extensions=(".ema", ".est"),
    sniff=sniff,
    read=read_est_track,
    channel_name=channel_name,
))
