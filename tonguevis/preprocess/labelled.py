"""Productions and annotation tiers, both ways: productions taken from a labelled tier
(instead of the automatic segmentation of §3.2), and productions written as tiers for Praat.
"""

from __future__ import annotations

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Label, Recording
from tonguevis.preprocess.productions import Production, ProductionTable

#: Tier names of :func:`production_labels`.
PRODUCTIONS_TIER = "productions"
EVENTS_TIER = "events"
#: Intervals closer than this (s) belong to one train.
CONTIGUOUS = 1e-3


def productions_from_tier(rec: Recording, tier: str, tip: str = "TT", axis: int = 2) -> ProductionTable:
    """Every non-empty interval of label tier ``tier`` as a production, in time order.

    Intervals that touch (end of one = start of the next, within 1 ms) form
    one train, numbered from 1 with positions counted from 1; a gap starts a
    new train.  ``start == release`` is the interval's start and ``end`` its
    end; the vowel is the time of the tip sensor's lowest point (coordinate
    ``axis``) inside the interval, NaN without a valid tip sample.  Every
    interval is kept (the 2nd-4th rule of the automatic segmentation does not
    apply to intervals someone chose).  A missing tier, or a point tier, is a
    :class:`RecordingError` listing the tiers there are.
    """
    from tonguevis.io.textgrid import tier_labels, tier_names

    file = rec.metadata.get("file")
    names = tier_names(rec.labels)
    if tier not in names:
        there = ", ".join(names) if names else "none (give a TextGrid with --labels FILE or beside the recording)"
        raise RecordingError(f"no label tier {tier!r} to take the productions from; tiers: {there}", file)
    intervals = [lab for lab in tier_labels(rec.labels, tier) if lab.text.strip() and lab.end > lab.start]
    if not intervals:
        kind = "a point tier" if all(lab.start == lab.end for lab in rec.labels if lab.tier == tier) else "empty"
        raise RecordingError(f"label tier {tier!r} is {kind}: it has no non-empty interval to take as a "
                             f"production; tiers: {', '.join(names)}", file)
    height = rec.sensors[tip][:, axis] if tip in rec.sensors else None
    table = ProductionTable()
    train, index, previous_end = 0, 0, None
    for lab in intervals:
        if previous_end is None or lab.start - previous_end > CONTIGUOUS:
            train, index = train + 1, 0
            table.trains.append((lab.start, lab.end))
            table.counts.append(0)
        index += 1
        table.trains[-1] = (table.trains[-1][0], lab.end)
        table.counts[-1] += 1
        previous_end = lab.end
        table.productions.append(Production(train, index, lab.start, lab.end, lab.start,
                                            _lowest(rec.times, height, lab.start, lab.end)))
    table.notes.append(f"productions from the {len(intervals)} non-empty intervals of label tier {tier!r}")
    return table


def _lowest(times: np.ndarray, height: np.ndarray | None, start: float, end: float) -> float:
    if height is None:
        return float("nan")
    inside = np.flatnonzero((times >= start) & (times <= end) & np.isfinite(height))
    if inside.size == 0:
        return float("nan")
    return float(times[inside[np.argmin(height[inside])]])


def production_labels(table: ProductionTable) -> list[Label]:
    """Productions as an interval tier ``productions`` (text ``train.index``) and their
    consonant releases and vowels as a point tier ``events`` (texts ``release``, ``vowel``)."""
    intervals = [Label(p.start, p.end, f"{p.train}.{p.index}", PRODUCTIONS_TIER) for p in table]
    points: dict[float, str] = {}
    for p in table:
        for time, what in ((p.release, "release"), (p.vowel, "vowel")):
            if np.isfinite(time):
                points.setdefault(round(float(time), 6), what)
    events = [Label(t, t, what, EVENTS_TIER) for t, what in sorted(points.items())]
    return intervals + events


def write_productions_textgrid(path, table: ProductionTable, rec: Recording) -> list[str]:
    """Write a Praat TextGrid of ``rec``'s label tiers plus the tiers of :func:`production_labels`
    (replacing tiers of those names), spanning the kinematics and the sound; returns the tier names.

    The TextGrid starts at 0 s, the time of the first audio sample, so it lines up with
    the recording's WAV in Praat.
    """
    from tonguevis.io.textgrid import tier_names, write_textgrid

    ours = production_labels(table)
    labels = [lab for lab in rec.labels if lab.tier not in (PRODUCTIONS_TIER, EVENTS_TIER)] + ours
    ends = [rec.times[-1] + 1.0 / rec.rate if rec.n_samples else 0.0] + [lab.end for lab in labels]
    start = min(0.0, float(rec.times[0])) if rec.n_samples else 0.0
    if rec.audio is not None:
        start = min(start, rec.audio.offset)
        ends.append(rec.audio.offset + rec.audio.duration)
    names = tier_names(labels)
    for name in (PRODUCTIONS_TIER, EVENTS_TIER):  # both tiers even when there is no production
        if name not in names:
            names.append(name)
    write_textgrid(labels, path, start=start, end=max(ends), tiers=names, point_tiers=[EVENTS_TIER])
    return names
