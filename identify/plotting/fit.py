"""Figures of identification results: measured vs fitted spectrum with labelled peaks, the loss
over the solver's evaluations, and severity / parameter trajectories with 95 % intervals.

The functions take plain data (arrays, lists) and return a matplotlib Figure; the ``dtwin
identify`` / ``dtwin severity`` commands and scripts call the same functions.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from dtwin.model.registry import REGISTRY
from dtwin.plotting.levels import level_axis, levels, place_labels, set_level_limits

__all__ = ["plot_fit_spectrum", "plot_loss_history", "plot_trajectories"]


def _merge_labels(labels, f: np.ndarray, m: np.ndarray, width: float):
    """One label per line: labels closer than `width` (Hz) are one peak (its neighbouring bins);
    the one on the highest measured bin stays, a kinematic label beating "no kinematic match"."""
    out: list[tuple[float, str]] = []
    for fr, text in sorted(labels, key=lambda p: p[0]):
        if out and fr - out[-1][0] <= width:
            pf, pt = out[-1]
            better = np.interp(fr, f, m) > np.interp(pf, f, m)
            keep_text = pt if (text.startswith("no kinematic") and not pt.startswith("no kinematic")) else text
            if not better:
                keep_text = text if (pt.startswith("no kinematic") and not text.startswith("no kinematic")) else pt
            out[-1] = (fr if better else pf, keep_text)
        else:
            out.append((fr, text))
    return out


def plot_fit_spectrum(
    freqs: np.ndarray,
    measured: np.ndarray,
    fitted: np.ndarray,
    *,
    labels: Sequence[tuple[float, str]] = (),
    unit: str | None = "m/s^2",
    scale: str = "db",
    title: str = "Measured vs fitted spectrum",
) -> Figure:
    """Measured and fitted levels (noise floor included) at the fitted points, one panel per
    band (the bands around the mesh harmonics, side by side on a common level axis), peaks
    numbered and listed under the panels.

    **Arguments:** `freqs` (Hz) of the points; `measured`, `fitted` (linear, `unit`); `labels`:
    ``(frequency, text)`` of peaks to number (e.g. from :func:`dtwin.signal.spectrum.label_peaks`);
    labels on neighbouring bins of one line are merged; `scale` ``"db"`` (dB re the unit's
    ISO 1683 reference, e.g. 1 µm/s²) or ``"linear"``.
    """
    f = np.asarray(freqs, dtype=float)
    order = np.argsort(f, kind="stable")
    f, m, s = f[order], np.asarray(measured)[order], np.asarray(fitted)[order]
    df = float(np.median(np.diff(f))) if f.size > 2 else 1.0
    gaps = np.flatnonzero(np.diff(f) > 5 * df) if f.size > 2 else np.array([], int)
    bounds = list(zip([0, *list(gaps + 1)], [*list(gaps + 1), f.size], strict=True))
    merged = _merge_labels(labels, f, m, 3.5 * df)
    ym, _ = levels(m, unit, scale)
    ys, _ = levels(s, unit, scale)
    n_list = len(merged)
    rows = (n_list + 1) // 2
    list_h = 0.16 * rows + 0.3 if n_list else 0.0
    fig = Figure(figsize=(10, 4.2 + list_h))
    widths = [max(f[b - 1] - f[a], df) for a, b in bounds]
    gs = fig.add_gridspec(2 if n_list else 1, len(bounds), width_ratios=widths,
                          height_ratios=[4.2, list_h] if n_list else None, wspace=0.06,
                          hspace=0.3)
    axes = []
    for k, (a, b) in enumerate(bounds):
        ax = fig.add_subplot(gs[0, k], sharey=axes[0] if axes else None)
        ax.plot(f[a:b], ym[a:b], color="0.35", lw=0.8, label="measured" if k == 0 else None)
        ax.plot(f[a:b], ys[a:b], color="C3", lw=0.8, alpha=0.85,
                label="fitted twin" if k == 0 else None)
        ax.set_xlim(f[a] - df, f[b - 1] + df)
        ax.grid(alpha=0.3)
        ax.tick_params(axis="x", labelsize=8)
        if k:
            ax.tick_params(axis="y", labelleft=False)
        axes.append(ax)
    set_level_limits(axes[0], np.concatenate([ym, ys]), scale, headroom=0.2)
    for k, (a, b) in enumerate(bounds):
        pts = [(i, fr) for i, (fr, _) in enumerate(merged, start=1) if f[a] - df <= fr <= f[b - 1] + df]
        place_labels(axes[k], [fr for _, fr in pts],
                     [float(np.interp(fr, f, ym)) for _, fr in pts], [str(i) for i, _ in pts],
                     color="k", fontsize=7, min_sep=0.05)
    axes[0].set_ylabel(level_axis("level", unit, scale))
    fig.supxlabel("frequency (Hz)", y=(list_h + 0.35) / (4.2 + list_h) if n_list else 0.01,
                  fontsize=10)
    fig.suptitle(title)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="upper right", fontsize=8, ncol=2,
               frameon=False)
    if n_list:
        tax = fig.add_subplot(gs[1, :])
        tax.axis("off")
        lines = [f"{i:>2}: {fr:8.2f} Hz  {text}" for i, (fr, text) in enumerate(merged, start=1)]
        for c, chunk in enumerate((lines[:rows], lines[rows:])):
            tax.text(0.0 + 0.5 * c, 1.0, "\n".join(chunk), fontsize=8, va="top",
                     family="monospace", transform=tax.transAxes)
    return fig


def plot_loss_history(history: Sequence[float], *, title: str = "Loss over solver evaluations") -> Figure:
    """½‖r‖² at every residual evaluation of the solver: log scale when it spans more than a
    factor of 3, otherwise linear with the values written out (a short or flat history)."""
    h = np.asarray(history, dtype=float)
    fig = Figure(figsize=(6, 3.6))
    ax = fig.add_subplot(111)
    pos = h[np.isfinite(h) & (h > 0)]
    if pos.size > 1 and pos.max() > 3.0 * pos.min():
        ax.set_yscale("log")
    else:
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)
    ax.plot(np.arange(1, h.size + 1), h, "o-", ms=3, label="½‖r‖² (log-spectrum residuals)")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("residual evaluation (count)")
    ax.set_ylabel("loss ½‖r‖² (dimensionless)")
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3, which="both")
    return fig


def plot_trajectories(
    labels: Sequence[str],
    values: Mapping[str, np.ndarray],
    lower: Mapping[str, np.ndarray],
    upper: Mapping[str, np.ndarray],
    *,
    truth: Mapping[str, Sequence[float]] | None = None,
    title: str = "Parameter trajectories (95 % intervals)",
) -> Figure:
    """One panel per parameter: estimate and 95 % interval over the records (a degradation
    series); `truth` values drawn when known."""
    names = list(values)
    fig = Figure(figsize=(7, 2.4 * len(names) + 0.6))
    x = np.arange(len(labels))
    for k, n in enumerate(names):
        ax = fig.add_subplot(len(names), 1, k + 1)
        v, lo, hi = (np.asarray(values[n]), np.asarray(lower[n]), np.asarray(upper[n]))
        ax.errorbar(x, v, yerr=[v - lo, hi - v], fmt="o-", capsize=3, label="estimate")
        if truth and n in truth:
            ax.plot(x, truth[n], "k_", ms=14, label="truth")
        ax.set_ylabel(f"{n} ({_unit(n)})")
        ax.grid(alpha=0.3)
        if k == 0:
            ax.set_title(title)
            ax.legend(loc="best", fontsize=8)
        ax.set_xticks(x, list(labels) if k == len(names) - 1 else [""] * len(x))
    ax.set_xlabel("record")
    return fig


def _unit(name: str) -> str:
    """The registry's unit of parameter `name` ("1" for dimensionless; "?" if unknown)."""

    info = REGISTRY.get(name)
    return "?" if info is None else ("dimensionless" if info.unit == "1" else info.unit)
