"""NDI Wave (WaveFront) TSV export, read and write (the writer adds the WAV).

Layout (one header line, then one tab-separated row per frame)::

    AudioTime[s] MeasId WavId  then per sensor:
    Sensor k Id  Sensor k Status  X[mm] Y[mm] Z[mm] Q0 Qx Qy Qz

* The sensor is named ``S<Id>`` from the **Id column**; the header's ``k`` does
  not always match it (in real exports k = Id + 1, and missing ports are skipped).
* Status 55 means OK; any other status, or empty fields, makes that sample NaN.
* Positions are converted from the header's unit (mm) to metres.  NDI Wave
  positions are in the field generator's frame, whose orientation relative to
  the head the file does not record: by default the reader returns that
  **device frame unchanged** (``metadata['frame'] == 'device'``).  Pass
  ``axes="-y,x,z"`` (or a 3 x 3 matrix, ours = A @ device) to map it to ours
  (x anterior, y left, z up); quaternions (w, x, y, z) are rotated to match.
* Frames the system dropped show as time gaps; they are listed in
  ``metadata['dropped_frames']`` as (time before the gap, frames missing).
  The samples are not re-gridded.
* The paired WAV (``x.tsv`` -> ``x.wav``, first sample at AudioTime 0) is attached
  by :func:`~tonguevis.io.registry.read_recording`, as for every format (see
  :mod:`tonguevis.io.companions`); this reader reads the TSV only.
* ``metadata['ndi_status']`` is the (N, S) int status of every sample (-1 where
  empty), columns in the order of ``metadata['ndi_ids']``; ``metadata['meas_id']``
  the (N,) MeasId column.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis._files import atomic_write
from tonguevis.io._common import (
    check_times, format_rows, decode_text, dropped_frames, estimate_rate, parse_axes,
    parse_number_table, read_bytes, rotate_quaternions, split_lines, unit_scale, unterminated_row_complete,
)
from tonguevis.io.fast_table import plain_table
from tonguevis.io.recording import Audio, Recording
from tonguevis.io.registry import RecordingFormat, register_format
from tonguevis.io.wav import write_wav

from tonguevis._logging import logger

STATUS_OK = 55
STATUS_MISSING = 119
NOMINAL_RATE = 100.0
PARSE_ROWS = 5000  # data rows turned into numbers at a time (bounds the reader's Python objects)
DEFAULT_AUDIO_RATE = 22050.0

_SENSOR_ID = re.compile(r"^Sensor\s*(\d+)\s*Id$", re.IGNORECASE)
_UNIT = re.compile(r"\[(\w+)\]")


def sniff(head: bytes, path: Path) -> bool:
    first = head.split(b"\n", 1)[0]
    return b"\t" in first and re.search(rb"Sensor\s*\d+\s*Id", first) is not None


def channel_name(value) -> str:
    """Sensor-map value (an NDI Id such as 3 or "3") -> default name "S3"."""
    return f"S{int(value)}"


def _parse_header(header: list[str], path) -> tuple[list[dict], str]:
    """Sensor blocks (Id column, Status column, X/Y/Z columns, Q columns) and the length unit."""
    starts = [i for i, h in enumerate(header) if _SENSOR_ID.match(h.strip())]
    if not starts:
        raise RecordingError("header has no 'Sensor N Id' column; not an NDI Wave TSV export", path)
    if starts[0] == 0:
        raise RecordingError("header has no time column before the first sensor block", path)
    for i, label in enumerate(header[: starts[0]]):
        if re.search(r"sensor|status|\[", label, re.IGNORECASE) and i > 0:
            raise RecordingError(
                f"header column {i + 1} {label.strip()!r} lies outside a sensor block "
                "(expected a 'Sensor N Id' column before it)", path)
    blocks, units = [], set()
    bounds = starts + [len(header)]
    for start, stop in zip(bounds[:-1], bounds[1:]):
        labels = [h.strip() for h in header[start:stop]]
        block = {"id_col": start, "label": labels[0]}
        if len(labels) < 5 or "status" not in labels[1].lower():
            raise RecordingError(
                f"sensor block '{labels[0]}' (column {start + 1}) lacks Status and X/Y/Z columns", path
            )
        block["status_col"] = start + 1
        upper = [lab.upper() for lab in labels]
        try:
            block["xyz_cols"] = [start + upper.index(next(u for u in upper if u.startswith(a)))
                                 for a in ("X", "Y", "Z")]
        except StopIteration:
            raise RecordingError(f"sensor block '{labels[0]}' has no X, Y and Z columns", path) from None
        q = [start + j for j, u in enumerate(upper) if u in ("Q0", "QX", "QY", "QZ")]
        block["q_cols"] = q if len(q) == 4 else []
        for col in block["xyz_cols"]:
            m = _UNIT.search(header[col])
            if m:
                units.add(m.group(1))
        blocks.append(block)
    if len(units) > 1:
        raise RecordingError(f"sensor columns use different units {sorted(units)}", path)
    return blocks, (units.pop() if units else "mm")


def _header_fields(header_text: str) -> list[str]:
    header = header_text.rstrip("\r\n").split("\t")
    while header and not header[-1].strip():
        header.pop()
    return header


def _read_table(path: Path) -> tuple[list[str], np.ndarray, int, bool]:
    """(header fields, (N, C) float64 table, line number of the first data row, whether an incomplete
    last line was dropped) of the file at ``path``.

    A well-formed file goes through :func:`tonguevis.io.fast_table.plain_table` (C++ parsing);
    anything it declines is read by :func:`_read_table_carefully`, which names every problem.
    A test proves both give the same table.
    """
    data = read_bytes(path)
    fast = plain_table(data)
    if fast is not None:
        checked = _checked_fast_table(fast, path)
        if checked is not None:
            return _header_fields(fast.header), checked[0], fast.first_data_line, checked[1]
    return _read_table_carefully(data, path)


def _checked_fast_table(fast, path: Path) -> tuple[np.ndarray, bool] | None:
    """(table, truncated): the fast table cut to the header's width, its end checked as the careful
    path checks it; None when only the careful path can say what is wrong."""
    ncols = len(_header_fields(fast.header))
    table = fast.values
    if table.shape[1] < ncols or (table.shape[1] > ncols and not np.isnan(table[:, ncols:]).all()):
        return None
    table = table[:, :ncols]
    if fast.ended:
        return table, False
    # An unterminated last line may be cut inside a number: keep it only if it is whole.
    rows = [text.rstrip("\r\n").split("\t")[:ncols] for _, text in fast.last_lines]
    if unterminated_row_complete(rows[-1], rows[-2] if len(rows) > 1 else None):
        return table, False
    if len(table) == 1:
        return None  # no complete data row: the careful path's error
    logger.warning("%s: dropped the incomplete last line %d (file truncated?)", path, fast.last_lines[-1][0])
    return table[:-1], True


def _read_table_carefully(data: bytes, path: Path) -> tuple[list[str], np.ndarray, int, bool]:
    """:func:`_read_table` in Python, line by line: any file, every problem named with its line."""
    text = decode_text(data, path)
    del data
    lines, ended = split_lines(text)
    del text  # the lines hold it now
    numbered = [(i + 1, line) for i, line in enumerate(lines) if line.strip()]
    del lines
    if not numbered:
        raise RecordingError("empty file", path)
    header = _header_fields(numbered[0][1])
    _, unit = _parse_header(header, path)  # the header's problems first, as they come first in the file
    unit_scale(unit, path)
    ncols = len(header)
    body = numbered[1:]
    if not body:
        raise RecordingError("header only: no data rows", path)
    first_data_line = body[0][0]
    # Rows become numbers PARSE_ROWS at a time: a 30-minute recording is 18 million cells, which
    # as Python strings and floats all at once took 1.5 GB; the last two rows wait for the end checks.
    tables, rows, parsed, truncated = [], [], 0, None
    for k, (line_no, line) in enumerate(body):
        fields = line.rstrip("\r\n").split("\t")
        if len(fields) > ncols and not any(f.strip() for f in fields[ncols:]):
            fields = fields[:ncols]
        if len(fields) != ncols:
            if k == len(body) - 1 and len(fields) < ncols:
                truncated = line_no
                break
            raise RecordingError(f"line {line_no} has {len(fields)} fields, the header has {ncols}", path)
        rows.append(fields)
        if len(rows) == PARSE_ROWS + 2:
            tables.append(parse_number_table(rows[:-2], path, first_data_line + parsed))
            parsed += len(rows) - 2
            rows = rows[-2:]
    if truncated is None and not ended and rows:
        # An unterminated last line may be cut inside a number: keep it only if it is whole.
        previous = rows[-2] if len(rows) > 1 else None
        if not unterminated_row_complete(rows[-1], previous):
            truncated = body[parsed + len(rows) - 1][0]
            rows.pop()
    if truncated is not None:
        logger.warning("%s: dropped the incomplete last line %d (file truncated?)", path, truncated)
    if not rows and not tables:
        raise RecordingError("no complete data row", path)
    if rows:
        tables.append(parse_number_table(rows, path, first_data_line + parsed))
    del rows
    table = tables[0] if len(tables) == 1 else np.concatenate(tables)
    del tables
    return header, table, first_data_line, truncated is not None


def read_ndi_wave(path, axes=None, rate: float | None = None) -> Recording:
    """Read an NDI Wave TSV export (see the module docstring).

    axes : None (device frame) or an axis mapping for :func:`parse_axes`.
    rate : sample rate in Hz; default estimated from the times (100 Hz if one frame).
    """
    path = Path(path)
    header, table, first_data_line, truncated = _read_table(path)
    blocks, unit = _parse_header(header, path)
    scale = unit_scale(unit, path)
    times = table[:, 0]
    check_times(times, path, "AudioTime column", first_line=first_data_line)
    if rate is None:
        rate = estimate_rate(times, default=NOMINAL_RATE)
    rate = float(rate)
    if not np.isfinite(rate) or rate <= 0:
        raise RecordingError(f"impossible sample rate {rate} Hz", path)
    A = parse_axes(axes, path)
    sensors, orientations, ids, status_all = {}, {}, [], []
    for block in blocks:
        id_values = table[:, block["id_col"]]
        finite = id_values[np.isfinite(id_values)]
        if finite.size == 0:
            raise RecordingError(f"sensor block '{block['label']}' has an empty Id column", path)
        if np.any(finite != finite[0]) or finite[0] != np.round(finite[0]) or finite[0] < 0:
            raise RecordingError(
                f"Id column of sensor block '{block['label']}' is not one non-negative integer "
                f"(found {np.unique(finite)[:5].tolist()})", path)
        sensor_id = int(finite[0])
        if sensor_id in ids:
            raise RecordingError(f"sensor Id {sensor_id} appears in two sensor blocks", path)
        ids.append(sensor_id)
        status = table[:, block["status_col"]]
        xyz = table[:, block["xyz_cols"]] * scale
        ok = (status == STATUS_OK) & np.all(np.isfinite(xyz), axis=1)
        xyz[~ok] = np.nan
        name = channel_name(sensor_id)
        sensors[name] = xyz @ A.T
        if block["q_cols"]:
            quats = table[:, block["q_cols"]]
            quats[~ok] = np.nan
            orientations[name] = rotate_quaternions(quats, A)
        plausible = np.isfinite(status) & (np.abs(status) < 2**31)
        status_all.append(np.where(plausible, status, -1).astype(np.int64))
    metadata = {
        "format": "ndi_wave",
        "file": str(path),
        "original_unit": unit,
        "frame": "device" if axes is None else "tonguevis",
        "axes": A.tolist(),
        "orientation_kind": "quaternion_wxyz",
        "dropped_frames": dropped_frames(times, rate),
        "ndi_ids": ids,
        "ndi_status": np.stack(status_all, axis=1),
        "meas_id": table[:, 1].copy() if blocks[0]["id_col"] > 1 else None,
        "truncated": truncated,
    }
    return Recording(rate=rate, times=times.copy(), sensors=sensors, orientations=orientations,
                     metadata=metadata)


def _assign_ids(names: list[str], sensor_map) -> dict[str, int]:
    """NDI Id of each sensor: ``S<n>`` -> n, then the map (default the 'paper' preset), then free Ids."""
    from tonguevis.io.sensor_map import load_sensor_map

    mapping = load_sensor_map(sensor_map if sensor_map is not None else "paper")
    ids: dict[str, int] = {}
    for name in names:
        m = re.fullmatch(r"S(\d+)", name)
        if m:
            ids[name] = int(m.group(1))
        elif name in mapping:
            try:
                ids[name] = int(mapping[name])
            except (TypeError, ValueError):
                raise RecordingError(f"sensor map gives {name} the channel {mapping[name]!r}, not an NDI Id") from None
    used = set(ids.values())
    if len(used) != len(ids):
        raise RecordingError(f"two sensors would get the same NDI Id: {ids}")
    free = (i for i in range(10_000) if i not in used)
    for name in names:
        if name not in ids:
            ids[name] = next(free)
            logger.info("NDI Wave writer: sensor %s gets Id %d (not in the sensor map)", name, ids[name])
    return ids


def write_ndi_wave(rec: Recording, path, sensor_map=None, audio: bool = True) -> None:
    """Write ``rec`` as an NDI Wave TSV export (mm, 6 decimals) and its audio as ``<stem>.wav``.

    Sensor Ids: names ``S<n>`` keep Id n; other names take their Id from
    ``sensor_map`` (default: the 'paper' preset, TT=1, TD=2 ...), the rest the
    lowest free Ids.  Samples with a NaN coordinate get status 119 and empty
    fields.  Quaternions are written when the recording has (N, 4) w-x-y-z
    orientations, else the Q fields stay empty.  The WAV is int16 mono and
    starts at AudioTime 0 (audio with an offset is padded or trimmed).
    """
    path = Path(path)
    names = rec.sensor_names
    ids = _assign_ids(names, sensor_map)
    order = sorted(names, key=lambda n: ids[n])
    n = rec.n_samples
    quaternion = rec.metadata.get("orientation_kind", "quaternion_wxyz") == "quaternion_wxyz"
    audio_rate = float(rec.audio.rate) if rec.audio is not None else DEFAULT_AUDIO_RATE
    times = np.asarray(rec.times, dtype=float)
    header = ["AudioTime[s]", "MeasId", "WavId"]
    columns = [times, np.round((times - times[0]) * rec.rate) + 1 if n else times,
               np.floor(times * audio_rate)]
    for name in order:
        k = ids[name] + 1
        header += [f"Sensor {k} Id", f"Sensor {k} Status", "X[mm]", "Y[mm]", "Z[mm]", "Q0", "Qx", "Qy", "Qz"]
        xyz = np.asarray(rec.sensors[name], dtype=float) * 1000.0
        ok = np.all(np.isfinite(xyz), axis=1)
        quats = rec.orientations.get(name)
        if not quaternion or quats is None or np.shape(quats) != (n, 4):
            quats = np.full((n, 4), np.nan)
        block = np.column_stack([np.full(n, ids[name], float), np.where(ok, STATUS_OK, STATUS_MISSING),
                                 xyz, quats])
        block[~ok, 2:] = np.nan
        columns += list(block.T)
    table = np.column_stack(columns) if n else np.zeros((0, len(header)))
    lines = ["\t".join(header)] + format_rows(table, "\t")
    text = "\n".join(lines) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="ascii"))
    if audio and rec.audio is not None:
        samples = np.asarray(rec.audio.samples, dtype=float)
        shift = int(round(rec.audio.offset * rec.audio.rate))
        if shift > 0:
            samples = np.concatenate([np.zeros(shift), samples])
        elif shift < 0:
            logger.warning("%s: audio starts %.3f s before AudioTime 0; the WAV drops that part",
                        path, -rec.audio.offset)
            samples = samples[-shift:]
        write_wav(Audio(samples=samples, rate=rec.audio.rate), path.with_suffix(".wav"))


register_format(RecordingFormat(
    name="ndi_wave",
    description="NDI Wave / WaveFront TSV export (+ paired WAV)",
    extensions=(".tsv",),
    sniff=sniff,
    read=read_ndi_wave,
    write=write_ndi_wave,
    channel_name=channel_name,
))
