"""Figures of identification results: measured vs fitted spectrum with labelled peaks, the loss
over the solver's evaluations, and severity / parameter trajectories with 95 % intervals.

The functions take plain data (arrays, lists) and return a matplotlib Figure; the ``dtwin
identify`` / ``dtwin severity`` commands and scripts call the same functions.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

__all__ = ["plot_fit_spectrum", "plot_loss_history", "plot_trajectories"]


def _db(a):
    return 20 * np.log10(np.maximum(np.asarray(a, dtype=float), 1e-300))


def plot_fit_spectrum(
    freqs: np.ndarray,
    measured: np.ndarray,
    fitted: np.ndarray,
    *,
    labels: Sequence[tuple[float, str]] = (),
    unit: str = "m/s²",
    title: str = "Measured vs fitted spectrum",
) -> Figure:
    """Measured and fitted levels (dB re 1 `unit`, noise floor included) at the fitted points.

    **Arguments:** `freqs` (Hz) of the points (bands around the mesh harmonics: drawn band by
    band, gaps between bands left open); `measured`, `fitted` (linear); `labels`: ``(frequency,
    text)`` of peaks to number (e.g. from :func:`dtwin.spectrum.label_peaks`), listed under
    the plot.
    """
    f = np.asarray(freqs, dtype=float)
    fig = Figure(figsize=(10, 4.8 + 0.2 * len(labels)))
    ax = fig.add_subplot(111)
    order = np.argsort(f, kind="stable")
    f, m, s = f[order], np.asarray(measured)[order], np.asarray(fitted)[order]
    gaps = np.flatnonzero(np.diff(f) > 5 * np.median(np.diff(f)) if f.size > 2 else [])
    start = 0
    for k, end in enumerate(list(gaps + 1) + [f.size]):
        ax.plot(f[start:end], _db(m[start:end]), color="0.35", lw=0.8,
                label="measured" if k == 0 else None)
        ax.plot(f[start:end], _db(s[start:end]), color="C3", lw=0.8, alpha=0.85,
                label="fitted twin" if k == 0 else None)
        start = end
    lines = []
    for i, (fr, text) in enumerate(labels, start=1):
        y = _db(np.interp(fr, f, m))
        ax.annotate(str(i), (fr, y), textcoords="offset points", xytext=(0, 6), ha="center",
                    fontsize=7)
        lines.append(f"{i}: {fr:.1f} Hz  {text}")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"level (dB re 1 {unit})")
    ax.set_title(title)
    ax.legend(loc="upper right")
    ax.grid(alpha=0.3)
    if lines:
        fig.text(0.01, 0.01, "\n".join(lines), fontsize=7, va="bottom", family="monospace")
        fig.subplots_adjust(bottom=0.12 + 0.035 * len(lines))
    return fig


def plot_loss_history(history: Sequence[float], *, title: str = "Loss over solver evaluations") -> Figure:
    """½‖r‖² at every residual evaluation of the solver (log scale)."""
    h = np.asarray(history, dtype=float)
    fig = Figure(figsize=(6, 3.6))
    ax = fig.add_subplot(111)
    ax.semilogy(np.arange(1, h.size + 1), h, "o-", ms=3, label="½‖r‖² (log-spectrum residuals)")
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
    from dtwin.registry import REGISTRY

    info = REGISTRY.get(name)
    return "?" if info is None else ("dimensionless" if info.unit == "1" else info.unit)
