"""Sweeps: one named, numbered take of live biofeedback, collected sample by sample and saved as files every tonguevis command opens.

A :class:`Sweep` collects samples as they arrive (:meth:`Sweep.add`): the time (s, on the
stream's clock), the raw positions per sensor slot (m, NaN when a sensor is missing),
optionally the head-corrected positions the live view computed and the quaternions.  It
scores them against the targets at once (the value to colour the target with) and, at
the end, :meth:`Sweep.save` writes, in the sweep's folder:

``raw.tsv`` (+ ``raw.wav``)
    the raw stream as an NDI Wave TSV (mm, 6 decimals; the AudioTime column is the sweep's
    clock, 0 at its start: the stream's microsecond timestamps are kept exactly); read by
    :func:`tonguevis.io.read_recording`, so by every command (``info``, ``simulate``,
    ``view --compare``, ``batch``).
``head_corrected.tsv`` (+ ``head_corrected.wav``)
    the head-corrected positions: those given live, else
    :func:`tonguevis.preprocess.correction.head_corrected` of the raw stream (the same rule
    as every other command; the raw positions when there are fewer than three REF sensors).
``sensor_map.json``
    each sensor name's NDI Id in the TSVs (and the device's axes when known), so both files
    read back with the sensor names of the sweep.
``targets.json``
    the targets, the per-sensor offsets and the cycle plan (enough to replay the sweep
    with its target configuration).
``accuracy.csv``
    one row per sample: ``time_s``, ``frame``, then per target ``T<k>_distance_mm`` and
    ``T<k>_accuracy_percent`` (k from 1, in the order of targets.json); empty where missing.
``cycles.csv``
    one row per cycle per target: ``cycle``, ``start_s``, ``end_s``, ``complete``, ``target``,
    ``mean_accuracy_percent``, ``hit_fraction``, ``n_samples``, ``n_missing`` (no file when the
    targets have no cycle).
``summary.json``
    name, number, profile, start, duration, sensors, how the head was corrected, the accuracy
    per target over the sweep, and the files.  Written last: a folder with a summary is complete.

Scoring: a target scores its sensor's head-corrected position (the raw one when no
correction was given live) plus the profile's offset for that sensor; the saved accuracy is
exactly what was shown live.  Times given to the targets are the sweep's clock.

A batch over a folder of sweeps walks every ``.tsv`` and ``.csv``: pass the sweeps'
``head_corrected.tsv`` (or ``raw.tsv``) files themselves (``tonguevis batch sweeps/*/head_corrected.tsv``).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from tonguevis._files import atomic_write_text
from tonguevis.errors import RecordingError, TonguevisError
from tonguevis.live.profiles import Profile, SweepRecord, apply_sensor_offsets, save_profile
from tonguevis.live.targets import (
    MAX_CYCLE_S, Target, accuracy_colour, cycle_period, per_cycle, summarise, target_from_dict,
)

from tonguevis._logging import logger

RAW_FILE = "raw.tsv"
CORRECTED_FILE = "head_corrected.tsv"
SENSOR_MAP_FILE = "sensor_map.json"
TARGETS_FILE = "targets.json"
ACCURACY_FILE = "accuracy.csv"
CYCLES_FILE = "cycles.csv"
SUMMARY_FILE = "summary.json"
SWEEP_SCHEMA_VERSION = 1
#: Rate assumed when a sweep has a single sample (the NDI Wave's usual rate, Hz).
DEFAULT_RATE = 100.0


class SweepError(TonguevisError):
    """A sweep cannot take a sample or cannot be saved."""


class _Buffer:
    """A growing (N, ...) float64 array: appends in amortised constant time (capacity doubles)."""

    def __init__(self, shape: tuple[int, ...], capacity: int = 1024):
        self._data = np.empty((capacity, *shape))
        self.n = 0

    def append(self, rows: np.ndarray) -> None:
        k = len(rows)
        if self.n + k > len(self._data):
            grown = np.empty((max(2 * len(self._data), self.n + k), *self._data.shape[1:]))
            grown[:self.n] = self._data[:self.n]
            self._data = grown
        self._data[self.n:self.n + k] = rows
        self.n += k

    @property
    def array(self) -> np.ndarray:
        return self._data[:self.n]


@dataclass
class SavedSweep:
    """What :meth:`Sweep.save` wrote: the folder, its files (name -> path), the summary and the profile's record."""

    folder: Path
    files: dict[str, Path]
    summary: dict
    record: SweepRecord


def _channel_ids(names: Sequence[str], sensor_map: Mapping[str, int]) -> dict[str, int]:
    """NDI Id of each sensor in the saved TSVs: ``S<n>`` -> n, then the profile's slot, then the sensor's
    slot in the stream when free, else the lowest free Id."""
    ids: dict[str, int] = {}
    for name in names:
        m = re.fullmatch(r"S(\d+)", name)
        if m:
            ids[name] = int(m.group(1))
        elif name in sensor_map:
            ids[name] = int(sensor_map[name])
    if len(set(ids.values())) != len(ids):
        raise SweepError(f"two sensors would get the same NDI Id in the saved files: {ids}")
    used = set(ids.values())
    for slot, name in enumerate(names):
        if name not in ids:
            ids[name] = slot if slot not in used else next(i for i in range(10_000) if i not in used)
            used.add(ids[name])
    return ids


class Sweep:
    """One take: collect samples with :meth:`add`, then :meth:`save`.

    name : what the clinician calls it ("ta x10").
    sensor_names : the name of each slot of the stream, in slot order (S of them).
    profile : the patient's :class:`~tonguevis.live.profiles.Profile`; it gives the sweep its
        number (one more than its last), the default targets, offsets, sensor map and axes,
        and :meth:`save` adds the sweep to it.  Without one, pass ``number`` (default 1).
    targets, sensor_offsets : override the profile's (offsets: name -> (3,) m).
    start_s : the stream time (s) of the sweep's start, its clock's 0; default the first sample's time.
    rate : the stream's sample rate (Hz); default estimated from the times when saved.
    stop_after_s : optional automatic stop: :attr:`finished` turns true this long after the start.
    axes : the device's axes as the readers' ``axes=`` (default the profile's; None: unknown, the
        files then read in the device's frame).
    """

    def __init__(self, name: str, sensor_names: Sequence[str], *, profile: Profile | None = None,
                 number: int | None = None, targets: Sequence[Target] | None = None,
                 sensor_offsets: Mapping[str, Any] | None = None, start_s: float | None = None,
                 rate: float | None = None, stop_after_s: float | None = None, axes: str | None = None,
                 max_cycle_s: float = MAX_CYCLE_S):
        self.name = str(name).strip() or "sweep"
        self.sensor_names = [str(n) for n in sensor_names]
        if not self.sensor_names or len(set(self.sensor_names)) != len(self.sensor_names):
            raise SweepError(f"a sweep needs distinct sensor names, one per slot, got {list(sensor_names)}")
        self.profile = profile
        self.number = int(number) if number is not None else (profile.next_sweep_number() if profile else 1)
        self.targets = list(targets if targets is not None else (profile.targets if profile else []))
        offsets = sensor_offsets if sensor_offsets is not None else (profile.sensor_offsets if profile else {})
        self.sensor_offsets = {n: np.asarray(v, float).reshape(3) for n, v in offsets.items()}
        for target in self.targets:
            missing = [s for s in target.sensors_needed if s not in self.sensor_names]
            if missing:
                raise SweepError(f"target {target.name!r} needs sensor(s) {', '.join(missing)}, not among the "
                                 f"streamed {', '.join(self.sensor_names)}")
        self.start_s = None if start_s is None else float(start_s)
        self.rate = None if rate is None else float(rate)
        self.stop_after_s = None if stop_after_s is None else float(stop_after_s)
        self.axes = axes if axes is not None else (profile.axes if profile else None)
        self.started = datetime.now(timezone.utc).isoformat(timespec="seconds")
        self.cycle = cycle_period(self.targets, max_cycle_s)
        s, t = len(self.sensor_names), len(self.targets)
        self._times = _Buffer(())
        self._frames = _Buffer(())
        self._raw = _Buffer((s, 3))
        self._corrected = _Buffer((s, 3))
        self._quats = _Buffer((s, 4))
        self._distance = _Buffer((t,))
        self._accuracy = _Buffer((t,))
        self._live_correction: bool | None = None
        self._has_quats: bool | None = None
        self.audio = None

    # ------------------------------------------------------------------ collecting

    @property
    def n_samples(self) -> int:
        return self._times.n

    @property
    def times(self) -> np.ndarray:
        """(N,) s on the sweep's clock (0 at its start)."""
        return self._times.array - (self.start_s or 0.0)

    @property
    def raw(self) -> np.ndarray:
        """(N, S, 3) m, the raw positions per slot."""
        return self._raw.array

    @property
    def corrected(self) -> np.ndarray | None:
        """(N, S, 3) m, the head-corrected positions given live (None when none were)."""
        return self._corrected.array if self._live_correction else None

    @property
    def accuracy(self) -> np.ndarray:
        """(N, T) %, each sample's accuracy per target (NaN where missing)."""
        return self._accuracy.array

    @property
    def distance(self) -> np.ndarray:
        """(N, T) m, each sample's distance to each target's centre (NaN where missing)."""
        return self._distance.array

    @property
    def elapsed_s(self) -> float:
        """Seconds from the start to the last sample (0 before any)."""
        return float(self._times.array[-1] - self.start_s) if self.n_samples else 0.0

    @property
    def finished(self) -> bool:
        """True once ``stop_after_s`` has elapsed (the automatic stop; never without one)."""
        return self.stop_after_s is not None and self.n_samples > 0 and self.elapsed_s >= self.stop_after_s

    def add(self, time_s, positions, corrected=None, quaternions=None, frame=None) -> np.ndarray:
        """Add samples; returns their accuracy (%) per target, (T,) for one sample or (K, T) for K.

        time_s : a float or (K,) s on the stream's clock, increasing and after every earlier sample.
        positions : (S, 3) or (K, S, 3) m, raw, slots in ``sensor_names`` order; NaN where missing.
        corrected : the same, head-corrected by the live view, in the same axes as ``positions`` (head motion
            removed, not turned into tonguevis's axes: as :func:`~tonguevis.preprocess.correction.correct_head`
            gives them; the saved files' sensor map turns both); give it for every sample or never.
        quaternions : (S, 4) or (K, S, 4) w, x, y, z, or None; give them for every sample or never.
        frame : the stream's frame number(s) (kept in accuracy.csv), or None.
        """
        t = np.atleast_1d(np.asarray(time_s, dtype=float))
        single = np.ndim(time_s) == 0
        k, s = len(t), len(self.sensor_names)

        def rows(value, width, what):
            arr = np.asarray(value, dtype=float)
            if single:
                arr = arr[None]
            if arr.shape != (k, s, width):
                raise SweepError(f"{what}: expected shape {(s, width) if single else (k, s, width)} "
                                 f"(slots {', '.join(self.sensor_names)}), got {np.shape(value)}")
            return arr

        raw = rows(positions, 3, "positions")
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0) or (
                self.n_samples and t[0] <= self._times.array[-1]):
            last = self._times.array[-1] if self.n_samples else None
            raise SweepError(f"sample times must be finite and increasing (last {last}, got {t[:3].tolist()}...)")
        live = corrected is not None
        if self._live_correction is None:
            self._live_correction = live
        elif live != self._live_correction:
            raise SweepError("head-corrected positions must be given with every sample or with none")
        has_q = quaternions is not None
        if self._has_quats is None:
            self._has_quats = has_q
        elif has_q != self._has_quats:
            raise SweepError("quaternions must be given with every sample or with none")
        fixed = rows(corrected, 3, "corrected positions") if live else raw
        if self.start_s is None:
            self.start_s = float(t[0])
        elif t[0] < self.start_s:
            raise SweepError(f"a sample at {t[0]} s comes before the sweep's start ({self.start_s} s)")
        frames = np.full(k, np.nan) if frame is None else np.atleast_1d(np.asarray(frame, dtype=float))
        if frames.shape != (k,):
            raise SweepError(f"frame numbers: expected {k}, got shape {frames.shape}")
        sensors = apply_sensor_offsets({n: fixed[:, i] for i, n in enumerate(self.sensor_names)},
                                       self.sensor_offsets)
        clock = t - self.start_s
        dist = np.full((k, len(self.targets)), np.nan)
        acc = np.full((k, len(self.targets)), np.nan)
        for j, target in enumerate(self.targets):
            dist[:, j], acc[:, j] = target.score(clock, sensors)
        self._times.append(t)
        self._frames.append(frames)
        self._raw.append(raw)
        self._corrected.append(fixed)
        self._quats.append(rows(quaternions, 4, "quaternions") if has_q else np.full((k, s, 4), np.nan))
        self._distance.append(dist)
        self._accuracy.append(acc)
        return acc[0] if single else acc

    def add_frame(self, frame, corrected=None) -> np.ndarray:
        """Add one live frame as the sources give it (:class:`tonguevis.live.source.LiveFrame` or alike:
        ``timestamp_s``, ``positions`` (S, 3) in **mm**, optional ``quaternions`` (S, 4) and ``frame``);
        ``corrected`` (S, 3) in **metres** as in :meth:`add`.  Returns the accuracy per target (T,)."""
        quats = getattr(frame, "quaternions", None)
        if self._has_quats is False:
            quats = None  # the first frames had none: keep the sweep consistent
        return self.add(frame.timestamp_s, np.asarray(frame.positions, dtype=float) / 1000.0, corrected=corrected,
                        quaternions=quats, frame=getattr(frame, "frame", None))

    def colours(self, accuracy=None) -> np.ndarray:
        """(T, 3) RGB for each target: the last sample's accuracy (or ``accuracy``), grey when missing."""
        if accuracy is None:
            accuracy = self.accuracy[-1] if self.n_samples else np.full(len(self.targets), np.nan)
        return accuracy_colour(accuracy)

    def set_audio(self, samples, rate: float, offset_s: float = 0.0) -> None:
        """The microphone's sound: (K,) floats in [-1, 1] at ``rate`` Hz, its first sample ``offset_s``
        after the sweep's start (sweep clock)."""
        from tonguevis.io.recording import Audio

        rate = float(rate)
        if not rate > 0:
            raise SweepError(f"audio rate must be positive, got {rate}")
        self.audio = Audio(samples=np.asarray(samples, dtype=np.float32).ravel(), rate=rate, offset=float(offset_s))

    # ------------------------------------------------------------------ results

    def summaries(self):
        """One :class:`~tonguevis.live.targets.AccuracySummary` per target over the whole sweep."""
        return [summarise(self.accuracy[:, j]) for j in range(len(self.targets))]

    def cycles(self):
        """Per-cycle figures (:func:`~tonguevis.live.targets.per_cycle`), [] when the targets have no cycle."""
        if self.cycle.period_s is None or not self.n_samples:
            return []
        return per_cycle(self.times, self.accuracy, self.cycle.period_s, 0.0)

    def recording(self, corrected: bool = False):
        """The sweep as a :class:`~tonguevis.io.recording.Recording` (m, times on the sweep's clock).

        corrected : the head-corrected positions (given live, else computed as every command does,
            which rotates the quaternions too; positions corrected live are saved without orientations).
        """
        from tonguevis.io._common import estimate_rate
        from tonguevis.io.recording import Recording
        from tonguevis.preprocess.correction import head_corrected

        if not self.n_samples:
            raise SweepError(f"sweep {self.number} ({self.name}) has no samples")
        times = self.times
        rate = self.rate or estimate_rate(times, default=DEFAULT_RATE)
        data = self._corrected.array if (corrected and self._live_correction) else self.raw
        sensors = {n: data[:, i].copy() for i, n in enumerate(self.sensor_names)}
        # Positions corrected live come without their rotated quaternions: the raw ones would be wrong there.
        orientations = ({n: self._quats.array[:, i].copy() for i, n in enumerate(self.sensor_names)}
                        if self._has_quats and not (corrected and self._live_correction) else {})
        rec = Recording(rate=float(rate), times=times.copy(), sensors=sensors, orientations=orientations,
                        audio=self.audio,
                        metadata={"format": "ndi_wave", "file": f"sweep {self.number} ({self.name})",
                                  "original_unit": "mm", "orientation_kind": "quaternion_wxyz",
                                  "frame": "device"})
        if corrected and not self._live_correction:
            rec = head_corrected(rec)
        return rec

    def save(self, folder: str | os.PathLike | None = None, *, profiles_root: str | os.PathLike | None = None,
             update_profile: bool = True, overwrite: bool = False) -> SavedSweep:
        """Write the sweep's files (see the module docstring) and return what was written.

        folder : where (default ``<profile folder>/sweeps/NNN_<name>`` under ``profiles_root``).
        update_profile : add the sweep to the profile and save the profile (when there is one).
        overwrite : write into a folder that already holds a sweep (default: SweepError).
        A sweep numbered like one the profile already lists is renumbered first.
        """
        from tonguevis.io.ndi_wave import write_ndi_wave

        if not self.n_samples:
            raise SweepError(f"sweep {self.number} ({self.name}) has no samples to save")
        profile = self.profile
        number = self.number
        if profile is not None and update_profile and any(r.number == number for r in profile.sweeps):
            number = profile.next_sweep_number()
            logger.info("sweep %d (%s) is saved as %d: the profile already has a sweep %d", self.number, self.name,
                     number, self.number)
        if folder is None:
            if profile is None:
                raise SweepError("say where to save a sweep that has no profile (folder=...)")
            folder = profile.sweep_folder(number, self.name, profiles_root)
        folder = Path(folder)
        if (folder / SUMMARY_FILE).exists() and not overwrite:
            raise SweepError("a sweep is already saved here (pass overwrite=True to replace it)", folder)
        self.number = number
        folder.mkdir(parents=True, exist_ok=True)
        files = {k: folder / v for k, v in (("raw", RAW_FILE), ("head_corrected", CORRECTED_FILE),
                                           ("sensor_map", SENSOR_MAP_FILE), ("targets", TARGETS_FILE),
                                           ("accuracy", ACCURACY_FILE), ("summary", SUMMARY_FILE))}
        ids = _channel_ids(self.sensor_names, profile.sensor_map if profile else {})
        smap = {"description": f"sensor names of sweep {self.number} ({self.name}) -> their NDI Id in the TSVs",
                "sensors": ids}
        if self.axes:
            smap["axes"] = self.axes
        atomic_write_text(files["sensor_map"], json.dumps(smap, indent=1) + "\n")
        raw = self.recording(corrected=False)
        try:
            corrected = self.recording(corrected=True)
        except RecordingError as exc:
            # Offline head correction can fail (collinear references): keep the sweep, say so.
            logger.warning("sweep %d (%s): no head correction (%s); head_corrected.tsv holds the raw positions",
                        self.number, self.name, exc)
            corrected, correction = raw, f"none ({exc})"
        else:
            if self._live_correction:
                correction = "live (as given with each sample)"
            elif corrected is raw:
                correction = "none (fewer than three REF sensors): the raw positions"
            else:
                correction = "offline: tonguevis.preprocess.correction.head_corrected of the raw stream"
        write_ndi_wave(raw, files["raw"], sensor_map=ids)
        write_ndi_wave(corrected, files["head_corrected"], sensor_map=ids)
        if self.audio is not None:
            files["raw_audio"] = files["raw"].with_suffix(".wav")
            files["head_corrected_audio"] = files["head_corrected"].with_suffix(".wav")
        atomic_write_text(files["targets"], json.dumps(self._targets_json(), indent=1, allow_nan=False) + "\n")
        atomic_write_text(files["accuracy"], self._accuracy_csv())
        cycles = self.cycles()
        if cycles:
            files["cycles"] = folder / CYCLES_FILE
            atomic_write_text(files["cycles"], self._cycles_csv(cycles))
        sweep_figures = [{"target": t.name, "sensor": t.sensor, **s.to_dict()}
                         for t, s in zip(self.targets, self.summaries())]
        summary = {
            "kind": "tonguevis sweep",
            "schema_version": SWEEP_SCHEMA_VERSION,
            "name": self.name,
            "number": self.number,
            "profile": profile.id if profile else None,
            "started": self.started,
            "stream_start_s": self.start_s,
            "duration_s": float(raw.duration),
            "n_samples": self.n_samples,
            "rate_hz": float(raw.rate),
            "sensors": self.sensor_names,
            "ndi_ids": ids,
            "head_correction": correction,
            "scored_on": ("head-corrected positions" if self._live_correction else "raw positions") +
                         (" plus the per-sensor offsets" if self.sensor_offsets else ""),
            "missing_samples": {n: int(np.sum(~np.all(np.isfinite(self.raw[:, i]), axis=1)))
                                for i, n in enumerate(self.sensor_names)},
            "cycle": {"period_s": self.cycle.period_s, "exact": self.cycle.exact, "reason": self.cycle.reason,
                      "n_cycles": len(cycles), "n_complete": sum(c.complete for c in cycles)},
            "accuracy": sweep_figures,
            "audio": None if self.audio is None else {"rate_hz": self.audio.rate, "seconds": self.audio.duration},
            "files": {k: p.name for k, p in files.items()},
        }
        atomic_write_text(files["summary"], json.dumps(summary, indent=1, allow_nan=False) + "\n")
        record = SweepRecord(self.number, self.name, "", self.started, float(raw.duration), self.n_samples,
                             sweep_figures)
        if profile is not None:
            try:
                record.folder = os.path.relpath(folder, profile.folder(profiles_root))
            except ValueError:  # another drive on Windows
                record.folder = str(folder)
            if update_profile:
                profile.sweeps.append(record)
                save_profile(profile, profiles_root)
        else:
            record.folder = str(folder)
        return SavedSweep(folder, files, summary, record)

    def _targets_json(self) -> dict:
        return {"kind": "tonguevis sweep targets", "schema_version": SWEEP_SCHEMA_VERSION,
                "units": {"positions": "m", "times": "s (sweep clock)", "frequency": "Hz"},
                "targets": [dict(t.to_dict(), column=f"T{j + 1}") for j, t in enumerate(self.targets)],
                "sensor_offsets_m": {n: v.tolist() for n, v in self.sensor_offsets.items()},
                "cycle": {"period_s": self.cycle.period_s, "exact": self.cycle.exact, "reason": self.cycle.reason}}

    def _accuracy_csv(self) -> str:
        header = ["time_s", "frame"]
        for j in range(len(self.targets)):
            header += [f"T{j + 1}_distance_mm", f"T{j + 1}_accuracy_percent"]
        table = np.column_stack([self.times, self._frames.array,
                                 *[col for j in range(len(self.targets))
                                   for col in (self.distance[:, j] * 1000.0, self.accuracy[:, j])]])
        out = io.StringIO()
        out.write(",".join(header) + "\n")
        for row in table.tolist():
            cells = ["%.6f" % row[0], "" if math.isnan(row[1]) else "%d" % row[1]]
            cells += ["" if math.isnan(v) else "%.4f" % v for v in row[2:]]
            out.write(",".join(cells) + "\n")
        return out.getvalue()

    def _cycles_csv(self, cycles) -> str:
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(["cycle", "start_s", "end_s", "complete", "target", "mean_accuracy_percent", "hit_fraction",
                         "n_samples", "n_missing"])
        for c in cycles:
            for j, s in enumerate(c.targets):
                writer.writerow([c.index + 1, f"{c.start_s:.6f}", f"{c.end_s:.6f}", int(c.complete), f"T{j + 1}",
                                 "" if math.isnan(s.mean_percent) else f"{s.mean_percent:.4f}",
                                 "" if math.isnan(s.hit_fraction) else f"{s.hit_fraction:.4f}",
                                 s.n_samples, s.n_missing])
        return out.getvalue()


def open_sweep(folder: str | os.PathLike, corrected: bool = True):
    """A saved sweep's positions as a :class:`~tonguevis.io.recording.Recording` (m), with its sound and sensor names.

    corrected : ``head_corrected.tsv`` (default: what a replay target or ghost tongue should use),
    else ``raw.tsv``.  Read by :func:`tonguevis.io.read_recording` like any recording.
    """
    from tonguevis.io.registry import read_recording

    path = Path(folder) / (CORRECTED_FILE if corrected else RAW_FILE)
    if not path.is_file():
        raise SweepError(f"not a saved sweep: no {path.name} in it", folder)
    return read_recording(path)


def load_sweep_targets(path: str | os.PathLike) -> list[Target]:
    """The targets a saved sweep's ``targets.json`` (or its folder) holds; SweepError naming the file when bad."""
    path = Path(path)
    if path.is_dir():
        path = path / TARGETS_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return [target_from_dict(t) for t in data["targets"]]
    except FileNotFoundError:
        raise SweepError("no such targets file", path) from None
    except json.JSONDecodeError as exc:
        raise SweepError(f"malformed JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}", path) from None
    except (KeyError, TypeError, ValueError, OSError) as exc:
        raise SweepError(f"not a sweep's targets file ({exc})", path) from None
