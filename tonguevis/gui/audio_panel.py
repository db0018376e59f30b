"""The sound: waveform and spectrogram with the shared cursor, the productions and their
gesture landmarks over them, and the label tiers under them."""

from __future__ import annotations

import numpy as np
from scipy.signal import spectrogram

from tonguevis.appstate import AppState, connected
from tonguevis.render.label_tiers import draw_tiers, fit_texts, tiers
from tonguevis.gui.timeplot import TimePlot
from tonguevis.render.production_marks import mark_landmarks, shade_productions

#: Waveform drawn as a min/max envelope over this many bins (fast at any length).
ENVELOPE_BINS = 3000
SPECTROGRAM_MAX_HZ = 8000.0
#: Most spectrogram columns computed (a long recording's are spread evenly over it).
SPECTROGRAM_COLUMNS = 4000
#: Height of one label tier's row relative to the waveform's axes.
TIER_ROW_RATIO = 0.3
#: Minimum heights (px) of the plot without tiers and with them (base + per tier), so the
#: waveform and spectrogram keep their room when rows are added.
MIN_HEIGHT, MIN_HEIGHT_WITH_TIERS, MIN_HEIGHT_PER_TIER = 110, 200, 26
#: Height (px) of the one line that says a recording has no sound (and no label tiers to show).
SILENT_HEIGHT = 22
SILENT_TEXT = "no sound in this recording"
_ANY_HEIGHT = 16777215  # Qt's QWIDGETSIZE_MAX


def envelope(samples: np.ndarray, rate: float, offset: float, bins: int = ENVELOPE_BINS):
    """(times (B,), low (B,), high (B,)): min and max of ``samples`` per bin."""
    n = len(samples)
    per_bin = max(1, n // bins)
    usable = (n // per_bin) * per_bin
    blocks = samples[:usable].reshape(-1, per_bin)
    times = offset + (np.arange(len(blocks)) + 0.5) * per_bin / rate
    return times, blocks.min(axis=1), blocks.max(axis=1)


def bounded_spectrogram(samples: np.ndarray, rate: float, nperseg: int, columns: int = SPECTROGRAM_COLUMNS):
    """(frequencies (k,), times (c,), power (k, c)): scipy's spectrogram with half-overlapping windows,
    or, when that would make more than ``columns`` of them (a long recording: 30 minutes of 16 kHz
    sound is 225,000 windows and a GB of temporaries), ``columns`` windows spread evenly over the sound."""
    step = nperseg - nperseg // 2
    if (len(samples) - nperseg) // step + 1 <= columns or len(samples) < nperseg:
        return spectrogram(samples, fs=rate, nperseg=nperseg, noverlap=nperseg // 2)
    starts = np.round(np.linspace(0, len(samples) - nperseg, columns)).astype(np.int64)
    return np.fft.rfftfreq(nperseg, 1.0 / rate), (starts + nperseg / 2) / rate, window_power(samples, starts, rate,
                                                                                           nperseg)


def window_power(samples: np.ndarray, starts: np.ndarray, rate: float, nperseg: int) -> np.ndarray:
    """(k, c) power spectral density of the windows starting at ``starts``, scaled as scipy's
    spectrogram scales its own (Tukey window, constant detrend, one-sided density)."""
    from scipy.signal import get_window

    window = get_window(("tukey", 0.25), nperseg)  # scipy.signal.spectrogram's default
    segments = np.asarray(samples[starts[:, None] + np.arange(nperseg)], dtype=np.float64)
    segments = (segments - segments.mean(axis=1, keepdims=True)) * window
    power = np.abs(np.fft.rfft(segments, axis=1)) ** 2 / (rate * (window ** 2).sum())
    power[:, 1:-1 if nperseg % 2 == 0 else None] *= 2
    return power.T


class AudioPlot(TimePlot):
    """Waveform and spectrogram; with labels, a third axes ``tiers_ax`` holds one row per tier."""

    def __init__(self, state: AppState, parent=None):
        super().__init__(state, parent, height=1.8)
        self.tiers_ax = None
        self.n_tiers = 0
        self.silent = False  # True: one thin line saying there is no sound, instead of two empty plots
        self._tier_texts: list = []
        self._time_range = (0.0, 1.0)
        self._marks: list = []  # the productions' artists, replaced when they are corrected
        self._layout(0)
        connected(state.events.productions, self._on_productions)
        connected(state.events.session, self._on_session)

    def _layout(self, n_tiers: int) -> None:
        """(Re)make the axes: waveform, spectrogram and, when there are tiers, their rows."""
        self.figure.clear()
        self.figure.set_layout_engine("constrained")
        self.silent = False
        self.setMaximumHeight(_ANY_HEIGHT)
        if n_tiers:
            self.wave_ax, self.spec_ax, self.tiers_ax = self.figure.subplots(
                3, 1, sharex=True, height_ratios=[1, 1.3, TIER_ROW_RATIO * n_tiers])
        else:
            self.wave_ax, self.spec_ax = self.figure.subplots(2, 1, sharex=True, height_ratios=[1, 1.3])
            self.tiers_ax = None
        self.n_tiers = n_tiers
        self.setMinimumHeight(MIN_HEIGHT_WITH_TIERS + MIN_HEIGHT_PER_TIER * n_tiers if n_tiers else MIN_HEIGHT)
        self.set_time_axes(self.time_axes)

    def _layout_silent(self) -> None:
        """One thin line saying there is no sound: the waveform and spectrogram axes exist (the
        productions are marked on them as ever) but are hidden, and take no room."""
        self.figure.clear()
        self.figure.set_layout_engine("none")  # nothing to lay out: no "collapsed to zero" warning
        self.wave_ax, self.spec_ax = self.figure.subplots(2, 1, sharex=True)
        self.tiers_ax = None
        for ax in (self.wave_ax, self.spec_ax):
            ax.set_visible(False)
        self.figure.text(0.5, 0.5, SILENT_TEXT, ha="center", va="center", fontsize=8, color="#5f6b6d")
        self.n_tiers = 0
        self.silent = True
        self.setMinimumHeight(SILENT_HEIGHT)
        self.setMaximumHeight(SILENT_HEIGHT)
        self.set_time_axes([])

    @property
    def time_axes(self) -> list:
        if self.silent:
            return []
        return [ax for ax in (self.wave_ax, self.spec_ax, self.tiers_ax) if ax is not None]

    def show_audio(self, audio, time_range: tuple[float, float], productions=(), labels=(), landmarks=()) -> None:
        """Draw ``audio`` over ``time_range`` (s), the productions (shaded, starts dashed) with
        their ``landmarks`` (GestureLandmarks) along the waveform's top, and the label tiers of
        ``labels`` (a list of :class:`~tonguevis.io.Label`) in rows below."""
        labels = list(labels or ())
        n_tiers = len(tiers(labels))
        no_sound = audio is None or len(audio.samples) == 0
        if no_sound and not n_tiers:
            self._layout_silent()
            self._time_range = (float(time_range[0]), float(time_range[1]))
            self._marks = []
            self.show_productions(productions, landmarks, draw=False)
            self.wave_ax.set_xlim(*time_range)
            self.draw_idle()
            return
        if n_tiers != self.n_tiers or self.silent:
            self._layout(n_tiers)
        self._time_range = (float(time_range[0]), float(time_range[1]))
        self._tier_texts = []
        for ax in self.time_axes:
            ax.clear()
            ax.tick_params(labelsize=7)
        if audio is None or len(audio.samples) == 0:
            self.wave_ax.text(0.5, 0.5, "no audio in this recording", ha="center", va="center",
                              transform=self.wave_ax.transAxes, color="#7f8c8d")
        else:
            samples = np.asarray(audio.samples, dtype=np.float64)
            t, low, high = envelope(samples, audio.rate, audio.offset)
            self.wave_ax.fill_between(t, low, high, color="#34495e", lw=0)
            self.wave_ax.set_ylabel("sound\n(amplitude)", fontsize=8)
            peak = float(np.max(np.abs(samples))) or 1.0
            self.wave_ax.set_ylim(-peak * 1.05, peak * 1.05)
            # Spectrogram: 25 ms windows; cheap even for minutes of 44.1 kHz audio.
            nperseg = int(2 ** np.floor(np.log2(0.025 * audio.rate)))  # ≤ 25 ms: formants and bursts show
            f, st, power = bounded_spectrogram(samples, audio.rate, nperseg)
            keep = f <= min(SPECTROGRAM_MAX_HZ, audio.rate / 2)
            db = 10 * np.log10(power[keep] + 1e-12)
            top = float(np.max(db))
            self.spec_ax.imshow(db, origin="lower", aspect="auto", cmap="Greys", vmin=top - 70, vmax=top,
                                extent=(audio.offset + st[0], audio.offset + st[-1], f[keep][0] / 1e3,
                                        f[keep][-1] / 1e3), interpolation="nearest")
            self.spec_ax.set_ylabel("frequency\n(kHz)", fontsize=8)
        self._marks = []
        self.show_productions(productions, landmarks, draw=False)
        bottom = self.spec_ax
        if self.tiers_ax is not None:
            self._tier_texts = draw_tiers(self.tiers_ax, labels, self._time_range)
            self._fit_tier_texts()
            bottom = self.tiers_ax
        bottom.set_xlabel("time (s)", fontsize=8)
        self.wave_ax.set_xlim(*time_range)
        self.set_time_axes(self.time_axes)
        self.draw_idle()

    def show_productions(self, productions, landmarks=(), draw: bool = True) -> None:
        """Replace the productions' marks: shaded spans over the waveform and spectrogram, the
        gesture landmarks along the waveform's top."""
        for artist in self._marks:
            artist.remove()
        self._marks = []
        for ax in (self.wave_ax, self.spec_ax):
            self._marks += shade_productions(ax, productions, alpha=0.08)
        if landmarks:
            self._marks += mark_landmarks(self.wave_ax, landmarks, size=5.0)
        if draw:
            self.draw_idle()

    def _on_session(self, event) -> None:
        """A recording opened in the primary slot: its sound, productions, landmarks and labels."""
        session = event.value
        if event.key != "primary" or session is None:
            return
        start, end, _period = session.time_range
        table = session.production_table
        self.show_audio(session.recording.audio, (start, end), session.productions, session.recording.labels,
                        list(getattr(table, "landmarks", []) or []))

    def _on_productions(self, event) -> None:
        if event.key == "primary":
            table = event.value.production_table
            self.show_productions(event.value.productions, list(getattr(table, "landmarks", []) or []))

    def _fit_tier_texts(self) -> None:
        """Hide the interval texts wider than their interval at the plot's present width."""
        if not self._tier_texts:
            return
        start, end = self._time_range
        width_px = self.figure.get_figwidth() * self.figure.dpi * 0.85  # the axes span ~85 % of the figure
        fit_texts(self._tier_texts, width_px / max(end - start, 1e-9))

    def resizeEvent(self, event) -> None:  # noqa: N802 (Qt name)
        super().resizeEvent(event)  # resizes the figure and redraws
        self._fit_tier_texts()
