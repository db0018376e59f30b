"""A corpus of recordings labelled by speaker, CV syllable and trial.

Labels come, in increasing priority, from

1. the file name: ``<speaker>_<syllable>[_<trial>]`` (``spk1_ta.tsv``,
   ``S03-ka-2.pos``, ``spk2_la_t3.tsv``), or ``<syllable>[_<trial>]`` inside a
   folder named after the speaker (``spk1/ta_2.tsv``); in other names, a CV
   token is the syllable (``Kah`` -> ka, :func:`~tonguevis.preprocess.articulators.syllable_from_name`),
   a letters-then-digits token the speaker (``OSN12``) and ``take2``/``t2`` the
   trial (``006_OSN12_Kah_nofb_natural_take2_HR.tsv``);
2. the recording's metadata keys ``speaker``, ``syllable``, ``trial`` (when a
   reader or the user put them there; applied by :meth:`CorpusEntry.apply_metadata`);
3. a small user table (CSV with a ``file`` column and any of ``speaker``,
   ``syllable``, ``trial``), matched on the path relative to the table, the file
   name, or the stem;
4. labels given for every recording (``tonguevis energy --speaker/--syllable``,
   :func:`with_labels`).

An empty label is unknown: :func:`unknown_labels` says which.
"""

from __future__ import annotations

import csv
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Sequence

from tonguevis.errors import TonguevisError



class CorpusError(TonguevisError):
    """A corpus folder or label table that cannot be used."""


_SEP = r"[_\-\s]"
_TRIAL = rf"(?:{_SEP}(?:t|trial|take|rep|r)?(?P<trial>\d+))?"
NAME_PATTERN = re.compile(rf"^(?P<speaker>[^_\-\s]+){_SEP}(?P<syllable>[A-Za-z]+){_TRIAL}$")
SYLLABLE_PATTERN = re.compile(rf"^(?P<syllable>[A-Za-z]{{1,4}}){_TRIAL}$")
SPEAKER_TOKEN = re.compile(r"^[A-Za-z]{1,4}\d{1,3}$")  # OSN12, spk1, F01 (not recording0001)
TRIAL_TOKEN = re.compile(r"^(?:t|trial|take|rep|r)(?P<trial>\d+)$", re.IGNORECASE)


@dataclass(frozen=True)
class CorpusEntry:
    """One recording file with its labels (empty string / 1 when unknown)."""

    path: Path
    speaker: str = ""
    syllable: str = ""
    trial: int = 1
    source: str = "name"  # where the labels came from: name, folder, tokens, metadata, table, given
    walked: bool = False  # found by walking a folder (not named by the user): skipped if unreadable

    @property
    def name(self) -> str:
        """The recording's name: its file stem."""
        return self.path.stem if not self.path.name.endswith(".tar.gz") else self.path.name

    def apply_metadata(self, metadata: dict) -> "CorpusEntry":
        """Labels overridden by a recording's ``speaker``/``syllable``/``trial`` metadata."""
        changes = {k: metadata[k] for k in ("speaker", "syllable") if metadata.get(k)}
        if metadata.get("trial") not in (None, ""):
            changes["trial"] = _trial(metadata["trial"], self.path)
        return replace(self, **changes, source="metadata") if changes else self


def labels_from_name(path: Path) -> CorpusEntry:
    """Labels parsed from a file name (see the module doc); unmatched names keep empty labels."""
    path = Path(path)
    stem = path.name.split(".")[0]
    m = NAME_PATTERN.match(stem)
    if m:
        return CorpusEntry(path, m["speaker"], m["syllable"].lower(), _trial(m["trial"] or 1, path), "name")
    m = SYLLABLE_PATTERN.match(stem)
    if m and path.parent.name:
        return CorpusEntry(path, path.parent.name, m["syllable"].lower(), _trial(m["trial"] or 1, path), "folder")
    return _labels_from_tokens(path, stem)


def _labels_from_tokens(path: Path, stem: str) -> CorpusEntry:
    """Labels of a name in no fixed layout (``006_OSN12_Kah_nofb_natural_take2_HR``): the CV token,
    the first letters-then-digits token that is no trial, and a trial token; empty where none."""
    from tonguevis.preprocess.articulators import syllable_from_name

    tokens = [t for t in re.split(r"[^A-Za-z0-9]+", stem) if t]
    trials = [TRIAL_TOKEN.match(t) for t in tokens]
    trial = next((int(m["trial"]) for m in trials if m), 1)
    speaker = next((t for t, m in zip(tokens, trials) if not m and SPEAKER_TOKEN.match(t)), "")
    syllable = syllable_from_name(stem) or ""
    return CorpusEntry(path, speaker, syllable, trial, "tokens" if speaker or syllable else "none")


def with_labels(corpus: "Corpus", speaker: str | None = None, syllable: str | None = None) -> "Corpus":
    """``corpus`` with ``speaker`` and/or ``syllable`` given to every recording (they win over names,
    metadata and tables: ``tonguevis energy --speaker/--syllable``)."""
    changes = {k: v for k, v in (("speaker", speaker), ("syllable", syllable and syllable.lower())) if v}
    if not changes:
        return corpus
    return Corpus([replace(e, **changes, source="given") for e in corpus.entries])


def unknown_labels(curves) -> dict[str, list[str]]:
    """{recording: ["speaker", "syllable"] (those still empty)} over energy ``curves``, recordings with one."""
    unknown: dict[str, list[str]] = {}
    for c in curves:
        for name in ("speaker", "syllable"):
            if not getattr(c, name) and name not in unknown.setdefault(c.recording, []):
                unknown[c.recording].append(name)
    return {k: v for k, v in unknown.items() if v}


def _trial(value, path) -> int:
    try:
        return int(value)
    except (TypeError, ValueError):
        raise CorpusError(f"trial {value!r} is not a whole number", path) from None


def recording_extensions() -> tuple[str, ...]:
    """File extensions of every registered recording reader (``.tsv``, ``.pos``, ...)."""
    from tonguevis.io.registry import registered_formats

    return tuple(sorted({ext for f in registered_formats().values() if f.read is not None for ext in f.extensions}))


def find_recordings(paths: Iterable[str | os.PathLike], extensions: Sequence[str] | None = None) -> list[Path]:
    """Recording files among ``paths``: files as given, folders walked recursively (sorted)."""
    exts = tuple(e.lower() for e in (extensions or recording_extensions()))
    found: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found.extend(sorted(f for f in p.rglob("*") if f.is_file() and f.name.lower().endswith(exts)))
        elif p.is_file():
            found.append(p)
        else:
            raise CorpusError("no such file or folder", p)
    seen, unique = set(), []
    for f in found:
        key = f.resolve()
        if key not in seen:
            seen.add(key)
            unique.append(f)
    return unique


def read_label_table(path: str | os.PathLike) -> dict[str, dict]:
    """The user's label table: ``{file key: {speaker, syllable, trial}}`` (CSV with a header).

    The ``file`` (or ``recording``/``path``) column names a recording by path
    relative to the table, file name, or stem.
    """
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise CorpusError(f"cannot read the label table: {exc}", path) from exc
    if not rows:
        raise CorpusError("the label table has no rows", path)
    columns = {c.strip().lower(): c for c in rows[0] if c}
    file_col = next((columns[c] for c in ("file", "recording", "path") if c in columns), None)
    if file_col is None:
        raise CorpusError(f"the label table needs a 'file' column (found {', '.join(columns) or 'none'})", path)
    labels = {}
    for line, row in enumerate(rows, start=2):
        key = (row.get(file_col) or "").strip()
        if not key:
            raise CorpusError(f"line {line}: empty file name", path)
        entry = {}
        for name in ("speaker", "syllable", "trial"):
            if name in columns and (row.get(columns[name]) or "").strip():
                value = row[columns[name]].strip()
                entry[name] = _trial(value, f"{path}, line {line}") if name == "trial" else value
        labels[key] = entry
        labels.setdefault(str((path.parent / key).resolve()), entry)
    return labels


@dataclass
class Corpus:
    """Labelled recordings; :meth:`groups` sorts them by any of speaker, syllable, trial."""

    entries: list[CorpusEntry] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.entries)

    def __iter__(self):
        return iter(self.entries)

    @property
    def speakers(self) -> list[str]:
        return sorted({e.speaker for e in self.entries})

    @property
    def syllables(self) -> list[str]:
        return sorted({e.syllable for e in self.entries})

    def groups(self, by: Sequence[str] = ("speaker", "syllable")) -> dict[tuple, list[CorpusEntry]]:
        """Entries keyed by the tuple of their ``by`` labels, keys sorted."""
        for k in by:
            if k not in ("speaker", "syllable", "trial"):
                raise CorpusError(f"cannot group by {k!r}; choose speaker, syllable or trial")
        out: dict[tuple, list[CorpusEntry]] = {}
        for e in self.entries:
            out.setdefault(tuple(getattr(e, k) for k in by), []).append(e)
        return dict(sorted(out.items()))

    def select(self, speakers=None, syllables=None) -> "Corpus":
        """The entries of the given speakers and syllables (None = all)."""
        return Corpus([e for e in self.entries
                       if (speakers is None or e.speaker in speakers)
                       and (syllables is None or e.syllable in syllables)])


def load_corpus(paths: Iterable[str | os.PathLike], table: str | os.PathLike | None = None,
                extensions: Sequence[str] | None = None) -> Corpus:
    """Walk ``paths`` for recordings and label them (names, then the optional table)."""
    paths = [Path(p) for p in paths]
    named = {p.resolve() for p in paths if p.is_file()}
    files = find_recordings(paths, extensions)
    labels = read_label_table(table) if table is not None else {}
    entries = []
    for f in files:
        entry = replace(labels_from_name(f), walked=f.resolve() not in named)
        override = (labels.get(str(f.resolve())) or labels.get(f.name) or labels.get(f.name.split(".")[0]))
        if override:
            entry = replace(entry, **override, source="table")
        entries.append(entry)
    return Corpus(entries)
