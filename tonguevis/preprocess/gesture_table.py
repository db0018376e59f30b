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
        return str(value)
    if kind == "int":
        return str(int(value))
    return "" if value is None or math.isnan(float(value)) else f"{float(value):.4f}"


def to_arrow(rows: list[dict]):
    """An Arrow table of :func:`gesture_rows` (NaN floats become nulls)."""
    import pyarrow as pa

    types = {"str": pa.string(), "int": pa.int64(), "float": pa.float64()}
    data = {}
    for column, kind in COLUMNS.items():
        values = [row.get(column) for row in rows]
        if kind == "float":
            values = [None if v is None or math.isnan(float(v)) else float(v) for v in values]
        data[column] = values
    return pa.Table.from_pydict(data, schema=pa.schema([(c, types[k]) for c, k in COLUMNS.items()]))


def write_gestures(table, path: str | os.PathLike) -> Path:
    """Write the gesture landmarks of ``table``: Parquet for ``.parquet``, else CSV; atomically."""
    from tonguevis._files import atomic_write, atomic_write_text

    path = Path(path)
    rows = gesture_rows(table)
    if path.suffix.lower() == ".parquet":
        import pyarrow.parquet as pq

        arrow = to_arrow(rows)
        atomic_write(path, lambda tmp: pq.write_table(arrow, tmp))
        return path
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(COLUMNS)
    for row in rows:
        writer.writerow([_text(row[c], k) for c, k in COLUMNS.items()])
    atomic_write_text(path, buffer.getvalue())
    return path
