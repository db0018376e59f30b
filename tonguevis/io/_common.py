"""Helpers shared by the readers and writers: units, axes, time gaps, text tables, safe writes."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np

from tonguevis.errors import RecordingError


#: metres per unit, for the units EMA files use.
UNIT_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def unit_scale(unit: str, path: str | os.PathLike | None = None) -> float:
    """Metres per ``unit`` ('m', 'cm' or 'mm'); RecordingError for anything else."""
    try:
        return UNIT_SCALE[str(unit).strip().lower()]
    except KeyError:
        raise RecordingError(
            f"unknown length unit {unit!r}; expected one of {sorted(UNIT_SCALE)}", path
        ) from None


def parse_axes(axes, path: str | os.PathLike | None = None) -> np.ndarray:
    """The 3 x 3 matrix A with ``ours = A @ device`` from an axis specification.

    ``axes`` is ``None`` (identity), a 3 x 3 signed permutation / orthogonal
    matrix, or a string of three signed device axes naming what becomes our
    x (anterior), y (left) and z (up), e.g. ``"-y,x,z"`` (our x is the
    device's -y, our y the device's x, our z the device's z).
    """
    if axes is None:
        return np.eye(3)
    if isinstance(axes, str):
        parts = [p.strip().lower() for p in axes.replace(" ", "").split(",")]
        if len(parts) == 1 and len(parts[0]) in (3, 4, 5, 6):
            # compact "xyz" / "-yxz": split before every letter
            compact, parts, cur = parts[0], [], ""
            for ch in compact:
                cur += ch
                if ch in "xyz":
                    parts.append(cur)
                    cur = ""
        matrix = np.zeros((3, 3))
        if len(parts) != 3:
            raise RecordingError(f"axes {axes!r}: expected three signed axes like '-y,x,z'", path)
        for row, part in enumerate(parts):
            sign = -1.0 if part.startswith("-") else 1.0
            letter = part.lstrip("+-")
            if letter not in ("x", "y", "z"):
                raise RecordingError(f"axes {axes!r}: {part!r} is not a signed axis x, y or z", path)
            matrix[row, "xyz".index(letter)] = sign
    else:
        matrix = np.asarray(axes, dtype=float)
    if matrix.shape != (3, 3) or not np.allclose(matrix @ matrix.T, np.eye(3), atol=1e-9):
        raise RecordingError(f"axes {axes!r}: not an orthogonal 3 x 3 axis mapping", path)
    return matrix


def rotate_quaternions(quats: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(N, 4) quaternions (w, x, y, z) re-expressed after the axis change ``axes``.

    The rotation R becomes A R Aᵀ; its axis maps to det(A)·A·axis, so the vector
    part maps the same way and w is unchanged (true for reflections as well).
    """
    out = quats.copy()
    out[:, 1:] = np.linalg.det(axes) * quats[:, 1:] @ axes.T
    return out


def estimate_rate(times: np.ndarray, default: float | None = None, path=None) -> float:
    """Sample rate in Hz from (N,) times: 1 / median step, the steps over dropped frames left out.

    The steps longer than 1.5 times the median of all steps (time gaps where
    frames were dropped) do not count: with a jittered clock and many dropped
    frames they would pull the plain median up (±1 ms of jitter and every third
    frame of a 100 Hz recording dropped read as 98 Hz).
    """
    steps = np.diff(times)
    steps = steps[np.isfinite(steps) & (steps > 0)]
    if steps.size == 0:
        if default is None:
            raise RecordingError("cannot tell the sample rate from fewer than two frames", path)
        return float(default)
    regular = steps[steps <= 1.5 * np.median(steps)]
    rate = 1.0 / float(np.median(regular))
    if not np.isfinite(rate) or rate <= 0:
        raise RecordingError(f"impossible sample rate {rate} Hz from the time column", path)
    # Rounded to 9 significant digits so that a clock of 0.01 s steps reads as 100 Hz,
    # not 99.99999999999991.
    return float(f"{rate:.9g}")


def dropped_frames(times: np.ndarray, rate: float) -> list[tuple[float, int]]:
    """Time gaps longer than 1.5 sample periods: [(time of the last sample before, n_missing)]."""
    if len(times) < 2:
        return []
    steps = np.diff(times) * rate
    gaps = np.flatnonzero(steps > 1.5)
    return [(float(times[i]), int(round(steps[i])) - 1) for i in gaps]


def check_times(times: np.ndarray, path, what: str = "time column", first_line: int | None = None) -> None:
    """RecordingError unless (N,) times are finite and strictly increasing."""
    bad = ~np.isfinite(times)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        where = f"line {first_line + i}" if first_line is not None else f"sample {i}"
        raise RecordingError(f"{what} is not a number at {where}", path)
    back = np.flatnonzero(np.diff(times) <= 0)
    if back.size:
        i = int(back[0]) + 1
        where = f"line {first_line + i}" if first_line is not None else f"sample {i}"
        raise RecordingError(
            f"{what} does not increase at {where} ({times[i - 1]!r} then {times[i]!r})", path
        )


def read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except IsADirectoryError:
        raise RecordingError("is a folder, not a recording file", path) from None


def decode_text(data: bytes, path) -> str:
    """Text of a file that should be ASCII/UTF-8 (Latin-1 accepted for header comments)."""
    if b"\x00" in data:
        raise RecordingError("expected a text file but found binary bytes (NUL)", path)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def split_lines(text: str) -> tuple[list[str], bool]:
    """Lines of ``text`` (any newline convention) and whether the last one was ended."""
    ended = text.endswith(("\n", "\r"))
    lines = text.splitlines()
    return lines, ended


def parse_number_table(
    rows: Sequence[Sequence[str]], path, first_line: int, what: str = "value"
) -> np.ndarray:
    """(R, C) float64 from equally long rows of number strings; empty strings become NaN.

    ``first_line`` is the 1-based line number of ``rows[0]`` for error messages.
    """
    if not rows:
        return np.zeros((0, 0))
    width = len(rows[0])
    try:
        # Fast path: Python's float() in one comprehension (C-speed parsing per cell).
        flat = [float(cell or "nan") for row in rows for cell in row]
        return np.array(flat, dtype=np.float64).reshape(len(rows), width)
    except ValueError:
        pass  # whitespace-only cells, or a bad number: the careful path below
    cells = np.char.strip(np.array(rows, dtype=object).astype(str))
    cells[cells == ""] = "nan"
    try:
        return cells.astype(np.float64)
    except ValueError:
        pass
    # Find the first offending cell to name it (slow path, only on bad input).
    for r, row in enumerate(cells):
        for c, cell in enumerate(row):
            try:
                float(cell)
            except ValueError:
                raise RecordingError(
                    f"line {first_line + r}, column {c + 1}: {what} {cell[:40]!r} is not a number", path
                ) from None
    raise RecordingError("could not parse the numbers", path)  # pragma: no cover


def sensor_names_in_order(sensors: dict) -> list[str]:
    return list(sensors)


def stack_positions(rec, names: Sequence[str]) -> np.ndarray:
    """(N, S, 3) positions in metres of the named sensors."""
    if not names:
        return np.zeros((rec.n_samples, 0, 3))
    return np.stack([np.asarray(rec.sensors[n], dtype=float) for n in names], axis=1)


def regrid_dropped_frames(rec):
    """``rec`` on a uniform time grid: frames lost in time gaps re-inserted as NaN samples.

    Frame k of the result is at ``times[0] + k / rate``; samples keep their
    values and move by at most half a period (clock jitter).  Returns ``rec``
    itself when nothing was dropped.
    """
    from dataclasses import replace

    n_in = rec.n_samples
    if n_in < 2:
        return rec
    # Frame numbers from the steps, not from the absolute times: a clock a little off the stated rate
    # (jitter, a rate read to a few digits) drifts by whole periods over minutes, which rounding the
    # absolute times would turn into collisions.  A step of k periods (rounded, at least 1) is k - 1 lost frames.
    steps = np.maximum(1, np.round(np.diff(rec.times) * rec.rate).astype(np.int64))
    if np.all(steps == 1):
        return rec
    idx = np.concatenate([[0], np.cumsum(steps)])
    n = int(idx[-1]) + 1

    def fill(a):
        a = np.asarray(a, dtype=float)
        out = np.full((n,) + a.shape[1:], np.nan)
        out[idx] = a
        return out

    metadata = dict(rec.metadata)
    metadata["regridded_from_samples"] = n_in
    return replace(
        rec,
        times=rec.times[0] + np.arange(n) / rec.rate,
        sensors={k: fill(v) for k, v in rec.sensors.items()},
        orientations={k: fill(v) for k, v in rec.orientations.items()},
        metadata=metadata,
    )


def format_rows(table: np.ndarray, sep: str, nan: str = "", fmt: str = "%.6f") -> list[str]:
    """Lines of text for a (R, C) float table, NaN written as ``nan`` (e.g. an empty field).

    One ``%`` format per row runs in C; this is 3-4 times faster than np.char.mod.
    """
    if table.size == 0:
        return [""] * table.shape[0]
    row_fmt = sep.join([fmt] * table.shape[1])
    lines = [row_fmt % tuple(row) for row in table.tolist()]
    if nan != "nan" and np.isnan(table).any():
        # "nan" appears nowhere else in %f output, so a plain replace is exact.
        lines = [line.replace("nan", nan) for line in lines]
    return lines


def _decimals(cell: str) -> int:
    cell = cell.strip()
    return len(cell) - cell.index(".") - 1 if "." in cell else -1


def unterminated_row_complete(row: Sequence[str], previous: Sequence[str] | None) -> bool:
    """Whether a last line without a newline is whole rather than cut inside its last number.

    Exporters write a column with a fixed number of decimals, so the last field
    must parse and carry as many decimals as the same field one line above
    (an empty field, or no line above, cannot be judged and counts as whole).
    """
    last = row[-1].strip() if row else ""
    if not last:
        return True
    try:
        float(last)
    except ValueError:
        return False
    if previous is None or len(previous) < len(row) or not previous[len(row) - 1].strip():
        return True
    return _decimals(last) == _decimals(previous[len(row) - 1])
