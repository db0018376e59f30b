"""The format registry: every reader module registers itself; ``read_recording`` dispatches.

Like meshio's ``register_format`` and MNE's extension table: a format has a name,
file extensions, a content sniffer (``sniff(head: bytes, path) -> bool`` on the
first 4 KiB), a reader ``read(path, **options) -> Recording`` that returns the
format's default sensor names, an optional writer ``write(rec, path, **options)``
and ``channel_name(value) -> str`` turning a sensor-map value (an NDI Id, a
Carstens channel number ...) into the default name the reader gives it.
"""

from __future__ import annotations

import inspect
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Recording

from tonguevis._logging import logger

SNIFF_BYTES = 4096


@dataclass(frozen=True)
class RecordingFormat:
    name: str
    description: str
    extensions: tuple[str, ...]
    sniff: Callable[[bytes, Path], bool]
    read: Callable[..., Recording] | None = None
    write: Callable[..., None] | None = None
    channel_name: Callable[[Any], str] = str


FORMATS: dict[str, RecordingFormat] = {}


def register_format(fmt: RecordingFormat) -> None:
    FORMATS[fmt.name] = fmt


#: Modules that register formats, in dispatch-priority order.
FORMAT_MODULES = ("ndi_wave", "optispeech", "carstens", "est_track", "mview", "bvh", "csv_format")


def _ensure_registered() -> None:
    # Importing the modules registers them (done lazily so import order never matters
    # and ``import tonguevis.io`` stays light).
    import importlib

    for module in FORMAT_MODULES:
        importlib.import_module(f"tonguevis.io.{module}")


def registered_formats() -> dict[str, RecordingFormat]:
    """Every registered format by name (importing the format modules first)."""
    _ensure_registered()
    return dict(FORMATS)


def supported_formats() -> str:
    """One line per format: name, extensions and what it reads/writes."""
    _ensure_registered()
    lines = []
    for fmt in FORMATS.values():
        mode = "read" + ("/write" if fmt.write else "") if fmt.read else "write"
        lines.append(f"{fmt.name} ({', '.join(fmt.extensions)}; {mode}): {fmt.description}")
    return "; ".join(lines)


def _extension_matches(path: Path, fmt: RecordingFormat) -> bool:
    name = path.name.lower()
    return any(name.endswith(ext) for ext in fmt.extensions)


def detect_format(path: str | os.PathLike) -> RecordingFormat:
    """The format of the file at ``path``, from its content first, then its extension."""
    _ensure_registered()
    path = Path(path)
    if not path.exists():
        raise RecordingError("no such file", path)
    if path.is_dir():
        raise RecordingError("is a folder, not a recording file", path)
    with open(path, "rb") as f:
        head = f.read(SNIFF_BYTES)
    readable = [f for f in FORMATS.values() if f.read is not None]
    by_content = [f for f in readable if _safe_sniff(f, head, path)]
    by_extension = [f for f in readable if _extension_matches(path, f)]
    both = [f for f in by_content if f in by_extension]
    if both:
        return both[0]
    if by_content:
        return by_content[0]
    if by_extension:
        # Let that reader say precisely what is wrong with the content.
        return by_extension[0]
    raise RecordingError(
        "unknown recording format (neither its content nor its extension matches); "
        f"supported: {supported_formats()}",
        path,
    )


def _safe_sniff(fmt: RecordingFormat, head: bytes, path: Path) -> bool:
    try:
        return bool(fmt.sniff(head, path))
    except Exception:  # a sniffer must never decide dispatch by crashing
        logger.debug("sniffer of %s failed on %s", fmt.name, path, exc_info=True)
        return False


#: Low-level errors a reader may hit on malformed bytes; turned into RecordingError.
_MALFORMED = (
    ValueError, IndexError, KeyError, struct.error, EOFError, UnicodeError,
    OverflowError, zlib.error, TypeError, MemoryError,
)


SENSOR_MAP_BESIDE = "sensor_map.json"


def read_recording(
    path: str | os.PathLike,
    sensor_map: dict | str | os.PathLike | None = None,
    format: str | None = None,
    audio: Any = None,
    labels: Any = None,
    **format_options: Any,
) -> Recording:
    """Read an EMA recording in any supported format, with its sound and labels.

    Parameters
    ----------
    path : the file.
    sensor_map : None, a dict, a JSON file or a preset name (see
        :func:`tonguevis.io.sensor_map.load_sensor_map`) from canonical names
        (TT, TB, TD, TBK, TL, TR, JAW, REF1, ...) to the channel as the file
        names it; unmapped channels keep the reader's default names.  When
        None and a ``sensor_map.json`` lies beside the file (as in a corpus
        folder), that map is used; pass ``{}`` to read the raw channel names.
        A map file's ``"axes"`` entry is the reader's ``axes=`` unless that is given.
    format : force a format by name instead of detecting it.
    audio : None/True (the file's own audio, else a WAV with the same stem
        beside it or in the Carstens ``wav`` folder), a WAV path, or False
        (none); see :mod:`tonguevis.io.companions`.
    labels : None/True (a ``.TextGrid`` with the same stem beside it), a
        TextGrid path, or False (no labels at all).
    **format_options : passed to the reader (e.g. ``axes=`` for NDI Wave,
        ``channels=`` for headerless Carstens AG500).

    Returns a :class:`Recording` with positions in metres.
    Raises :class:`RecordingError` naming the file and the problem.
    """
    from tonguevis.io.companions import attach_audio, attach_labels
    from tonguevis.io.sensor_map import apply_sensor_map, load_sensor_map, resolve_two_meanings

    path = Path(path)
    if format is not None:
        _ensure_registered()
        if format not in FORMATS or FORMATS[format].read is None:
            raise RecordingError(f"no reader for format {format!r}; supported: {supported_formats()}", path)
        fmt = FORMATS[format]
        if not path.exists():
            raise RecordingError("no such file", path)
    else:
        fmt = detect_format(path)
    if sensor_map is None and (path.parent / SENSOR_MAP_BESIDE).is_file():
        sensor_map = path.parent / SENSOR_MAP_BESIDE
        logger.info("%s: using the sensor map %s beside it", path, sensor_map)
    mapping = load_sensor_map(sensor_map) if sensor_map else None
    if mapping is not None and mapping.axes is not None and "axes" not in format_options:
        if "axes" in inspect.signature(fmt.read).parameters:
            format_options = {**format_options, "axes": mapping.axes}
        else:
            logger.info("%s: the sensor map's axes %r do not apply to %s files (their reader places the axes itself)",
                     path, mapping.axes, fmt.name)
    try:
        rec = fmt.read(path, **format_options)
    except RecordingError:
        raise
    except TypeError as exc:
        if "unexpected keyword argument" in str(exc):
            raise RecordingError(f"{fmt.name} reader: {exc}", path) from exc
        raise RecordingError(f"malformed {fmt.name} file: {exc}", path) from exc
    except _MALFORMED as exc:
        raise RecordingError(f"malformed {fmt.name} file ({type(exc).__name__}: {exc})", path) from exc
    rec.metadata.setdefault("format", fmt.name)
    rec.metadata.setdefault("file", str(path))
    attach_audio(rec, path, audio)
    attach_labels(rec, path, labels)
    if mapping is not None:
        rec = apply_sensor_map(rec, mapping, fmt.channel_name, path)
        rec.metadata["sensor_map"] = dict(mapping)
    else:
        rec = resolve_two_meanings(rec, path)
    _check_recording(rec, path)
    return rec


def _check_recording(rec: Recording, path: Path) -> None:
    """Invariants every reader promises (a bug, not bad input, if they fail)."""
    n = rec.n_samples
    for name, xyz in rec.sensors.items():
        if xyz.shape != (n, 3):
            raise AssertionError(f"{path}: sensor {name} has shape {xyz.shape}, expected ({n}, 3)")
    if n > 1 and not np.all(np.diff(rec.times) > 0):
        raise AssertionError(f"{path}: times not increasing")


def write_recording(
    rec: Recording,
    path: str | os.PathLike,
    format: str | None = None,
    **format_options: Any,
) -> None:
    """Write ``rec`` to ``path`` in the format its extension names (or ``format``).

    Writers go through a temporary file and ``os.replace``: an interrupted
    write never leaves a half file.  Options go to the writer (e.g.
    ``sensor_map=`` for NDI Wave Ids, ``unit=`` for CSV).
    """
    _ensure_registered()
    path = Path(path)
    writable = [f for f in FORMATS.values() if f.write is not None]
    if format is not None:
        matches = [f for f in writable if f.name == format]
    else:
        matches = [f for f in writable if _extension_matches(path, f)]
    if not matches:
        names = ", ".join(f"{f.name} ({', '.join(f.extensions)})" for f in writable)
        raise RecordingError(f"cannot write this format; writable formats: {names}", path)
    matches[0].write(rec, path, **format_options)
