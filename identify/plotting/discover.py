"""Figures of a discrepancy search (:func:`dtwin.identify.discover.discover`): measured vs model
spectra at each step with the residual lines marked, and the held-out gap step by step.

Functions take a :class:`dtwin.identify.discover.DiscoveryResult` and return matplotlib Figures; the
CLI (``dtwin discover``) saves them.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from dtwin.plotting.levels import level_axis, levels, place_labels, set_level_limits

__all__ = ["plot_gap_bars", "plot_step_spectra"]


def plot_step_spectra(result, step: int, *, band: tuple[float, float] | None = None,
                      unit: str = "m/s^2", max_marks: int = 12, scale: str = "db") -> Figure:
    """Measured and model amplitude spectra before step `step` (0 = the base model;
    ``len(result.steps)`` = the final model), residual lines marked: ▼ in the measurement but
    missing from the model, ▲ in the model only; their labels are lifted apart where they would
    overlap.

    **Arguments:** `band` (Hz, default the whole spectrum), `unit` of the record, `scale`
    ``"db"`` (dB re the unit's ISO 1683 reference, e.g. 1 µm/s²) or ``"linear"``, `max_marks`
    residual lines marked (largest first)."""
    freqs, meas = np.asarray(result.freqs), np.asarray(result.measured)
    model = np.asarray(result.models[step])
    lines = result.residuals[step]
    sel = np.ones(freqs.shape, bool) if band is None else (freqs >= band[0]) & (freqs <= band[1])
    ym, _ = levels(meas[sel], unit, scale)
    yo, _ = levels(model[sel], unit, scale)
    fig = Figure(figsize=(10, 4.6))
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(freqs[sel], ym, lw=0.6, color="0.25", label="measured")
    ax.plot(freqs[sel], yo, lw=0.7, color="tab:orange", alpha=0.85, label="model")
    lo, hi = (float(freqs[sel][0]), float(freqs[sel][-1])) if band is None else band
    ax.set_xlim(lo, hi)
    set_level_limits(ax, np.concatenate([ym, yo]), scale, headroom=0.35)
    shown = sorted([r for r in lines if lo <= r.frequency <= hi][:max_marks],
                   key=lambda r: r.frequency)
    number = {id(r): k for k, r in enumerate(shown, start=1)}
    for side, mk, col in (("measured", "v", "tab:red"), ("model", "^", "tab:blue")):
        rs = [r for r in shown if (r.side == "measured") == (side == "measured")]
        if not rs:
            continue
        src = meas if side == "measured" else model
        ys = [float(levels(np.array([src[r.bin]]), unit, scale)[0][0]) for r in rs]
        ax.plot([r.frequency for r in rs], ys, mk, color=col, ms=6, linestyle="none",
                label="in the measurement, missing in the model" if side == "measured"
                else "in the model only")
        place_labels(ax, [r.frequency for r in rs], ys, [str(number[id(r)]) for r in rs],
                     color=col, fontsize=7, min_sep=0.012)
    if shown:  # the numbered lines' descriptions under the plot, two columns
        entries = [f"{number[id(r)]:>2} {'▼' if r.side == 'measured' else '▲'} "
                   f"{r.frequency:8.2f} Hz  {r.text}" for r in shown]
        half = (len(entries) + 1) // 2
        for c, chunk in enumerate((entries[:half], entries[half:])):
            fig.text(0.06 + 0.48 * c, 0.0, "\n".join(chunk), fontsize=7, va="top",
                     family="monospace")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(level_axis("amplitude", unit, scale))
    what = "base model" if step == 0 else f"after step {step} ({result.steps[step - 1].named})"
    ax.set_title(f"Measured vs {what}", pad=20)
    ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.01, 1.0, 0.1), ncol=4, fontsize=8,
              frameon=False, borderaxespad=0.0)
    ax.grid(alpha=0.3)
    return fig


def plot_gap_bars(result) -> Figure:
    """Bar chart of the held-out gap (dB): the base model, then after each step — the gap as
    reported (:attr:`DiscoveryResult.initial_gap`, each step's ``heldout_after``) beside the
    search's (bins `threshold_db` over the floor; each step's twin simulated in full)."""
    labels = ["base"] + [f"+ {s.named}" for s in result.steps]
    values = [result.initial_gap.total] + [
        np.nan if s.heldout_after is None else s.heldout_after.total for s in result.steps]
    search = ([result.steps[0].gap_before.total] if result.steps else [np.nan]) + [
        s.gap_confirmed.total for s in result.steps]
    fig = Figure(figsize=(max(4.0, 1.6 * len(labels)), 3.6))
    ax = fig.add_subplot(1, 1, 1)
    x = np.arange(len(labels))
    ax.bar(x - 0.18, values, 0.36, color="tab:blue", label="held-out gap (cross-validated)")
    ax.bar(x + 0.18, search, 0.36, color="tab:gray",
           label=f"the search's (bins {result.settings.threshold_db:g} dB over the floor)")
    for xi, v in zip(x, values, strict=True):
        ax.text(xi - 0.18, v, f"{v:.1f}", ha="center", va="bottom", fontsize=8)
    ax.set_xticks(x, labels, rotation=15, fontsize=8)
    ax.set_xlabel("model (base, then each effect added)")
    ax.set_ylabel("held-out gap (dB)")
    ax.set_title("Held-out gap, step by step")
    ax.legend(fontsize=7)
    return fig
