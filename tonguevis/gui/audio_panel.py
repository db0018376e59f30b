"""The sound: waveform and spectrogram with the shared cursor."""

from __future__ import annotations

import numpy as np
from scipy.signal import spectrogram

from tonguevis.appstate import AppState
from tonguevis.gui.timeplot import TimePlot

#: Waveform drawn as a min/max envelope over this many bins (fast at any length).
ENVELOPE_BINS = 3000
SPECTROGRAM_MAX_HZ = 8000.0


def envelope(samples: np.ndarray, rate: float, offset: float, bins: int = ENVELOPE_BINS):
    """(times (B,), low (B,), high (B,)): min and max of ``samples`` per bin."""
    n = len(samples)
    per_bin = max(1, n // bins)
    usable = (n // per_bin) * per_bin
    blocks = samples[:usable].reshape(-1, per_bin)
    times = offset + (np.arange(len(blocks)) + 0.5) * per_bin / rate
    return times, blocks.min(axis=1), blocks.max(axis=1)


class AudioPlot(TimePlot):
    def __init__(self, state: AppState, parent=None):
        super().__init__(state, parent, height=1.8)
        self.wave_ax, self.spec_ax = self.figure.subplots(2, 1, sharex=True, height_ratios=[1, 1.3])
        self.set_time_axes([self.wave_ax, self.spec_ax])

    def show_audio(self, audio, time_range: tuple[float, float], productions=()) -> None:
        for ax in (self.wave_ax, self.spec_ax):
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
            f, st, power = spectrogram(samples, fs=audio.rate, nperseg=nperseg, noverlap=nperseg // 2)
            keep = f <= min(SPECTROGRAM_MAX_HZ, audio.rate / 2)
            db = 10 * np.log10(power[keep] + 1e-12)
            top = float(np.max(db))
            self.spec_ax.imshow(db, origin="lower", aspect="auto", cmap="Greys", vmin=top - 70, vmax=top,
                                extent=(audio.offset + st[0], audio.offset + st[-1], f[keep][0] / 1e3,
                                        f[keep][-1] / 1e3), interpolation="nearest")
            self.spec_ax.set_ylabel("frequency\n(kHz)", fontsize=8)
        for start, end in productions:
            for ax in (self.wave_ax, self.spec_ax):
                ax.axvline(start, color="#2980b9", lw=0.6, ls="--")
        self.spec_ax.set_xlabel("time (s)", fontsize=8)
        self.wave_ax.set_xlim(*time_range)
        self.set_time_axes([self.wave_ax, self.spec_ax])
        self.draw_idle()
