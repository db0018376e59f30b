"""Praat TextGrids in and out of :class:`~tonguevis.io.recording.Label` lists (with praatio).

A label list is flat: each :class:`Label` names its tier.  Reading keeps the
TextGrid's tiers in order: every non-empty interval of an interval tier
becomes ``Label(start, end, text, tier)``, every point of a point tier
``Label(t, t, text, tier)``.  Writing groups the labels by tier again; a tier
whose labels all have ``start == end`` is written as a point tier, any other
as an interval tier (Praat fills the gaps between intervals with empty ones).

praatio is imported only when a TextGrid is read or written, so
``import tonguevis.io`` stays light.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Iterable

from tonguevis._files import atomic_write
from tonguevis.errors import RecordingError
from tonguevis.io.recording import Label

from tonguevis._logging import logger

SUFFIX = ".TextGrid"


def tier_names(labels: Iterable[Label]) -> list[str]:
    """Tier names in order of first appearance."""
    names: list[str] = []
    for label in labels:
        if label.tier not in names:
            names.append(label.tier)
    return names


def tier_labels(labels: Iterable[Label], tier: str) -> list[Label]:
    """The labels of one tier, in time order."""
    return sorted((lab for lab in labels if lab.tier == tier), key=lambda lab: (lab.start, lab.end))


def is_point_tier(labels: Iterable[Label], tier: str) -> bool:
    """True when every label of ``tier`` is a point (start == end)."""
    own = [lab for lab in labels if lab.tier == tier]
    return bool(own) and all(lab.start == lab.end for lab in own)


def read_textgrid(path: str | os.PathLike) -> list[Label]:
    """The labels of every tier of a Praat TextGrid (long, short or praatio's JSON form).

    Raises :class:`RecordingError` naming the file when it is missing or not a
    readable TextGrid.
    """
    from praatio import textgrid as praat_textgrid
    from praatio.data_classes.interval_tier import IntervalTier

    path = Path(path)
    if not path.is_file():
        raise RecordingError("label file does not exist", path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            grid = praat_textgrid.openTextgrid(str(path), includeEmptyIntervals=False,
                                               duplicateNamesMode="rename")
        except MemoryError:
            raise
        except Exception as exc:  # praatio fails with IndexError, ValueError ... on damaged files
            raise RecordingError(f"not a readable Praat TextGrid ({type(exc).__name__}: {exc})", path) from None
    for warning in caught:
        logger.warning("%s: %s", path, warning.message)
    labels: list[Label] = []
    for name in grid.tierNames:
        tier = grid.getTier(name)
        if isinstance(tier, IntervalTier):
            labels += [Label(float(e.start), float(e.end), e.label, name) for e in tier.entries if e.label.strip()]
        else:
            labels += [Label(float(e.time), float(e.time), e.label, name) for e in tier.entries]
    return labels


def write_textgrid(labels: Iterable[Label], path: str | os.PathLike, start: float = 0.0,
                   end: float | None = None, tiers: list[str] | None = None,
                   point_tiers: Iterable[str] = ()) -> None:
    """Write ``labels`` as a long-format Praat TextGrid, atomically.

    start, end : the TextGrid's time span in seconds (end defaults to the last
    label's end); labels outside it are an error.  tiers : which tiers and in
    which order (default: every tier, in order of first appearance).  point_tiers :
    tiers written as point tiers even when they have no label (others are decided
    by their labels).
    Intervals of one tier must not overlap.
    """
    from praatio import textgrid as praat_textgrid
    from praatio.data_classes.interval_tier import IntervalTier
    from praatio.data_classes.point_tier import PointTier

    path = Path(path)
    labels = list(labels)
    names = tier_names(labels) if tiers is None else list(tiers)
    points = set(point_tiers)
    last = max((lab.end for lab in labels), default=start)
    end = max(last, start) if end is None else float(end)
    if end <= start:
        end = start + 1.0  # an empty TextGrid still needs a span
    outside = [lab for lab in labels if lab.tier in names and (lab.start < start - 1e-9 or lab.end > end + 1e-9)]
    if outside:
        lab = outside[0]
        raise RecordingError(f"label {lab.text!r} of tier {lab.tier!r} ({lab.start:.3f}-{lab.end:.3f} s) lies "
                             f"outside the TextGrid's span {start:.3f}-{end:.3f} s", path)
    grid = praat_textgrid.Textgrid(start, end)
    for name in names:
        own = tier_labels(labels, name)
        if name in points or is_point_tier(labels, name):
            tier = PointTier(name, [(lab.start, lab.text) for lab in own], start, end)
        else:
            for a, b in zip(own[:-1], own[1:]):
                if b.start < a.end - 1e-9:
                    raise RecordingError(f"tier {name!r}: intervals {a.text!r} ({a.start:.3f}-{a.end:.3f} s) and "
                                         f"{b.text!r} ({b.start:.3f}-{b.end:.3f} s) overlap", path)
            tier = IntervalTier(name, [(lab.start, lab.end, lab.text) for lab in own], start, end)
        grid.addTier(tier)
    atomic_write(path, lambda tmp: grid.save(str(tmp), format="long_textgrid", includeBlankSpaces=True,
                                              reportingMode="error"))
