"""The tables a batch writes, one fixed Arrow schema each, and their files (Parquet, optionally CSV).

Per recording and gathered for the corpus (``DIR/<table>.parquet``):

* ``energy``: the long format of ``tonguevis energy`` (one row per frame of
  each production curve, the same columns; floats at full precision).
* ``productions``: one row per production (train, index, times in s, the
  1-based ``number`` that ``tonguevis segment --production`` takes), its
  energy curve's peak (J), time of peak, area (J·s), mean (J), and its gesture
  landmarks (label, articulator, clarity, closure, each landmark's time and position,
  peak speeds, durations: the columns of ``tonguevis syllables --gestures``).
* ``simulation``: one row per recording: rest, alignment, plausibility figures.
* ``segmentation``: one row per partition of each segmented production.
* ``validation``: one row per held-out sensor: RMSE (mm) and correlation per method.
* ``measures``: one row per production: the columns of ``tonguevis measures --out``.
* ``trajectories``: one row per production, sensor and percent of its normalised time: the vertical
  position (mm) and its z-score, the records the STI is computed from.

Gathered for the corpus only, from ``trajectories``: ``repetitions`` (the STI of each group of
``group_by`` and sensor, with the count) and ``averages`` (each group's mean ± SD trajectories).

Every table but ``energy`` has ``file`` (the recording's path relative to the
corpus folder) besides ``recording`` (its stem, as ``tonguevis energy`` names it).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from tonguevis.analysis.energy import CSV_COLUMNS
from tonguevis.analysis.measures import COLUMNS as MEASURE_COLUMNS
from tonguevis.analysis.repetitions import AVERAGE_COLUMNS
from tonguevis.preprocess.gesture_table import COLUMNS as GESTURE_COLUMNS
from tonguevis.preprocess.gesture_table import gesture_rows

TABLES = ("simulation", "energy", "productions", "segmentation", "validation", "measures", "trajectories",
          "repetitions", "averages")
#: The table(s) each step writes.
STEP_TABLES = {"simulate": ("simulation",), "energy": ("energy", "productions"), "segment": ("segmentation",),
               "validate": ("validation",), "measures": ("measures", "trajectories")}
_ARROW_KINDS = {"str": "string", "int": "int64", "float": "float64", "bool": "bool_"}
VALIDATION_METHODS = ("model", "linear", "static", "kinematic")

_LABELS = [("recording", "string"), ("file", "string"), ("speaker", "string"), ("syllable", "string"),
           ("trial", "int64")]
#: The gesture landmarks of each production (tonguevis.preprocess.gesture_table), less what the table has.
_GESTURE_COLUMNS = [(c, {"str": "string", "int": "int64", "float": "float64"}[k])
                    for c, k in GESTURE_COLUMNS.items() if c not in ("production", "train", "index", "release_s", "vowel_s")]
_COLUMNS: dict[str, list[tuple[str, str]]] = {
    "energy": [(c, {"recording": "string", "production": "string", "speaker": "string", "syllable": "string",
                    "trial": "int64", "train": "int64", "index": "int64", "frame": "int64"}.get(c, "float64"))
               for c in CSV_COLUMNS],
    "productions": _LABELS + [
        ("production", "string"), ("number", "int64"), ("train", "int64"), ("index", "int64"),
        ("start_s", "float64"), ("end_s", "float64"), ("release_s", "float64"), ("vowel_s", "float64"),
        ("duration_s", "float64"), ("window", "string"), ("curve_start_s", "float64"), ("curve_end_s", "float64"),
        ("peak_J", "float64"), ("peak_time_s", "float64"), ("peak_time_norm", "float64"), ("area_Js", "float64"),
        ("mean_J", "float64")] + _GESTURE_COLUMNS,
    "simulation": _LABELS + [
        ("format", "string"), ("frames", "int64"), ("duration_s", "float64"), ("rate_hz", "float64"),
        ("modes", "int64"), ("warping", "bool_"), ("landmarks", "string"), ("sensor_stiffness", "float64"),
        ("sensors", "string"), ("rest_start_s", "float64"), ("rest_end_s", "float64"), ("rest_how", "string"),
        ("alignment_scale", "float64"), ("alignment_rms_mm", "float64"), ("amplification", "float64"),
        ("max_volume_change_pct", "float64"), ("sensor_misfit_rms_mm", "float64"),
        ("sensor_misfit_max_mm", "float64"), ("unconverged_frames", "int64"), ("flagged_frames", "int64"),
        ("peak_energy_mJ", "float64"), ("peak_energy_time_s", "float64"), ("seconds", "float64")],
    "segmentation": _LABELS + [
        ("production", "string"), ("number", "int64"), ("train", "int64"), ("index", "int64"),
        ("start_s", "float64"), ("end_s", "float64"), ("mode", "string"), ("frames", "int64"),
        ("partitions", "int64"), ("relative_error", "float64"), ("seconds", "float64"), ("partition", "int64"),
        ("tets", "int64"), ("volume_cm3", "float64"), ("rms_error_mm", "float64"), ("seed_tet", "int64"),
        ("centroid_x_m", "float64"), ("centroid_y_m", "float64"), ("centroid_z_m", "float64")],
    "validation": _LABELS + [
        ("sensor", "string"), ("node", "int64"), ("drivers", "string"), ("frames", "int64"),
        ("measured_peak_mm", "float64"), ("outside_drivers", "bool_")]
        + [(f"{m}_{what}", kind) for m in VALIDATION_METHODS
           for what, kind in (("rmse_mm", "float64"), ("corr", "float64"), ("unconverged_frames", "int64"))],
    "measures": _LABELS + [(c, _ARROW_KINDS[k]) for c, k in MEASURE_COLUMNS.items()],
    "trajectories": _LABELS + [
        ("production", "string"), ("train", "int64"), ("index", "int64"), ("label", "string"), ("start_s", "float64"),
        ("end_s", "float64"), ("sensor", "string"), ("time_percent", "float64"), ("z_mm", "float64"),
        ("zscore", "float64")],
    "repetitions": [("group", "string"), ("by", "string"), ("sensor", "string"), ("n", "int64"),
                    ("recordings", "int64"), ("sti", "float64"), ("signal", "string")],
    "averages": [("group", "string"), ("by", "string")] + [(c, _ARROW_KINDS[k]) for c, k in AVERAGE_COLUMNS.items()],
}


def schema(name: str):
    """The Arrow schema of table ``name``."""
    import pyarrow as pa

    return pa.schema([(column, getattr(pa, kind)()) for column, kind in _COLUMNS[name]])


def columns(name: str) -> list[str]:
    return [c for c, _ in _COLUMNS[name]]


def to_arrow(name: str, rows: list[dict]):
    """An Arrow table of ``rows`` (dicts keyed by column; missing keys and NaN floats become nulls)."""
    import pyarrow as pa

    data = {}
    for column, kind in _COLUMNS[name]:
        values = [row.get(column) for row in rows]
        if kind == "float64":
            values = [None if v is None or not math.isfinite(float(v)) else float(v) for v in values]
        data[column] = values
    return pa.Table.from_pydict(data, schema=schema(name))


def write(table, path: Path, csv: bool = False) -> list[Path]:
    """Write an Arrow table as Parquet (and CSV beside it), atomically; returns the paths written."""
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    from tonguevis._files import atomic_write

    path = Path(path)
    atomic_write(path, lambda tmp: pq.write_table(table, tmp))
    written = [path]
    if csv:
        atomic_write(path.with_suffix(".csv"), lambda tmp: pacsv.write_csv(table, tmp))
        written.append(path.with_suffix(".csv"))
    return written


# ---------------------------------------------------------------- rows of each table
def _labels(entry, file: str) -> dict:
    return {"recording": entry.name, "file": file, "speaker": entry.speaker, "syllable": entry.syllable,
            "trial": int(entry.trial)}


def energy_table(curves):
    """The energy table of curves, in the row order of ``tonguevis energy``'s CSV."""
    import pyarrow as pa

    parts = {c: [] for c in CSV_COLUMNS}
    for c in curves:
        n = len(c.energy)
        parts["recording"].append(np.full(n, c.recording, dtype=object))
        parts["production"].append(np.full(n, c.production, dtype=object))
        parts["time_s"].append(np.asarray(c.time_s, dtype=np.float64))
        parts["time_norm"].append(np.asarray(c.time_norm, dtype=np.float64))
        parts["energy_J"].append(np.asarray(c.energy, dtype=np.float64))
        parts["speaker"].append(np.full(n, c.speaker, dtype=object))
        parts["syllable"].append(np.full(n, c.syllable, dtype=object))
        for key in ("trial", "train", "index"):
            parts[key].append(np.full(n, getattr(c, key), dtype=np.int64))
        parts["recording_time_s"].append(np.asarray(c.times, dtype=np.float64))
        parts["frame"].append(np.asarray(c.frames, dtype=np.int64))
    s = schema("energy")
    data = {c: (np.concatenate(v) if v else []) for c, v in parts.items()}
    return pa.Table.from_pydict({c: pa.array(data[c], type=s.field(c).type) for c in CSV_COLUMNS}, schema=s)


def production_rows(entry, file: str, table, curves, window: str) -> list[dict]:
    """One row per production of ``table`` with its curve's statistics (None when it has no curve)."""
    by_key = {(c.train, c.index): c for c in curves}
    gestures = {(g["train"], g["index"]): g for g in gesture_rows(table)}
    rows = []
    for number, p in enumerate(table, start=1):
        row = {**gestures.get((p.train, p.index), {}), **_labels(entry, file), "production": f"{p.train}.{p.index}",
               "number": number, "train": p.train, "index": p.index, "start_s": p.start, "end_s": p.end,
               "release_s": p.release, "vowel_s": p.vowel, "duration_s": p.end - p.start, "window": window}
        curve = by_key.get((p.train, p.index))
        if curve is not None:
            stats = curve.stats()
            row.update(curve_start_s=curve.start, curve_end_s=curve.end,
                       **{k: stats[k] for k in ("peak_J", "peak_time_s", "peak_time_norm", "area_Js", "mean_J")})
        rows.append(row)
    return rows


def simulation_row(entry, file: str, rec, motion, seconds: float) -> dict:
    from tonguevis.workflows import rest_of

    meta = motion.metadata
    plaus = meta.get("plausibility", {})
    rest = rest_of(motion)
    peak = int(np.argmax(motion.energy)) if motion.n_frames else 0
    stiffness = meta.get("sensor_stiffness")
    return {
        **_labels(entry, file), "format": rec.metadata.get("format"), "frames": motion.n_frames,
        "duration_s": float(motion.times[-1] - motion.times[0]) if motion.n_frames else 0.0,
        "rate_hz": float(rec.rate), "modes": int(motion.q.shape[1]), "warping": bool(motion.warping),
        "landmarks": meta.get("landmarks"), "sensor_stiffness": stiffness,
        "sensors": ",".join(motion.sensor_names),
        "rest_start_s": rest.interval[0] if rest else None, "rest_end_s": rest.interval[1] if rest else None,
        "rest_how": rest.how if rest else None, "alignment_scale": meta.get("alignment_scale"),
        "alignment_rms_mm": 1e3 * meta["alignment_rms_m"] if meta.get("alignment_rms_m") is not None else None,
        "amplification": plaus.get("amplification"), "max_volume_change_pct": plaus.get("volume_change_max_percent"),
        "sensor_misfit_rms_mm": plaus.get("sensor_misfit_rms_mm"),
        "sensor_misfit_max_mm": plaus.get("sensor_misfit_max_mm"),
        "unconverged_frames": len(meta.get("unconverged_frames", [])),
        "flagged_frames": len(meta.get("recovered_frames", [])) + len(meta.get("implausible_frames", [])),
        "peak_energy_mJ": 1e3 * float(motion.energy[peak]) if motion.n_frames else None,
        "peak_energy_time_s": float(motion.times[peak]) if motion.n_frames else None,
        "seconds": seconds,
    }


def segmentation_rows(entry, file: str, number: int, production, result) -> list[dict]:
    """One row per partition of a :class:`~tonguevis.analysis.segmentation.SegmentationResult`."""
    head = {**_labels(entry, file), "production": f"{production.train}.{production.index}", "number": number,
            "train": production.train, "index": production.index, "start_s": production.start,
            "end_s": production.end, "mode": result.mode, "frames": result.n_frames,
            "partitions": result.n_partitions, "relative_error": result.relative_error,
            "seconds": result.metadata.get("seconds")}
    rows = []
    for part in result.partition_rows():
        x, y, z = part["centroid_m"]
        rows.append({**head, "partition": part["partition"], "tets": part["tets"], "volume_cm3": part["volume_cm3"],
                     "rms_error_mm": part["rms_error_mm"], "seed_tet": part["seed"], "centroid_x_m": x,
                     "centroid_y_m": y, "centroid_z_m": z})
    return rows


def validation_rows(entry, file: str, document: dict) -> list[dict]:
    """One row per held-out sensor of a validation document (:meth:`ValidationResult.as_dict`)."""
    rows = []
    for sensor, s in document["sensors"].items():
        row: dict[str, Any] = {**_labels(entry, file), "sensor": sensor, "node": s["node"],
                               "drivers": ",".join(s["drivers"]), "frames": s["frames"],
                               "measured_peak_mm": s.get("measured_peak_mm"),
                               "outside_drivers": s.get("outside_drivers")}
        for m in VALIDATION_METHODS:
            for what in ("rmse_mm", "corr", "unconverged_frames"):
                row[f"{m}_{what}"] = s.get(f"{m}_{what}")
        rows.append(row)
    return rows


def measures_rows(entry, file: str, rows: list[dict]) -> list[dict]:
    """The rows of ``tonguevis measures`` with the recording's labels."""
    return [{**row, **_labels(entry, file)} for row in rows]


def trajectories_table(entry, file: str, table, repetitions):
    """The trajectories table of one recording: its productions' time-normalised records, per sensor."""
    import pyarrow as pa

    from tonguevis.analysis.repetitions import PERCENT

    k, names = len(PERCENT), repetitions.sensors
    count = len(table.productions) * len(names) * k
    productions = [p for p in table.productions for _ in names for _ in range(k)]
    data = {**{key: [value] * count for key, value in _labels(entry, file).items()},
            "production": [f"{p.train}.{p.index}" for p in productions], "train": [p.train for p in productions],
            "index": [p.index for p in productions], "label": [p.label for p in productions],
            "start_s": [p.start for p in productions], "end_s": [p.end for p in productions],
            "sensor": [name for _ in table.productions for name in names for _ in range(k)],
            "time_percent": np.tile(PERCENT, len(table.productions) * len(names)),
            "z_mm": np.stack([repetitions.records_mm[n] for n in names], axis=1).ravel() if names else [],
            "zscore": np.stack([repetitions.zscores[n] for n in names], axis=1).ravel() if names else []}
    s = schema("trajectories")
    return pa.Table.from_pydict({c: pa.array(data[c], type=s.field(c).type) for c in columns("trajectories")}, schema=s)


def repetition_tables(trajectories, by) -> tuple:
    """(repetitions, averages) Arrow tables of a gathered trajectories table, pooled by the labels ``by``.

    Per group and sensor, the stored z-scored records of every production in the group give its STI
    (:func:`tonguevis.analysis.repetitions.sti_of`: the same figure as ``tonguevis measures`` on the one
    recording of a group of one), and the mm records its mean ± SD trajectories.
    """
    from tonguevis.analysis.repetitions import PERCENT, SIGNAL, Repetitions

    k = len(PERCENT)
    data = {c: trajectories.column(c).to_pylist() for c in ("file", "production", "sensor", "label", *by)}
    z_mm = np.asarray(trajectories.column("z_mm").to_numpy(zero_copy_only=False), dtype=np.float64)
    zscore = np.asarray(trajectories.column("zscore").to_numpy(zero_copy_only=False), dtype=np.float64)
    starts = np.asarray(trajectories.column("start_s").to_numpy(zero_copy_only=False), dtype=np.float64)
    ends = np.asarray(trajectories.column("end_s").to_numpy(zero_copy_only=False), dtype=np.float64)
    # Rows come in blocks of k (one record of one production and sensor), in the order each recording wrote them.
    groups: dict[tuple, dict] = {}
    for first in range(0, len(z_mm), k):
        key = tuple("" if data[b][first] is None else str(data[b][first]) for b in by)
        sensor = data["sensor"][first]
        members = groups.setdefault(key, {}).setdefault(sensor, {"mm": [], "z": [], "files": set(), "spans": [],
                                                                  "labels": []})
        members["mm"].append(z_mm[first:first + k])
        members["z"].append(zscore[first:first + k])
        members["files"].add(data["file"][first])
        members["spans"].append((starts[first], ends[first]))
        members["labels"].append(data["label"][first])
    repetition_rows, average_rows = [], []
    for key, sensors in groups.items():
        group = " ".join(key) or "all"
        for sensor, m in sensors.items():
            reps = Repetitions(np.array(m["spans"]), m["labels"], {sensor: np.array(m["mm"])},
                               {sensor: np.array(m["z"])})
            repetition_rows.append({"group": group, "by": ",".join(by), "sensor": sensor, "n": reps.n,
                                    "recordings": len(m["files"]), "sti": reps.sti[sensor], "signal": SIGNAL})
            average_rows += [{"group": group, "by": ",".join(by), **row} for row in reps.average_rows()]
    return to_arrow("repetitions", repetition_rows), to_arrow("averages", average_rows)
