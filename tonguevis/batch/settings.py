"""What a batch computes, with which model and settings, and the content hashes that make it resumable.

Every step's results are keyed by a SHA-256 of what they depend on: the
recording's bytes and those of the files read with it (the WAV and TextGrid
beside it, its sensor map), its corpus labels, the tongue model's content
(mesh, anchors, sensor landmarks, material), the settings of that step and
the tonguevis version.  A rerun skips a step whose key is unchanged and redoes
the rest; a new setting for one step (say, ``--segment-first``) leaves the
others' results alone.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterable

from tonguevis.errors import TonguevisError
from tonguevis.sim.settings import RunSettings, build_model

#: The steps, in the order they run for a recording ("measures" needs no simulation: the sensors and a palate).
STEPS = ("simulate", "energy", "segment", "validate", "measures")
#: What ``tonguevis batch`` runs unless told otherwise (validation is slow: asked for).
DEFAULT_STEPS = ("simulate", "energy", "segment")


class BatchError(TonguevisError):
    """A batch asked with settings or paths that cannot be used."""


def parse_steps(steps: str | Iterable[str]) -> tuple[str, ...]:
    """The steps of ``"simulate,energy"`` (or a sequence) in run order; unknown names raise BatchError."""
    names = [s.strip().lower() for s in (steps.split(",") if isinstance(steps, str) else steps)]
    names = [s for s in names if s]
    bad = [s for s in names if s not in STEPS]
    if bad or not names:
        raise BatchError(f"unknown step(s) {', '.join(bad) or '(none given)'}; choose from {', '.join(STEPS)}")
    return tuple(s for s in STEPS if s in names)


@dataclass(frozen=True)
class BatchSettings(RunSettings):
    """The settings of every step (the defaults are those of the single-file commands): the run's
    :class:`~tonguevis.sim.settings.RunSettings` (how each recording is simulated; the model
    comes from the :class:`ModelSpec`) and the batch's own steps.

    steps : subset of :data:`STEPS`.  "simulate" saves each motion (``motion.npz``)
        and its summary row; energy and segment simulate when no saved motion
        with the same key exists.
    every :class:`RunSettings` field : as ``tonguevis simulate`` (``rest`` (start_s, end_s) for every
        recording, None to find it; ``palate`` a palate file for every recording).
    sensor_map : sensor map for every recording (preset name, JSON path or dict);
        None uses a ``sensor_map.json`` beside each recording.
    labels : CSV table of speaker/syllable/trial per file (as ``tonguevis energy --labels``); None: from the
        file names.  A recording's labels enter its own input hash, so a changed row redoes that recording only.
    read_options : reader options for every recording (``-O``: ``axes=``, ``audio=False`` ...), a dict
        or (key, value) pairs; kept as sorted pairs.
    keep : production positions kept per train (None: every production), as ``tonguevis energy --all``.
    window : energy curve span, "release" or "vowel", as ``tonguevis energy --window``.
    tier : productions from this label tier instead (``--productions-from``).
    segment_first : segment only the first N productions of each recording (None: all).
    quasi_static : the quasi-static baseline of the validation (``tonguevis validate --no-static``).
    csv : write CSV beside every Parquet table.
    measures_palate : the palate of the measures step ("generic": the shipped one placed in each speaker;
        a palate file from ``tonguevis palate``; None: no constriction), as ``tonguevis measures --palate``.
    group_by : the labels (speaker, syllable, trial, recording, train, index) whose productions the repetitions' STI
        and averages pool (``DIR/repetitions.parquet``, ``DIR/averages.parquet``), as ``tonguevis energy --group-by``.
    """

    steps: tuple[str, ...] = DEFAULT_STEPS
    sensor_map: Any = None
    labels: Any = None
    read_options: tuple = ()
    keep: tuple[int, ...] | None = (2, 3, 4)
    window: str = "release"
    tier: str | None = None
    segment_first: int | None = None
    quasi_static: bool = True
    csv: bool = False
    measures_palate: Any = "generic"
    group_by: tuple[str, ...] = ("speaker", "syllable")

    def __post_init__(self) -> None:
        if int(self.modes) < 1:
            raise BatchError(f"modes must be at least 1, got {self.modes}")
        super().__post_init__()
        object.__setattr__(self, "steps", parse_steps(self.steps))
        object.__setattr__(self, "read_options", tuple(sorted(dict(self.read_options or ()).items())))
        if self.keep is not None:
            object.__setattr__(self, "keep", tuple(int(k) for k in self.keep))
        if self.window not in ("release", "vowel"):
            raise BatchError(f"window must be 'release' or 'vowel', got {self.window!r}")
        if self.segment_first is not None and int(self.segment_first) < 1:
            raise BatchError(f"segment_first must be at least 1, got {self.segment_first}")
        by = tuple(k.strip() for k in (self.group_by.split(",") if isinstance(self.group_by, str) else self.group_by)
                   if k.strip())
        from tonguevis.analysis.energy import GROUP_KEYS  # the same labels as tonguevis energy --group-by

        if not by or any(k not in GROUP_KEYS for k in by):
            raise BatchError(f"group_by {','.join(by) or '(none)'}: choose from {', '.join(GROUP_KEYS)}")
        object.__setattr__(self, "group_by", by)

    def run_settings(self) -> RunSettings:
        """How each recording is simulated, as a plain :class:`RunSettings`."""
        return RunSettings(**{f.name: getattr(self, f.name) for f in dataclasses.fields(RunSettings)})

    def step_settings(self, step: str) -> dict:
        """The settings ``step``'s results depend on (JSON-able): every field of the run's
        :class:`RunSettings` (:meth:`RunSettings.key`: a palate by its content; the model is the
        :class:`ModelSpec`'s, hashed apart), the reader options, and the step's own."""
        sim = {**self.run_settings().key(model=False), "read_options": dict(self.read_options)}
        if step == "simulate":
            return sim
        if step == "energy":
            return {**sim, "keep": self.keep, "window": self.window, "tier": self.tier}
        if step == "segment":
            return {**sim, "keep": self.keep, "tier": self.tier, "segment_first": self.segment_first,
                    "mode": "constraint", "seeds": "auto", "threshold": 0.05, "adjust": False}
        if step == "measures":
            return {"keep": self.keep, "tier": self.tier, "palate": _palate_identity(self.measures_palate)}
        if step == "validate":
            return {**sim, "quasi_static": self.quasi_static}
        raise BatchError(f"unknown step {step!r}")

    def as_dict(self) -> dict:
        out = asdict(self)
        out["sensor_map"] = _sensor_map_text(self.sensor_map)
        out["labels"] = None if self.labels is None else os.fspath(self.labels)
        out["measures_palate"] = None if self.measures_palate is None else os.fspath(self.measures_palate) \
            if not hasattr(self.measures_palate, "metadata") else "given in Python"
        for name in ("mesh", "mesh_axes"):  # the model is the ModelSpec's
            out.pop(name, None)
        out["palate"] = None if self.palate is None else (self.palate if isinstance(self.palate, str)
                                                          else "a palate given in Python")
        if out.get("rest") is not None and hasattr(self.rest, "as_dict"):
            out["rest"] = self.rest.as_dict()
        return out


def _palate_identity(palate) -> Any:
    """What the measures depend on of a palate: "generic"/None as they are, a file by its grid's bytes."""
    if palate is None or str(palate) in ("generic", "none"):
        return None if palate is None else str(palate)
    from tonguevis.palate import grid_path

    h = hashlib.sha256()
    for path in (Path(palate), grid_path(palate)):
        if path.is_file():
            _hash_file(h, path)
    return {"file": os.fspath(palate), "sha256": h.hexdigest()}


def _sensor_map_text(sensors) -> Any:
    if sensors is None or isinstance(sensors, (dict, str)):
        return sensors
    return os.fspath(sensors)


@dataclass
class ModelSpec:
    """How a worker gets the tongue model, small enough to send with every task.

    kind "default": the shipped tongue; "file": ``mesh`` is a path (read on
    the worker, with ``axes``); "parts": a model given in Python, sent as its
    mesh, landmarks and material.  ``key`` is the model's content hash; a worker
    builds each model once and keeps it (:func:`tonguevis.batch.tasks.model_for`).
    """

    kind: str = "default"
    mesh: Any = None
    axes: str | None = None
    landmarks: Any = None
    material: Any = None
    key: str = field(default="", compare=False)

    @classmethod
    def of(cls, model=None, mesh: str | os.PathLike | None = None, axes: str | None = None) -> "ModelSpec":
        """The spec of ``model`` (a TongueModel), of a mesh file, or of the shipped tongue."""
        if model is not None and mesh is not None:
            raise BatchError("give a model or a mesh file, not both")
        if model is not None:
            return cls("parts", model.mesh, None, model.landmarks, model.material)
        if mesh is not None:
            return cls("file", os.fspath(Path(mesh).resolve()), axes)
        return cls("default")

    def build(self):
        """The :class:`~tonguevis.sim.TongueModel` this spec describes."""
        from tonguevis.sim import TongueModel

        if self.kind in ("default", "file"):  # the one way a model is built from settings
            return build_model(RunSettings(mesh=self.mesh, mesh_axes=self.axes))
        if self.kind == "parts":
            return TongueModel(self.mesh, self.landmarks, self.material)
        raise BatchError(f"unknown model kind {self.kind!r}")


def model_key(model) -> str:
    """Content hash of a tongue model: mesh, anchors, sensor landmarks and material."""
    import numpy as np

    h = hashlib.sha256()
    for array in (model.mesh.points, model.mesh.tets, model.anchors):
        a = np.ascontiguousarray(array)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.tobytes())
    h.update(json.dumps({k: int(v) for k, v in model.landmarks.sensors.items()}, sort_keys=True).encode())
    h.update(json.dumps(model.material.as_dict(), sort_keys=True).encode())
    return h.hexdigest()


def _hash_file(h, path: Path) -> None:
    h.update(f"{path.name}\0".encode())
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)


def input_digest(path: str | os.PathLike, sensor_map=None, labels: dict | None = None) -> str:
    """SHA-256 of one recording's inputs: its bytes, the WAV and TextGrid read with it, its sensor map, its labels."""
    from tonguevis.io.companions import find_audio, find_labels
    from tonguevis.io.registry import SENSOR_MAP_BESIDE

    path = Path(path)
    h = hashlib.sha256()
    _hash_file(h, path)
    for companion in (find_audio(path), find_labels(path)):
        if companion is not None:
            _hash_file(h, Path(companion))
    if sensor_map is None:
        beside = path.parent / SENSOR_MAP_BESIDE
        if beside.is_file():
            _hash_file(h, beside)
    elif isinstance(sensor_map, dict):
        h.update(json.dumps(sensor_map, sort_keys=True, default=str).encode())
    elif Path(sensor_map).is_file():
        _hash_file(h, Path(sensor_map))
    else:  # a preset name
        h.update(f"preset:{sensor_map}".encode())
    h.update(json.dumps(labels or {}, sort_keys=True, default=str).encode())
    return h.hexdigest()


def step_keys(inputs: str, model: str, settings: BatchSettings) -> dict[str, str]:
    """{step: key} for every step of ``settings`` (and "simulate", whose motion energy and segment reuse)."""
    from tonguevis import __version__

    out = {}
    for step in dict.fromkeys(("simulate", *settings.steps)):
        text = json.dumps({"inputs": inputs, "model": model, "step": step, "version": __version__,
                           "settings": settings.step_settings(step)}, sort_keys=True, default=str)
        out[step] = hashlib.sha256(text.encode()).hexdigest()
    return out
