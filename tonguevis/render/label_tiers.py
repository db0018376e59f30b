"""Label tiers drawn under the waveform: one row per tier, like Praat's TextGrid editor.

Interval tiers show their boundaries as vertical ticks and each interval's
text centred between them; point tiers show a tick and the text beside it.
Texts that would not fit their interval at the current width are left out
(the boundaries stay).  Drawing only: the axes belong to the audio plot, so
the time cursor runs across the rows and a click seeks like the waveform.
"""

from __future__ import annotations

from tonguevis.io.recording import Label

TIER_COLOURS = ("#2c3e50", "#8e44ad", "#16a085", "#c0392b", "#d35400")
#: Rough width of one character of the 7-point label font, in pixels.
CHAR_PX = 5.5


def tiers(labels: list[Label]) -> list[tuple[str, list[Label], bool]]:
    """(tier name, its labels in time order, is a point tier) per tier, in order of first appearance."""
    from tonguevis.io.textgrid import is_point_tier, tier_labels, tier_names

    return [(name, tier_labels(labels, name), is_point_tier(labels, name)) for name in tier_names(labels)]


def draw_tiers(ax, labels: list[Label], time_range: tuple[float, float]) -> list:
    """Draw ``labels`` in ``ax`` (cleared by the caller): tier k in the row from y = n-k-1 to n-k.

    Returns [(text artist, interval length in s)] of the interval texts, for :func:`fit_texts`.
    """
    rows = tiers(labels)
    n = len(rows)
    start, end = time_range
    texts = []
    ax.set_ylim(0, max(n, 1))
    ax.set_yticks([n - k - 0.5 for k in range(n)])
    ax.set_yticklabels([name for name, _, _ in rows], fontsize=7)
    ax.tick_params(axis="y", length=0)
    for k in range(1, n):
        ax.axhline(k, color="#bdc3c7", lw=0.6)
    for k, (name, own, point) in enumerate(rows):
        low, high = n - k - 1, n - k
        colour = TIER_COLOURS[k % len(TIER_COLOURS)]
        middle = (low + high) / 2
        for lab in own:
            if lab.end < start or lab.start > end:
                continue
            if point:
                ax.vlines(lab.start, low + 0.1, high - 0.1, color=colour, lw=1.0)
                if lab.text:
                    ax.text(lab.start, middle, f" {lab.text}", fontsize=7, color=colour, ha="left", va="center",
                            clip_on=True)
                continue
            ax.vlines([lab.start, lab.end], low, high, color=colour, lw=0.8)
            if lab.text:
                artist = ax.text((max(lab.start, start) + min(lab.end, end)) / 2, middle, lab.text, fontsize=7,
                                 color=colour, ha="center", va="center", clip_on=True)
                texts.append((artist, lab.end - lab.start))
    return texts


def fit_texts(texts: list, px_per_second: float) -> None:
    """Show only the interval texts that fit between their boundaries at ``px_per_second``."""
    for artist, seconds in texts:
        artist.set_visible(seconds * px_per_second >= CHAR_PX * (len(artist.get_text()) + 1))
