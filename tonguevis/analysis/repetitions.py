"""Repetition variability: the spatiotemporal index (STI) and time-normalised mean ± SD trajectories.

The STI of Smith, Goffman, Zelaznik, Ying & McGillem (1995, Exp Brain Res 104:493), computed as in
Smith, Johnson, McGillem & Goffman (2000, JSLHR 43:277-286), per sensor, over a set of productions:

1. each production's record is the sensor's vertical position (z, head-corrected, low-passed at
   12 Hz like the gesture landmarks: zero-phase 4th-order Butterworth over the whole recording)
   from the production's start to its end;
2. linearly time-normalised: interpolated at :data:`RECORD_POINTS` equally spaced instants from the
   start to the end (0.1 % steps);
3. amplitude-normalised: its mean subtracted, divided by its standard deviation (over those points);
4. the standard deviation across the productions (n - 1 in the denominator) at 2 % steps of
   normalised time, 0, 2, ..., 98 % (:data:`STI_PERCENT`, 50 points);
5. STI = the sum of those 50 standard deviations.

Fewer productions underestimate the STI and longer stimuli raise it: the count (``n``) and the
productions' boundaries travel with every figure.  The mean ± SD trajectories are the same
time-normalised records in millimetres (and z-scored), at 1 % steps (:data:`PERCENT`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Points of each time-normalised record (0 to 100 % in 0.1 % steps).
RECORD_POINTS = 1001
#: The trajectories' grid: 0 to 100 % in 1 % steps (every 10th point of the record).
PERCENT = np.arange(101, dtype=np.float64)
#: Where the STI takes the standard deviations: 0, 2, ..., 98 % (50 points, indices into PERCENT).
STI_PERCENT = np.arange(0, 100, 2)
#: What the records are, for tables and JSON.
SIGNAL = ("vertical position z (head-corrected, low-passed at 12 Hz), from each production's start to its end, "
          "linearly time-normalised, z-scored; SD across productions at 0, 2, ..., 98 % (50 points), summed")


def normalised_records(times: np.ndarray, values: np.ndarray, intervals) -> np.ndarray:
    """(P, RECORD_POINTS) ``values`` (N,) sampled at ``times`` (N,) s, linearly interpolated at equally spaced
    instants from each (start_s, end_s) of ``intervals`` (P pairs) to its end."""
    intervals = np.asarray(intervals, dtype=np.float64).reshape(-1, 2)
    fraction = np.linspace(0.0, 1.0, RECORD_POINTS)
    instants = intervals[:, :1] + (intervals[:, 1:] - intervals[:, :1]) * fraction
    return np.interp(instants.ravel(), times, values).reshape(instants.shape)


def zscored(records: np.ndarray) -> np.ndarray:
    """Each row minus its mean, divided by its standard deviation (a flat row: all zeros)."""
    mean = records.mean(axis=1, keepdims=True)
    sd = records.std(axis=1, keepdims=True)
    return np.divide(records - mean, sd, out=np.zeros_like(records), where=sd > 0)


def sti_of(zscores: np.ndarray) -> float:
    """The STI of z-scored records on the :data:`PERCENT` grid (P, 101): the sum of the across-production
    standard deviations (n - 1) at :data:`STI_PERCENT`; NaN with fewer than two productions."""
    if len(zscores) < 2:
        return float("nan")
    return float(np.std(zscores[:, STI_PERCENT], axis=0, ddof=1).sum())


@dataclass
class Repetitions:
    """Time-normalised records of a set of productions, per sensor.

    intervals : (P, 2) start and end (s) of each production; labels : (P,) their labels;
    records_mm : sensor -> (P, 101) vertical position (mm) at 0..100 % (:data:`PERCENT`);
    zscores : sensor -> (P, 101) the same z-scored (over the whole 0.1 % record);
    signal : what the records are (:data:`SIGNAL`).
    """

    intervals: np.ndarray
    labels: list[str]
    records_mm: dict[str, np.ndarray]
    zscores: dict[str, np.ndarray]
    signal: str = SIGNAL
    notes: list[str] = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.intervals)

    @property
    def sensors(self) -> list[str]:
        return list(self.records_mm)

    @property
    def sti(self) -> dict[str, float]:
        """Sensor -> STI (dimensionless; NaN with fewer than two productions)."""
        return {name: sti_of(z) for name, z in self.zscores.items()}

    def subset(self, rows) -> "Repetitions":
        """The repetitions of the productions ``rows`` (indices) only."""
        rows = np.asarray(list(rows), dtype=np.int64)
        return Repetitions(self.intervals[rows], [self.labels[i] for i in rows],
                           {k: v[rows] for k, v in self.records_mm.items()},
                           {k: v[rows] for k, v in self.zscores.items()}, self.signal, list(self.notes))

    def as_json(self) -> dict:
        """``{"sti": {sensor: STI}, "signal": ..., "n": P, ...}`` with the productions' boundaries (s)."""
        return {"sti": {k: (None if not np.isfinite(v) else round(v, 6)) for k, v in self.sti.items()},
                "signal": self.signal, "n": self.n, "points": len(STI_PERCENT),
                "productions": [{"start_s": float(a), "end_s": float(b), "label": label}
                                for (a, b), label in zip(self.intervals, self.labels)],
                "notes": list(self.notes)}

    def average_rows(self) -> list[dict]:
        """The mean ± SD trajectories: one row per sensor and percent of normalised time (none without productions)."""
        rows = []
        if self.n == 0:
            return rows
        for name in self.sensors:
            mm, z = self.records_mm[name], self.zscores[name]
            ddof = 1 if len(mm) > 1 else 0
            mean_mm, sd_mm = mm.mean(axis=0), mm.std(axis=0, ddof=ddof)
            mean_z, sd_z = z.mean(axis=0), z.std(axis=0, ddof=ddof)
            for k, percent in enumerate(PERCENT):
                rows.append({"sensor": name, "time_percent": float(percent), "n": self.n,
                             "mean_z_mm": float(mean_mm[k]), "sd_z_mm": float(sd_mm[k]),
                             "mean_zscore": float(mean_z[k]), "sd_zscore": float(sd_z[k])})
        return rows


#: Columns of :meth:`Repetitions.average_rows` (name -> kind), in order.
AVERAGE_COLUMNS = {"sensor": "str", "time_percent": "float", "n": "int", "mean_z_mm": "float", "sd_z_mm": "float",
                   "mean_zscore": "float", "sd_zscore": "float"}


def repetitions(times: np.ndarray, rate: float, sensors: dict[str, np.ndarray], intervals, labels=None) -> Repetitions:
    """The :class:`Repetitions` of ``intervals`` [(start_s, end_s)] over ``sensors`` {name: (N, 3) m}.

    The positions are low-passed at 12 Hz first (:func:`tonguevis.preprocess.gestures.lowpass`, gaps
    filled); a sensor with no valid sample is left out (said in ``notes``).
    """
    from tonguevis.preprocess.gestures import lowpass

    intervals = np.asarray(intervals, dtype=np.float64).reshape(-1, 2)
    labels = [""] * len(intervals) if labels is None else [str(label) for label in labels]
    records, zscores, notes = {}, {}, []
    for name, xyz in sensors.items():
        z = np.asarray(xyz, dtype=np.float64)[:, 2]
        if not np.isfinite(z).any():
            notes.append(f"{name}: no valid sample, left out")
            continue
        record = normalised_records(times, lowpass(z, rate), intervals)
        records[name] = 1e3 * record[:, ::10]
        zscores[name] = zscored(record)[:, ::10]
    return Repetitions(intervals, labels, records, zscores, notes=notes)

