"""Figures of spectra with numbered, labelled peaks (like the paper's Figures 7–9) and waveforms.

Functions take data (arrays and :class:`dtwin.signal.spectrum.LabelledPeak` lists) and return a
matplotlib Figure; the CLI (``dtwin spectrum``) and the notebooks call the same functions.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from ..signal.indicators import time_stats
from ..signal.spectrum import LabelledPeak
from .levels import level_axis, levels, place_labels, set_level_limits, unit_text

__all__ = ["drawn_points", "peak_table_rows", "plot_spectrum_peaks", "plot_waveform"]

#: Points of a curve drawn at most: two per column of a 2000-pixel-wide figure.
MAX_DRAWN = 4000


def drawn_points(x: np.ndarray, y: np.ndarray, max_points: int = MAX_DRAWN
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The points of the curve ``y(x)`` to draw: all of them up to `max_points`, else the
    minimum and the maximum of each of about ``max_points / 2`` runs of equal length, in their
    order (every extreme is drawn, so the figure looks the same at up to that many pixel
    columns). The data written next to a figure stay whole; only the drawing is thinned."""
    x, y = np.asarray(x), np.asarray(y)
    n = y.size
    if n <= max_points:
        return x, y
    k = -(-n // (max_points // 2))  # samples per run
    runs = -(-n // k)
    pad = runs * k - n
    lo = np.concatenate([np.where(np.isnan(y), np.inf, y), np.full(pad, np.inf)]).reshape(runs, k)
    hi = np.concatenate([np.where(np.isnan(y), -np.inf, y), np.full(pad, -np.inf)]).reshape(runs, k)
    start = np.arange(runs) * k
    keep = np.unique(np.concatenate([start + np.argmin(lo, axis=1), start + np.argmax(hi, axis=1)]))
    return x[keep], y[keep]


def peak_table_rows(labelled: Sequence[LabelledPeak], unit: str) -> list[list[str]]:
    """Rows ``[No., f (Hz), amplitude (unit), dB over floor, label]`` of the label table."""
    u = unit_text(unit)
    return [
        [str(lp.number), f"{lp.peak.frequency:.2f}", f"{lp.peak.amplitude:.3g} {u}",
         f"{lp.peak.above_floor_db:.1f}", lp.text]
        for lp in labelled
    ]


def plot_spectrum_peaks(
    freqs: np.ndarray,
    spec: np.ndarray,
    labelled: Sequence[LabelledPeak],
    *,
    band: tuple[float, float] | None = None,
    unit: str = "m/s^2",
    db: bool | None = None,
    scale: str | None = None,
    floor: np.ndarray | None = None,
    title: str = "Amplitude spectrum",
    table: bool = True,
    channel: str | None = None,
) -> Figure:
    """Spectrum over `band` (Hz) with the peaks numbered 1, 2, … and a label table below.

    **Arguments:**

    - `freqs`, `spec`: one-sided amplitude spectrum (Hz, `unit`).
    - `labelled`: peaks from :func:`dtwin.signal.spectrum.label_peaks` (numbered, labelled).
    - `band`: frequency range shown (Hz), None for the whole spectrum (callers pass the
      gearbox's mesh band, :func:`dtwin.plotting.levels.mesh_band`).
    - `scale`: ``"db"`` (levels in dB re the unit's ISO 1683 reference, e.g. 1 µm/s², the
      default) or ``"linear"``; `db` is the older switch (``db=False`` is ``scale="linear"``).
    - `floor`: noise floor to draw (same unit as `spec`), optional.
    - `table`: add the table of numbers, frequencies, amplitudes and labels.
    - `channel`: channel name shown in the title (several channels: one figure each).
    """
    scale = scale or ("linear" if db is False else "db")
    freqs = np.asarray(freqs)
    spec = np.asarray(spec)
    sel = np.ones(freqs.shape, bool) if band is None else (freqs >= band[0]) & (freqs <= band[1])
    n_rows = len(labelled) if table else 0
    table_h = 0.24 * n_rows + 0.5 if n_rows else 0.0
    fig = Figure(figsize=(10, 4.2 + table_h))
    if n_rows:
        gs = fig.add_gridspec(2, 1, height_ratios=[4.2, table_h], hspace=0.12 + 0.9 / (4.2 + table_h))
        ax = fig.add_subplot(gs[0])
        tax = fig.add_subplot(gs[1])
    else:
        ax = fig.add_subplot(1, 1, 1)
        tax = None
    y, _ = levels(spec[sel], unit, scale)
    ax.plot(*drawn_points(freqs[sel], y), lw=0.7, color="C0", label="spectrum")
    if floor is not None:
        ax.plot(*drawn_points(freqs[sel], levels(np.asarray(floor)[sel], unit, scale)[0]),
                lw=0.8, ls="--", color="0.5", label="noise floor (running median)")
    xs = [lp.peak.frequency for lp in labelled]
    ys = [float(levels(np.array([lp.peak.amplitude]), unit, scale)[0][0]) for lp in labelled]
    if labelled:
        ax.plot(xs, ys, "v", color="C3", ms=5, label="numbered peaks (see table)")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(level_axis("amplitude", unit, scale))
    ax.set_title(title + (f" [{channel}]" if channel else ""), pad=20)
    lo, hi = band if band is not None else (float(freqs[0]), float(freqs[-1]))
    ax.set_xlim(lo - 0.015 * (hi - lo), hi + 0.015 * (hi - lo))  # edge peaks stay readable
    set_level_limits(ax, y, scale, headroom=0.25)
    place_labels(ax, xs, ys, [str(lp.number) for lp in labelled], min_sep=0.02)
    ax.grid(alpha=0.3)
    # the legend above the plot area, clear of the peaks and their numbers
    ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.01, 1.0, 0.1), ncol=3, fontsize=8,
              frameon=False, borderaxespad=0.0)
    if tax is not None:
        tax.axis("off")
        tab = tax.table(
            cellText=peak_table_rows(labelled, unit),
            colLabels=["No.", "f (Hz)", "amplitude", "dB over floor", "label"],
            colWidths=[0.07, 0.12, 0.18, 0.14, 0.49],
            loc="upper center", cellLoc="center",
        )
        tab.auto_set_font_size(False)
        tab.set_fontsize(8)
        tab.scale(1.0, 1.15)
    return fig


def plot_waveform(
    t: np.ndarray, x: np.ndarray, *, unit: str = "m/s^2", title: str = "Time waveform",
    stats: bool = True,
) -> Figure:
    """Time waveform (s, `unit`), with RMS, kurtosis and crest factor in the legend."""
    unit = unit_text(unit)

    fig = Figure(figsize=(9, 3.2))
    ax = fig.add_subplot(1, 1, 1)
    label = "signal"
    if stats:
        s = time_stats(np.asarray(x))
        label = (f"RMS {float(s.rms):.3g} {unit}, kurtosis {float(s.kurtosis):.2f}, "
                 f"crest {float(s.crest_factor):.2f}")
    ax.plot(*drawn_points(t, x), lw=0.5, color="C0", label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"amplitude ({unit})")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return fig
