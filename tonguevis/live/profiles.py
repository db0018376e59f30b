"""Patient (or experiment) profiles for live biofeedback, saved as JSON so the next session starts where the last ended.

A :class:`Profile` holds what a clinician sets up once per patient: the targets
(:mod:`tonguevis.live.targets`), per-sensor offsets (a sensor glued back from the tip to
spare the gag reflex stands for a point in front of it), the rest pose taken, the sensor
map (stream slot of each sensor name, and the device's axes when known) and the list of
past sweeps with their accuracy.

Layout on disk, in a profiles folder (default :func:`profiles_dir`; every function takes
a ``folder``)::

    <folder>/<profile id>/profile.json        this profile (schema version SCHEMA_VERSION)
    <folder>/<profile id>/sweeps/003_name/     each sweep's files (tonguevis.live.sweeps)

Units: metres, seconds.  JSON has no NaN: missing coordinates are written as null.
``profile.json`` is written atomically (a crash never leaves half a profile), and a
malformed or newer file gives a :class:`ProfileError` naming it and the problem.
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from tonguevis._files import atomic_write_text
from tonguevis.errors import TonguevisError
from tonguevis.live.targets import Target, TargetError, target_from_dict

#: Version of profile.json's layout; files of a newer version are refused, older ones upgraded on load.
SCHEMA_VERSION = 1
PROFILE_FILE = "profile.json"
SWEEPS_FOLDER = "sweeps"
FILE_KIND = "tonguevis live profile"
_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


class ProfileError(TonguevisError):
    """A profile cannot be read, written or used."""


def profiles_dir() -> Path:
    """The default profiles folder (not created here).

    ``$TONGUEVIS_PROFILES`` when set; else the user's data folder: ``$XDG_DATA_HOME`` or
    ``~/.local/share`` on Linux, ``~/Library/Application Support`` on macOS, ``%APPDATA%``
    on Windows; then ``tonguevis/profiles``.
    """
    root = os.environ.get("TONGUEVIS_PROFILES")
    if root:
        return Path(root)
    if sys.platform == "win32":
        base = Path(os.environ.get("APPDATA") or Path.home() / "AppData" / "Roaming")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Application Support"
    else:
        base = Path(os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share")
    return base / "tonguevis" / "profiles"


def check_profile_id(profile_id: str) -> str:
    """``profile_id`` when it is a safe folder name (letters, digits, ``_ . -``; up to 64), else ProfileError."""
    if not isinstance(profile_id, str) or not _ID.match(profile_id):
        raise ProfileError(f"a profile id must be 1-64 letters, digits, '_', '.' or '-' starting with a letter "
                           f"or digit (it names a folder), got {profile_id!r}")
    return profile_id


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _vector(value, what: str) -> np.ndarray:
    v = np.asarray([np.nan if x is None else x for x in value] if isinstance(value, (list, tuple)) else value,
                   dtype=float)
    if v.shape != (3,):
        raise ProfileError(f"{what} must be three coordinates in metres, got {value!r}")
    return v


def _json_vector(v: np.ndarray) -> list:
    return [None if not math.isfinite(x) else float(x) for x in np.asarray(v, float)]


@dataclass
class RestPose:
    """The rest pose taken: name -> (3,) m (head-corrected), the interval (s) it was taken over, and when."""

    positions: dict[str, np.ndarray]
    interval_s: tuple[float, float] | None = None
    taken: str = field(default_factory=_now)

    def to_dict(self) -> dict:
        return {"positions_m": {n: _json_vector(p) for n, p in self.positions.items()},
                "interval_s": None if self.interval_s is None else [float(x) for x in self.interval_s],
                "taken": self.taken}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "RestPose":
        interval = d.get("interval_s")
        return cls({str(n): _vector(p, f"rest position of {n}") for n, p in d["positions_m"].items()},
                   None if interval is None else (float(interval[0]), float(interval[1])),
                   str(d.get("taken", "")))


@dataclass
class SweepRecord:
    """A past sweep as the profile lists it.

    number : 1, 2, ... per profile.  folder : the sweep's folder, relative to the profile's.
    started : ISO 8601 UTC.  duration_s, n_samples : its length.
    accuracy : one dict per target: ``target`` (name), ``sensor``, ``mean_percent``,
        ``hit_fraction``, ``n_samples``, ``n_missing`` (see :class:`~tonguevis.live.targets.AccuracySummary`).
    """

    number: int
    name: str
    folder: str
    started: str
    duration_s: float
    n_samples: int
    accuracy: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"number": self.number, "name": self.name, "folder": self.folder, "started": self.started,
                "duration_s": self.duration_s, "n_samples": self.n_samples, "accuracy": self.accuracy}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "SweepRecord":
        return cls(int(d["number"]), str(d["name"]), str(d["folder"]), str(d.get("started", "")),
                   float(d.get("duration_s", 0.0)), int(d.get("n_samples", 0)), list(d.get("accuracy", [])))


@dataclass
class Profile:
    """A patient's or experiment's live set-up and history (see the module docstring).

    id : a safe folder name (:func:`check_profile_id`); name : free text shown to the clinician.
    targets : the biofeedback targets (:class:`~tonguevis.live.targets.Target`).
    sensor_offsets : name -> (3,) m added to that sensor's head-corrected position before it is
        scored (a sensor glued 10 mm back from the tip: about +10 mm along x, anterior).  A fixed
        vector in the head frame: it does not turn with the tongue (good enough for a few mm).
    rest : the rest pose taken, or None.
    sensor_map : sensor name -> slot of the stream (the item's place in a frame).
    axes : the device's axes as the readers' ``axes=`` option (e.g. ``"-y,x,z"``), or None (unknown).
    sweeps : the past sweeps, oldest first.
    """

    id: str
    name: str = ""
    targets: list[Target] = field(default_factory=list)
    sensor_offsets: dict[str, np.ndarray] = field(default_factory=dict)
    rest: RestPose | None = None
    sensor_map: dict[str, int] = field(default_factory=dict)
    axes: str | None = None
    sweeps: list[SweepRecord] = field(default_factory=list)
    notes: str = ""
    created: str = field(default_factory=_now)

    def __post_init__(self) -> None:
        check_profile_id(self.id)
        self.name = self.name or self.id
        self.sensor_offsets = {str(n): _vector(v, f"offset of sensor {n}") for n, v in self.sensor_offsets.items()}
        for name, slot in self.sensor_map.items():
            if not isinstance(slot, (int, np.integer)) or isinstance(slot, bool) or slot < 0:
                raise ProfileError(f"sensor map: {name!r} must map to a slot number >= 0, got {slot!r}")
        if len(set(self.sensor_map.values())) != len(self.sensor_map):
            raise ProfileError(f"sensor map gives two sensors the same slot: {self.sensor_map}")

    def next_sweep_number(self) -> int:
        """The number the next sweep gets: one more than the highest so far (1 for the first)."""
        return max((s.number for s in self.sweeps), default=0) + 1

    def folder(self, root: str | os.PathLike | None = None) -> Path:
        """This profile's folder under ``root`` (default :func:`profiles_dir`)."""
        return Path(root if root is not None else profiles_dir()) / self.id

    def sweep_folder(self, number: int, name: str, root: str | os.PathLike | None = None) -> Path:
        """Where sweep ``number`` called ``name`` goes: ``<profile folder>/sweeps/NNN_<name>``."""
        safe = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "sweep"
        return self.folder(root) / SWEEPS_FOLDER / f"{number:03d}_{safe[:48]}"

    def to_dict(self) -> dict:
        return {
            "kind": FILE_KIND,
            "schema_version": SCHEMA_VERSION,
            "id": self.id,
            "name": self.name,
            "created": self.created,
            "notes": self.notes,
            "units": {"positions": "m", "times": "s", "frequency": "Hz", "accuracy": "%"},
            "targets": [t.to_dict() for t in self.targets],
            "sensor_offsets_m": {n: _json_vector(v) for n, v in self.sensor_offsets.items()},
            "rest": None if self.rest is None else self.rest.to_dict(),
            "sensor_map": {"sensors": {n: int(s) for n, s in self.sensor_map.items()}, "axes": self.axes},
            "sweeps": [s.to_dict() for s in self.sweeps],
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], path: str | os.PathLike | None = None) -> "Profile":
        """The profile ``d`` describes (as :meth:`to_dict` writes it); ProfileError naming ``path`` when it is wrong."""
        if not isinstance(d, Mapping):
            raise ProfileError(f"a profile must be a JSON object, found {type(d).__name__}", path)
        if d.get("kind") != FILE_KIND:
            raise ProfileError(f"not a tonguevis live profile (its \"kind\" is {d.get('kind')!r}, "
                               f"expected {FILE_KIND!r})", path)
        version = d.get("schema_version")
        if not isinstance(version, int) or version < 1:
            raise ProfileError(f"schema_version must be a whole number >= 1, found {version!r}", path)
        if version > SCHEMA_VERSION:
            raise ProfileError(f"written by a newer tonguevis (schema version {version}; this one reads up to "
                               f"{SCHEMA_VERSION}): update tonguevis to open it", path)
        where = "?"
        try:
            where = "id"
            profile_id = d["id"]
            where = "targets"
            targets = []
            for i, t in enumerate(d.get("targets", [])):
                where = f"targets[{i}]"
                targets.append(target_from_dict(t))
            where = "sensor_map"
            smap = d.get("sensor_map") or {}
            where = "rest"
            rest = None if d.get("rest") is None else RestPose.from_dict(d["rest"])
            where = "sweeps"
            sweeps = [SweepRecord.from_dict(s) for s in d.get("sweeps", [])]
            where = "sensor_offsets_m"
            return cls(id=profile_id, name=str(d.get("name", "")), targets=targets,
                       sensor_offsets=dict(d.get("sensor_offsets_m", {})), rest=rest,
                       sensor_map=dict(smap.get("sensors", {})), axes=smap.get("axes"), sweeps=sweeps,
                       notes=str(d.get("notes", "")), created=str(d.get("created", "")))
        except (ProfileError, TargetError) as exc:
            raise ProfileError(f"{where}: {exc}", path) from None
        except KeyError as exc:
            raise ProfileError(f"{where}: missing field {exc.args[0]!r}", path) from None
        except (TypeError, ValueError, AttributeError, IndexError) as exc:
            raise ProfileError(f"{where}: malformed ({type(exc).__name__}: {exc})", path) from None


def profile_path(profile_id: str, folder: str | os.PathLike | None = None) -> Path:
    """``<folder>/<id>/profile.json`` (folder default :func:`profiles_dir`)."""
    return Path(folder if folder is not None else profiles_dir()) / check_profile_id(profile_id) / PROFILE_FILE


def save_profile(profile: Profile, folder: str | os.PathLike | None = None) -> Path:
    """Write ``profile`` atomically to ``<folder>/<id>/profile.json`` (folders created); returns the path."""
    path = profile_path(profile.id, folder)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(profile.to_dict(), indent=1, allow_nan=False) + "\n")
    return path


def load_profile(profile: str | os.PathLike, folder: str | os.PathLike | None = None) -> Profile:
    """Read a profile: an id (looked up in ``folder``) or the path of a ``profile.json`` (or its folder).

    A missing, unreadable, malformed or newer file raises :class:`ProfileError` naming it.
    """
    text = os.fspath(profile)
    if isinstance(profile, os.PathLike) or os.sep in text or text.endswith(".json"):
        path = Path(profile)
        if path.is_dir():
            path = path / PROFILE_FILE
    else:
        path = profile_path(text, folder)
    try:
        raw = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ProfileError("no such profile file", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ProfileError(f"cannot read the profile ({exc})", path) from None
    try:
        data = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise ProfileError(f"malformed JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}", path) from None
    return Profile.from_dict(data, path)


def list_profiles(folder: str | os.PathLike | None = None) -> list[str]:
    """Ids of the profiles in ``folder`` (those with a profile.json), sorted."""
    root = Path(folder if folder is not None else profiles_dir())
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / PROFILE_FILE).is_file() and _ID.match(p.name))


def apply_sensor_offsets(sensors: Mapping[str, np.ndarray], offsets: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """``sensors`` (name -> (..., 3) m) with each sensor's offset (m) added; sensors without one unchanged."""
    return {n: (np.asarray(p, float) + np.asarray(offsets[n], float) if n in offsets else np.asarray(p, float))
            for n, p in sensors.items()}
