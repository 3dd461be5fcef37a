"""Figures of a calibration (:func:`dtwin.identify.calibrate.calibrate`): measured against the
twin before and after calibration, and the held-out gap per band."""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from dtwin.signal.spectrum import noise_floor

__all__ = ["plot_calibration_spectra", "plot_calibration_gap"]


def plot_calibration_spectra(result, unit: str = "record unit"):
    """Amplitude spectra in dB (re 1 `unit`) of the first record half: measured, the user's twin
    (best single gain) and the calibrated twin simulated in full, with the noise floor."""
    f = result.freqs
    a_m = result.a_meas[0]
    floor = noise_floor(a_m, 31)

    def db(a):
        return 20.0 * np.log10(np.maximum(a, 1e-12 * np.max(a_m)))

    fig, axes = plt.subplots(2, 1, figsize=(11, 7), sharex=True, constrained_layout=True)
    for ax, a, name in ((axes[0], result.a_before[0], "spec as written (one gain)"),
                        (axes[1], result.a_after[0], "calibrated twin (full simulation)")):
        ax.plot(f, db(a_m), color="0.35", lw=0.8, label="measured")
        ax.plot(f, db(a), color="C3", lw=0.9, alpha=0.85, label=name)
        ax.plot(f, db(floor), color="C2", lw=0.8, ls="--", label="measured noise floor")
        top = max(db(a_m).max(), db(a).max())
        ax.set_ylim(db(floor).min() - 10.0, top + 8.0)
        ax.set_ylabel(f"amplitude (dB re 1 {unit})")
        ax.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"calibration on {', '.join(result.records)}: gap "
                      f"{result.gap_before.total:.1f} dB before, "
                      f"{result.gap_confirmed.total:.1f} dB calibrated")
    axes[1].set_xlabel("frequency (Hz)")
    axes[1].set_xlim(0.0, f[-1])
    return fig


def plot_calibration_gap(result):
    """The gap per named band (dB): before, cross-validated (held-out halves) and confirmed."""
    names = [n for n in result.gap_confirmed.bands if result.gap_confirmed.counts.get(n, 0) or
             result.gap_before.counts.get(n, 0)]
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(9, 4), constrained_layout=True)
    for i, (g, lab) in enumerate(((result.gap_before, "before"),
                                  (result.gap_heldout, "held-out (cross-validated)"),
                                  (result.gap_confirmed, "calibrated, full simulation"))):
        vals = [g.bands.get(n, 0.0) for n in names]
        bars = ax.bar(x + (i - 1) * 0.27, vals, 0.27, label=lab)
        ax.bar_label(bars, fmt="%.1f", fontsize=7)
    ax.set_xticks(x, names)
    ax.set_ylabel("gap (dB)")
    ax.set_ylim(0.0, None)
    ax.legend(fontsize=8)
    ax.grid(axis="y", alpha=0.3)
    return fig
