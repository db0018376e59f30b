"""A corpus's energy curves, one recording at a time, as ``tonguevis energy``, the Energy tab and the batch
run them.

:func:`open_entry` and :func:`entry_curves` are the per-recording steps; the batch's tasks
(:mod:`tonguevis.batch.tasks`) call the same two, so a corpus gives the same curves whether
it is run here (in memory, one recording after another: :func:`corpus_energy_curves`) or by
``tonguevis batch`` (on disk, resumable, in parallel).  The corpus itself (files, labels) is
:mod:`tonguevis.analysis.corpus`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from tonguevis._logging import logger
from tonguevis.analysis.corpus import Corpus, CorpusEntry
from tonguevis.workflows.recording import find_recording_productions
from tonguevis.workflows.simulation import rest_of, simulate_recording

__all__ = ["CorpusResult", "CurveSettings", "corpus_energy_curves", "entry_curves", "open_entry"]


@dataclass
class CorpusResult:
    """What :func:`corpus_energy_curves` made: curves, and the motion, productions and rest per recording name."""

    curves: list
    motions: dict
    productions: dict
    skipped: list = field(default_factory=list)  # (path, reason) of walked files that were not recordings
    rests: dict = field(default_factory=dict)  # recording name -> the RestChoice its simulation used


@dataclass(frozen=True)
class CurveSettings:
    """How each simulated recording of a corpus is cut into energy curves (``tonguevis energy``'s ``--all``,
    ``--window`` and ``--productions-from``; the batch's ``keep``, ``window`` and ``tier``).

    keep : production positions kept per train (the paper's 2-4; None = all).
    window : "release" (release to next release, §3.2) or "vowel" (previous vowel to own vowel: the consonant
        mid-curve, see :func:`~tonguevis.analysis.energy.vowel_windows`).
    tier : take every recording's productions from this label tier instead of finding them (every non-empty
        interval; ``keep`` then unused).
    """

    keep: tuple[int, ...] | None = (2, 3, 4)
    window: str = "release"
    tier: str | None = None

    def __post_init__(self) -> None:
        from tonguevis.analysis.energy import EnergyError

        if self.window not in ("release", "vowel"):
            raise EnergyError(f"window must be 'release' or 'vowel', got {self.window!r}")
        if self.keep is not None:
            object.__setattr__(self, "keep", tuple(int(k) for k in self.keep))


def corpus_energy_curves(corpus: Corpus, settings=None, model=None, *, curves: CurveSettings | None = None,
                         reading: dict | None = None, keep_motions: bool = True, progress=None,
                         **overrides) -> CorpusResult:
    """Simulate every recording of ``corpus`` as ``settings`` (a :class:`~tonguevis.sim.settings.RunSettings`,
    default everyone's; ``overrides``: its fields as keywords) describe, on ``model`` (default: the settings'),
    and cut its energy into production curves as ``curves`` (:class:`CurveSettings`) say.

    reading : keywords of :func:`tonguevis.workflows.open_recording` for every recording: ``sensor_map``
        (dict, JSON path or preset; None uses a ``sensor_map.json`` beside a recording when there is one),
        ``audio=``, ``labels=``, reader options.
    progress(done, total, message) is called once per recording.
    """
    from tonguevis._progress import report
    from tonguevis.errors import RecordingError
    from tonguevis.sim.settings import build_model, run_settings

    settings = run_settings(settings, **overrides)
    curves = curves if curves is not None else CurveSettings()
    reading = dict(reading or {})
    sensor_map = reading.pop("sensor_map", None)
    model = model if model is not None else build_model(settings)
    found_curves, motions, tables, skipped, rests = [], {}, {}, [], {}
    for k, entry in enumerate(corpus.entries):
        report(progress, k, len(corpus), f"simulating {entry.path.name}")
        try:
            entry, rec = open_entry(entry, sensor_map, reading)
        except RecordingError as exc:
            if not entry.walked:
                raise
            logger.warning("skipping %s: %s", entry.path, exc)
            skipped.append((entry.path, str(exc)))
            continue
        motion = simulate_recording(rec, model, settings)
        rests[entry.name] = rest_of(motion)
        found, table = entry_curves(entry, rec, motion, keep=curves.keep, window=curves.window, tier=curves.tier)
        found_curves.extend(found)
        if keep_motions:
            motions[entry.name] = motion
        tables[entry.name] = table
    report(progress, len(corpus), len(corpus), "done")
    return CorpusResult(found_curves, motions, tables, skipped, rests)


def open_entry(entry: CorpusEntry, sensor_map=None, open_options: dict | None = None):
    """(entry, recording): read one corpus entry as :func:`corpus_energy_curves` does.

    sensor_map : for this file (dict, JSON path or preset); None uses a
        ``sensor_map.json`` beside it when there is one.  The entry's labels are
        then taken from the recording's metadata unless a label table gave them.
    """
    from tonguevis.workflows.recording import open_recording

    mapping = sensor_map
    if mapping is None and (entry.path.parent / "sensor_map.json").is_file():
        mapping = entry.path.parent / "sensor_map.json"
    rec = open_recording(entry.path, mapping, **(open_options or {}))
    return (entry.apply_metadata(rec.metadata) if entry.source not in ("table", "given") else entry), rec


def entry_curves(entry: CorpusEntry, rec, motion, keep=(2, 3, 4), window: str = "release",
                 tier: str | None = None):
    """(energy curves, production table) of one simulated entry, as :func:`corpus_energy_curves` cuts them.

    window "release": the productions ``keep`` of
    :func:`~tonguevis.workflows.find_recording_productions`; "vowel": their
    vowel-to-vowel windows (the table then holds every production).
    """
    from tonguevis.analysis.energy import EnergyError, production_curves, vowel_windows

    if window == "release":
        table = find_recording_productions(rec, keep=keep, tier=tier, syllable=entry.syllable or None)
        spans = list(table)
    elif window == "vowel":
        table = find_recording_productions(rec, keep=None, tier=tier, syllable=entry.syllable or None)
        spans = [w for w in vowel_windows(table) if keep is None or tier is not None or w.index in keep]
    else:
        raise EnergyError(f"window must be 'release' or 'vowel', got {window!r}")
    curves = production_curves(motion, spans, recording=entry.name, speaker=entry.speaker,
                               syllable=entry.syllable, trial=entry.trial)
    return curves, table
