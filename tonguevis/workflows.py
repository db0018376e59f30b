"""The pipeline in one place, for every front end: open -> rest -> prepare -> simulate -> productions.

The CLI commands, the app, the corpus loader and the scripts call these
functions; none strings the stages together on its own (when each did, they
drifted apart).  No Qt here.

* :func:`open_recording`: read any supported file with its sensor map, sound and labels.
* :func:`head_corrected`: head motion removed when there are >= 3 head references.
* :func:`find_recording_productions`: head-correct, then find the CV productions (or take
  them from a label tier).
* :func:`simulate_recording`: choose the rest (given, detected, or the stillest
  window), prepare the targets and simulate; ``motion.metadata["rest"]`` says
  which rest was used and :func:`rest_of` gives it back as a :class:`RestChoice`.
"""

from __future__ import annotations

import os
from typing import Any

from tonguevis._progress import ProgressCallback
from tonguevis.io.recording import Recording
from tonguevis.preprocess.correction import head_corrected, head_references
from tonguevis.preprocess.rest import RestChoice, check_rest_interval, choose_rest_interval

__all__ = [
    "RestChoice", "check_rest_interval", "choose_rest_interval", "find_recording_productions", "head_corrected",
    "head_references", "open_recording", "rest_of", "simulate_recording",
]


def open_recording(path: str | os.PathLike, sensors: dict | str | os.PathLike | None = None, *,
                   audio: Any = None, labels: Any = None, **options: Any) -> Recording:
    """Read the recording at ``path`` (any supported format) with its sensor map, sound and labels.

    sensors : a preset name (paper, haskins, mngu0), a JSON file or a dict of
        canonical name -> channel; None uses a ``sensor_map.json`` beside the
        file when there is one.
    audio : None (the file's own sound, else a WAV with the same name beside it
        or in the Carstens ``wav/`` folder), a WAV path, or False (none).
    labels : None (a ``NAME.TextGrid`` beside it), a TextGrid path, or False (none).
        See :mod:`tonguevis.io.companions`.
    options : passed to :func:`tonguevis.io.read_recording` (``format=``, reader options).
    """
    from tonguevis.io.registry import read_recording

    return read_recording(path, sensor_map=sensors, audio=audio, labels=labels, **options)


def find_recording_productions(recording: Recording, tip: str = "TT", keep=(2, 3, 4), trains=None,
                               head_correction: bool = True, tier: str | None = None):
    """The CV productions (a :class:`~tonguevis.preprocess.ProductionTable`) of ``recording``.

    Head motion is removed first (:func:`head_corrected`; ``head_correction=False``
    keeps the positions as recorded), then :func:`tonguevis.preprocess.find_productions`
    with ``tip``, ``keep`` (1-based positions per train; None: all) and ``trains``.
    tier : take the productions from this label tier instead (every non-empty
        interval, ``keep`` and ``trains`` unused; see
        :func:`tonguevis.preprocess.labelled.productions_from_tier`); a missing tier
        raises RecordingError listing the tiers.
    """
    from tonguevis.preprocess.labelled import productions_from_tier
    from tonguevis.preprocess.productions import find_productions

    rec = head_corrected(recording) if head_correction else recording
    if tier is not None:
        return productions_from_tier(rec, tier, tip=tip)
    return find_productions(rec, tip=tip, keep=keep, trains=trains)


def simulate_recording(recording: Recording, model=None, *, modes: int = 100, warping: bool = True,
                       landmarks: str = "speaker", rest: RestChoice | tuple[float, float] | None = None,
                       progress: ProgressCallback | None = None, **options: Any):
    """Drive ``model`` (default: the shipped tongue) with ``recording``; returns a :class:`~tonguevis.sim.Motion`.

    rest : None (the longest still interval, else the stillest window, with a
        warning), a (start_s, end_s) the user gave (checked: a bad one raises
        RecordingError naming the file and the problem), or a :class:`RestChoice`.
    options : passed to :func:`tonguevis.sim.simulate` (``smooth_window``, ``tolerance``...).
    The choice is in ``motion.metadata["rest"]``; :func:`rest_of` reads it back.
    """
    from tonguevis.sim.simulate import simulate

    return simulate(recording, model, modes=modes, warping=warping, landmarks=landmarks, rest_interval=rest,
                    progress=progress, **options)


def rest_of(motion) -> RestChoice | None:
    """The rest a motion was simulated with (None for motions saved before it was recorded)."""
    data = getattr(motion, "metadata", {}).get("rest")
    return RestChoice.from_dict(data) if isinstance(data, dict) and "interval" in data else None
