"""Figures of the signal-processing views: order spectrum, TSA and planet averages, envelope
spectrum, kurtogram, cepstrum, waterfall / Campbell diagram, PSD.

Each function takes the data computed by :mod:`dtwin.signal.order`, :mod:`dtwin.signal.tsa`,
:mod:`dtwin.signal.envelope`, :mod:`dtwin.signal.cepstrum` or :mod:`dtwin.signal.psd` and returns a matplotlib
Figure with title, axis labels with units and a legend; ``dtwin view`` and the notebooks use them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import matplotlib
import numpy as np
from matplotlib import cm, colors, patches
from matplotlib.figure import Figure

from ..signal.envelope import Kurtogram
from ..signal.order import CampbellData, OrderMap, Waterfall
from ..signal.tsa import TSA, PlanetAverages
from .levels import level_axis, levels, set_level_limits, unit_text

__all__ = [
    "plot_campbell",
    "plot_cepstrum",
    "plot_envelope_spectrum",
    "plot_iso20816",
    "plot_kurtogram",
    "plot_order_cuts",
    "plot_order_map",
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
    unit: str = "m/s^2", max_order: float | None = None, shaft: str = "reference shaft",
    title: str = "Order spectrum", scale: str = "db", channel: str | None = None,
) -> Figure:
    """Amplitude against order (cycles per revolution of `shaft`), `marks`: name → order;
    `scale` ``"db"`` (re the unit's ISO 1683 reference) or ``"linear"``."""
    fig = Figure(figsize=(9, 3.8))
    ax = fig.add_subplot(1, 1, 1)
    hi = float(orders[-1]) if max_order is None else float(max_order)
    sel = orders <= hi
    y, _ = levels(amplitude[sel], unit, scale)
    ax.plot(orders[sel], y, lw=0.7, color="C0", label="order spectrum")
    _marks(ax, marks, 0.0, hi)
    ax.set_xlim(0.0, hi)
    set_level_limits(ax, y, scale)
    ax.set_xlabel(f"order (cycles per revolution of the {shaft})")
    ax.set_ylabel(level_axis("amplitude", unit, scale))
    ax.set_title(title + (f" [{channel}]" if channel else ""))
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return fig


def plot_tsa(
    tsa: TSA, *, unit: str = "m/s^2", shaft: str = "carrier", title: str | None = None,
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
    ax.set_ylabel(f"amplitude ({unit_text(unit)})")
    ax.set_title(title or f"Time-synchronous average on the {shaft}")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return fig


def plot_planet_averages(
    sep: PlanetAverages, indicator: Sequence[float] | None = None, *, unit: str = "m/s^2",
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
        ax.set_ylabel(f"({unit_text(unit)})")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("planet tooth in the ring mesh (teeth)")
    axes[0].set_title(f"{title}; {sep.window} window of {sep.window_teeth:g} teeth")
    return fig


def plot_envelope_spectrum(
    freqs: np.ndarray, amplitude: np.ndarray, *, band: tuple[float, float] | None = None,
    marks: Mapping[str, float] | None = None, max_freq: float | None = None,
    unit: str = "m/s^2", harmonics: int = 3, title: str = "Envelope spectrum",
    scale: str = "linear", channel: str | None = None,
) -> Figure:
    """Envelope spectrum up to `max_freq` (Hz) with fault-frequency `marks` and harmonics;
    `scale` ``"linear"`` (the usual view of an envelope) or ``"db"``."""
    fig = Figure(figsize=(9, 3.8))
    ax = fig.add_subplot(1, 1, 1)
    hi = float(freqs[-1]) if max_freq is None else float(max_freq)
    sel = freqs <= hi
    lab = "envelope spectrum" + (f" of {band[0]:.0f}–{band[1]:.0f} Hz" if band else "")
    y, _ = levels(amplitude[sel], unit, scale)
    ax.plot(freqs[sel], y, lw=0.8, color="C0", label=lab)
    _marks(ax, marks, 0.0, hi, harmonics)
    ax.set_xlim(0.0, hi)
    set_level_limits(ax, y[1:] if y.size > 1 else y, scale)  # DC of the envelope left out
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(level_axis("envelope amplitude", unit, scale))
    ax.set_title(title + (f" [{channel}]" if channel else ""))
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
    for r, nb in enumerate(kg.n_bands):  # one mesh per level: a cell per band (thousands)
        k = np.clip(np.nan_to_num(kg.kurtosis[r, :nb], nan=0.0), 0.0, None)
        ax.pcolormesh(np.linspace(0.0, nyq, nb + 1), [r, r + 1], k[None, :], cmap=cmap,
                      norm=norm, shading="flat", lw=0)

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
    channel: str | None = None,
) -> Figure:
    """Cepstrum against quefrency (ms); `spacings` name → Δf (Hz) marks rahmonics k/Δf.

    Each family has its own colour, line style and a row of ▼ markers with ``k/Δf`` texts at the
    top, one row per family, so that coinciding rahmonics (1/fc is the N-th rahmonic of
    1/(N fc)) stay visible; the legend says which coincide."""
    fig = Figure(figsize=(9, 4.0))
    ax = fig.add_subplot(1, 1, 1)
    hi = float(quefrency[-1]) if max_quefrency is None else float(max_quefrency)
    sel = (quefrency > 0) & (quefrency <= hi)
    ax.plot(1e3 * quefrency[sel], cepstrum[sel], lw=0.7, color="C0", label="cepstrum")
    fams = [(k, 1e3 / v) for k, v in (spacings or {}).items() if v > 0]
    styles = ["--", ":", "-.", (0, (5, 2, 1, 2))]
    n = len(fams)
    y = cepstrum[sel]
    lo, top = float(np.min(y)), float(np.max(y))
    span = top - lo or 1.0
    ax.set_ylim(lo - 0.05 * span, top + (0.12 + 0.09 * n) * span)
    ax.set_xlim(0.0, 1e3 * hi)
    for j, (name, q1) in enumerate(fams):
        col = f"C{(j + 1) % 10}"
        yrow = top + (0.1 + 0.09 * (n - j)) * span
        same = []
        for k in range(1, rahmonics + 1):
            q = k * q1
            if q > 1e3 * hi:
                break
            ax.axvline(q, ls=styles[j % len(styles)], lw=1.6 - 0.35 * j, color=col, alpha=0.8,
                       zorder=3 + n - j)
            ax.plot([q], [yrow], "v", color=col, ms=6, zorder=5)
            ax.annotate(f"{k}/{name}" if k > 1 else f"1/{name}", (q, yrow),
                        textcoords="offset points", xytext=(4, -3), fontsize=7, color=col)
            for i2, (n2, q2) in enumerate(fams):
                if i2 != j and any(abs(q - m * q2) < 0.01 * q for m in range(1, 50)):
                    same.append(n2)
        label = f"rahmonics k/{name} ({q1:.1f} ms)"
        if same:
            label += f"; coincide with 1/{', 1/'.join(sorted(set(same)))} multiples"
        ax.plot([], [], ls=styles[j % len(styles)], color=col, label=label)
    ax.set_xlabel("quefrency (ms)")
    ax.set_ylabel("cepstrum (dimensionless, natural log)")
    ax.set_title(title + (f" [{channel}]" if channel else ""))
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=7, bbox_to_anchor=(1.0, 0.8 - 0.06 * n))
    return fig


def plot_waterfall(
    wf: Waterfall, *, unit: str = "m/s^2", max_freq: float | None = None,
    orders: Mapping[str, float] | None = None, dynamic_range_db: float = 60.0,
    title: str = "Waterfall (short-time amplitude spectra)",
) -> Figure:
    """Colour map of the STFT amplitude (dB re 1 `unit`) against time and frequency; with a
    speed in `wf`, `orders` (name → order) are drawn as ``order × speed`` lines."""
    fig = Figure(figsize=(9, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    hi = float(wf.freqs[-1]) if max_freq is None else float(max_freq)
    sel = wf.freqs <= hi
    db, _ = levels(wf.amplitude[sel], unit, "db")
    top = float(np.max(db))
    mesh = ax.pcolormesh(wf.times, wf.freqs[sel], db, shading="nearest",
                         vmin=top - dynamic_range_db, vmax=top, cmap="viridis")
    fig.colorbar(mesh, ax=ax, label=level_axis("amplitude", unit, "db"))
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
    cd: CampbellData, *, unit: str = "m/s^2", max_freq: float | None = None,
    dynamic_range_db: float = 60.0, title: str = "Campbell diagram",
) -> Figure:
    """Amplitude (dB) against shaft speed and frequency with order lines and natural frequencies."""
    fig = Figure(figsize=(9, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    hi = float(cd.freqs[-1]) if max_freq is None else float(max_freq)
    sel = cd.freqs <= hi
    db, _ = levels(cd.amplitude[sel], unit, "db")
    top = float(np.max(db))
    mesh = ax.pcolormesh(60 * cd.speed, cd.freqs[sel], db, shading="nearest",
                         vmin=top - dynamic_range_db, vmax=top, cmap="viridis")
    fig.colorbar(mesh, ax=ax, label=level_axis("amplitude", unit, "db"))
    for j, (name, f) in enumerate(cd.order_lines.items()):
        ax.plot(60 * cd.speed, f, ls="--", lw=1.2, color=f"C{(j + 1) % 10}",
                label=f"order line {name}")
    for name, f in cd.natural_frequencies.items():
        if f <= hi:
            ax.axhline(f, ls=":", lw=1.0, color="w", label=f"natural frequency {name} = {f:.0f} Hz")
    ax.set_ylim(0, hi)
    ax.set_xlabel("shaft speed (rpm)")
    ax.set_ylabel("frequency (Hz)")
    ax.set_title(title)
    ax.legend(loc="upper left", fontsize=7)
    return fig


def plot_psd(
    freqs: np.ndarray, psd: np.ndarray, *, unit: str = "m/s^2",
    marks: Mapping[str, float] | None = None, title: str = "Power spectral density (Welch)",
    scale: str = "db", channel: str | None = None,
) -> Figure:
    """PSD in dB re (ISO 1683 reference)²/Hz, e.g. dB re (1 µm/s²)²/Hz, or linear in unit²/Hz,
    against frequency, with optional frequency `marks` (Hz)."""
    fig = Figure(figsize=(9, 3.8))
    ax = fig.add_subplot(1, 1, 1)
    y, _ = levels(psd, unit, scale, power=True)
    ax.plot(freqs, y, lw=0.8, color="C0", label="PSD")
    _marks(ax, marks, float(freqs[0]), float(freqs[-1]))
    ax.set_xlim(float(freqs[0]), float(freqs[-1]))
    set_level_limits(ax, y[1:] if y.size > 1 else y, scale, dynamic_range_db=100.0)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(level_axis("PSD", unit, scale, power=True))
    ax.set_title(title + (f" [{channel}]" if channel else ""))
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    return fig


def plot_order_map(
    om: OrderMap, *, unit: str = "m/s^2", orders: Mapping[str, float] | None = None,
    dynamic_range_db: float = 60.0, title: str = "Order map", channel: str | None = None,
    speed_source: str | None = None,
) -> Figure:
    """Colour map of the order spectra of a run-up (dB re the unit's ISO 1683 reference)
    against reference-shaft speed (rpm) and order; `orders` name → order are drawn as
    horizontal lines (an order stays at one height whatever the speed)."""
    fig = Figure(figsize=(9, 4.6))
    ax = fig.add_subplot(1, 1, 1)
    db, _ = levels(om.amplitude, unit, "db")
    top = float(np.max(db))
    mesh = ax.pcolormesh(om.rpm, om.orders, db, shading="nearest", vmin=top - dynamic_range_db,
                         vmax=top, cmap="viridis")
    fig.colorbar(mesh, ax=ax, label=level_axis("amplitude", unit, "db"))
    for j, (name, o) in enumerate((orders or {}).items()):
        if o <= float(om.orders[-1]):
            ax.axhline(o, ls="--", lw=1.0, color=f"C{(j + 1) % 10}", label=f"{name} (order {o:.3g})")
    ax.set_ylim(0, float(om.orders[-1]))
    ax.set_xlabel("reference-shaft speed (rpm)" + (f", from {speed_source}" if speed_source else ""))
    ax.set_ylabel("order (cycles per revolution)")
    ax.set_title(f"{title}: {om.revs_per_segment} revolutions per spectrum, resolution "
                 f"{om.orders[1] - om.orders[0]:.3g} orders" + (f" [{channel}]" if channel else ""))
    if orders:
        ax.legend(loc="upper left", fontsize=8)
    return fig


def plot_order_cuts(
    om: OrderMap, cuts: Mapping[str, np.ndarray], *, unit: str = "m/s^2", scale: str = "db",
    title: str = "Order cuts", channel: str | None = None, speed_source: str | None = None,
) -> Figure:
    """Amplitude of each order against speed (rpm), from :func:`dtwin.signal.order.order_cuts`."""
    fig = Figure(figsize=(9, 4.0))
    ax = fig.add_subplot(1, 1, 1)
    allv = []
    for j, (name, a) in enumerate(cuts.items()):
        y, _ = levels(a, unit, scale)
        ax.plot(om.rpm, y, "o-", ms=3, lw=1.0, color=f"C{j % 10}", label=name)
        allv.append(y)
    if allv:
        set_level_limits(ax, np.concatenate(allv), scale, dynamic_range_db=60.0)
    ax.set_xlabel("reference-shaft speed (rpm)" + (f", from {speed_source}" if speed_source else ""))
    ax.set_ylabel(level_axis("amplitude", unit, scale))
    ax.set_title(title + (f" [{channel}]" if channel else ""))
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return fig


def plot_iso20816(
    rms_mm_s: Mapping[str, float], zones, *, band: tuple[float, float] = (10.0, 1000.0),
    title: str = "Broadband velocity RMS against ISO 20816 zones",
) -> Figure:
    """One bar per channel: broadband velocity RMS (mm/s) over the zones A–D of `zones`
    (:func:`dtwin.signal.units.iso20816_zones`), shaded, with the boundaries stated."""
    names = list(rms_mm_s)
    fig = Figure(figsize=(max(5.5, 1.2 * len(names) + 3.5), 3.8))
    ax = fig.add_subplot(1, 1, 1)
    vals = np.array([float(rms_mm_s[n]) for n in names])
    vmax = float(np.max(vals, initial=0.0))
    log = vmax > 3 * zones.cd  # far beyond zone D: a log axis keeps the boundaries readable
    top = 2.0 * vmax if log else max(1.25 * zones.cd, 1.15 * vmax)
    bottom = min(0.1, 0.5 * float(np.min(vals, initial=1.0))) if log else 0.0
    edges = [bottom, zones.ab, zones.bc, zones.cd, top]
    cols = ["#cfe8cf", "#fff2b3", "#ffd0a8", "#f5b5b5"]
    for z, (lo, hi) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
        ax.axhspan(lo, hi, color=cols[z], zorder=0, label=f"zone {'ABCD'[z]}")
    for name, b in zones.boundaries.items():
        ax.axhline(b, color="0.3", lw=0.8, ls="--", zorder=1)
        ax.text(1.0, b, f" {name} {b:g}", transform=ax.get_yaxis_transform(), va="center",
                fontsize=8)
    x = np.arange(len(names))
    ax.bar(x, vals - bottom, 0.5, bottom=bottom, color="tab:blue", zorder=2)
    for xi, v in zip(x, vals, strict=True):
        ax.text(xi, v, f"{v:.2f}", ha="center", va="bottom", fontsize=8, zorder=3)
    ax.set_xticks(x, names)
    if log:
        ax.set_yscale("log")
    ax.set_ylim(bottom, top)
    ax.set_ylabel(f"velocity RMS, {band[0]:g}–{band[1]:g} Hz (mm/s)")
    ax.set_title(title, fontsize=10)
    ax.text(0.0, -0.2, zones.description + "; an orientation for a gearbox (ISO 20816-9 covers "
            "gear units), ISO 20816-1 method", transform=ax.transAxes, fontsize=7, va="top",
            wrap=True)
    ax.legend(loc="upper left", fontsize=7, ncol=4)
    return fig
