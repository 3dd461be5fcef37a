"""Figures of the traditional-versus-coupled comparison (the paper's Figure 15).

Functions take a :class:`dtwin.report.drive_comparison.DriveComparison` or
:class:`dtwin.report.drive_comparison.SensitivitySweep` and return a matplotlib `Figure`; the CLI
(``dtwin compare-drives``) and notebooks call the same functions.
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from ..plotting.levels import unit_text
from .drive_comparison import MODELS, DriveComparison, SensitivitySweep

__all__ = ["plot_drive_comparison", "plot_sensitivity", "plot_sensitivity_sweep"]

_COLOURS = {"traditional": "tab:gray", "coupled": "tab:blue"}
_STYLES = {"traditional": "s--", "coupled": "o-"}
_LABELS = {"traditional": "traditional (ideal speed source)", "coupled": "twin with PMSM drive"}


def plot_drive_comparison(cmp: DriveComparison, *, title: str | None = None) -> Figure:
    """Figure 15 side by side: RMS versus sun missing-tooth severity for both models.

    Left: RMS of the sensor signal (grouped bars, the paper's presentation), one group per
    severity. Right: the rise of the RMS over the healthy (first) severity, in per cent, so that
    the two models' sensitivities compare directly.

    **Arguments:** `cmp` (from :func:`dtwin.report.drive_comparison.compare_drives`), `title` (default: spec and
    model kind). **Returns:** the `Figure`.
    """
    s = np.asarray(cmp.severities)
    fig = Figure(figsize=(11, 4.2))
    ax1, ax2 = fig.subplots(1, 2)
    width = 0.8 * (np.min(np.diff(s)) if s.size > 1 else 0.5) / len(MODELS)
    for k, m in enumerate(MODELS):
        off = (k - (len(MODELS) - 1) / 2) * width
        ax1.bar(s + off, cmp.rms[m], width=width, color=_COLOURS[m], label=_LABELS[m])
        ax2.plot(s, 100.0 * cmp.relative_rise(m), _STYLES[m], color=_COLOURS[m], label=_LABELS[m],
                 markerfacecolor="none" if m == "traditional" else None, markersize=8)
    hi = max(float(np.max(cmp.rms[m])) for m in MODELS)
    ax1.set_ylim(0.0, 1.45 * hi)  # bars start at zero: their heights compare; room for the legend
    for k, m in enumerate(MODELS):
        off = (k - (len(MODELS) - 1) / 2) * width
        for si, v in zip(s, cmp.rms[m], strict=True):
            ax1.text(si + off, v, f"{v:.3g}", ha="center", va="bottom", fontsize=7, rotation=90)
    ax1.set_xticks(s)
    ax1.set_xlabel("sun missing-tooth severity (fraction of face width removed)")
    ax1.set_ylabel(f"RMS of the sensor signal ({unit_text(cmp.unit)})")
    ax1.set_title("RMS versus fault severity")
    ax1.legend(loc="upper left", fontsize=8)
    ax2.axhline(0.0, color="k", lw=0.6)
    ax2.set_xticks(s)
    ax2.set_xlabel("sun missing-tooth severity (fraction of face width removed)")
    ax2.set_ylabel("RMS rise over the healthy gearbox (%)")
    ax2.set_title("Relative rise")
    ax2.legend(loc="upper left", fontsize=8)
    st = cmp.settings
    fig.suptitle(title or (f"Traditional model vs motor-coupled twin — {st.get('spec', '')}, "
                           f"{st.get('kind', '')}, {st.get('quantity', '')} "
                           f"({st.get('duration_s', 0):.3g} s window)"))
    fig.tight_layout()
    return fig


def plot_sensitivity(cmp: DriveComparison, *, title: str | None = None) -> Figure:
    """Sensitivity ``dRMS/dseverity`` (autodiff) of both models versus severity, with the secant
    slopes between neighbouring severities as an independent check.

    **Arguments:** `cmp` with `slope` computed (``compare_drives(..., sensitivity=True)``).
    **Returns:** the `Figure`.
    """
    if cmp.slope is None:
        raise ValueError("the comparison has no sensitivities: run compare_drives(..., "
                         "sensitivity=True)")
    s = np.asarray(cmp.severities)
    fig = Figure(figsize=(6.5, 4.2))
    ax = fig.subplots()
    for m in MODELS:
        ax.plot(s, cmp.slope[m], _STYLES[m], color=_COLOURS[m], label=f"{_LABELS[m]}: autodiff")
        if s.size > 1:
            mid = 0.5 * (s[1:] + s[:-1])
            sec = np.diff(cmp.rms[m]) / np.diff(s)
            ax.plot(mid, sec, "x--", color=_COLOURS[m], alpha=0.7,
                    label=f"{_LABELS[m]}: secant")
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel("sun missing-tooth severity (fraction of face width removed)")
    ax.set_ylabel(f"dRMS / dseverity ({unit_text(cmp.unit)} per unit severity)")
    ax.set_title(title or "Fault sensitivity of the RMS indicator")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def plot_sensitivity_sweep(sweep: SensitivitySweep, *, title: str | None = None) -> Figure:
    """``dRMS/dseverity`` at one severity versus shaft stiffness, one line per speed-loop
    bandwidth for the coupled twin and one for the traditional model (left); the ratio coupled /
    traditional (right).

    **Arguments:** `sweep` (from :func:`dtwin.report.drive_comparison.sensitivity_sweep`). **Returns:** the
    `Figure`.
    """
    fig = Figure(figsize=(11, 4.2))
    ax1, ax2 = fig.subplots(1, 2)
    k = sweep.k_shafts
    ax1.plot(k, sweep.traditional, "s-", color=_COLOURS["traditional"],
             label=_LABELS["traditional"])
    cmap = ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple"]
    ratio = sweep.ratio()
    for j, b in enumerate(sweep.bandwidths):
        c = cmap[j % len(cmap)]
        ax1.plot(k, sweep.coupled[:, j], "o-", color=c, label=f"PMSM, speed loop {b:g} Hz")
        ax2.plot(k, ratio[:, j], "o-", color=c, label=f"speed loop {b:g} Hz")
    for ax in (ax1, ax2):
        ax.set_xscale("log")
        ax.set_xlabel("shaft + coupling stiffness k_shaft (N·m/rad)")
        ax.legend(fontsize=8)
    ax1.axhline(0.0, color="k", lw=0.6)
    ax1.set_ylabel(f"dRMS / dseverity at s = {sweep.severity:g} ({unit_text(sweep.unit)})")
    ax1.set_title("Sensitivity of both models")
    ax2.axhline(1.0, color="k", lw=0.6)
    ax2.set_ylabel("sensitivity ratio coupled / traditional (1)")
    ax2.set_title("Coupled over traditional")
    fig.suptitle(title or f"Fault sensitivity vs shaft stiffness and speed-loop bandwidth — "
                          f"{sweep.settings.get('spec', '')}, {sweep.settings.get('kind', '')}")
    fig.tight_layout()
    return fig
