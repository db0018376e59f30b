"""Corrections of a recording's productions by hand, saved as a TextGrid beside it (no Qt).

:class:`ProductionEditor` holds a recording's productions as intervals someone may correct:
move a boundary, add a production, delete one.  Every correction rebuilds the table with
:func:`~tonguevis.preprocess.labelled.productions_from_intervals` (vowels and gesture
landmarks measured anew).  :meth:`ProductionEditor.save` writes ``NAME.TextGrid`` beside the
recording (its own tiers kept, the productions as tier ``productions``), which
:func:`tonguevis.workflows.open_recording` reads with it and
:func:`tonguevis.workflows.find_recording_productions` then uses: every command sees the
corrected productions.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Recording
from tonguevis.preprocess.productions import ProductionTable

#: The shortest production a correction may leave (s).
MIN_DURATION = 0.02
#: A production added where no closing movement is found lasts this long (s) when others give no typical length.
DEFAULT_DURATION = 0.4


class ProductionEditor:
    """Hand corrections of ``table``, the productions of ``recording`` (as recorded; the
    corrections are measured on its head-corrected positions).

    path : the recording's file (where :meth:`save` writes beside it), or None.
    """

    def __init__(self, recording: Recording, table: ProductionTable, path: str | os.PathLike | None = None):
        from tonguevis.preprocess.correction import head_corrected

        self.recording = recording
        self.corrected = head_corrected(recording)
        self.path = None if path is None else Path(path)
        self.table = table
        self.articulator = table.articulator or None
        self.label = next((p.label for p in table if p.label), "")
        self.edited = False

    @property
    def intervals(self) -> list[tuple[float, float, str]]:
        return [(p.start, p.end, p.label) for p in self.table]

    def index_at(self, time: float) -> int | None:
        """The production containing ``time`` (s), else None."""
        for k, p in enumerate(self.table):
            if p.start <= time <= p.end:
                return k
        return None

    def _rebuild(self, intervals) -> ProductionTable:
        from tonguevis.preprocess.labelled import productions_from_intervals

        table = productions_from_intervals(self.corrected, intervals, articulator=self.articulator,
                                           syllable=self.label or None)
        table.notes.append("corrected by hand")
        self.table, self.edited = table, True
        return table

    def move_boundary(self, index: int, side: str, time: float) -> ProductionTable:
        """Move the ``side`` ("start" or "end") of production ``index`` to ``time`` (s), kept
        inside the recording, at least MIN_DURATION long and not past its neighbours."""
        if side not in ("start", "end"):
            raise ValueError(f"side must be 'start' or 'end', not {side!r}")
        intervals = self.intervals
        if not 0 <= index < len(intervals):
            raise IndexError(f"no production {index + 1} (there are {len(intervals)})")
        start, end, label = intervals[index]
        times = self.recording.times
        if side == "start":
            low = intervals[index - 1][1] if index > 0 else float(times[0])
            start = float(np.clip(time, low, end - MIN_DURATION))
        else:
            high = intervals[index + 1][0] if index + 1 < len(intervals) else float(times[-1])
            end = float(np.clip(time, start + MIN_DURATION, high))
        intervals[index] = (start, end, label)
        return self._rebuild(intervals)

    def add(self, time: float) -> ProductionTable:
        """Add the production at ``time`` (s): the closing movement nearest it when there is one
        (:func:`~tonguevis.preprocess.productions.production_near`), else from ``time`` for the
        typical length; clipped to the gap it is in.  Inside a production: RecordingError."""
        from tonguevis.preprocess.productions import production_near

        if self.index_at(time) is not None:
            raise RecordingError(f"{time:.3f} s is inside production {self.index_at(time) + 1}: move its "
                                 "boundaries or delete it instead", self.path)
        intervals = self.intervals
        before = max((b for _, b, _ in intervals if b <= time), default=float(self.recording.times[0]))
        after = min((a for a, _, _ in intervals if a >= time), default=float(self.recording.times[-1]))
        found = production_near(self.corrected, self.articulator, time) if self.articulator else None
        if found is not None and before <= found[0] < after:
            start, end = found
        else:
            durations = [b - a for a, b, _ in intervals]
            start, end = time, time + (float(np.median(durations)) if durations else DEFAULT_DURATION)
        start, end = max(start, before), min(end, after)
        if end - start < MIN_DURATION:
            raise RecordingError(f"no room for a production at {time:.3f} s (the gap is "
                                 f"{1000 * (after - before):.0f} ms)", self.path)
        return self._rebuild(intervals + [(start, end, self.label)])

    def delete(self, index: int) -> ProductionTable:
        """Remove production ``index``."""
        intervals = self.intervals
        if not 0 <= index < len(intervals):
            raise IndexError(f"no production {index + 1} (there are {len(intervals)})")
        del intervals[index]
        return self._rebuild(intervals)

    def beside(self) -> Path:
        """Where :meth:`save` writes: ``NAME.TextGrid`` beside the recording."""
        if self.path is None:
            raise RecordingError("this recording has no file to save its productions beside; save them with "
                                 "a name (tonguevis syllables FILE --textgrid OUT)", None)
        return self.path.with_suffix(".TextGrid")

    def save(self, path: str | os.PathLike | None = None) -> Path:
        """Write the productions (and the recording's own tiers) as a TextGrid, atomically;
        default :meth:`beside`.  Returns the path."""
        from tonguevis.preprocess.labelled import write_productions_textgrid

        target = self.beside() if path is None else Path(path)
        write_productions_textgrid(target, self.table, self.recording)
        self.edited = False
        return target
