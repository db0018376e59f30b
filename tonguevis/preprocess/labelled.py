"""Productions and annotation tiers, both ways: productions taken from a labelled tier
(instead of the automatic segmentation of §3.2), and productions written as tiers for Praat.
"""

from __future__ import annotations

import re

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Label, Recording
from tonguevis.preprocess.productions import Production, ProductionTable

#: Tier names of :func:`production_labels`.
PRODUCTIONS_TIER = "productions"
EVENTS_TIER = "events"
#: Intervals closer than this (s) belong to one train.
CONTIGUOUS = 1e-3


def productions_from_tier(rec: Recording, tier: str, articulator: str | None = None, syllable: str | None = None,
                          tip: str | None = None) -> ProductionTable:
    """Every labelled interval of label tier ``tier`` as a production, in time order.

    Silence labels (:data:`SILENCE_LABELS`, case-insensitive, and empty texts) are skipped.
    Intervals that touch (end of one = start of the next, within 1 ms) form one train,
    numbered from 1 with positions counted from 1; a gap starts a new train.
    ``start == release`` is the interval's start and ``end`` its end; the text is the
    production's label (a ``train.index`` text, as tonguevis writes when it knows no
    syllable, is not).  On ``articulator`` (default: the syllable's place, else TT) the
    vowel is its lowest point inside the interval and the gesture landmarks are measured
    around the highest point near the start; NaN without valid samples.  Every interval is
    kept (the 2nd-4th rule does not apply to intervals someone chose).  A missing tier, or
    a point tier, is a :class:`RecordingError` listing the tiers there are.
    """
    from tonguevis.io.textgrid import tier_labels, tier_names

    file = rec.metadata.get("file")
    names = tier_names(rec.labels)
    if tier not in names:
        there = ", ".join(names) if names else "none (give a TextGrid with --labels FILE or beside the recording)"
        raise RecordingError(f"no label tier {tier!r} to take the productions from; tiers: {there}", file)
    spoken = [lab for lab in tier_labels(rec.labels, tier) if not is_silence(lab.text) and lab.end > lab.start]
    if not spoken:
        kind = "a point tier" if all(lab.start == lab.end for lab in rec.labels if lab.tier == tier) else \
            "without a spoken interval (only silence labels)"
        raise RecordingError(f"label tier {tier!r} is {kind}: it has no interval to take as a "
                             f"production; tiers: {', '.join(names)}", file)
    table = productions_from_intervals(rec, [(lab.start, lab.end, _label_text(lab.text)) for lab in spoken],
                                       articulator=articulator or tip, syllable=syllable)
    skipped = len([lab for lab in tier_labels(rec.labels, tier) if lab.end > lab.start]) - len(spoken)
    table.notes.append(f"productions from the {len(spoken)} labelled intervals of tier {tier!r}"
                       + (f" ({skipped} silence or empty intervals skipped)" if skipped else ""))
    return table


def productions_from_intervals(rec: Recording, intervals, articulator: str | None = None,
                               syllable: str | None = None) -> ProductionTable:
    """Productions from ``intervals`` [(start_s, end_s, label)] someone chose, in time order.

    Touching intervals (within 1 ms) form a train.  On ``articulator`` (default: the place
    of ``syllable`` or of the labels, else TT) the vowel is the lowest point inside each
    interval and the gesture landmarks are measured around the highest point near its
    start (:func:`~tonguevis.preprocess.productions.labelled_measures`).
    """
    from tonguevis.preprocess.articulators import ARTICULATOR_OF_PLACE, available, constriction_signal, place_of
    from tonguevis.preprocess.productions import labelled_measures

    intervals = sorted((float(a), float(b), str(text)) for a, b, text in intervals)
    texts = [text for _, _, text in intervals]
    if articulator is None:
        place = place_of(syllable) or next((place_of(t) for t in texts if place_of(t)), None)
        choice = ARTICULATOR_OF_PLACE.get(place) if place else None
        options = available(rec)
        articulator = choice if choice in options else ("TT" if "TT" in options else (options[0] if options else None))
    signal = constriction_signal(rec, articulator) if articulator else None
    table = ProductionTable(articulator=articulator or "", articulator_reason="labelled")
    train, index, previous_end = 0, 0, None
    for start, end, text in intervals:
        if previous_end is None or start - previous_end > CONTIGUOUS:
            train, index = train + 1, 0
            table.trains.append((start, end))
            table.counts.append(0)
        index += 1
        table.trains[-1] = (table.trains[-1][0], end)
        table.counts[-1] += 1
        previous_end = end
        vowel, closure, landmarks = labelled_measures(rec, signal, start, end)
        table.productions.append(Production(train, index, start, end, start, vowel, closure,
                                            text or (syllable or ""), articulator or ""))
        table.landmarks.append(landmarks)
    return table


#: Interval texts that mark silence, not a production (Praat, MAUS, the Montreal aligner, MVIEW).
SILENCE_LABELS = frozenset({"", "sp", "sil", "sil1", "pau", "pause", "<p:>", "<p>", "#", "_", "spn", "<sil>",
                            "silence"})


def is_silence(text: str) -> bool:
    """True for a silence label (:data:`SILENCE_LABELS`) or an empty text."""
    return text.strip().lower() in SILENCE_LABELS


def _label_text(text: str) -> str:
    """The production's label from an interval text: a bare ``train.index`` (ours) is no label."""
    text = text.strip()
    return "" if re.fullmatch(r"\d+\.\d+", text) else text


#: Point tier of each gesture landmark, in MVIEW's names (landmark key -> tier name).
LANDMARK_TIERS = {"gons": "GONS", "pvel": "PVEL", "nons": "NONS", "maxc": "MAXC", "noffs": "NOFFS",
                  "pvel2": "PVEL2", "goffs": "GOFFS", "vowel": "VTARG"}


def production_labels(table: ProductionTable) -> list[Label]:
    """Productions as an interval tier ``productions`` (text: the label, else ``train.index``),
    their consonant releases and vowels as a point tier ``events`` (texts ``release``,
    ``vowel``), and their gesture landmarks as one point tier each (:data:`LANDMARK_TIERS`,
    text: the production's ``train.index``)."""
    intervals = [Label(p.start, p.end, p.label or f"{p.train}.{p.index}", PRODUCTIONS_TIER) for p in table]
    points: dict[float, str] = {}
    for p in table:
        for time, what in ((p.release, "release"), (p.vowel, "vowel")):
            if np.isfinite(time):
                points.setdefault(round(float(time), 6), what)
    events = [Label(t, t, what, EVENTS_TIER) for t, what in sorted(points.items())]
    marks = []
    for key, tier in LANDMARK_TIERS.items():
        seen: set[float] = set()
        for p, landmarks in zip(table.productions, table.landmarks):
            time = landmarks.times[key]
            if np.isfinite(time) and round(time, 6) not in seen:  # Praat wants distinct times in a tier
                seen.add(round(time, 6))
                marks.append(Label(time, time, f"{p.train}.{p.index}", tier))
    order = list(LANDMARK_TIERS.values())
    return intervals + events + sorted(marks, key=lambda lab: (order.index(lab.tier), lab.start))


def write_productions_textgrid(path, table: ProductionTable, rec: Recording) -> list[str]:
    """Write a Praat TextGrid of ``rec``'s label tiers plus the tiers of :func:`production_labels`
    (replacing tiers of those names), spanning the kinematics and the sound; returns the tier names.

    The TextGrid starts at 0 s, the time of the first audio sample, so it lines up with
    the recording's WAV in Praat.  Beside the recording as ``NAME.TextGrid`` it is read
    with it, and its ``productions`` tier is then the recording's productions for every
    command (:func:`tonguevis.workflows.find_recording_productions`).
    """
    from tonguevis.io.textgrid import tier_names, write_textgrid

    ours = production_labels(table)
    replaced = {PRODUCTIONS_TIER, EVENTS_TIER, *LANDMARK_TIERS.values()}
    labels = [lab for lab in rec.labels if lab.tier not in replaced] + ours
    ends = [rec.times[-1] + 1.0 / rec.rate if rec.n_samples else 0.0] + [lab.end for lab in labels]
    start = min(0.0, float(rec.times[0])) if rec.n_samples else 0.0
    if rec.audio is not None:
        start = min(start, rec.audio.offset)
        ends.append(rec.audio.offset + rec.audio.duration)
    names = tier_names(labels)
    ours_in_order = [PRODUCTIONS_TIER, EVENTS_TIER, *LANDMARK_TIERS.values()]
    for name in ours_in_order:  # every tier even when there is no production
        if name not in names:
            names.append(name)
    write_textgrid(labels, path, start=start, end=max(ends), tiers=names,
                   point_tiers=[EVENTS_TIER, *LANDMARK_TIERS.values()])
    return names
