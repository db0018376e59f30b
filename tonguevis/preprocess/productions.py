"""CV productions of a recording, on real sessions and in the paper's trains (§3.2).

A production is one CV syllable, from its consonant release to the next production's
release within a train (the paper's boundary), or to the end of its vowel (80 % of the
way back up) when the syllable stands alone.  The consonant's articulator is chosen by
:func:`~tonguevis.preprocess.articulators.choose_articulator` (the syllable's place, else
the data); its closures, releases, vowel targets and MVIEW-style gesture landmarks come
from :mod:`tonguevis.preprocess.gestures`.

Trains: with sound, a train is a stretch of sound (:func:`find_trains`) and closures in
silence are not productions; without sound, closures less than ``TRAIN_GAP`` apart form a
train.  The paper keeps the 2nd to 4th productions of its trains of five (the first and
last are longer and larger); that rule applies only to trains of three or more:
isolated repetitions and pairs are all kept.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import astuple, dataclass, field
from pathlib import Path

import numpy as np

from tonguevis._files import atomic_write_text
from tonguevis.io.recording import Recording
from tonguevis.preprocess import gestures
from tonguevis.preprocess.gestures import GestureLandmarks
from tonguevis.preprocess.trains import find_trains

from tonguevis._logging import logger

#: Closures closer than this (s) without sound to separate them belong to one train.
TRAIN_GAP = 1.0
#: Closures up to this long (s) before a train's sound still belong to it (the stop closure is silent).
PAD = 0.25


@dataclass(frozen=True)
class Production:
    """One CV production; times in seconds on the recording's clock.

    train : 1-based train number; index : 1-based position in its train;
    start == release : the consonant release opening it; end : the next
    release in the train, the train's end, or the end of the vowel; vowel : the vowel
    target (articulator lowest), between start and end; closure : the maximum
    constriction (NaN for labelled productions); label : the syllable ("ta") or the
    label's text; articulator : the sensor it was found on (TT, TD, LA); clarity : 0 at
    the detection threshold to 1 for a closure whose fall to the vowel spans half the articulator's range
    (NaN for labelled productions).
    """

    train: int
    index: int
    start: float
    end: float
    release: float
    vowel: float
    closure: float = float("nan")
    label: str = ""
    articulator: str = ""
    clarity: float = float("nan")

    @property
    def duration(self) -> float:
        return self.end - self.start

    @property
    def name(self) -> str:
        """``train.index``, followed by the label when there is one (``1.2 ka``)."""
        return f"{self.train}.{self.index}" + (f" {self.label}" if self.label else "")


#: The numeric fields of :meth:`ProductionTable.as_array`, in order.
ARRAY_FIELDS = ("train", "index", "start", "end", "release", "vowel")
#: Columns of the productions CSV and of the screen table: units in every time column.
CSV_COLUMNS = ("train", "index", "label", "articulator", "start_s", "end_s", "release_s", "closure_s", "vowel_s",
               "duration_ms", "clarity")


@dataclass
class ProductionTable:
    """The productions of a recording, in time order, with the trains they came from.

    productions : list[Production]; trains : list of (start_s, end_s);
    counts : productions found in each train (before ``keep``); notes :
    human-readable warnings; landmarks : one :class:`GestureLandmarks` per production
    (empty for labelled productions); articulator and why it was chosen; clear : False
    when the recording's syllables are unclear (the notes say why).
    """

    productions: list[Production] = field(default_factory=list)
    trains: list[tuple[float, float]] = field(default_factory=list)
    counts: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    landmarks: list[GestureLandmarks] = field(default_factory=list)
    articulator: str = ""
    articulator_reason: str = ""
    clear: bool = True

    def __len__(self) -> int:
        return len(self.productions)

    def __iter__(self):
        return iter(self.productions)

    def __getitem__(self, item):
        return self.productions[item]

    @property
    def columns(self) -> list[str]:
        return list(CSV_COLUMNS)

    def as_array(self) -> np.ndarray:
        """(P, 6) float64: train, index, start, end, release, vowel."""
        return np.array([astuple(p)[:6] for p in self.productions], dtype=np.float64).reshape(-1, 6)

    def rows(self) -> list[list]:
        """One row per production in :data:`CSV_COLUMNS` order (times in s, duration in ms)."""
        return [[p.train, p.index, p.label, p.articulator, p.start, p.end, p.release, p.closure, p.vowel,
                 1000 * p.duration, p.clarity] for p in self.productions]

    def to_text(self) -> str:
        """A fixed-width table for the terminal, with the CSV's column names."""
        widths = (5, 5, 5, 11, 9, 9, 9, 9, 9, 11, 7)
        lines = [" ".join(f"{c:>{w}}" for c, w in zip(CSV_COLUMNS, widths))]
        for row in self.rows():
            cells = []
            for value, w, column in zip(row, widths, CSV_COLUMNS):
                if isinstance(value, str):
                    cells.append(f"{value or '-':>{w}}")
                elif column in ("train", "index"):
                    cells.append(f"{value:{w}d}")
                elif column == "duration_ms":
                    cells.append(f"{value:{w}.0f}")
                elif column == "clarity":
                    cells.append(f"{'-':>{w}}" if math.isnan(value) else f"{value:{w}.2f}")
                else:
                    cells.append(f"{'-':>{w}}" if math.isnan(value) else f"{value:{w}.3f}")
            lines.append(" ".join(cells))
        return "\n".join(lines)

    def to_csv(self, path) -> None:
        """Write a CSV (header: :data:`CSV_COLUMNS`) atomically; NaN is an empty cell."""
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(CSV_COLUMNS)
        for row in self.rows():
            writer.writerow([_cell(v, c) for v, c in zip(row, CSV_COLUMNS)])
        atomic_write_text(Path(path), buffer.getvalue())


def _cell(value, column: str) -> str:
    if isinstance(value, str):
        return value
    if column in ("train", "index"):
        return str(int(value))
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return f"{value:.1f}" if column == "duration_ms" else f"{value:.4f}"


def find_productions(rec: Recording, articulator: str | None = None, keep=(2, 3, 4), trains=None,
                     syllable: str | None = None, tip: str | None = None) -> ProductionTable:
    """The CV productions of ``rec`` (head-corrected positions; see the module docstring).

    articulator : the sensor to find them on (TT, TD, ... or LA for the lip aperture);
        None chooses it (:func:`~tonguevis.preprocess.articulators.choose_articulator`).
    keep : 1-based positions within each train of three or more to keep (None or "all":
        every production); isolated productions and pairs are always kept.
    trains : (start_s, end_s) spans to look in; None: the sound's trains when the
        recording has sound, else closures less than ``TRAIN_GAP`` s apart.
    syllable : the syllable spoken ("ka"): its place decides the articulator and it
        labels every production; None: the recording's metadata or file name.
    tip : the old name of ``articulator`` (kept for one release).
    """
    from tonguevis.preprocess.articulators import choose_articulator, constriction_signal, syllable_from_name

    file = rec.metadata.get("file")
    if articulator is None and tip is not None:
        articulator = tip
    if articulator is None:
        articulator, reason = choose_articulator(rec, syllable)
    else:
        reason = "given"
    signal = constriction_signal(rec, articulator)
    label = syllable or rec.metadata.get("syllable") or syllable_from_name(file) or ""
    table = ProductionTable(articulator=articulator, articulator_reason=reason)
    keep_all = keep is None or keep == "all"
    if rec.n_samples < 5 or signal.valid.sum() < 5:
        table.notes.append(f"too few valid samples of {articulator} to find productions")
        table.clear = False
        return table
    times, rate, s, scale = rec.times, rec.rate, signal.signal, signal.scale
    closures, near = gestures.find_closures(s, rate, scale)
    sound = trains is None and rec.audio is not None and len(rec.audio.samples) > 0
    if sound:
        trains = find_trains(rec, use_audio=True)
    if trains is not None:
        spans = [(float(a), float(b)) for a, b in trains]
        groups = [[c for c in closures if a - PAD <= times[c.peak] <= b] for a, b in spans]
        if sound:
            # A train's first consonant may start from a rest posture already near the closure (a
            # small rise); the sound vouches that speech starts there, so its fall alone decides.
            for g, (a, b) in zip(groups, spans):
                first = [c for c in near if a - PAD <= times[c.peak] <= b
                         and c.fall >= max(gestures.MIN_SIZE * scale, gestures.MIN_SIZE_M)
                         and (not g or c.peak < g[0].peak)]
                if first:
                    g.insert(0, first[0])
                    near = [c for c in near if c is not first[0]]
        inside = {c.peak for g in groups for c in g}
        silent = [c for c in closures if c.peak not in inside]
        if silent:
            table.notes.append(f"{len(silent)} closing movement(s) of {articulator} outside the "
                               f"{'sound' if sound else 'given trains'} ignored (at "
                               + ", ".join(f"{times[c.peak]:.2f}" for c in silent[:8])
                               + (" ..." if len(silent) > 8 else "") + " s)")
        near = [c for c in near if any(a - PAD <= times[c.peak] <= b for a, b in spans)]
        closures = [c for g in groups for c in g]
    else:
        spans, groups = None, []
        for c in closures:
            if groups and times[c.peak] - times[groups[-1][-1].peak] < TRAIN_GAP:
                groups[-1].append(c)
            else:
                groups.append([c])
    peaks = [c.peak for c in closures]
    found = {}
    for number, group in enumerate(groups):
        limit = int(np.searchsorted(times, spans[number][1], side="right")) - 1 if sound else None
        found.update({c.peak: _measure(times, rate, signal, c, peaks, scale, limit) for c in group})
    lengths = [len(g) for g in groups if len(g) >= 3]
    usual = max(set(lengths), key=lengths.count) if lengths else 0
    for number, group in enumerate(groups, start=1):
        measured = [found[c.peak] for c in group]
        table.counts.append(len(group))
        if spans is not None:
            begin, finish = spans[number - 1]
        elif measured:
            begin, finish = measured[0]["landmarks"].times["gons"], measured[-1]["vowel_end"]
        table.trains.append((float(begin), float(finish)))
        if spans is not None and not group:
            table.notes.append(f"train {number} ({begin:.2f}-{finish:.2f} s): no closing movement of {articulator}")
        elif len(group) >= 3 and len(group) != usual:
            table.notes.append(f"train {number} ({begin:.2f}-{finish:.2f} s): {len(group)} productions, the other "
                               f"trains {usual}; positions counted from its first")
        for index, m in enumerate(measured, start=1):
            if index < len(measured):
                end = measured[index]["release"]
            elif spans is not None:
                end = max(finish, m["release"])
            else:
                end = m["vowel_end"]
            if keep_all or len(group) < 3 or index in keep:
                table.productions.append(Production(number, index, m["release"], float(end), m["release"],
                                                    m["vowel"], m["closure"], label, articulator, m["clarity"]))
                table.landmarks.append(m["landmarks"])
    if not keep_all and groups and all(len(g) < 3 for g in groups):
        table.notes.append("no trains (no three productions in a row): every production kept, not the "
                           "paper's 2nd-4th")
    _judge_clarity(table, times, near, closures, scale, articulator)
    for note in table.notes:  # the table carries them; callers decide how loudly to report
        logger.info("%s: %s", file or "recording", note)
    return table


def _measure(times: np.ndarray, rate: float, signal, closure, peaks: list[int], scale: float,
             limit: int | None = None) -> dict:
    """Release, vowel target and its end, landmarks and clarity of one closure; the vowel
    is looked for up to sample ``limit`` at most (the end of the train's sound: a vowel is voiced)."""
    s = signal.signal
    n = len(s)
    peak = closure.peak
    later = [p for p in peaks if p > peak]
    earlier = [p for p in peaks if p < peak]
    reach = int(round(gestures.VOWEL_REACH * rate))
    stop = min(later[0] if later else n - 1, peak + reach, n - 1)
    if limit is not None and limit > peak + 1:
        stop = min(stop, limit)
    segment = s[peak:stop + 1]
    rising = np.flatnonzero(segment - np.minimum.accumulate(segment) >= gestures.NEAR_SIZE * scale)
    if rising.size:
        segment = segment[:rising[0]]
    vowel = peak + int(np.argmin(segment))
    level = s[peak] - gestures.RELEASE_FRACTION * (s[peak] - s[vowel])
    release = gestures.crossing_time(times, s, peak, level, +1, vowel)
    back_stop = min(later[0] if later else n - 1, vowel + reach, n - 1)
    top = float(s[vowel:back_stop + 1].max())
    back = s[vowel] + gestures.VOWEL_END_FRACTION * (top - s[vowel])
    vowel_end = gestures.crossing_time(times, -s, vowel, -back, +1, back_stop)
    if vowel_end is None:
        vowel_end = float(times[back_stop])
    end_index = min(int(np.searchsorted(times, vowel_end)), n - 1)
    floor = max(peak - int(round(2 * gestures.RISE_REACH * rate)), 0)
    if earlier:
        floor = max(floor, earlier[-1] + 1)
    search_start = floor + int(np.argmin(s[floor:peak + 1]))
    landmarks = gestures.gesture_landmarks(times, signal.positions, signal.speed, s, peak, search_start, vowel,
                                           max(end_index, vowel))
    # How clearly this is a CV production: its fall from the closure to the vowel (the release), against
    # the range.  Not the rise, which only has to pass MIN_SIZE: in isolated repetitions of a coronal
    # the tip rests high, near its closure, and rises only from a short opening dip (the certain /ta/
    # of Opti-Speech 009 at 2.4 s rose 0.34 of the range and fell 0.60), so the rise called every
    # production of a clean /ta/ session weak and the session unclear.
    clarity = float(np.clip((closure.fall / scale - gestures.MIN_SIZE) / gestures.MIN_SIZE, 0.0, 1.0))
    return {"release": float(release if release is not None else times[peak]), "vowel": float(times[vowel]),
            "vowel_end": float(vowel_end), "closure": landmarks.times["maxc"], "landmarks": landmarks,
            "clarity": clarity}


def _judge_clarity(table: ProductionTable, times, near, closures, scale: float, articulator: str) -> None:
    """Notes, and ``table.clear`` False, when the syllables are not clear enough to trust."""
    if not closures:
        table.clear = False
        table.notes.append(f"no CV production found: {articulator} never rose and fell by "
                           f"{100 * gestures.MIN_SIZE:.0f} % of its range ({1000 * scale:.1f} mm) around a closure")
        return
    if near:
        table.notes.append(f"{len(near)} movement(s) of {articulator} nearly counted as productions "
                           f"({100 * gestures.NEAR_SIZE:.0f}-{100 * gestures.MIN_SIZE:.0f} % of its range) at "
                           + ", ".join(f"{times[c.peak]:.2f}" for c in near[:8]) + (" ..." if len(near) > 8 else "")
                           + " s")
    weak = [p for p in table.productions if p.clarity < 0.5]
    if len(near) >= max(2, 0.5 * len(closures)) or len(weak) > 0.25 * max(len(table.productions), 1):
        table.clear = False
        table.notes.append("the syllables of this recording are unclear: check the productions against the "
                           "recording, or give them as labels (--productions-from TIER)")


def labelled_measures(rec: Recording, signal, start: float, end: float) -> tuple[float, float, GestureLandmarks]:
    """(vowel_s, closure_s, landmarks) of a labelled production from ``start`` to ``end`` s.

    signal : the articulator's :class:`~tonguevis.preprocess.articulators.ConstrictionSignal`
    or None.  The vowel is the lowest point inside the interval, the closure peak the
    highest point from ``RISE_REACH`` s before the start to the vowel; NaN without
    valid samples there.
    """
    times = rec.times
    nan = float("nan")
    if signal is None:
        return nan, nan, gestures.missing_landmarks()
    s = signal.signal
    inside = np.flatnonzero((times >= start) & (times <= end) & signal.valid)
    if inside.size == 0:
        return nan, nan, gestures.missing_landmarks()
    vowel = int(inside[np.argmin(s[inside])])
    lo = int(np.searchsorted(times, start - gestures.RISE_REACH))
    if vowel <= lo:
        return float(times[vowel]), nan, gestures.missing_landmarks()
    peak = lo + int(np.argmax(s[lo:vowel]))
    floor = max(peak - int(round(2 * gestures.RISE_REACH * rec.rate)), 0)
    search_start = floor + int(np.argmin(s[floor:peak + 1]))
    stop = min(int(np.searchsorted(times, end)), len(s) - 1)
    landmarks = gestures.gesture_landmarks(times, signal.positions, signal.speed, s, peak, search_start, vowel,
                                           max(stop, vowel))
    return float(times[vowel]), landmarks.times["maxc"], landmarks


def production_near(rec: Recording, articulator: str, time: float, reach: float = 0.5) -> tuple[float, float] | None:
    """(start_s, end_s) of the CV whose closure lies nearest ``time`` (within ``reach`` s), found
    as :func:`find_productions` finds them but also among its near misses; None when no closing
    movement is there.  For adding a production the finder missed."""
    from tonguevis.preprocess.articulators import constriction_signal

    signal = constriction_signal(rec, articulator)
    if rec.n_samples < 5 or signal.valid.sum() < 5:
        return None
    scale = signal.scale
    closures, near = gestures.find_closures(signal.signal, rec.rate, scale)
    candidates = sorted(closures + near, key=lambda c: abs(rec.times[c.peak] - time))
    if not candidates or abs(rec.times[candidates[0].peak] - time) > reach:
        return None
    chosen = candidates[0]
    m = _measure(rec.times, rec.rate, signal, chosen, sorted(c.peak for c in closures + near), scale)
    return m["release"], m["vowel_end"]
