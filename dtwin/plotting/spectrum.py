"""Figures of spectra with numbered, labelled peaks (like the paper's Figures 7–9) and waveforms.

Functions take data (arrays and :class:`dtwin.spectrum.LabelledPeak` lists) and return a
matplotlib Figure; the CLI (``dtwin spectrum``) and the notebooks call the same functions.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from ..spectrum import LabelledPeak

__all__ = ["peak_table_rows", "plot_spectrum_peaks", "plot_waveform"]


def peak_table_rows(labelled: Sequence[LabelledPeak], unit: str) -> list[list[str]]:
    """Rows ``[No., f (Hz), amplitude (unit), dB over floor, label]`` of the label table."""
    return [
        [str(lp.number), f"{lp.peak.frequency:.2f}", f"{lp.peak.amplitude:.3g} {unit}",
         f"{lp.peak.above_floor_db:.1f}", lp.text]
        for lp in labelled
    ]


def plot_spectrum_peaks(
    freqs: np.ndarray,
    spec: np.ndarray,
    labelled: Sequence[LabelledPeak],
    *,
    band: tuple[float, float] | None = (450.0, 550.0),
    unit: str = "m/s²",
    db: bool = False,
    floor: np.ndarray | None = None,
    title: str = "Amplitude spectrum",
    table: bool = True,
) -> Figure:
    """Spectrum zoomed to `band` (Hz) with the peaks numbered 1, 2, … and a label table below.

    **Arguments:**

    - `freqs`, `spec`: one-sided amplitude spectrum (Hz, `unit`).
    - `labelled`: peaks from :func:`dtwin.spectrum.label_peaks` (numbered, labelled).
    - `band`: frequency range shown (Hz), None for all.
    - `db`: plot ``20 log10(spec)`` (dB re 1 `unit`) instead of the linear amplitude.
    - `floor`: noise floor to draw (same unit as `spec`), optional.
    - `table`: add the table of numbers, frequencies, amplitudes and labels.
    """
    freqs = np.asarray(freqs)
    spec = np.asarray(spec)
    sel = slice(None) if band is None else (freqs >= band[0]) & (freqs <= band[1])
    conv = (lambda v: 20 * np.log10(np.maximum(v, 1e-300))) if db else (lambda v: v)
    n_rows = len(labelled)
    fig = Figure(figsize=(9, 4.5 + (0.22 * n_rows + 0.6 if table and n_rows else 0)))
    if table and n_rows:
        gs = fig.add_gridspec(2, 1, height_ratios=[4.5, 0.22 * n_rows + 0.6], hspace=0.35)
        ax = fig.add_subplot(gs[0])
        tax = fig.add_subplot(gs[1])
    else:
        ax = fig.add_subplot(1, 1, 1)
        tax = None
    ax.plot(freqs[sel], conv(spec[sel]), lw=0.8, color="C0", label="spectrum")
    if floor is not None:
        ax.plot(freqs[sel], conv(np.asarray(floor)[sel]), lw=0.8, ls="--", color="0.5",
                label="noise floor (running median)")
    for lp in labelled:
        y = conv(lp.peak.amplitude)
        ax.plot([lp.peak.frequency], [y], "v", color="C3", ms=5)
        ax.annotate(str(lp.number), (lp.peak.frequency, y), textcoords="offset points",
                    xytext=(0, 6), ha="center", fontsize=8, color="C3")
    if labelled:
        ax.plot([], [], "v", color="C3", label="numbered peaks (see table)")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"amplitude (dB re 1 {unit})" if db else f"amplitude ({unit})")
    ax.set_title(title)
    if band is not None:
        ax.set_xlim(band)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    if tax is not None:
        tax.axis("off")
        tab = tax.table(
            cellText=peak_table_rows(labelled, unit),
            colLabels=["No.", "f (Hz)", "amplitude", "dB over floor", "label"],
            loc="upper center", cellLoc="center",
        )
        tab.auto_set_font_size(False)
        tab.set_fontsize(8)
        tab.scale(1.0, 1.15)
    return fig


def plot_waveform(
    t: np.ndarray, x: np.ndarray, *, unit: str = "m/s²", title: str = "Time waveform",
    stats: bool = True,
) -> Figure:
    """Time waveform (s, `unit`), with RMS, kurtosis and crest factor in the legend."""
    from ..indicators import time_stats

    fig = Figure(figsize=(9, 3.2))
    ax = fig.add_subplot(1, 1, 1)
    label = "signal"
    if stats:
        s = time_stats(np.asarray(x))
        label = (f"RMS {float(s.rms):.3g} {unit}, kurtosis {float(s.kurtosis):.2f}, "
                 f"crest {float(s.crest_factor):.2f}")
    ax.plot(t, x, lw=0.5, color="C0", label=label)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"amplitude ({unit})")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return fig
