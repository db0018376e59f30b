"""Sensor maps: which channel of a file is the tongue tip, the jaw, a head reference ...

A sensor map is data: a dict from our canonical names to the channel as the
file names it.  Canonical names: tongue ``TT`` tip, ``TB`` blade, ``TD``
dorsum, ``TBK`` back/rear, ``TL`` left lateral, ``TR`` right lateral; ``JAW``;
head references ``REF1``, ``REF2``, ...  Channel values: an NDI Wave Id (``3``),
a Carstens channel number counted from 1, an EST_Track coil prefix or number,
an MVIEW ``NAME``, a BVH ROOT name, or simply the default sensor name the reader
gives (``"S3"``, ``"CH5"``).  Presets ship in ``tonguevis/presets/*.json``.

A map's JSON file may also state the file's **axes** (``"axes": "-y,x,z"``, the
readers' ``axes=`` option: which signed file axis becomes our x anterior, y
left, z up; ``"x,y,z"`` when the file is in our frame already), so that a
corpus folder says once how its recordings lie and no command warns about it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Callable

from tonguevis.errors import RecordingError
from tonguevis.io.recording import Recording

PRESET_DIR = Path(__file__).resolve().parents[1] / "presets"

from tonguevis._logging import logger

#: Channel names that mean two things when no sensor map says which: name -> (our meaning,
#: {format: that format's meaning}).  Haskins (MVIEW) files call the tongue *rear* TR, which is
#: our right lateral sensor; a file with a TL beside its TR has the lateral pair, no doubt.
TWO_MEANINGS = {"TR": ("TR", {"mview": "TBK"})}
MEANING_WORDS = {"TR": "the right lateral tongue sensor", "TBK": "the tongue rear (back)"}

CANONICAL_NAMES = ("TT", "TB", "TD", "TBK", "TL", "TR", "JAW")

#: Metadata entries keyed by sensor name, renamed together with the sensors.
PER_SENSOR_METADATA = ("rotation_orders", "orientation_channels")


class SensorMap(dict):
    """A sensor map (canonical name -> file channel) whose ``optional`` names may be absent.

    Presets mark the sensors a layout may or may not have (extra head
    references) as optional; every other entry must exist in the file.
    """

    def __init__(self, mapping=(), optional=(), axes=None):
        super().__init__(mapping)
        self.optional = frozenset(optional)
        #: The files' axis mapping into ours (the readers' ``axes=``), or None when the map does not state it.
        self.axes = axes


def preset_names() -> list[str]:
    return sorted(p.stem for p in PRESET_DIR.glob("*.json"))


def how_to_map(recording: Recording) -> str:
    """How to name a recording's tongue channels, for the message of a command that found too few.

    Gives the command-line option, the presets and a JSON example built from
    the recording's own channels (those with valid samples first).
    """
    working = [n for n in recording.sensor_names if recording.valid(n).any()]
    channels = working + [n for n in recording.sensor_names if n not in working]
    example = json.dumps(dict(zip(("TT", "TB", "TD"), channels)))
    return ("name the tongue channels with a sensor map: --sensors MAP, a preset "
            f"({', '.join(preset_names())}) or a JSON file of name -> channel such as {example} "
            "(names: TT tip, TB blade, TD dorsum, TBK back, TL/TR left/right lateral, JAW); "
            "a sensor_map.json beside the file is used when there is one")


def load_sensor_map(spec: dict | str | os.PathLike) -> SensorMap:
    """A sensor map from a dict, a JSON file path or a preset name ('paper', 'haskins', 'mngu0').

    A JSON file holds either the map itself or ``{"sensors": {...},
    "optional": [names that may be absent], "axes": "-y,x,z", ...}`` (the
    presets' layout, whose other keys are documentation); ``axes`` (see the
    module docstring) is checked here and kept in ``SensorMap.axes``.
    """
    optional: list = []
    axes = getattr(spec, "axes", None)
    if isinstance(spec, dict):
        mapping = spec
        optional = list(getattr(spec, "optional", ()))
        source = "sensor map"
    else:
        text_spec = os.fspath(spec)
        path = Path(text_spec)
        if not path.exists() and (PRESET_DIR / f"{text_spec}.json").exists():
            path = PRESET_DIR / f"{text_spec}.json"
        if not path.exists():
            raise RecordingError(
                f"sensor map {text_spec!r} is neither a JSON file nor a preset "
                f"(presets: {', '.join(preset_names())})"
            )
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeError, json.JSONDecodeError) as exc:
            raise RecordingError(f"sensor map is not valid JSON: {exc}", path) from None
        mapping = data.get("sensors", data) if isinstance(data, dict) else data
        if isinstance(data, dict) and "sensors" in data:
            optional = data.get("optional", [])
            if not isinstance(optional, list):
                raise RecordingError("'optional' must be a list of sensor names", path)
            axes = data.get("axes")
            if axes is not None:
                from tonguevis.io._common import parse_axes

                try:
                    parse_axes(axes)
                except (RecordingError, TypeError, ValueError) as exc:
                    raise RecordingError(f"'axes' {axes!r} is not an axis mapping such as \"-y,x,z\" ({exc})",
                                         path) from None
        source = str(path)
    if not isinstance(mapping, dict):
        raise RecordingError(f"{source}: a sensor map must be an object name -> channel")
    out = SensorMap(optional=[o for o in optional if isinstance(o, str)], axes=axes)
    for name, channel in mapping.items():
        if not isinstance(name, str) or not name:
            raise RecordingError(f"{source}: sensor name {name!r} is not a non-empty string")
        if isinstance(channel, bool) or not isinstance(channel, (str, int)):
            raise RecordingError(f"{source}: channel of {name} must be a name or a number, not {channel!r}")
        out[name] = channel
    channels = [str(c) for c in out.values()]
    repeated = sorted({c for c in channels if channels.count(c) > 1})
    if repeated:
        raise RecordingError(f"{source}: channel(s) {', '.join(repeated)} mapped to more than one name")
    return out


def resolve_channel(value: Any, names: list[str], channel_name: Callable[[Any], str]) -> str | None:
    """The default sensor name of a sensor-map ``value`` among ``names``, or None."""
    if isinstance(value, str) and value in names:
        return value
    try:
        candidate = channel_name(value)
    except (ValueError, TypeError):
        candidate = None
    if candidate in names:
        return candidate
    if str(value) in names:
        return str(value)
    return None


def apply_sensor_map(
    rec: Recording, mapping: dict[str, Any], channel_name: Callable[[Any], str], path=None
) -> Recording:
    """``rec`` with its channels renamed by ``mapping`` (canonical name -> file channel).

    Raises RecordingError naming a channel the file lacks, or a canonical name
    that would collide with an unmapped channel of the same name.
    """
    names = rec.sensor_names
    rename: dict[str, str] = {}
    for canonical, value in mapping.items():
        found = resolve_channel(value, names, channel_name)
        if found is None and canonical in getattr(mapping, "optional", ()):
            continue
        if found is None:
            raise RecordingError(
                f"sensor map names channel {value!r} for {canonical}, but the file has no such "
                f"channel (it has {', '.join(names) or 'none'})",
                path,
            )
        rename[found] = canonical
    targets = set(rename.values())
    clashes = [n for n in names if n in targets and n not in rename]
    if clashes:
        raise RecordingError(
            f"sensor map gives the name(s) {', '.join(clashes)} to other channels, but unmapped "
            "channels already carry them; map them too",
            path,
        )
    renamed = rec.renamed(rename)
    renamed.metadata = dict(rec.metadata)
    for key in PER_SENSOR_METADATA:
        if isinstance(rec.metadata.get(key), dict):
            renamed.metadata[key] = {rename.get(k, k): v for k, v in rec.metadata[key].items()}
    return renamed


def resolve_two_meanings(rec: Recording, path=None) -> Recording:
    """``rec`` (read without a sensor map) with its channels whose names could mean two things
    given one meaning, and a warning naming the choice made and how to choose the other.

    TR is our right lateral sensor unless the file's format names the tongue rear so (MVIEW,
    Haskins: then it becomes TBK); with TL beside it, it is the right lateral in any format.
    The choices are kept in ``metadata["channel_meanings"]`` (channel -> canonical name).
    """
    fmt = str(rec.metadata.get("format", ""))
    where = path or rec.metadata.get("file", "recording")
    rename, chosen = {}, {}
    for name, (ours, by_format) in TWO_MEANINGS.items():
        if name not in rec.sensors or "TL" in rec.sensors:
            continue
        meaning = by_format.get(fmt, ours)
        if meaning != name and meaning in rec.sensors:
            continue  # the other meaning's name is taken: keep the channel's own name
        others = sorted({m for m in (ours, *by_format.values()) if m != meaning})
        how = ", ".join(f"{{\"{m}\": \"{name}\"}}" for m in others)
        logger.warning("%s: channel %s could mean %s; read as %s (%s)%s. If it is %s, give a sensor map "
                    "(--sensors MAP with %s%s)", where, name,
                    " or ".join(MEANING_WORDS.get(m, m) for m in (meaning, *others)),
                    MEANING_WORDS.get(meaning, meaning), meaning,
                    f", as {fmt.upper()} (Haskins) files name it" if meaning != ours else
                    ", tonguevis's own name; Haskins files use TR for the tongue rear",
                    " or ".join(MEANING_WORDS.get(m, m) for m in others), how,
                    ", or the preset haskins" if "TBK" in others else "")
        chosen[name] = meaning
        if meaning != name:
            rename[name] = meaning
    if not chosen:
        return rec
    out = rec.renamed(rename) if rename else rec
    out.metadata = dict(rec.metadata)
    for key in PER_SENSOR_METADATA:
        if rename and isinstance(rec.metadata.get(key), dict):
            out.metadata[key] = {rename.get(k, k): v for k, v in rec.metadata[key].items()}
    out.metadata["channel_meanings"] = chosen
    return out

