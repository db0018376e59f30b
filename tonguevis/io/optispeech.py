"""Opti-Speech sweep exports (the NDI Wave biofeedback tool, Unity), both layouts.

Opti-Speech records an NDI Wave through Unity and writes one tab-separated row
per Unity frame.  Two layouts exist:

* **Marker layout** (Opti-Speech 1)::

      timestamp  then 9 x (Marker Number, Qw, Qx, Qy, Qz, X, Y, Z)  then targets, a landmark

  X, Y, Z are Unity's x (right), y (up), z (forward), in mm.  Markers 1 and 2
  are constant placeholders (dropped); 3 tongue tip, 4 blade, 5 right
  lateral, 6 left lateral, 7 dorsum, 8 jaw (it reads some 70 mm below the
  tongue yet follows its vertical motion: r = 0.7-0.9 on real /ta/, /ka/),
  10 the palate probe in trace sweeps (huge garbage elsewhere: dropped).
* **Sensor layout** (Opti-Speech 2's legacy reader)::

      timestamp  Placeholder1  Placeholder2  then per sensor (Sensor, Status, X, Y, Z, Qw, Qx, Qy, Qz) ...

  Sensor Ids: 1 forehead, 2 left ear, 3 right ear (head references REF1-3),
  4 tip, 5 dorsum, 6 right, 7 left, 8 back, 9 jaw, 10 other (the probe).
  Here the X, Y, Z columns hold Unity's y (up), z (forward) and x (right).

Both are mapped into ours (x anterior = Unity z, y left = -Unity x, z up =
Unity y; Unity's frame is left-handed, so quaternions are re-expressed with the
reflection, see :func:`rotate_quaternions`) and named canonically (TT, TB, TR,
TL, TD, TBK, JAW, REF1-3, PROBE), so a user needs no sensor map.

**Clock.** The timestamp (ms) is Unity's frame time: steps of 1-45 ms, and
rows that merely repeat the previous sample (a Unity frame with no new Wave
sample).  Older Sensor-layout exports also write such a frame as a second row
with the **same timestamp** (differing only in an unused slot and a counter):
those rows are merged into the first row of their time, each sensor keeping
its first valid sample (``metadata['resampled']['repeated_time_rows_merged']``
says how many).  The reader drops repeated rows, then resamples the distinct samples
onto a uniform ``rate`` clock (default 100 Hz, the NDI Wave's own rate, so
frame-based filters mean what they mean for Wave exports) by monotone cubic
(PCHIP) interpolation per sensor; a gap between distinct samples longer than
``max_gap`` seconds is not bridged (NaN).  ``metadata['resampled']`` says what
was done.  There is no audio in these exports.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io._common import decode_text, parse_number_table, read_bytes, rotate_quaternions, split_lines
from tonguevis.io.recording import Recording
from tonguevis.io.registry import RecordingFormat, register_format

from tonguevis._logging import logger

#: ours = AXES_UNITY @ (Unity x right, y up, z forward).
AXES_UNITY = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
MARKER_NAMES = {3: "TT", 4: "TB", 5: "TR", 6: "TL", 7: "TD", 8: "JAW", 10: "PROBE"}
SENSOR_NAMES = {1: "REF1", 2: "REF2", 3: "REF3", 4: "TT", 5: "TD", 6: "TR", 7: "TL", 8: "TBK", 9: "JAW", 10: "PROBE"}
STATUS_OK = 55  # NDI Wave's code, which Opti-Speech passes on
DEFAULT_RATE = 100.0
DEFAULT_MAX_GAP = 0.1  # s: longer holes between distinct samples stay NaN
GARBAGE_MM = 1e5  # a coordinate beyond 100 m is not a position


def sniff(head: bytes, path: Path) -> bool:
    first = head.split(b"\n", 1)[0].lower()
    if not first.startswith(b"timestamp\t"):
        return False
    return b"marker number" in first or (b"placeholder1" in first and b"\tsensor" in first)


def channel_name(value) -> str:
    """Sensor-map values for this format are the canonical names the reader gives."""
    return str(value)


def _marker_blocks(header: list[str]) -> list[dict]:
    starts = [i for i, h in enumerate(header) if h.strip().lower() == "marker number"]
    blocks = []
    for s in starts:
        labels = [h.strip().upper() for h in header[s:s + 8]]
        if labels[1:] != ["QW", "QX", "QY", "QZ", "X", "Y", "Z"]:
            raise RecordingError(f"marker block at column {s + 1} is not 'Marker Number, Qw..Qz, X, Y, Z'")
        blocks.append({"id": s, "status": None, "xyz": [s + 5, s + 6, s + 7], "q": [s + 1, s + 2, s + 3, s + 4],
                       "axes": AXES_UNITY})
    return blocks


def _sensor_blocks(header: list[str]) -> list[dict]:
    starts = [i for i, h in enumerate(header) if h.strip().lower() == "sensor"]
    # The file's X, Y, Z are Unity's y, z, x: ours = AXES_UNITY @ P @ file with P taking file -> Unity.
    file_to_unity = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    blocks = []
    for s in starts:
        labels = [h.strip().upper() for h in header[s:s + 9]]
        if labels[1:] != ["STATUS", "X", "Y", "Z", "QW", "QX", "QY", "QZ"]:
            raise RecordingError(f"sensor block at column {s + 1} is not 'Sensor, Status, X, Y, Z, Qw..Qz'")
        blocks.append({"id": s, "status": s + 1, "xyz": [s + 2, s + 3, s + 4], "q": [s + 5, s + 6, s + 7, s + 8],
                       "axes": AXES_UNITY @ file_to_unity})
    return blocks


def read_optispeech(path, rate: float = DEFAULT_RATE, max_gap: float = DEFAULT_MAX_GAP) -> Recording:
    """Read an Opti-Speech sweep export (see the module docstring); positions in metres, our axes.

    rate : the uniform clock (Hz) the samples are resampled onto.
    max_gap : longest hole (s) between distinct samples that interpolation bridges.
    """
    path = Path(path)
    text = decode_text(read_bytes(path), path)
    lines, ended = split_lines(text)
    lines = [line for line in lines if line.strip()]
    if len(lines) < 2:
        raise RecordingError("no data rows after the header", path)
    header = lines[0].rstrip("\r\n").split("\t")
    try:
        if any(h.strip().lower() == "marker number" for h in header):
            layout, blocks, names = "marker", _marker_blocks(header), MARKER_NAMES
        else:
            layout, blocks, names = "sensor", _sensor_blocks(header), SENSOR_NAMES
    except RecordingError as exc:
        raise RecordingError(str(exc), path) from None
    if not blocks:
        raise RecordingError("header has no 'Marker Number' or 'Sensor' blocks; not an Opti-Speech export", path)
    width = len(header)
    rows = [line.rstrip("\r\n").split("\t") for line in lines[1:]]
    if len(rows[-1]) < width:
        logger.warning("%s: dropped the incomplete last line (file truncated?)", path)
        rows.pop()
    rows = [r[:width] + [""] * (width - len(r)) if len(r) != width else r for r in rows]
    short = [i for i, r in enumerate(rows) if not any(c.strip() for c in r[width // 2:])]
    if short:
        raise RecordingError(f"line {short[0] + 2} is empty past column {width // 2}", path)
    table = parse_number_table(rows, path, first_line=2)
    times = table[:, 0] / 1000.0
    if not np.all(np.isfinite(times)):
        raise RecordingError("timestamp column holds a non-number", path)
    order = np.argsort(times, kind="stable")
    if np.any(np.diff(times) < 0):
        logger.warning("%s: timestamps go backwards; rows sorted by time", path)
        table, times = table[order], times[order]

    raw_pos, raw_q, ids = {}, {}, {}
    for block in blocks:
        id_values = table[:, block["id"]]
        finite = id_values[np.isfinite(id_values)]
        if finite.size == 0:
            continue
        marker = int(np.round(np.median(finite)))
        xyz = table[:, block["xyz"]].copy()
        bad = ~np.all(np.isfinite(xyz), axis=1) | np.any(np.abs(xyz) > GARBAGE_MM, axis=1)
        if block["status"] is not None:
            bad |= table[:, block["status"]] != STATUS_OK
        if layout == "marker" and marker in (1, 2):
            continue  # constant placeholders
        name = names.get(marker, f"M{marker}")
        if bad.all():
            logger.info("%s: channel %s (%d) holds no valid sample; dropped", path, name, marker)
            continue
        if name in raw_pos:
            raise RecordingError(f"sensor {marker} ({name}) appears in two blocks", path)
        xyz[bad] = np.nan
        raw_pos[name] = 1e-3 * xyz @ block["axes"].T
        quats = table[:, block["q"]].copy()
        quats[bad | np.all(quats == 0, axis=1)] = np.nan  # all-zero: not recorded
        if np.isfinite(quats).any():
            raw_q[name] = rotate_quaternions(quats, block["axes"])
        ids[name] = marker
    if not raw_pos:
        raise RecordingError("no sensor holds a valid sample", path)
    n_rows = len(times)
    times, merged = _merge_repeated_times(times, [*raw_pos.values(), *raw_q.values()])
    raw_pos = dict(zip(raw_pos, merged[:len(raw_pos)]))
    raw_q = dict(zip(raw_q, merged[len(raw_pos):]))
    repeated_time_rows = n_rows - len(times)
    if repeated_time_rows:
        logger.info("%s: %d of %d rows repeat the previous row's timestamp; merged into it (each sensor keeps "
                 "the first valid sample of that time)", path, repeated_time_rows, n_rows)

    stacked = np.stack(list(raw_pos.values()), axis=1)  # (N, S, 3)
    same = np.all((stacked[1:] == stacked[:-1]) | (np.isnan(stacked[1:]) & np.isnan(stacked[:-1])), axis=(1, 2))
    keep = np.concatenate([[True], ~same])
    sample_times = times[keep]
    if len(sample_times) < 2:
        raise RecordingError("fewer than two distinct samples", path)
    grid = sample_times[0] + np.arange(int(np.floor((sample_times[-1] - sample_times[0]) * rate)) + 1) / rate
    sensors = {n: _resample(sample_times, p[keep], grid, max_gap) for n, p in raw_pos.items()}
    orientations = {n: _resample(sample_times, q[keep], grid, max_gap) for n, q in raw_q.items()}
    steps = np.diff(sample_times)
    metadata = {
        "format": "optispeech",
        "file": str(path),
        "original_unit": "mm",
        "frame": "tonguevis",
        "layout": layout,
        "channels": ids,
        "orientation_kind": "quaternion_wxyz",
        "resampled": {
            "rate_hz": float(rate), "method": "pchip", "max_gap_s": float(max_gap),
            "rows": int(n_rows), "repeated_time_rows_merged": int(repeated_time_rows),
            "distinct_samples": int(keep.sum()),
            "median_step_ms": float(1e3 * np.median(steps)), "max_step_ms": float(1e3 * steps.max()),
        },
        "dropped_frames": [],
        "audio_file": None,
        "truncated": not ended,
    }
    logger.info("%s: %d distinct samples of %d rows (median step %.0f ms) resampled to %g Hz", path,
             keep.sum(), n_rows, 1e3 * np.median(steps), rate)
    return Recording(rate=float(rate), times=grid, sensors=sensors, orientations=orientations,
                     metadata=metadata)


def _merge_repeated_times(times: np.ndarray, arrays: list[np.ndarray]) -> tuple[np.ndarray, list[np.ndarray]]:
    """Rows of a sorted clock ``times`` (s) that repeat the previous row's time, merged into the first row of it.

    Older Sensor-layout exports write a Unity frame that saw no new Wave sample as a
    second row with the same timestamp (only an unused slot and a counter differ).
    Each (N, k) array keeps, per time, its first row whose values are all finite
    (NaN when none is).  Returns the distinct times and the merged arrays.
    """
    first = np.concatenate([[True], np.diff(times) > 0])
    if first.all():
        return times, arrays
    group = np.cumsum(first) - 1
    merged = []
    for values in arrays:
        out = values[first].copy()
        for row in np.flatnonzero(~first):
            if not np.all(np.isfinite(out[group[row]])) and np.all(np.isfinite(values[row])):
                out[group[row]] = values[row]
        merged.append(out)
    return times[first], merged


def _resample(t: np.ndarray, values: np.ndarray, grid: np.ndarray, max_gap: float) -> np.ndarray:
    """(G, k) PCHIP interpolation of (N, k) ``values`` at times ``t`` onto ``grid``; NaN across gaps > max_gap."""
    from scipy.interpolate import PchipInterpolator

    out = np.full((len(grid), values.shape[1]), np.nan)
    ok = np.all(np.isfinite(values), axis=1)
    # Runs of valid samples with no step longer than max_gap are interpolated on their own.
    breaks = np.flatnonzero(~ok[1:] | ~ok[:-1] | (np.diff(t) > max_gap)) + 1
    for run in np.split(np.arange(len(t)), breaks):
        run = run[ok[run]]
        if len(run) == 0:
            continue
        # A grid point within a microsecond of a sample belongs to its run (clock round-off).
        lo = np.searchsorted(grid, t[run[0]] - 1e-6, side="left")
        hi = np.searchsorted(grid, t[run[-1]] + 1e-6, side="right")
        if hi <= lo:
            continue
        if len(run) == 1:
            out[lo:hi] = values[run[0]]
        else:
            out[lo:hi] = PchipInterpolator(t[run], values[run], axis=0)(grid[lo:hi])
    return out


register_format(RecordingFormat(
    name="optispeech",
    description="Opti-Speech sweep export (Unity TSV, marker or sensor layout; resampled to a uniform clock)",
    extensions=(".tsv",),
    sniff=sniff,
    read=read_optispeech,
    channel_name=channel_name,
))
