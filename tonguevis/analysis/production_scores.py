"""Productions found against hand-labelled ones: counts, one-to-one matches, timing errors.

Labels are a Praat TextGrid with a point tier ``release`` (one point per labelled syllable,
its consonant release) and optionally an interval tier ``ambiguous`` whose non-empty
stretches count neither way: a production starting inside one is neither right nor wrong.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment

#: A production's start matches a labelled release this close (s).
TOLERANCE_S = 0.060


def labelled_recordings(folder: str | os.PathLike) -> list[tuple[Path, Path]]:
    """(recording, labels) pairs: every ``NAME.labels.TextGrid`` in ``folder`` with a ``NAME.*`` recording."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    pairs = []
    for labels in sorted(folder.glob("*.labels.TextGrid")):
        stem = labels.name[: -len(".labels.TextGrid")]
        matches = [p for p in sorted(folder.glob(stem + ".*")) if p.suffix.lower() not in (".textgrid", ".png")]
        if matches:
            pairs.append((matches[0], labels))
    return pairs


def score_against_labels(table, labels_path: str | os.PathLike, tolerance: float = TOLERANCE_S) -> dict:
    """Score a :class:`~tonguevis.preprocess.ProductionTable` against ``labels_path``.

    Returns found (productions outside ambiguous stretches), labelled (releases),
    matched (one-to-one within ``tolerance``, the assignment minimising the total error),
    missed, extra, median_error_ms and max_error_ms (NaN without matches), errors_ms
    (signed, found minus labelled, in time order), tolerance_s.
    """
    from tonguevis.io.textgrid import read_textgrid

    labels = read_textgrid(labels_path)
    ambiguous = [(lab.start, lab.end) for lab in labels if lab.tier == "ambiguous" and lab.text.strip()]
    releases = np.array(sorted(lab.start for lab in labels if lab.tier == "release"))

    def unclear(t: float) -> bool:
        return any(a <= t <= b for a, b in ambiguous)

    starts = np.array([p.start for p in table if not unclear(p.start)])
    releases = np.array([t for t in releases if not unclear(t)])
    errors = np.zeros(0)
    if starts.size and releases.size:
        cost = np.abs(starts[:, None] - releases[None, :])
        rows, cols = linear_sum_assignment(np.where(cost <= tolerance, cost, 1e6))
        good = cost[rows, cols] <= tolerance
        order = np.argsort(releases[cols[good]])
        errors = (starts[rows[good]] - releases[cols[good]])[order]
    matched = int(errors.size)
    return {"found": int(starts.size), "labelled": int(releases.size), "matched": matched,
            "missed": int(releases.size - matched), "extra": int(starts.size - matched),
            "median_error_ms": float(np.median(np.abs(errors)) * 1000) if matched else float("nan"),
            "max_error_ms": float(np.max(np.abs(errors)) * 1000) if matched else float("nan"),
            "errors_ms": [round(float(e) * 1000, 1) for e in errors], "tolerance_s": tolerance}
