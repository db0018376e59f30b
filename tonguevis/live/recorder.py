"""Record a live stream as an NDI Wave TSV export, row by row, so that nothing received is ever lost.

:class:`TsvRecorder` writes the layout :func:`tonguevis.io.ndi_wave.read_ndi_wave` reads
(``AudioTime[s] MeasId WavId``, then per slot ``Sensor k Id, Sensor k Status, X[mm] Y[mm]
Z[mm] Q0 Qx Qy Qz`` with k = Id + 1, status 55 present and 119 missing with empty fields).
Each row is written and flushed as its frame arrives (and the file synced to disk about
once a second), so a crash or a pulled cable loses nothing already received; a row cut
by a crash is the incomplete last line the reader drops with a warning.  Numbers are
written with 9 significant digits, which gives every float32 from the wire back exactly.

* AudioTime is the device's time stamp (s, to the µs it sends); MeasId its frame number;
  WavId the time stamp in samples of 22,050 Hz audio, as WaveFront's exports count.
* Sensor Ids: the ids the device listed (the replay server's SendParameters), else the
  slot numbers 0, 1, ...
* When the slots have names (the device listed them, or a sensor map was given),
  ``sensor_map.json`` is written beside the file unless one is already there, so every
  tonguevis command reads the sensors under their names (with ``"axes": "x,y,z"`` when the
  device said its positions are already in tonguevis's frame, as the replay server does for
  a recording read with its axes).

:func:`record` drives a :class:`~tonguevis.live.source.Source` into a recorder and at the
end writes the head-corrected version (``NAME_headcorrected.tsv``, atomically), or says
why not (fewer than three REF* head references).
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tonguevis._files import atomic_write
from tonguevis.errors import RecordingError, TonguevisError
from tonguevis.live.source import LiveFrame, Source, SourceStatus

from tonguevis._logging import logger

STATUS_OK = 55
STATUS_MISSING = 119
AUDIO_RATE = 22050.0
HEAD_CORRECTED_SUFFIX = "_headcorrected"
SENSOR_MAP_FILE = "sensor_map.json"


class TsvRecorder:
    """Append :class:`LiveFrame` rows to an NDI Wave TSV at ``path`` (created on the first frame).

    ids : the NDI Id of each slot (default: the slot numbers).  The slot count is fixed
    by the first frame; later frames with more slots lose the extra ones, with fewer
    get missing samples (both counted in :attr:`mismatched`).
    """

    def __init__(self, path, ids: list[int] | None = None, sync_interval: float = 1.0):
        self.path = Path(path)
        self.ids = list(ids) if ids is not None else None
        self.sync_interval = float(sync_interval)
        self.rows = 0
        self.mismatched = 0
        #: Frames not written because their time stamp did not follow the last row's (a repeated
        #: frame after a reconnection, or a device whose clock went back): readers need increasing times.
        self.out_of_order = 0
        self._last_time = -np.inf
        #: Frames without any sensor slot, not written.
        self.empty = 0
        self._file = None
        self._n_slots: int | None = None
        self._last_sync = 0.0

    def _open(self, n_slots: int) -> None:
        if self.ids is None or len(self.ids) != n_slots or len(set(self.ids)) != n_slots \
                or any(not isinstance(i, (int, np.integer)) or i < 0 for i in self.ids):
            if self.ids is not None:
                logger.warning("%s: the device's sensor ids %s do not fit %d slots; slot numbers used",
                            self.path, self.ids, n_slots)
            self.ids = list(range(n_slots))
        header = ["AudioTime[s]", "MeasId", "WavId"]
        for sensor_id in self.ids:
            k = int(sensor_id) + 1
            header += [f"Sensor {k} Id", f"Sensor {k} Status", "X[mm]", "Y[mm]", "Z[mm]", "Q0", "Qx", "Qy", "Qz"]
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # "x": never overwrite an earlier session's file.
        self._file = open(self.path, "x", encoding="ascii", newline="\n")
        self._file.write("\t".join(header) + "\n")
        self._file.flush()
        self._n_slots = n_slots

    def write(self, frame: LiveFrame) -> bool:
        """Write one frame's row and flush it to the operating system; False (not written) when its
        time stamp does not come after the last row's (see :attr:`out_of_order`)."""
        if frame.n_sensors == 0:  # nothing measured (no sensor plugged in yet): no row, no header fixed by it
            self.empty += 1
            return False
        stamp = f"{frame.timestamp_s:.6f}"
        if not float(stamp) > self._last_time:
            self.out_of_order += 1
            return False
        if self._file is None:
            self._open(frame.n_sensors)
        n = self._n_slots
        positions, quaternions = frame.positions, frame.quaternions
        if len(positions) != n:
            self.mismatched += 1
            positions = _fit(positions, n)
            quaternions = _fit(quaternions, n)
        fields = [stamp, str(int(frame.frame)), str(int(np.floor(frame.timestamp_s * AUDIO_RATE)))]
        ok = np.all(np.isfinite(positions), axis=1)
        for slot in range(n):
            if ok[slot]:
                values = np.concatenate([positions[slot], quaternions[slot]])
                numbers = ["" if not np.isfinite(v) else f"{v:.9g}" for v in values.tolist()]
                fields += [str(int(self.ids[slot])), str(STATUS_OK), *numbers]
            else:
                fields += [str(int(self.ids[slot])), str(STATUS_MISSING)] + [""] * 7
        self._file.write("\t".join(fields) + "\n")
        self._file.flush()
        self.rows += 1
        self._last_time = float(stamp)
        now = time.monotonic()
        if now - self._last_sync > self.sync_interval:
            os.fsync(self._file.fileno())
            self._last_sync = now
        return True

    def close(self) -> None:
        if self._file is not None and not self._file.closed:
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()

    def __enter__(self) -> "TsvRecorder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _fit(array: np.ndarray, n: int) -> np.ndarray:
    out = np.full((n, array.shape[1]), np.nan)
    m = min(n, len(array))
    out[:m] = array[:m]
    return out


@dataclass
class RecordResult:
    """What :func:`record` did.

    path : the TSV written (None when no frame came).  head_corrected : its
    head-corrected version, or None (``notes`` says why).  frames : rows written.
    status : the source's last :class:`SourceStatus`.  interrupted : stopped by the user.
    """

    path: Path | None
    head_corrected: Path | None
    frames: int
    seconds: float
    status: SourceStatus
    interrupted: bool = False
    notes: list[str] = field(default_factory=list)


def free_path(out_dir, name: str) -> Path:
    """``out_dir/name.tsv``, or ``name_2.tsv``, ``name_3.tsv``... when taken (never overwrite a session)."""
    out_dir = Path(out_dir)
    path = out_dir / f"{name}.tsv"
    k = 2
    while path.exists():
        path = out_dir / f"{name}_{k}.tsv"
        k += 1
    return path


def record(source: Source, path, *, seconds: float | None = None, stop: threading.Event | None = None,
           sensor_map: dict | str | os.PathLike | None = None, report: Callable[[str], None] | None = None,
           report_interval: float = 1.0, head_correction: bool = True) -> RecordResult:
    """Write every frame of ``source`` (already started) to the NDI Wave TSV ``path`` until the end.

    The end: ``seconds`` after the first frame, ``stop`` set, the source finished or
    failed, or Ctrl-C (KeyboardInterrupt; the file is kept, ``interrupted`` is True).
    sensor_map : names of the slots (name -> NDI Id, a preset or a JSON file), used for
        the head correction and saved as ``sensor_map.json`` beside; default the names
        the device listed.
    report : called with a status line about every ``report_interval`` seconds and on events.
    The source is closed at the end.
    """
    path = Path(path)
    recorder = TsvRecorder(path, ids=source.sensor_ids)
    first = None
    last_report = time.monotonic()
    interrupted = False
    try:
        while True:
            if stop is not None and stop.is_set():
                break
            frame = source.get(0.1)
            now = time.monotonic()
            if frame is not None:
                if recorder.rows == 0 and source.sensor_ids is not None and recorder.ids is None:
                    recorder.ids = list(source.sensor_ids)
                recorder.write(frame)
                if first is None:
                    first = now
            elif source.finished:
                break
            if seconds is not None and first is not None and now - first >= seconds:
                break
            if report is not None and now - last_report >= report_interval:
                last_report = now
                st = source.status()
                report(f"{st.state}: {recorder.rows} frames written"
                       + (f", {st.missed} missed by the device" if st.missed else "")
                       + (f", {st.dropped} dropped (recorder too slow)" if st.dropped else "")
                       + (f", {st.reconnects} reconnection(s)" if st.reconnects else ""))
    except KeyboardInterrupt:
        interrupted = True
    finally:
        source.close()
        # Frames already queued when we stopped were received: they belong in the file too.
        while (frame := source.get(0)) is not None:
            recorder.write(frame)
        recorder.close()
    status = source.status()
    result = RecordResult(path=path if recorder.rows else None, head_corrected=None, frames=recorder.rows,
                          seconds=(time.monotonic() - first) if first is not None else 0.0, status=status,
                          interrupted=interrupted)
    if not recorder.rows:
        result.notes.append("no frame arrived: nothing written")
        return result
    if recorder.out_of_order:
        result.notes.append(f"{recorder.out_of_order} frames not written: their time stamps did not come after "
                            "the last row's (repeated after a reconnection, or the device's clock went back)")
    if recorder.mismatched:
        result.notes.append(f"{recorder.mismatched} frames had a different number of sensor slots than the first")
    mapping = _slot_names(source, recorder.ids, sensor_map)
    beside = False
    if mapping:
        note, beside = _save_sensor_map(path.parent, mapping, source.axes)
        result.notes.append(note)
    if head_correction:
        # The map saved beside the file also carries the axes: let the reader find it there.
        try:
            result.head_corrected, note = write_head_corrected(path, None if beside else (mapping or None))
        except TonguevisError as exc:  # the raw recording is safe; say why there is no corrected one
            note = f"no head-corrected file: {exc}"
        result.notes.append(note)
    return result


def _slot_names(source: Source, ids: list[int], sensor_map) -> dict[str, int]:
    """name -> NDI Id of the recorded slots: from ``sensor_map`` when given, else from the device's names."""
    if sensor_map is not None:
        from tonguevis.io.sensor_map import load_sensor_map

        mapping = dict(load_sensor_map(sensor_map))
        try:
            mapping = {name: int(channel) for name, channel in mapping.items()}
        except (TypeError, ValueError):
            raise RecordingError(f"sensor map {sensor_map}: NDI channels must be numbers ({mapping})") from None
        # Only the slots recorded: a name for a channel the file lacks would stop every reader.
        return {name: channel for name, channel in mapping.items() if channel in ids}
    names = source.sensor_names
    if not names or len(names) != len(ids) or all(name == f"S{i}" for name, i in zip(names, ids)):
        return {}
    return {str(name): int(i) for name, i in zip(names, ids)}


def _save_sensor_map(folder: Path, mapping: dict[str, int], axes: str | None = None) -> tuple[str, bool]:
    """Write ``sensor_map.json`` in ``folder`` unless one is there: (a note, whether the folder's map fits)."""
    target = folder / SENSOR_MAP_FILE
    content = {"description": "sensor names of live recordings (written by tonguevis record)", "format": "ndi_wave",
               **({"axes": axes} if axes else {}), "sensors": mapping}
    if target.exists():
        try:
            existing = json.loads(target.read_text(encoding="utf-8"))
            existing = existing.get("sensors", existing)
        except (OSError, ValueError):
            existing = None
        if isinstance(existing, dict) and {k: v for k, v in existing.items() if k in mapping} == mapping:
            return f"sensor names: {target} (already there)", True
        return f"sensor names not saved: {target} already exists with other names (read with --sensors)", False
    atomic_write(target, lambda tmp: tmp.write_text(json.dumps(content, indent=1) + "\n", encoding="utf-8"))
    return f"sensor names saved in {target}", True


def write_head_corrected(path, sensor_map: dict[str, int] | None = None) -> tuple[Path | None, str]:
    """Write ``NAME_headcorrected.tsv`` beside the recorded ``path`` (atomically): (its path or None, a note).

    None when the recording has fewer than three REF* head references (the note says so).
    """
    from tonguevis.io.ndi_wave import write_ndi_wave
    from tonguevis.preprocess.correction import head_corrected, head_references
    from tonguevis.workflows.recording import open_recording

    path = Path(path)
    rec = open_recording(path, sensor_map, audio=False, labels=False)
    references = head_references(rec)
    if not references:
        found = [s for s in rec.sensor_names if s.upper().startswith("REF")]
        return None, (f"no head-corrected file: {len(found)} head reference(s) "
                      f"({', '.join(found) or 'none named REF*'}); 3 are needed (name them with --sensors)")
    corrected = head_corrected(rec)
    ids = sensor_map if sensor_map else {name: int(i) for name, i in zip(rec.sensor_names, rec.metadata["ndi_ids"])}
    out = path.with_name(path.stem + HEAD_CORRECTED_SUFFIX + ".tsv")
    write_ndi_wave(corrected, out, sensor_map=ids, audio=False)
    return out, f"head-corrected ({', '.join(references)}): {out}"
