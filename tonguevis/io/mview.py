"""MVIEW ``.mat`` files (Haskins Laboratories; Mark Tiede's MVIEW), MAT v5 and v7.3.

The file holds one struct array with a row per channel and the fields
``NAME``, ``SRATE`` (Hz), ``SIGNAL`` (samples x columns) and, usually on the
first (audio) channel, ``SENTENCE``, ``WORDS`` and ``PHONES`` (struct arrays of
``LABEL`` and ``OFFS`` = [start end] in seconds) or ``LABELS`` (``NAME``,
``OFFSET`` and ``VALUE`` = duration, in ms).

* Sensor channels have >= 3 columns: x, y, z in mm, then orientation angles in
  degrees (kept as (N, k - 3) orientations).  Haskins data are head-corrected
  with x anterior, y left, z up, which is our frame, so positions are only
  converted to metres (``axes=`` can remap other set-ups).
* A one-column channel named ``AUDIO`` (else the fastest one-column channel)
  becomes ``rec.audio``; other one-column channels go to
  ``metadata['extra_channels']``.
* Sensors must share one rate and length; channels that do not are skipped
  with a warning.
* v5 files are read by :mod:`tonguevis.io.matv5` (scipy's loadmat can crash on damaged
  files); v7.3 files (HDF5) with h5py.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from tonguevis.errors import RecordingError
from tonguevis.io._common import parse_axes
from tonguevis.io.recording import Audio, Label, Recording
from tonguevis.io.registry import RecordingFormat, register_format

from tonguevis._logging import logger

REQUIRED_FIELDS = ("NAME", "SRATE", "SIGNAL")


def sniff(head: bytes, path: Path) -> bool:
    return head.startswith(b"MATLAB 5.0 MAT-file") or head.startswith(b"MATLAB 7.3 MAT-file")


def channel_name(value) -> str:
    return str(value)


# ---------------------------------------------------------------- MAT v5 (our defensive reader)
def _text(value) -> str:
    """MATLAB text (a str from either reader) or '' for an empty/missing value."""
    return value if isinstance(value, str) else ""


def _tier(value, text_field: str, time_field: str) -> list[tuple[str, np.ndarray]]:
    """[(label, times)] from a struct array of labels (list of dicts); [] when empty or absent."""
    if not isinstance(value, list):
        return []
    out = []
    for item in value:
        if not isinstance(item, dict):
            continue
        times = item.get(time_field)
        out.append((_text(item.get(text_field)),
                    np.asarray(times, dtype=float).ravel() if isinstance(times, np.ndarray) else np.zeros(0)))
    return out


def _normalise(elements: list, path) -> list[dict[str, Any]]:
    """Channel dicts (name, srate, signal, sentence, words, phones, labels) from struct elements."""
    channels = []
    for item in elements:
        if not isinstance(item, dict):
            raise RecordingError("MVIEW struct element is not a struct", path)
        name, srate, signal = item.get("NAME"), item.get("SRATE"), item.get("SIGNAL")
        if not isinstance(name, str) or not isinstance(srate, np.ndarray) or not isinstance(signal, np.ndarray):
            raise RecordingError("MVIEW channel lacks a text NAME or a numeric SRATE/SIGNAL", path)
        if srate.dtype.kind not in "fiub":
            raise RecordingError(f"channel {name!r} has a non-numeric SRATE", path)
        # LABELS hold OFFSET and VALUE (the duration), both in ms.
        raw_labels = item.get("LABELS") if isinstance(item.get("LABELS"), list) else []
        labels = []
        for lab in raw_labels:
            if isinstance(lab, dict) and isinstance(lab.get("OFFSET"), np.ndarray) and isinstance(lab.get("VALUE"), np.ndarray):
                off, dur = np.asarray(lab["OFFSET"], float).ravel(), np.asarray(lab["VALUE"], float).ravel()
                if off.size and dur.size:
                    labels.append((_text(lab.get("NAME")), np.array([off[0], dur[0]])))
        channels.append({
            "name": name, "srate": srate.astype(float).ravel(), "signal": signal,
            "sentence": _text(item.get("SENTENCE")),
            "words": _tier(item.get("WORDS"), "LABEL", "OFFS"),
            "phones": _tier(item.get("PHONES"), "LABEL", "OFFS"),
            "labels": labels,
        })
    return channels


def _pick(candidates: dict, variable: str | None, path, names: list[str]):
    if variable is not None:
        if variable not in candidates:
            raise RecordingError(f"no MVIEW struct variable {variable!r} (variables: {', '.join(names)})", path)
        return candidates[variable]
    if not candidates:
        raise RecordingError(
            "no MVIEW struct array (fields NAME, SRATE, SIGNAL) in this MAT file "
            f"(variables: {', '.join(names) or 'none'})", path)
    return next(iter(candidates.values()))


def _load_v5(path: Path, variable: str | None) -> list[dict[str, Any]]:
    from tonguevis.io.matv5 import MatStruct, read_mat5

    variables = read_mat5(path)
    candidates = {k: v for k, v in variables.items() if isinstance(v, MatStruct)
                  and all(f in v.fields for f in REQUIRED_FIELDS)}
    return _normalise(_pick(candidates, variable, path, list(variables)), path)


# ---------------------------------------------------------------- MAT v7.3 (h5py)
def _h5_class(obj) -> str:
    cls = obj.attrs.get("MATLAB_class", b"")
    return cls.decode() if isinstance(cls, bytes) else str(cls)


def _h5_value(obj, f):
    """A MATLAB value from an HDF5 dataset/group: str, ndarray, or list of dicts (struct array)."""
    import h5py

    if isinstance(obj, h5py.Group):
        return _h5_struct(obj, f)
    if obj.attrs.get("MATLAB_empty", 0):
        return np.zeros((0, 0))
    data = obj[()]
    if obj.dtype == h5py.ref_dtype:
        refs = np.asarray(data).T
        return [_h5_value(f[r], f) for r in refs.ravel()]
    if _h5_class(obj) == "char":
        return "".join(chr(c) for c in np.asarray(data).T.ravel())
    return np.asarray(data).T


def _h5_struct(group, f) -> list[dict[str, Any]]:
    import h5py

    fields = list(group.keys())
    ref_fields = [k for k in fields if isinstance(group[k], h5py.Dataset) and group[k].dtype == h5py.ref_dtype
                  and _h5_class(group[k]) != "cell"]
    if ref_fields and len(ref_fields) == len(fields):  # a struct array: one reference per element
        n = group[fields[0]].size
        values = {k: _h5_value(group[k], f) for k in fields}
        return [{k: values[k][i] for k in fields} for i in range(n)]
    return [{k: _h5_value(group[k], f) for k in fields}]


def _load_v73(path: Path, variable: str | None) -> list[dict[str, Any]]:
    import h5py

    try:
        f = h5py.File(str(path), "r")
    except OSError as exc:
        raise RecordingError(f"MAT v7.3 file is not readable HDF5: {exc}", path) from None
    try:
        with f:
            return _channels_v73(f, path, variable)
    except (RecordingError, MemoryError):
        raise
    except Exception as exc:  # h5py raises KeyError/OSError/RuntimeError on damaged files
        raise RecordingError(f"malformed MAT v7.3 file ({type(exc).__name__}: {exc})", path) from None


def _channels_v73(f, path, variable) -> list[dict[str, Any]]:
    import h5py

    groups = {k: f[k] for k in f.keys() if not k.startswith("#") and isinstance(f[k], h5py.Group)
              and all(fld in f[k] for fld in REQUIRED_FIELDS)}
    group = _pick(groups, variable, path, [k for k in f.keys() if not k.startswith("#")])
    return _normalise(_h5_struct(group, f), path)


# ---------------------------------------------------------------- common
def _labels(channels: list[dict], path) -> list[Label]:
    out: list[Label] = []
    for tier in ("words", "phones"):
        for ch in channels:
            for text, offs in ch.get(tier, []):
                if offs.size != 2 or not np.all(np.isfinite(offs)) or offs[1] < offs[0]:
                    raise RecordingError(f"{tier} label {text!r} of channel {ch['name']} has bad times {offs}", path)
                out.append(Label(start=float(offs[0]), end=float(offs[1]), text=text, tier=tier))
    if not out:  # fall back to LABELS: OFFSET and duration VALUE in ms
        for ch in channels:
            for text, (offset_ms, dur_ms) in ch.get("labels", []):
                out.append(Label(start=offset_ms / 1000.0, end=(offset_ms + dur_ms) / 1000.0, text=text, tier="labels"))
    return out


def read_mview(path, variable: str | None = None, axes=None) -> Recording:
    """Read a Haskins MVIEW ``.mat`` file; see the module docstring."""
    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.read(128)
    if not head:
        raise RecordingError("empty file", path)
    if head.startswith(b"MATLAB 7.3"):
        channels = _load_v73(path, variable)
    elif head.startswith(b"MATLAB 5.0") or head[:4] not in (b"MATL",):
        channels = _load_v5(path, variable)
    else:
        raise RecordingError(f"unsupported MAT file header {head[:20]!r}", path)
    A = parse_axes(axes, path)
    sensors_raw, one_column = [], []
    for ch in channels:
        signal, srate = ch["signal"], ch["srate"]
        if srate.size != 1 or not np.isfinite(srate[0]) or srate[0] <= 0:
            raise RecordingError(f"channel {ch['name']!r} has an impossible SRATE {srate.tolist()}", path)
        if signal.dtype.kind not in "fiu" or signal.ndim != 2:
            raise RecordingError(f"channel {ch['name']!r} SIGNAL is not a numeric matrix", path)
        (sensors_raw if signal.shape[1] >= 3 else one_column).append(ch)
    if not sensors_raw:
        raise RecordingError("no sensor channel (SIGNAL with x, y, z columns)", path)
    rate, n = Counter((float(c["srate"][0]), c["signal"].shape[0]) for c in sensors_raw).most_common(1)[0][0]
    if n == 0:
        raise RecordingError("sensor channels have no samples", path)
    sensors, orientations = {}, {}
    for ch in sensors_raw:
        if (float(ch["srate"][0]), ch["signal"].shape[0]) != (rate, n):
            logger.warning("%s: skipped channel %s (%g Hz, %d samples; the others %g Hz, %d)",
                        path, ch["name"], ch["srate"][0], ch["signal"].shape[0], rate, n)
            continue
        if ch["name"] in sensors:
            raise RecordingError(f"two channels are named {ch['name']!r}", path)
        sig = ch["signal"].astype(np.float64)
        xyz = sig[:, :3] * 0.001
        bad = ~np.all(np.isfinite(xyz), axis=1)
        xyz[bad] = np.nan
        sensors[ch["name"]] = xyz @ A.T
        if sig.shape[1] > 3:
            angles = sig[:, 3:].copy()
            angles[bad] = np.nan
            orientations[ch["name"]] = angles
    audio, extra = None, {}
    if one_column:
        named = [c for c in one_column if c["name"].upper() == "AUDIO"]
        chosen = named[0] if named else max(one_column, key=lambda c: c["srate"][0])
        audio = Audio(samples=chosen["signal"][:, 0].astype(np.float64), rate=float(chosen["srate"][0]))
        extra = {c["name"]: c["signal"][:, 0].astype(np.float64) for c in one_column if c is not chosen}
    sentence = next((c.get("sentence") for c in channels if c.get("sentence")), "")
    metadata = {
        "format": "mview",
        "file": str(path),
        "original_unit": "mm",
        "frame": "tonguevis" if axes is None else "tonguevis (remapped)",
        "axes": A.tolist(),
        "orientation_kind": "mview_angles_deg",
        "sentence": sentence,
        "extra_channels": extra,
        "mat_version": "7.3" if head.startswith(b"MATLAB 7.3") else "5",
        "dropped_frames": [],
    }
    return Recording(rate=rate, times=np.arange(n) / rate, sensors=sensors, orientations=orientations,
                     audio=audio, labels=_labels(channels, path), metadata=metadata)


register_format(RecordingFormat(
    name="mview",
    description="Haskins MVIEW .mat struct array (MAT v5; v7.3 via h5py) with audio and word/phone labels",
    extensions=(".mat",),
    sniff=sniff,
    read=read_mview,
    channel_name=channel_name,
))
