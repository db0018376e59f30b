"""The gesture landmarks of a recording's productions as a table (CSV or Parquet).

One row per production: its identity (train, index, label, articulator, clarity), its
release and closure, then for each landmark of :data:`~tonguevis.preprocess.gestures.LANDMARKS`
its time (s) and the articulator's position (mm, the recording's head frame: x anterior,
y left, z up), the two peak speeds (mm/s), the gesture, nucleus, closing and opening
durations (ms), and the landmarks placed by fallback (space-separated).
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

from tonguevis.preprocess.gestures import LANDMARKS

DURATIONS = ("gesture", "nucleus", "closing", "opening")
#: Column name -> kind ("int", "str", "float"), in order.
COLUMNS: dict[str, str] = {
    "production": "str", "train": "int", "index": "int", "label": "str", "articulator": "str", "clarity": "float",
    "release_s": "float", "closure_s": "float",
    **{f"{name}_{what}": "float" for name in LANDMARKS for what in ("s", "x_mm", "y_mm", "z_mm")},
    "pvel_speed_mm_per_s": "float", "pvel2_speed_mm_per_s": "float",
    **{f"{d}_duration_ms": "float" for d in DURATIONS},
    "fallbacks": "str",
}


def gesture_rows(table) -> list[dict]:
    """One dict per production of a :class:`~tonguevis.preprocess.ProductionTable` (keys: :data:`COLUMNS`)."""
    rows = []
    for production, marks in zip(table.productions, table.landmarks):
        row = {"production": f"{production.train}.{production.index}", "train": production.train,
               "index": production.index, "label": production.label, "articulator": production.articulator,
               "clarity": production.clarity, "release_s": production.release, "closure_s": production.closure,
               "pvel_speed_mm_per_s": 1000 * marks.peak_velocity, "pvel2_speed_mm_per_s": 1000 * marks.peak_velocity2,
               "fallbacks": " ".join(marks.fallbacks)}
        for name in LANDMARKS:
            row[f"{name}_s"] = marks.times[name]
            for axis, value in zip("xyz", marks.positions[name]):
                row[f"{name}_{axis}_mm"] = 1000 * float(value)
        for name, seconds in marks.durations().items():
            row[f"{name}_duration_ms"] = 1000 * seconds
        rows.append(row)
    return rows


def _text(value, kind: str) -> str:
    if kind == "str":
        return "" if value is None else str(value)
    if kind == "int":
        return str(int(value))
    if kind == "bool":
        return "" if value is None else ("true" if value else "false")
    return "" if value is None or math.isnan(float(value)) else f"{float(value):.4f}"


def to_arrow(rows: list[dict], columns: dict[str, str] | None = None):
    """An Arrow table of ``rows`` (dicts) with ``columns`` (name -> "str", "int", "float" or "bool";
    default: :data:`COLUMNS`, the rows of :func:`gesture_rows`); NaN floats become nulls."""
    import pyarrow as pa

    columns = COLUMNS if columns is None else columns
    types = {"str": pa.string(), "int": pa.int64(), "float": pa.float64(), "bool": pa.bool_()}
    data = {}
    for column, kind in columns.items():
        values = [row.get(column) for row in rows]
        if kind == "float":
            values = [None if v is None or math.isnan(float(v)) else float(v) for v in values]
        data[column] = values
    return pa.Table.from_pydict(data, schema=pa.schema([(c, types[k]) for c, k in columns.items()]))


def write_rows(rows: list[dict], columns: dict[str, str], path: str | os.PathLike) -> Path:
    """Write ``rows`` with ``columns`` (as :func:`to_arrow`): Parquet for ``.parquet``, else CSV (NaN: an
    empty cell, floats to 4 decimals); atomically."""
    from tonguevis._files import atomic_write, atomic_write_text

    path = Path(path)
    if path.suffix.lower() == ".parquet":
        import pyarrow.parquet as pq

        arrow = to_arrow(rows, columns)
        atomic_write(path, lambda tmp: pq.write_table(arrow, tmp))
        return path
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_text(row.get(c), k) for c, k in columns.items()])
    atomic_write_text(path, buffer.getvalue())
    return path


def write_gestures(table, path: str | os.PathLike) -> Path:
    """Write the gesture landmarks of ``table``: Parquet for ``.parquet``, else CSV; atomically."""
    return write_rows(gesture_rows(table), COLUMNS, path)
