"""The files that come with a recording: its sound and its labels, found or given, in one place.

:func:`~tonguevis.io.registry.read_recording` calls :func:`attach_audio` and
:func:`attach_labels` after every reader, so every format pairs them the same way.

Audio (``audio=``):

* ``None`` or ``True`` (default): audio the file itself carries (MVIEW's
  ``AUDIO`` channel) is kept; otherwise a WAV with the same stem beside the
  file (``x.pos`` -> ``x.wav``, any case of ``.wav``), else the Carstens layout
  (``.../pos/x.pos`` with ``.../wav/x.wav``).
* a path: that WAV (replacing any embedded audio); a missing file is a
  :class:`RecordingError` naming it.
* ``False``: no audio, not even embedded.

The WAV's first sample is at time 0 on the recording's clock (as NDI Wave's
AudioTime and Carstens' sample clock count).  When the sound and the
kinematics differ in length by more than :data:`MISMATCH_SECONDS` or
:data:`MISMATCH_FRACTION` of the kinematics, a warning gives both durations
(a WAV of another take is the usual cause).

Labels (``labels=``), the same way: ``None``/``True`` reads a Praat TextGrid
with the same stem beside the file (``x.TextGrid``, any case), a path reads
that one, ``False`` drops every label.  TextGrid tiers join the labels the
reader found (MVIEW's words and phones); a TextGrid tier replaces a reader's
tier of the same name.
"""

from __future__ import annotations

import os
from pathlib import Path

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Recording

from tonguevis._logging import logger

AUDIO_SUFFIX = ".wav"
LABEL_SUFFIX = ".textgrid"
#: Folder names of the Carstens layout: ``<session>/pos/x.pos`` beside ``<session>/wav/x.wav``.
CARSTENS_POS_FOLDER = "pos"
CARSTENS_WAV_FOLDER = "wav"
#: Audio and kinematics may differ in length by up to this much before a warning.
MISMATCH_SECONDS = 0.5
MISMATCH_FRACTION = 0.05


def _is_path(value) -> bool:
    return isinstance(value, (str, bytes)) or hasattr(value, "__fspath__")


def _same_stem(folder: Path, stem: str, suffix: str) -> Path | None:
    """``folder/<stem><suffix>`` with the suffix in any case, or None."""
    exact = folder / (stem + suffix)
    if exact.is_file():
        return exact
    try:
        entries = sorted(folder.iterdir())
    except OSError:
        return None
    return next((p for p in entries if p.stem == stem and p.suffix.lower() == suffix.lower() and p.is_file()), None)


def find_audio(path: str | os.PathLike) -> Path | None:
    """The WAV that belongs to the recording at ``path`` (same stem beside it, or the
    Carstens ``pos``/``wav`` folders), or None."""
    path = Path(path)
    found = _same_stem(path.parent, path.stem, AUDIO_SUFFIX)
    if found is None and path.parent.name.lower() == CARSTENS_POS_FOLDER:
        session = path.parent.parent
        wav_folder = next((p for p in (session / CARSTENS_WAV_FOLDER, session / CARSTENS_WAV_FOLDER.upper())
                           if p.is_dir()), None)
        if wav_folder is not None:
            found = _same_stem(wav_folder, path.stem, AUDIO_SUFFIX)
    return found


def find_labels(path: str | os.PathLike) -> Path | None:
    """The Praat TextGrid with the recording's stem beside it, or None."""
    path = Path(path)
    return _same_stem(path.parent, path.stem, LABEL_SUFFIX)


def length_mismatch(rec: Recording) -> str | None:
    """A sentence giving both durations when audio and kinematics differ too much, else None."""
    if rec.audio is None or rec.n_samples == 0:
        return None
    kinematic, sound = rec.duration, rec.audio.duration
    difference = abs(sound - kinematic)
    if difference > MISMATCH_SECONDS or difference > MISMATCH_FRACTION * kinematic:
        return (f"audio lasts {sound:.3f} s but the kinematics {kinematic:.3f} s "
                f"(differ by {difference:.3f} s); is it the right sound file?")
    return None


def attach_audio(rec: Recording, path: Path, audio=None) -> Recording:
    """Give ``rec`` its sound as described in the module docstring (changes ``rec`` in place)."""
    from tonguevis.io.wav import read_wav

    if audio is False:
        rec.audio = None
        rec.metadata["audio_file"] = None
        return rec
    if _is_path(audio):
        wav = Path(os.fsdecode(audio))
        if not wav.is_file():
            raise RecordingError(f"audio file {wav} does not exist", path)
        if rec.audio is not None:
            logger.info("%s: audio from %s instead of the file's own", path, wav)
    elif audio is None or audio is True:
        if rec.audio is not None:
            rec.metadata.setdefault("audio_file", None)
            rec.metadata.setdefault("audio_source", "embedded")
            _warn_mismatch(rec, path)
            return rec
        wav = find_audio(path)
        if wav is None:
            rec.metadata.setdefault("audio_file", None)
            return rec
        logger.info("%s: audio from %s", path, wav)
    else:
        raise RecordingError(f"audio= wants True, False, None or a WAV path, not {audio!r}", path)
    rec.audio = read_wav(wav)
    rec.metadata["audio_file"] = str(wav)
    rec.metadata["audio_source"] = "file"
    _warn_mismatch(rec, path)
    return rec


def _warn_mismatch(rec: Recording, path: Path) -> None:
    problem = length_mismatch(rec)
    if problem is not None:
        source = rec.metadata.get("audio_file") or "embedded audio"
        logger.warning("%s: %s (%s)", path, problem, source)
        rec.metadata["audio_mismatch"] = problem


def attach_labels(rec: Recording, path: Path, labels=None) -> Recording:
    """Add the TextGrid's tiers to ``rec.labels`` as described in the module docstring (in place)."""
    from tonguevis.io.textgrid import read_textgrid, tier_names

    if labels is False:
        rec.labels = []
        rec.metadata["labels_file"] = None
        return rec
    if _is_path(labels):
        grid = Path(os.fsdecode(labels))
        if not grid.is_file():
            raise RecordingError(f"label file {grid} does not exist", path)
    elif labels is None or labels is True:
        grid = find_labels(path)
        if grid is None:
            rec.metadata.setdefault("labels_file", None)
            return rec
        logger.info("%s: labels from %s", path, grid)
    else:
        raise RecordingError(f"labels= wants True, False, None or a TextGrid path, not {labels!r}", path)
    read = read_textgrid(grid)
    replaced = set(tier_names(read))
    kept = [lab for lab in rec.labels if lab.tier not in replaced]
    if len(kept) < len(rec.labels):
        logger.info("%s: tiers %s of %s replace the file's own", path, ", ".join(sorted(replaced)), grid)
    rec.labels = kept + read
    rec.metadata["labels_file"] = str(grid)
    return rec
