"""Playback: a clock, and a timer that moves the AppState to the clock's time.

During playback the clock *is* the audio device: the time shown is the
recording time of the sample the sink has consumed, so the picture cannot
drift from the sound (frames are skipped if drawing is slow, never delayed).
Slower speeds play the audio slowed down (resampled, lower pitch, like a
tape) and map its clock back to recording time.  Without an audio device,
or without audio, playback runs silently on a wall clock and says so.
"""

from __future__ import annotations


import numpy as np
from PySide6.QtCore import QBuffer, QByteArray, QElapsedTimer, QIODevice, QObject, Qt, QTimer, Signal

from tonguevis.appstate import AppState, Event, connected

TICK_MS = 15
PAD_S = 0.3
#: An audio clock that has not moved for this long (device stalled, e.g. a virtual
#: sink under load) is replaced by the wall clock so the picture never freezes.
STALL_S = 0.6
#: Before its first sample plays, a device may take longer (stream set-up): the picture
#: waits for the sound that long.
STARTUP_S = 2.0


class WallClock:
    """Recording time = start + elapsed wall time × speed."""

    kind = "wall"

    def __init__(self):
        self._timer = QElapsedTimer()
        self._start, self._speed = 0.0, 1.0

    def start(self, t0: float, t1: float, speed: float) -> None:
        self._start, self._speed = t0, speed
        self._timer.start()

    def time(self) -> float:
        return self._start + self._timer.nsecsElapsed() * 1e-9 * self._speed

    def exhausted(self) -> bool:
        return False

    def stop(self) -> None:
        pass


def audio_output_available() -> bool:
    try:
        from PySide6.QtMultimedia import QMediaDevices
    except ImportError:  # e.g. libpulse missing: QtMultimedia cannot load
        return False
    return not QMediaDevices.defaultAudioOutput().isNull()


def pcm16(samples: np.ndarray, rate: float, t0: float, t1: float, offset: float, speed: float) -> bytes:
    """Mono int16 PCM of the recording's audio from t0 to t1 (s), slowed by ``speed``
    (resampled by linear interpolation to 1/speed times as many samples)."""
    first = int(max(0, round((t0 - offset) * rate)))
    last = int(min(len(samples), round((t1 - offset) * rate)))
    part = np.asarray(samples[first:last], dtype=np.float64)
    if speed != 1.0 and len(part) > 1:
        n_out = int(len(part) / speed)
        part = np.interp(np.arange(n_out) * speed, np.arange(len(part)), part)
    return (np.clip(part, -1.0, 1.0) * 32767).astype("<i2").tobytes()


class AudioClock:
    """Plays the audio from t0 on the default output; its time is the sink's position."""

    kind = "audio"

    def __init__(self, audio, parent: QObject):
        from PySide6.QtMultimedia import QAudioFormat, QAudioSink, QMediaDevices

        self.audio = audio
        self.rate = int(round(audio.rate))
        fmt = QAudioFormat()
        fmt.setSampleRate(self.rate)
        fmt.setChannelCount(1)
        fmt.setSampleFormat(QAudioFormat.SampleFormat.Int16)
        device = QMediaDevices.defaultAudioOutput()
        if not device.isFormatSupported(fmt):
            raise RuntimeError(f"audio device cannot play {self.rate} Hz mono 16-bit")
        self.sink = QAudioSink(device, fmt, parent)
        self.buffer = QBuffer(parent)
        self._start, self._speed = 0.0, 1.0

    def start(self, t0: float, t1: float, speed: float) -> None:
        self.stop()
        self._start, self._speed = t0, speed
        # Trailing silence keeps the sink (and so its clock) running past the slice's end,
        # so the end is reached by time, not by a sink that stopped consuming.
        pcm = pcm16(self.audio.samples, self.rate, t0, t1, self.audio.offset, speed)
        self.buffer.setData(QByteArray(pcm + bytes(2 * int(PAD_S * self.rate))))
        self.buffer.open(QIODevice.OpenModeFlag.ReadOnly)
        self.sink.start(self.buffer)

    def time(self) -> float:
        return self._start + self.sink.processedUSecs() * 1e-6 * self._speed

    def exhausted(self) -> bool:
        """True once the sink has played all it was given (its clock then stops)."""
        from PySide6.QtMultimedia import QAudio

        return self.sink.state() == QAudio.State.IdleState

    def stop(self) -> None:
        self.sink.stop()
        if self.buffer.isOpen():
            self.buffer.close()


class PlaybackController(QObject):
    """Drives ``state.time`` from a clock while ``state.playing``.

    ``status(str)`` says which clock runs (shown in the status bar).
    """

    status = Signal(str)

    def __init__(self, state: AppState, parent: QObject):
        super().__init__(parent)
        self.state = state
        self.audio = None
        self.clock = None
        self._audio_clock = None  # made once per recording: opening the device takes ~1 s
        self.timer = QTimer(self)
        self.timer.setTimerType(Qt.TimerType.PreciseTimer)
        self.timer.setInterval(TICK_MS)
        self.timer.timeout.connect(self.tick)
        self.ticks = 0
        self._last_clock_time = 0.0
        self._advanced = False
        self._last_advance = QElapsedTimer()
        connected(state.events.playing, self._on_playing)
        connected(state.events.speed, self._restart_if_playing)
        connected(state.events.loop, self._restart_if_playing)
        connected(state.events.time, self._on_time)
        connected(state.events.session, self._on_session)

    def _on_session(self, event) -> None:
        """A recording opened in the primary slot: its sound is what plays."""
        if event.key == "primary" and event.value is not None:
            self.set_audio(event.value.recording.audio)

    def set_audio(self, audio) -> None:
        self.state.set_playing(False)
        self.audio = audio if audio is not None and len(audio.samples) else None
        if self._audio_clock is not None:
            self._audio_clock.stop()
        self._audio_clock = None

    def _make_clock(self):
        if self.audio is None:
            return WallClock(), "no audio in this recording: playing on the wall clock"
        if not audio_output_available():
            return WallClock(), "no audio output device: playing silently on the wall clock"
        try:
            if self._audio_clock is None:
                self._audio_clock = AudioClock(self.audio, self)
            return self._audio_clock, "playing with sound (audio clock)"
        except (RuntimeError, ImportError) as exc:
            return WallClock(), f"audio unavailable ({exc}): playing silently on the wall clock"

    def _on_playing(self, event: Event) -> None:
        if event.value:
            start, end = self.state.playback_bounds()
            if not (start <= self.state.time < end - 0.5 * self.state.frame_period):
                self.state.set_time(start, source=self)
            self._start_clock()
            self.timer.start()
        else:
            self.timer.stop()
            if self.clock is not None:
                self.clock.stop()

    def _start_clock(self) -> None:
        if self.clock is not None:
            self.clock.stop()
        self.clock, message = self._make_clock()
        self.clock.start(self.state.time, self.state.playback_bounds()[1], self.state.speed)
        self._last_clock_time = self.clock.time()
        self._advanced = False
        self._last_advance.start()
        self.status.emit(message)

    def _check_stall(self, t: float) -> float:
        """Switch to the wall clock if the audio clock stopped advancing; returns the time to show."""
        if t != self._last_clock_time:
            self._advanced = True
            self._last_clock_time = t
            self._last_advance.start()
            return t
        patience = STARTUP_S if not self._advanced else STALL_S
        if self.clock.kind == "audio" and self._last_advance.elapsed() > 1000 * patience:
            self.clock.stop()
            self.clock = WallClock()
            self.clock.start(self.state.time, self.state.playback_bounds()[1], self.state.speed)
            self.status.emit("the audio device stalled: playing silently on the wall clock")
            return self.clock.time()
        return t

    def _restart_if_playing(self, _event: Event) -> None:
        if self.state.playing:
            self._start_clock()

    def _on_time(self, event: Event) -> None:
        # A seek by the user while playing: continue from there.
        if self.state.playing and event.source is not self:
            self._start_clock()

    def tick(self) -> None:
        if self.clock is None:
            return
        self.ticks += 1
        start, end = self.state.playback_bounds()
        t = self._check_stall(self.clock.time())
        # The audio slice ends at `end` to within a sample, and an emptied sink stops its
        # clock: half a frame early, or an idle sink, counts as the end.
        if t >= end - 0.5 * self.state.frame_period or self.clock.exhausted():
            if self.state.loop is not None:
                self.state.set_time(start, source=self)
                self._start_clock()
                return
            self.state.set_time(end, source=self)
            self.state.set_playing(False, source=self)
            return
        self.state.set_time(t, source=self)

    def shutdown(self) -> None:
        self.timer.stop()
        if self.clock is not None:
            self.clock.stop()
