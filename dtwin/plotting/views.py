"""Figures of the signal-processing views: order spectrum, TSA and planet averages, envelope
spectrum, kurtogram, cepstrum, waterfall / Campbell diagram, PSD.

Each function takes the data computed by :mod:`dtwin.order`, :mod:`dtwin.tsa`,
:mod:`dtwin.envelope`, :mod:`dtwin.cepstrum` or :mod:`dtwin.psd` and returns a matplotlib
Figure with title, axis labels with units and a legend; ``dtwin view`` and the notebooks use them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib
import numpy as np
from matplotlib import cm, colors, patches
from matplotlib.figure import Figure

from ..envelope import Kurtogram
from ..order import CampbellData, Waterfall
from ..tsa import TSA, PlanetAverages

__all__ = [
    "plot_campbell",
    "plot_cepstrum",
    "plot_envelope_spectrum",
    "plot_kurtogram",
    "plot_order_spectrum",
    "plot_planet_averages",
    "plot_psd",
    "plot_tsa",
    "plot_waterfall",
]


def _db(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    return 20 * np.log10(np.maximum(a, max(float(np.max(a, initial=0.0)) * 1e-8, 1e-300)))


def _marks(ax, marks: Mapping[str, float] | None, lo: float, hi: float, harmonics: int = 1):
    for j, (name, v) in enumerate((marks or {}).items()):
        for h in range(1, harmonics + 1):
            if lo <= h * v <= hi:
                ax.axvline(h * v, ls="--", lw=0.8, color=f"C{(j + 1) % 10}",
                           label=name if h == 1 else None)


def plot_order_spectrum(
    orders: np.ndarray, amplitude: np.ndarray, *, marks: Mapping[str, float] | None = None,
    unit: str = "m/s²", max_order: float | None = None, shaft: str = "reference shaft",
    title: str = "Order spectrum",
) -> Figure:
    """Amplitude against order (cycles per revolution of `shaft`), `marks`: name → order."""
    fig = Figure(figsize=(9, 3.8))
    ax = fig.add_subplot(1, 1, 1)
    hi = float(orders[-1]) if max_order is None else float(max_order)
    sel = orders <= hi
    ax.plot(orders[sel], amplitude[sel], lw=0.8, color="C0", label="order spectrum")
    _marks(ax, marks, 0.0, hi)
    ax.set_xlabel(f"order (cycles per revolution of the {shaft})")
    ax.set_ylabel(f"amplitude ({unit})")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return fig


def plot_tsa(
    tsa: TSA, *, unit: str = "m/s²", shaft: str = "carrier", title: str | None = None,
) -> Figure:
    """The TSA over one revolution (deg), with the spread of single revolutions shaded."""
    fig = Figure(figsize=(9, 3.8))
    ax = fig.add_subplot(1, 1, 1)
    deg = np.degrees(tsa.angle)
    lo = np.percentile(tsa.revolutions, 5, axis=0)
    hi = np.percentile(tsa.revolutions, 95, axis=0)
    ax.fill_between(deg, lo, hi, color="0.85", label="single revolutions, 5–95 %")
    ax.plot(deg, tsa.average, lw=0.8, color="C0", label=f"average of {tsa.n_averages} revolutions")
    ax.set_xlabel(f"{shaft} angle (deg)")
    ax.set_ylabel(f"amplitude ({unit})")
    ax.set_title(title or f"Time-synchronous average on the {shaft}")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return fig


def plot_planet_averages(
    sep: PlanetAverages, indicator: Sequence[float] | None = None, *, unit: str = "m/s²",
    indicator_name: str = "FM4", title: str = "Separated planet averages (McFadden)",
) -> Figure:
    """One panel per planet: its windowed average over one planet revolution (teeth)."""
    n = sep.averages.shape[0]
    fig = Figure(figsize=(9, 1.9 * n + 0.8))
    axes = fig.subplots(n, 1, sharex=True, squeeze=False)[:, 0]
    for i, ax in enumerate(axes):
        label = f"planet {i}"
        if indicator is not None:
            label += f": {indicator_name} = {float(indicator[i]):.2f}"
        ax.plot(sep.tooth, sep.averages[i], lw=0.8, color=f"C{i}", label=label)
        ax.set_ylabel(f"({unit})")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("planet tooth in the ring mesh (teeth)")
    axes[0].set_title(f"{title}; {sep.window} window of {sep.window_teeth:g} teeth")
    return fig


def plot_envelope_spectrum(
    freqs: np.ndarray, amplitude: np.ndarray, *, band: tuple[float, float] | None = None,
    marks: Mapping[str, float] | None = None, max_freq: float | None = None,
    unit: str = "m/s²", harmonics: int = 3, title: str = "Envelope spectrum",
) -> Figure:
    """Envelope spectrum up to `max_freq` (Hz) with fault-frequency `marks` and harmonics."""
    fig = Figure(figsize=(9, 3.8))
    ax = fig.add_subplot(1, 1, 1)
    hi = float(freqs[-1]) if max_freq is None else float(max_freq)
    sel = freqs <= hi
    lab = "envelope spectrum" + (f" of {band[0]:.0f}–{band[1]:.0f} Hz" if band else "")
    ax.plot(freqs[sel], amplitude[sel], lw=0.8, color="C0", label=lab)
    _marks(ax, marks, 0.0, hi, harmonics)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"envelope amplitude ({unit})")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return fig


def plot_kurtogram(kg: Kurtogram, *, title: str = "Fast kurtogram (Antoni 2007)") -> Figure:
    """Spectral kurtosis per level and band; the picked band is outlined."""
    fig = Figure(figsize=(9, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    nyq = kg.sample_rate / 2
    vmax = np.nanmax(kg.kurtosis)
    cmap = matplotlib.colormaps["viridis"]
    norm = colors.Normalize(vmin=0.0, vmax=max(vmax, 1e-9))
    for r, nb in enumerate(kg.n_bands):
        w = nyq / nb
        for b in range(nb):
            k = kg.kurtosis[r, b]
            ax.add_patch(patches.Rectangle(
                (b * w, r), w, 1, color=cmap(norm(0.0 if np.isnan(k) else max(k, 0.0))), lw=0))
    r_best = int(np.argmin(np.abs(kg.levels - kg.best_level)))
    lo, hi = kg.best_band
    ax.add_patch(patches.Rectangle(
        (lo, r_best), hi - lo, 1, fill=False, ec="red", lw=1.5,
        label=f"picked: {lo:.0f}–{hi:.0f} Hz, level {kg.best_level:.1f}, K = {kg.best_kurtosis:.2f}"))
    ax.set_xlim(0, nyq)
    ax.set_ylim(len(kg.n_bands), 0)
    ax.set_yticks(np.arange(len(kg.levels)) + 0.5)
    ax.set_yticklabels([f"{v:.1f}" for v in kg.levels])
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("level (log2 of the number of bands)")
    ax.set_title(title)
    sm = cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=ax, label="spectral kurtosis of the complex envelope (-)")
    ax.legend(loc="lower right", fontsize=8)
    return fig


def plot_cepstrum(
    quefrency: np.ndarray, cepstrum: np.ndarray, *, spacings: Mapping[str, float] | None = None,
    max_quefrency: float | None = None, rahmonics: int = 3, title: str = "Real cepstrum",
) -> Figure:
    """Cepstrum against quefrency (ms); `spacings` name → Δf (Hz) marks rahmonics k/Δf."""
    fig = Figure(figsize=(9, 3.8))
    ax = fig.add_subplot(1, 1, 1)
    hi = float(quefrency[-1]) if max_quefrency is None else float(max_quefrency)
    sel = (quefrency > 0) & (quefrency <= hi)
    ax.plot(1e3 * quefrency[sel], cepstrum[sel], lw=0.8, color="C0", label="cepstrum")
    marks = {f"1/{k}": 1e3 / v for k, v in (spacings or {}).items() if v > 0}
    _marks(ax, marks, 0.0, 1e3 * hi, rahmonics)
    ax.set_xlabel("quefrency (ms)")
    ax.set_ylabel("cepstrum (-)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return fig


def plot_waterfall(
    wf: Waterfall, *, unit: str = "m/s²", max_freq: float | None = None,
    orders: Mapping[str, float] | None = None, dynamic_range_db: float = 60.0,
    title: str = "Waterfall (short-time amplitude spectra)",
) -> Figure:
    """Colour map of the STFT amplitude (dB re 1 `unit`) against time and frequency; with a
    speed in `wf`, `orders` (name → order) are drawn as ``order × speed`` lines."""
    fig = Figure(figsize=(9, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    hi = float(wf.freqs[-1]) if max_freq is None else float(max_freq)
    sel = wf.freqs <= hi
    db = _db(wf.amplitude[sel])
    top = float(np.max(db))
    mesh = ax.pcolormesh(wf.times, wf.freqs[sel], db, shading="nearest",
                         vmin=top - dynamic_range_db, vmax=top, cmap="viridis")
    fig.colorbar(mesh, ax=ax, label=f"amplitude (dB re 1 {unit})")
    if wf.speed is not None:
        for j, (name, o) in enumerate((orders or {}).items()):
            ax.plot(wf.times, o * wf.speed, ls="--", lw=1.0, color=f"C{(j + 1) % 10}",
                    label=f"{name} (order {o:.3g})")
    ax.set_ylim(0, hi)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("frequency (Hz)")
    ax.set_title(title)
    if orders and wf.speed is not None:
        ax.legend(loc="upper left", fontsize=8)
    return fig


def plot_campbell(
    cd: CampbellData, *, unit: str = "m/s²", max_freq: float | None = None,
    dynamic_range_db: float = 60.0, title: str = "Campbell diagram",
) -> Figure:
    """Amplitude (dB) against shaft speed and frequency with order lines and natural frequencies."""
    fig = Figure(figsize=(9, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    hi = float(cd.freqs[-1]) if max_freq is None else float(max_freq)
    sel = cd.freqs <= hi
    db = _db(cd.amplitude[sel])
    top = float(np.max(db))
    mesh = ax.pcolormesh(cd.speed, cd.freqs[sel], db, shading="nearest",
                         vmin=top - dynamic_range_db, vmax=top, cmap="viridis")
    fig.colorbar(mesh, ax=ax, label=f"amplitude (dB re 1 {unit})")
    for j, (name, f) in enumerate(cd.order_lines.items()):
        ax.plot(cd.speed, f, ls="--", lw=1.0, color=f"C{(j + 1) % 10}", label=f"order line {name}")
    for name, f in cd.natural_frequencies.items():
        if f <= hi:
            ax.axhline(f, ls=":", lw=1.0, color="w", label=f"natural frequency {name} = {f:.0f} Hz")
    ax.set_ylim(0, hi)
    ax.set_xlabel("shaft speed (Hz)")
    ax.set_ylabel("frequency (Hz)")
    ax.set_title(title)
    ax.legend(loc="upper left", fontsize=7)
    return fig


def plot_psd(
    freqs: np.ndarray, psd: np.ndarray, *, unit: str = "m/s²",
    marks: Mapping[str, float] | None = None, title: str = "Power spectral density (Welch)",
) -> Figure:
    """PSD in dB re 1 `unit`²/Hz against frequency, with optional frequency `marks` (Hz)."""
    fig = Figure(figsize=(9, 3.8))
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(freqs, 10 * np.log10(np.maximum(psd, max(float(np.max(psd)) * 1e-16, 1e-300))),
            lw=0.8, color="C0", label="PSD")
    _marks(ax, marks, float(freqs[0]), float(freqs[-1]))
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(f"PSD (dB re 1 {unit}²/Hz)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return fig
