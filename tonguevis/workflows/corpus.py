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

__all__ = ["CorpusResult", "corpus_energy_curves", "entry_curves", "open_entry"]


@dataclass
class CorpusResult:
    """What :func:`corpus_energy_curves` made: curves, and the motion, productions and rest per recording name."""

    curves: list
    motions: dict
    productions: dict
    skipped: list = field(default_factory=list)  # (path, reason) of walked files that were not recordings
    rests: dict = field(default_factory=dict)  # recording name -> the RestChoice its simulation used


def corpus_energy_curves(corpus: Corpus, model=None, sensor_map=None, modes: int = 100,
                         keep=(2, 3, 4), keep_motions: bool = True, window: str = "release", progress=None,
                         tier: str | None = None, open_options: dict | None = None,
                         **simulate_options) -> CorpusResult:
    """Simulate every recording of ``corpus`` and cut its energy into production curves.

    sensor_map : for every file (dict, JSON path or preset); None uses a
        ``sensor_map.json`` beside a recording when there is one.
    keep : production positions kept per train (the paper's 2-4; None = all).
    window : "release" (release to next release, §3.2) or "vowel" (previous
        vowel to own vowel: the consonant mid-curve, see :func:`vowel_windows`).
    progress(done, total, message) is called once per recording.
    tier : take every recording's productions from this label tier instead of
        finding them (every non-empty interval; ``keep`` then unused).
    open_options : passed to :func:`tonguevis.workflows.open_recording` for every
        recording (``audio=``, ``labels=``).
    simulate_options : passed to :func:`tonguevis.workflows.simulate_recording`
        (``rest=(start_s, end_s)`` for every recording, ``landmarks``, ``warping``...).
    """
    from tonguevis._progress import report
    from tonguevis.analysis.energy import EnergyError
    from tonguevis.errors import RecordingError
    from tonguevis.sim import TongueModel

    if window not in ("release", "vowel"):
        raise EnergyError(f"window must be 'release' or 'vowel', got {window!r}")

    model = model or TongueModel.default()
    curves, motions, tables, skipped, rests = [], {}, {}, [], {}
    for k, entry in enumerate(corpus.entries):
        report(progress, k, len(corpus), f"simulating {entry.path.name}")
        try:
            entry, rec = open_entry(entry, sensor_map, open_options)
        except RecordingError as exc:
            if not entry.walked:
                raise
            logger.warning("skipping %s: %s", entry.path, exc)
            skipped.append((entry.path, str(exc)))
            continue
        motion = simulate_recording(rec, model, modes=modes, **simulate_options)
        rests[entry.name] = rest_of(motion)
        found, table = entry_curves(entry, rec, motion, keep=keep, window=window, tier=tier)
        curves.extend(found)
        if keep_motions:
            motions[entry.name] = motion
        tables[entry.name] = table
    report(progress, len(corpus), len(corpus), "done")
    return CorpusResult(curves, motions, tables, skipped, rests)


def open_entry(entry: CorpusEntry, sensor_map=None, open_options: dict | None = None):
    """(entry, recording): read one corpus entry as :func:`corpus_energy_curves` does.

    sensor_map : for this file (dict, JSON path or preset); None uses a
        ``sensor_map.json`` beside it when there is one.  The entry's labels are
        then taken from the recording's metadata unless a label table gave them.
    """
    from tonguevis.workflows import open_recording  # the package's door (scripts and tests may wrap it)

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
