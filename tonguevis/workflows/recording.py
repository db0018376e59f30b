"""Opening a recording and finding its productions, as every front end does.

* :func:`open_recording`: read any supported file with its sensor map, sound and labels.
* :func:`head_corrected`: head motion removed when there are >= 3 head references.
* :func:`find_recording_productions`: head-correct, then find the CV productions (or take
  them from a label tier).
"""

from __future__ import annotations

import os
from typing import Any

from tonguevis._logging import verbose
from tonguevis.io.recording import Recording
from tonguevis.preprocess.correction import head_corrected, head_references

__all__ = ["find_recording_productions", "head_corrected", "head_references", "open_recording"]


@verbose
def open_recording(path: str | os.PathLike, sensor_map: dict | str | os.PathLike | None = None, *,
                   audio: Any = None, labels: Any = None, **options: Any) -> Recording:
    """Read the recording at ``path`` (any supported format) with its sensor map, sound and labels.

    sensor_map : a preset name (paper, haskins, mngu0), a JSON file or a dict of
        canonical name -> channel; None uses a ``sensor_map.json`` beside the
        file when there is one.
    audio : None (the file's own sound, else a WAV with the same name beside it
        or in the Carstens ``wav/`` folder), a WAV path, or False (none).
    labels : None (a ``NAME.TextGrid`` beside it), a TextGrid path, or False (none).
        See :mod:`tonguevis.io.companions`.
    options : passed to :func:`tonguevis.io.read_recording` (``format=``, reader options).
    """
    from tonguevis.io.registry import read_recording

    return read_recording(path, sensor_map=sensor_map, audio=audio, labels=labels, **options)


@verbose
def find_recording_productions(recording: Recording, articulator: str | None = None, keep=(2, 3, 4), trains=None,
                               head_correction: bool = True, tier: str | None = None, syllable: str | None = None,
                               labelled: bool = True, tip: str | None = None):
    """The CV productions (a :class:`~tonguevis.preprocess.ProductionTable`) of ``recording``.

    Head motion is removed first (:func:`head_corrected`; ``head_correction=False``
    keeps the positions as recorded).  Labels win: with ``tier`` the productions are
    that label tier's intervals; without it, a ``productions`` tier in the recording's
    TextGrid (the one ``tonguevis syllables --textgrid`` and the app write beside it) is
    used when ``labelled`` is true.  Otherwise :func:`tonguevis.preprocess.find_productions`
    finds them with ``articulator`` (None: chosen from ``syllable`` or the data), ``keep``
    (1-based positions per train of three or more; None: all) and ``trains``.
    A missing ``tier`` raises RecordingError listing the tiers; ``tip`` is the old name
    of ``articulator``.
    """
    from tonguevis.io.textgrid import tier_names
    from tonguevis.preprocess.labelled import PRODUCTIONS_TIER, productions_from_tier
    from tonguevis.preprocess.productions import find_productions

    rec = head_corrected(recording) if head_correction else recording
    articulator = articulator or tip
    if tier is None and labelled and PRODUCTIONS_TIER in tier_names(rec.labels):
        tier = PRODUCTIONS_TIER
    if tier is not None:
        return productions_from_tier(rec, tier, articulator=articulator, syllable=syllable)
    return find_productions(rec, articulator=articulator, keep=keep, trains=trains, syllable=syllable)
