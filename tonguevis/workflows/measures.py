"""The measures of a recording's productions, as ``tonguevis measures``, the batch and the app's Measures tab take them.

:func:`measure_recording` strings the steps together: head correction and the productions
(:func:`~tonguevis.workflows.find_recording_productions`: labels win), the rest (for the jaw and
lips), the palate in the recording's head frame (:func:`measurement_palate`), the per-production
measures (:mod:`tonguevis.analysis.measures`) and the repetitions (:mod:`tonguevis.analysis.repetitions`).
No tongue simulation is involved: everything is measured on the sensors and the palate.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tonguevis._logging import logger, verbose
from tonguevis.errors import TonguevisError

#: The sensors the repetitions are computed for: every sensor but the head references (and the palate probe).
_NOT_REPEATED = ("PROBE",)
#: Rest positions measured for the jaw opening and the lip protrusion.
REST_SENSORS = ("JAW", "UL", "LL")


@dataclass
class MeasuredPalate:
    """The palate measured against: ``surface`` (a PalateSurface in the recording's head frame, or None),
    ``label`` (what the table's ``palate`` column says) and ``notes`` (how it was placed)."""

    surface: Any = None
    label: str = ""
    notes: list[str] = field(default_factory=list)


def measurement_palate(recording, spec) -> MeasuredPalate:
    """The palate ``spec`` in ``recording``'s head-corrected frame.

    spec : None or "none" (no palate: no constriction), "generic" (the shipped palate, placed in the
    speaker by the rest sensors' fit onto the model, as the simulation places it at the default adult
    size: :func:`tonguevis.sim.simulate.placed_palate`), a palate file from ``tonguevis palate`` or a
    :class:`~tonguevis.palate.PalateSurface` (the speaker's, in the frame of its traces: carried into the
    speech's head frame by the head references both recorded, else taken as traced).  The speaker's
    palate is *not* raised to clear the sensors as the simulation does (that raise is a registration
    guess for the contact solve: it would move the traced roof away from the tip and bias every degree).
    """
    if spec is None or str(spec) == "none":
        return MeasuredPalate()
    from tonguevis.palate import load_palate
    from tonguevis.render.drawing import palate_label

    surface = load_palate(spec)
    if surface.metadata.get("generic"):
        from tonguevis.sim.placement import ADULT
        from tonguevis.sim.simulate import placed_palate

        try:
            placed, _, _ = placed_palate(recording, surface, frame="speaker", tongue_size=ADULT)
        except TonguevisError as exc:  # the default: the other measures do not need it
            return MeasuredPalate(None, "", [f"no constriction: the generic palate cannot be placed in this "
                                             f"speaker ({exc})"])
        return MeasuredPalate(placed, "generic palate",
                              ["the generic palate, placed in the speaker by the rest sensors' fit onto the model: "
                               "an estimate, not this speaker's palate (give the speaker's with --palate)"])
    notes = []
    if surface.metadata.get("head_references"):
        from tonguevis.preprocess.correction import head_corrected, reference_pose
        from tonguevis.sim.simulate import _by_head_references

        surface = _by_head_references(surface, reference_pose(head_corrected(recording)), quiet=True)
        done = surface.metadata.get("head_registration")
        notes.append(f"palate registered into the speech's head frame by {', '.join(done['references'])} "
                     f"(residual {done['residual_mm']:.2f} mm)" if done else
                     "the palate's and the speech's head references do not match: palate taken as traced")
    else:
        notes.append("palate taken as traced (no head references to register it by): traced in another sitting, "
                     "it may sit millimetres off")
    return MeasuredPalate(surface, palate_label(spec), notes)


@dataclass
class MeasuresResult:
    """What :func:`measure_recording` found.

    table : the ProductionTable measured; rows : one dict per production (:data:`tonguevis.analysis.measures.COLUMNS`);
    repetitions : the :class:`~tonguevis.analysis.repetitions.Repetitions` of those productions;
    palate : the :class:`MeasuredPalate`; rest : the RestChoice of the jaw's and lips' rest (None when none);
    notes : what else to say.
    """

    table: Any
    rows: list[dict]
    repetitions: Any
    palate: MeasuredPalate
    rest: Any = None
    notes: list[str] = field(default_factory=list)


def repeated_sensors(recording) -> list[str]:
    """The sensors whose repetitions are measured: every channel but the head references and a palate probe."""
    from tonguevis.preprocess._names import is_reference

    return [n for n in recording.sensor_names if not is_reference(n) and n not in _NOT_REPEATED]


def rest_positions(corrected, given=None):
    """(RestChoice, {JAW/UL/LL: (3,) m}) of a head-corrected recording (the rest every front end chooses);
    (None, {}) when none can be found."""
    from tonguevis.preprocess.rest import choose_rest_interval, rest_pose

    try:
        choice = choose_rest_interval(corrected, given=given)
    except TonguevisError as exc:
        logger.info("no rest for the jaw opening and lip protrusion: %s", exc)
        return None, {}
    positions = {}
    for name in REST_SENSORS:  # one by one: one lost at rest spoils no other
        if name in corrected.sensors:
            try:
                positions.update(rest_pose(corrected, choice.interval, sensors=[name]))
            except TonguevisError:
                pass
    return choice, positions


def measure_table(recording, table, palate: MeasuredPalate | None = None, rest=None,
                  head_correction: bool = True) -> MeasuresResult:
    """The measures of the productions ``table`` (a ProductionTable, e.g. the app's, edited) of ``recording``.

    recording : as read (head motion is removed here unless ``head_correction`` is false);
    palate : from :func:`measurement_palate` (None: no constriction); rest : (start_s, end_s) given, or None.
    """
    from tonguevis.analysis.measures import production_measures
    from tonguevis.analysis.repetitions import repetitions
    from tonguevis.preprocess.correction import head_corrected

    palate = palate or MeasuredPalate()
    corrected = head_corrected(recording) if head_correction else recording
    choice, rest_xyz = rest_positions(corrected, rest)
    rows = production_measures(corrected, table, palate.surface, palate.label, rest_xyz)
    intervals = [(p.start, p.end) for p in table.productions]
    sensors = {n: corrected.sensors[n] for n in repeated_sensors(corrected)}
    reps = repetitions(corrected.times, corrected.rate, sensors, intervals, [p.label for p in table.productions])
    notes = list(palate.notes)
    labels = sorted({p.label for p in table.productions})
    if len(labels) > 1:
        notes.append(f"the productions have {len(labels)} different labels ({', '.join(labels[:6])}"
                     f"{' ...' if len(labels) > 6 else ''}): the STI compares repetitions of one utterance; "
                     "choose one with --label")
    if choice is None:
        notes.append("no rest found: no jaw opening or lip protrusion")
    return MeasuresResult(table, rows, reps, palate, choice, notes)


@verbose
def measure_recording(recording, palate="generic", *, tier: str | None = None, keep=(2, 3, 4),
                      articulator: str | None = None, syllable: str | None = None, labelled: bool = True,
                      head_correction: bool = True, rest=None, label: str | None = None) -> MeasuresResult:
    """The productions of ``recording`` (as every command finds them: a ``productions`` tier or ``tier``
    wins) and their measures; ``palate`` as :func:`measurement_palate` takes it; ``label``: only the
    productions with that label.  ``keep``: positions kept per train of three or more (None: all)."""
    from tonguevis.workflows.recording import find_recording_productions

    table = find_recording_productions(recording, articulator=articulator, keep=keep, tier=tier,
                                       head_correction=head_correction, syllable=syllable, labelled=labelled)
    if label is not None:
        table = with_label(table, label, recording.metadata.get("file"))
    return measure_table(recording, table, measurement_palate(recording, palate), rest=rest,
                         head_correction=head_correction)


def with_label(table, label: str, file=None):
    """``table`` with only the productions labelled ``label``; TonguevisError listing the labels when none is."""
    from dataclasses import replace

    keep = [i for i, p in enumerate(table.productions) if p.label == label]
    if not keep:
        labels = sorted({p.label for p in table.productions if p.label})
        raise TonguevisError(f"no production labelled {label!r}; labels: {', '.join(labels) or 'none'}", file)
    return replace(table, productions=[table.productions[i] for i in keep],
                   landmarks=[table.landmarks[i] for i in keep] if table.landmarks else [])


def write_repetitions_json(result: MeasuresResult, path: str | os.PathLike, extra: dict | None = None) -> Path:
    """The STI JSON (``{"sti": {...}, "signal": ..., "n": ...}``, the productions, the notes) written atomically."""
    import json

    from tonguevis._files import atomic_write_text

    document = {**result.repetitions.as_json(), **(extra or {})}
    document["notes"] = list(dict.fromkeys(document.get("notes", []) + result.notes))
    atomic_write_text(Path(path), json.dumps(document, indent=1, allow_nan=False) + "\n")
    return Path(path)


def write_averages(result: MeasuresResult, path: str | os.PathLike) -> Path:
    """The mean ± SD trajectories (one row per sensor and percent): Parquet for ``.parquet``, else CSV."""
    from tonguevis.analysis.repetitions import AVERAGE_COLUMNS
    from tonguevis.preprocess.gesture_table import write_rows

    return write_rows(result.repetitions.average_rows(), AVERAGE_COLUMNS, path)


def constriction_track(recording, palate, sensor: str, head_correction: bool = True):
    """The constriction (:class:`~tonguevis.analysis.constriction.Constriction`) of ``sensor`` at every frame of
    ``recording`` against ``palate`` (a PalateSurface in its head frame, e.g. ``measurement_palate(...).surface``)."""
    from tonguevis.analysis.constriction import constriction
    from tonguevis.preprocess.correction import head_corrected

    corrected = head_corrected(recording) if head_correction else recording
    return constriction(palate, np.asarray(corrected.sensors[sensor], dtype=np.float64))
