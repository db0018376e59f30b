"""Plain CSV of sensor positions, read and write, in a documented layout.

Optional ``#`` comment lines come first; ``# key: value`` lines give the
``unit`` (m, cm or mm; required unless the reader gets ``unit=``) and the
``rate`` (Hz; else estimated from the times).  Then a header row and one row
per sample, comma-separated (``;`` or tab also read).  Two layouts:

wide (one row per frame; what the writer makes by default)::

    # tonguevis-csv 1
    # unit: mm
    # rate: 100
    time,TT_x,TT_y,TT_z,TD_x,TD_y,TD_z
    0.000000,12.500000,0.100000,31.000000,,,

long (one row per sensor and frame; ``layout="long"``)::

    # unit: mm
    time,sensor,x,y,z
    0.000000,TT,12.500000,0.100000,31.000000

Times are in seconds; an empty cell is a missing value (NaN).  Axes are the
file's own (tonguevis writes ours: x anterior, y left, z up).  Orientations are
not stored.  Other columns of the wide layout are kept in
``metadata['extra_channels']``.
"""

from __future__ import annotations

import csv
import io
import re
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis._files import atomic_write
from tonguevis.io._common import (
    check_times, decode_text, format_rows, dropped_frames, estimate_rate, parse_number_table,
    read_bytes, unit_scale, unterminated_row_complete,
)
from tonguevis.io.recording import Recording
from tonguevis.io.registry import RecordingFormat, register_format

from tonguevis._logging import logger

TIME_NAMES = ("time", "time_s", "time[s]", "t")
_AXIS = re.compile(r"^(.+)_([xyz])$", re.IGNORECASE)


def _delimiter(line: str) -> str:
    return max((",", ";", "\t"), key=line.count)


def _split_head(text: str) -> tuple[dict[str, str], int, list[str]]:
    """(comment keys, index of the header line, all lines)."""
    lines = text.splitlines()
    keys = {}
    for i, line in enumerate(lines):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            key, sep, value = stripped.lstrip("#").partition(":")
            if sep:
                keys[key.strip().lower()] = value.strip()
            continue
        return keys, i, lines
    return keys, -1, lines


def sniff(head: bytes, path: Path) -> bool:
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        return False
    if text.startswith("# tonguevis-csv"):
        return True
    _, i, lines = _split_head(text)
    if i < 0:
        return False
    fields = [f.strip().lower() for f in lines[i].split(_delimiter(lines[i]))]
    return len(fields) >= 4 and fields[0] in TIME_NAMES and (
        fields[1] == "sensor" or any(_AXIS.match(f) for f in fields[1:]))


def read_csv(path, unit: str | None = None, rate: float | None = None) -> Recording:
    """Read the CSV layouts of the module docstring; positions come back in metres."""
    path = Path(path)
    data = read_bytes(path)
    text = decode_text(data, path)
    keys, header_index, lines = _split_head(text)
    if header_index < 0:
        raise RecordingError("empty file (no header row)", path)
    delim = _delimiter(lines[header_index])
    header = [h.strip() for h in next(csv.reader([lines[header_index]], delimiter=delim))]
    lower = [h.lower() for h in header]
    if lower[0] not in TIME_NAMES:
        raise RecordingError(f"first column is {header[0]!r}, expected 'time'", path)
    unit = unit or keys.get("unit")
    if unit is None:
        raise RecordingError("no '# unit: mm' comment line; pass unit= ('m', 'cm' or 'mm')", path)
    scale = unit_scale(unit, path)
    rows, numbers = [], []
    body = lines[header_index + 1:]
    for k, row in enumerate(csv.reader(body, delimiter=delim)):
        if row and any(cell.strip() for cell in row):
            rows.append(row)
            numbers.append(header_index + 2 + k)
    if not rows:
        raise RecordingError("header only: no data rows", path)
    ended = text.endswith(("\n", "\r"))
    previous = rows[-2] if len(rows) > 1 else None
    if len(rows[-1]) < len(header) or (not ended and not unterminated_row_complete(rows[-1], previous)):
        logger.warning("%s: dropped the incomplete last line %d (file truncated?)", path, numbers[-1])
        rows.pop()
        numbers.pop()
        if not rows:
            raise RecordingError("no complete data row", path)
    for row, line_no in zip(rows, numbers):
        if len(row) != len(header):
            raise RecordingError(f"line {line_no} has {len(row)} fields, the header has {len(header)}", path)
    if lower[1:5] == ["sensor", "x", "y", "z"]:
        times, sensors = _long(rows, numbers, scale, path)
        extra = {}
    else:
        times, sensors, extra = _wide(header, rows, numbers, scale, path)
    if rate is None:
        stated = float(keys["rate"]) if _is_positive(keys.get("rate")) else None
        rate = estimate_rate(times, default=stated, path=path) if len(times) > 1 or stated is None else stated
        if stated is not None and abs(stated - rate) > 0.01 * rate:
            logger.warning("%s: '# rate: %s' disagrees with the time column (%.6g Hz); using the times",
                        path, keys["rate"], rate)
    metadata = {
        "format": "csv",
        "file": str(path),
        "original_unit": unit,
        "frame": "file",
        "extra_channels": extra,
        "dropped_frames": dropped_frames(times, float(rate)),
        "comments": keys,
    }
    return Recording(rate=float(rate), times=times, sensors=sensors, metadata=metadata)


def _is_positive(value) -> bool:
    try:
        return value is not None and float(value) > 0 and np.isfinite(float(value))
    except ValueError:
        return False


def _wide(header, rows, numbers, scale, path):
    table = parse_number_table(rows, path, numbers[0])
    times = table[:, 0].copy()
    check_times(times, path, "time column", first_line=numbers[0])
    columns: dict[str, dict[int, int]] = {}
    extra = {}
    for j, name in enumerate(header[1:], start=1):
        m = _AXIS.match(name)
        if m:
            axes = columns.setdefault(m.group(1), {})
            axis = "xyz".index(m.group(2).lower())
            if axis in axes:
                raise RecordingError(f"column {name!r} appears twice", path)
            axes[axis] = j
        else:
            extra[name] = table[:, j].copy()
    sensors = {}
    for name, axes in columns.items():
        if len(axes) != 3:
            raise RecordingError(f"sensor {name!r} lacks some of the _x, _y, _z columns", path)
        xyz = table[:, [axes[0], axes[1], axes[2]]] * scale
        xyz[~np.all(np.isfinite(xyz), axis=1)] = np.nan
        sensors[name] = xyz
    if not sensors:
        raise RecordingError("no sensor columns (names like TT_x, TT_y, TT_z)", path)
    return times, sensors, extra


def _long(rows, numbers, scale, path):
    names = [r[1].strip() for r in rows]
    if any(not n for n in names):
        raise RecordingError(f"line {numbers[names.index('')]}: empty sensor name", path)
    table = parse_number_table([[r[0], r[2], r[3], r[4]] for r in rows], path, numbers[0])
    if not np.all(np.isfinite(table[:, 0])):
        bad = int(np.flatnonzero(~np.isfinite(table[:, 0]))[0])
        raise RecordingError(f"line {numbers[bad]}: time is not a number", path)
    times, frame = np.unique(table[:, 0], return_inverse=True)
    sensor_names = list(dict.fromkeys(names))
    index = {n: i for i, n in enumerate(sensor_names)}
    which = np.array([index[n] for n in names])
    positions = np.full((len(times), len(sensor_names), 3), np.nan)
    flat = frame * len(sensor_names) + which
    if np.unique(flat).size != flat.size:
        raise RecordingError("a sensor appears twice at the same time", path)
    positions[frame, which] = table[:, 1:] * scale
    positions[~np.all(np.isfinite(positions), axis=2)] = np.nan
    return times, {n: positions[:, i].copy() for n, i in index.items()}


def write_csv(rec: Recording, path, unit: str = "mm", layout: str = "wide") -> None:
    """Write positions in the wide (default) or long layout; NaN as empty cells."""
    path = Path(path)
    scale = unit_scale(unit, path)
    if layout not in ("wide", "long"):
        raise RecordingError(f"layout={layout!r}: expected 'wide' or 'long'", path)
    for name in rec.sensor_names:
        if re.search(r"[,;\t\n\"]", name) or not name:
            raise RecordingError(f"sensor name {name!r} cannot be a CSV column name", path)
    names = rec.sensor_names
    times = np.asarray(rec.times, dtype=float)
    buf = io.StringIO()
    buf.write(f"# tonguevis-csv 1\n# unit: {unit}\n# rate: {rec.rate:.6f}\n")
    if rec.metadata.get("synthetic"):
        buf.write("# synthetic: true\n")
    if layout == "wide":
        buf.write(",".join(["time"] + [f"{n}_{a}" for n in names for a in "xyz"]) + "\n")
        table = np.column_stack([times] + [np.asarray(rec.sensors[n], float) / scale for n in names])
        name_col = None
    else:
        buf.write("time,sensor,x,y,z\n")
        n, s = len(times), len(names)
        stacked = np.stack([np.asarray(rec.sensors[k], float) / scale for k in names], axis=1) if s else np.zeros((n, 0, 3))
        table = np.column_stack([np.repeat(times, s), stacked.reshape(n * s, 3)])
        name_col = np.tile(np.array(names, dtype=object), n)
    if name_col is None:
        rows = format_rows(table, ",")
    else:
        rows = [f"{t},{name},{xyz}" for t, name, xyz in
                zip(format_rows(table[:, :1], ","), name_col, format_rows(table[:, 1:], ","))]
    buf.write("".join(row + "\n" for row in rows))
    text = buf.getvalue()
    atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


register_format(RecordingFormat(
    name="csv",
    description="CSV of positions, wide (time,TT_x,TT_y,TT_z,...) or long (time,sensor,x,y,z), '# unit:' header",
    extensions=(".csv",),
    sniff=sniff,
    read=read_csv,
    write=write_csv,
    channel_name=str,
))
