"""Figures of a discrepancy search (:func:`dtwin.identify.discover.discover`): measured vs model
spectra at each step with the residual lines marked, and the held-out gap step by step.

Functions take a :class:`dtwin.identify.discover.DiscoveryResult` and return matplotlib Figures; the
CLI (``dtwin discover``) saves them.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

__all__ = ["plot_gap_bars", "plot_step_spectra"]


def _db(a, ref):
    return 20.0 * np.log10(np.maximum(np.asarray(a), 1e-300) / ref)


def plot_step_spectra(result, step: int, *, band: tuple[float, float] | None = None,
                      unit: str = "m/s²", max_marks: int = 12) -> Figure:
    """Measured and model amplitude spectra (dB re the measured maximum) before step `step`
    (0 = the base model; ``len(result.steps)`` = the final model), residual lines marked:
    ▼ in the measurement but missing from the model, ▲ in the model only."""
    freqs, meas = result.freqs, result.measured
    model = result.models[step]
    lines = result.residuals[step]
    ref = float(np.max(meas))
    fig = Figure(figsize=(10, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(freqs, _db(meas, ref), lw=0.6, color="0.25", label="measured")
    ax.plot(freqs, _db(model, ref), lw=0.7, color="tab:orange", alpha=0.85, label="model")
    for r in lines[:max_marks]:
        y = _db(meas[r.bin] if r.side == "measured" else model[r.bin], ref)
        mk, col = ("v", "tab:red") if r.side == "measured" else ("^", "tab:blue")
        ax.plot([r.frequency], [y + 3], mk, color=col, ms=6)
        ax.annotate(r.text, (r.frequency, y + 5), fontsize=6, rotation=90, ha="center",
                    va="bottom", color=col)
    if band is not None:
        ax.set_xlim(*band)
    ax.set_ylim(max(float(np.min(_db(meas, ref))), -160), 15)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"amplitude (dB re {ref:.3g} {unit})")
    what = "base model" if step == 0 else f"after step {step} ({result.steps[step - 1].named})"
    ax.set_title(f"Measured vs {what}: ▼ missing in model, ▲ only in model")
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def plot_gap_bars(result) -> Figure:
    """Bar chart of the held-out gap (dB): the base model, then after each step."""
    labels = ["base"] + [f"+ {s.named}" for s in result.steps]
    values = [result.initial_gap.total] + [s.gap_after.total for s in result.steps]
    confirmed = [np.nan] + [s.gap_confirmed.total for s in result.steps]
    fig = Figure(figsize=(max(4.0, 1.6 * len(labels)), 3.6))
    ax = fig.add_subplot(1, 1, 1)
    x = np.arange(len(labels))
    ax.bar(x - 0.18, values, 0.36, color="tab:blue", label="held-out gap (cross-validated)")
    ax.bar(x + 0.18, confirmed, 0.36, color="tab:gray", label="full model, confirmed")
    for xi, v in zip(x, values, strict=True):
        ax.text(xi - 0.18, v, f"{v:.1f}", ha="center", va="bottom", fontsize=8)
    ax.set_xticks(x, labels, rotation=15, fontsize=8)
    ax.set_xlabel("model (base, then each effect added)")
    ax.set_ylabel("held-out gap (dB)")
    ax.set_title("Held-out gap, step by step")
    ax.legend(fontsize=7)
    return fig
