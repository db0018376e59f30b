"""Productions of CV syllables within trains (§3.2, second step).

Within each train the tongue-tip sensor's vertical displacement rises for
every consonant and falls for every vowel.  A consonant release is the
velocity zero crossing at a local maximum of the displacement, the vowel the
zero crossing at the local minimum that follows; one production runs from
one release to the next (the last of a train to the train's end).  The paper
keeps the second, third and fourth productions of five-syllable trains: the
first and last are longer and larger.
"""

from __future__ import annotations

import csv
import io
import logging
from dataclasses import astuple, dataclass, field, fields
from pathlib import Path

from tonguevis._files import atomic_write_text

import numpy as np
from scipy.signal import find_peaks, peak_prominences

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Recording
from tonguevis.preprocess._localpoly import savgol
from tonguevis.preprocess.trains import find_trains

log = logging.getLogger("tonguevis")


@dataclass(frozen=True)
class Production:
    """One CV production; times in seconds on the recording's clock.

    train : 1-based train number; index : 1-based position in its train;
    start == release : the consonant release opening it; end : the next
    release (or the train's end for the last of a train); vowel : the vowel
    target (tip lowest), between start and end.
    """

    train: int
    index: int
    start: float
    end: float
    release: float
    vowel: float

    @property
    def duration(self) -> float:
        return self.end - self.start


@dataclass
class ProductionTable:
    """The productions of a recording, in time order, with the trains they came from.

    productions : list[Production]; trains : list of (start_s, end_s);
    counts : productions found in each train (before ``keep``); notes :
    human-readable warnings (a train without five productions, ...).
    """

    productions: list[Production] = field(default_factory=list)
    trains: list[tuple[float, float]] = field(default_factory=list)
    counts: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.productions)

    def __iter__(self):
        return iter(self.productions)

    def __getitem__(self, item):
        return self.productions[item]

    @property
    def columns(self) -> list[str]:
        return [f.name for f in fields(Production)]

    def as_array(self) -> np.ndarray:
        """(P, 6) float64: train, index, start, end, release, vowel."""
        return np.array([astuple(p) for p in self.productions], dtype=np.float64).reshape(-1, 6)

    def to_text(self) -> str:
        """A fixed-width table for the terminal (times in seconds)."""
        lines = [f"{'train':>5} {'index':>5} {'start_s':>9} {'end_s':>9} {'release_s':>9} "
                 f"{'vowel_s':>9} {'dur_ms':>7}"]
        for p in self.productions:
            lines.append(f"{p.train:5d} {p.index:5d} {p.start:9.3f} {p.end:9.3f} {p.release:9.3f} "
                         f"{p.vowel:9.3f} {1000 * p.duration:7.0f}")
        return "\n".join(lines)

    def to_csv(self, path) -> None:
        """Write a CSV (header: the Production fields, times in seconds) atomically."""
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(self.columns)
        for p in self.productions:
            writer.writerow([p.train, p.index] + [f"{t:.4f}" for t in astuple(p)[2:]])
        atomic_write_text(Path(path), buffer.getvalue())


def _zero_crossing(times: np.ndarray, velocity: np.ndarray, near: int, falling: bool) -> float:
    """Time of the velocity sign change nearest sample ``near`` (linear interpolation).

    falling: + to - (a maximum of displacement); else - to +.  Falls back to
    the sample time when no sign change exists within 3 samples.
    """
    lo, hi = max(near - 3, 0), min(near + 3, len(velocity) - 1)
    v = velocity[lo:hi + 1]
    if falling:
        crossing = (v[:-1] >= 0) & (v[1:] < 0)
    else:
        crossing = (v[:-1] <= 0) & (v[1:] > 0)
    candidates = np.flatnonzero(crossing) + lo
    if candidates.size == 0:
        return float(times[near])
    k = int(candidates[np.argmin(np.abs(candidates + 0.5 - near))])
    fraction = velocity[k] / (velocity[k] - velocity[k + 1])
    return float(times[k] + fraction * (times[k + 1] - times[k]))


def _fill_gaps(values: np.ndarray) -> np.ndarray:
    """Linear interpolation over NaN samples (peak finding cannot take NaN)."""
    ok = np.isfinite(values)
    if ok.all() or not ok.any():
        return values
    index = np.arange(len(values))
    return np.interp(index, index[ok], values[ok])


def find_productions(rec: Recording, tip: str = "TT", keep=(2, 3, 4), trains=None, window: int = 9,
                     min_prominence: float = 0.3, pad: float = 0.25, axis: int = 2,
                     per_train: int = 5, min_fall: float = 0.001) -> ProductionTable:
    """Segment every train of ``rec`` into CV productions (release to release).

    tip : the most anterior tongue sensor; axis : its vertical coordinate (z).
    keep : 1-based positions within each train to keep (None or "all": every
    production).  trains : (start_s, end_s) spans, found by
    :func:`find_trains` when None.  The displacement is smoothed by a cubic
    Savitzky-Golay fit over ``window`` frames; a maximum counts as a release
    when the displacement then falls by ``min_prominence`` times the train's
    range, and by at least ``min_fall`` metres (1 mm: sensor noise is a few
    tenths), before rising above it again; the vowel is the lowest minimum
    between two releases.  Each is timed at the zero crossing of the smoothed
    velocity (sub-frame, linear interpolation).  Releases are searched from
    ``pad`` s before a train to its end.  The last production of a train ends
    at the train's end: the acoustic offset when the trains come from audio,
    the end of tip motion otherwise.  A train with other than ``per_train``
    productions gets a note in the table (positions still count from its
    first production).
    """
    file = rec.metadata.get("file")
    if tip not in rec.sensors:
        raise RecordingError(f"no tongue-tip sensor {tip!r} (sensors: {', '.join(rec.sensor_names)}); "
                             "give --sensors or another tip", file)
    if trains is None:
        trains = find_trains(rec, tip=tip)
    keep_all = keep is None or keep == "all"
    window = min(window, rec.n_samples - (1 - rec.n_samples % 2))
    table = ProductionTable(trains=[tuple(map(float, t)) for t in trains])
    if window < 5:
        return table
    delta = 1.0 / rec.rate
    height = savgol(rec.sensors[tip][:, axis], window, 3)
    velocity = savgol(rec.sensors[tip][:, axis], window, 3, deriv=1, delta=delta)
    times = rec.times
    for number, (begin, end) in enumerate(table.trains, start=1):
        lo = int(np.searchsorted(times, begin - pad))
        hi = int(np.searchsorted(times, end, side="right"))
        span = _fill_gaps(height[lo:hi])
        if hi - lo < 5 or not np.isfinite(span).all():
            table.counts.append(0)
            table.notes.append(f"train {number} ({begin:.2f}-{end:.2f} s): too few valid tip samples")
            continue
        # A release is a maximum followed by a fall of at least min_prominence of the
        # train's range (the rise before it may be small: /k/ and /r/ barely lift
        # the tip above its rest height when the jaw opens for the consonant).
        peaks, _ = find_peaks(span)
        if peaks.size:
            _, _, right_bases = peak_prominences(span, peaks)
            fall = span[peaks] - span[right_bases]
            peaks = peaks[fall >= max(min_prominence * float(np.ptp(span)), min_fall)]
        inside_train = times[peaks + lo] <= end
        peaks = peaks[inside_train] + lo
        troughs = find_peaks(-span)[0] + lo
        vel = np.where(np.isfinite(velocity), velocity, 0.0)
        releases = [_zero_crossing(times, vel, k, falling=True) for k in peaks]
        table.counts.append(len(releases))
        if len(releases) != per_train:
            table.notes.append(f"train {number} ({begin:.2f}-{end:.2f} s): {len(releases)} productions, "
                               f"not {per_train}; positions counted from its first")
        for index, release in enumerate(releases, start=1):
            stop = releases[index] if index < len(releases) else max(end, release)
            inside = troughs[(times[troughs] > release) & (times[troughs] < stop)]
            if inside.size:
                k = int(inside[np.argmin(height[inside])])
                vowel = _zero_crossing(times, vel, k, falling=False)
            else:
                between = np.flatnonzero((times > release) & (times < stop) & np.isfinite(height))
                vowel = float(times[between[np.argmin(height[between])]]) if between.size else np.nan
            if keep_all or index in keep:
                table.productions.append(Production(number, index, release, stop, release, vowel))
    for note in table.notes:  # the table carries them; callers decide how loudly to report
        log.info("%s: %s", file or "recording", note)
    return table
