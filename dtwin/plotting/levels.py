"""What every spectrum-like figure shares: the level scale (dB with a stated reference, or
linear), unit text, axis limits that keep every peak and label inside, labels placed without
overlap, and the default band around the gearbox's mesh harmonics.

- dB levels are ``20 log10(a / a_ref)`` with the reference of :func:`dtwin.signal.units.db_reference`
  (ISO 1683: 1 µm/s², 1 nm/s, 1 pm; 1 g for g; 1 unit otherwise), stated on the axis:
  ``"amplitude (dB re 1 µm/s²)"``. PSDs use ``10 log10(P / a_ref²)``.
- Linear levels are in the unit itself.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..signal.units import to_db, unit_name

__all__ = ["SCALES", "level_axis", "levels", "mesh_band", "place_labels", "set_level_limits",
           "unit_text"]

#: The level scales every spectrum-like figure accepts.
SCALES = ("db", "linear")


def unit_text(unit: str | None) -> str:
    """The unit as printed on an axis: ``m/s^2`` → ``m/s²``, ``um`` → ``µm``; a unit the record
    does not state reads ``record unit`` (`dtwin.signal.units.unit_name`)."""
    u = unit_name(unit).replace("^2", "²").replace("**2", "²")
    return "µm" if u == "um" else u


def _check_scale(scale: str) -> str:
    if scale not in SCALES:
        raise ValueError(f"scale must be one of {SCALES}, got {scale!r}")
    return scale


def levels(a: np.ndarray, unit: str | None, scale: str = "db", *, power: bool = False
           ) -> tuple[np.ndarray, str]:
    """Values to plot and the axis unit text: dB re the unit's reference, or linear.

    **Arguments:** `a` (amplitudes in `unit`, or powers per Hz with `power`), `unit`, `scale`
    (:data:`SCALES`). **Returns:** ``(y, text)`` with `text` e.g. ``"dB re 1 µm/s²"`` or
    ``"m/s²"`` (``"(m/s²)²/Hz"`` for a linear PSD).
    """
    a = np.asarray(a, dtype=np.float64)
    if _check_scale(scale) == "linear":
        return a, (f"({unit_text(unit)})²/Hz" if power else unit_text(unit))
    y, text = to_db(a, unit, power=power)
    return y, text.replace("^2", "²")


def level_axis(quantity: str, unit: str | None, scale: str, *, power: bool = False) -> str:
    """Axis label: ``"amplitude (dB re 1 µm/s²)"``, ``"amplitude (m/s²)"``."""
    return f"{quantity} ({levels(np.ones(1), unit, scale, power=power)[1]})"


def set_level_limits(ax, y: np.ndarray, scale: str, *, dynamic_range_db: float = 80.0,
                     headroom: float = 0.18) -> None:
    """Y limits that show every peak with room above for markers and labels: linear from 0 to
    (1 + `headroom`) × max; dB over at most `dynamic_range_db` below the top, with 12 % of the
    span above it."""
    y = np.asarray(y, dtype=np.float64)
    y = y[np.isfinite(y)]
    if not y.size:
        return
    top = float(np.max(y))
    if scale == "linear":
        lo = min(0.0, float(np.min(y)))
        ax.set_ylim(lo, top + headroom * (top - lo if top > lo else 1.0))
        return
    bottom = max(float(np.percentile(y, 0.5)) - 3.0, top - dynamic_range_db)
    span = max(top - bottom, 10.0)
    ax.set_ylim(bottom, top + headroom * span)


def place_labels(ax, xs: Sequence[float], ys: Sequence[float], texts: Sequence[str], *,
                 color: str = "C3", fontsize: float = 8, min_sep: float = 0.025,
                 rotation: float = 0.0) -> None:
    """Annotate points (data coordinates) with texts that do not overlap.

    Texts stand at least a separation apart: `min_sep` (fraction of the axis width, scaled by
    the text length), and never less than the longest text's printed width plus half an em at
    the axis's size. Points closer than that form a cluster; a cluster's texts sit side by side,
    one separation apart, centred on the cluster (inside the axis), on one line just above its
    highest point, each joined to its point by a thin leader line when it had to move sideways.
    A text never stands closer than one separation to the previous cluster's last text (a lone
    point's text moves right when that one was pushed over it). Call after the limits are set."""
    if not len(xs):
        return
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    width, height = (x1 - x0) or 1.0, (y1 - y0) or 1.0
    longest = max(len(t) for t in texts)
    # at least the longest text's width (~0.62 em a character) and half an em of white, in data
    # units of this axis at its size in points
    axis_pt = max(ax.get_position().width * ax.figure.get_figwidth() * 72.0, 1.0)
    text_w = (0.62 * longest + 0.5) * fontsize / axis_pt * width
    sep = max(min_sep * max(1.0, 0.6 * longest) * width, text_w)
    order = list(np.argsort(np.asarray(xs, dtype=float), kind="stable"))
    clusters: list[list[int]] = []
    for i in order:
        if clusters and float(xs[i]) - float(xs[clusters[-1][-1]]) < sep:
            clusters[-1].append(i)
        else:
            clusters.append([i])
    last = -np.inf
    for c in clusters:
        n = len(c)
        centre = float(np.mean([float(xs[i]) for i in c]))
        first = max(centre - 0.5 * (n - 1) * sep, last + sep, x0 + 0.5 * sep if n > 1 else x0)
        first = min(first, x1 - (n - 0.5) * sep) if n > 1 else first
        base = max(float(ys[i]) for i in c) + 0.05 * height
        for k, i in enumerate(c):
            xl = first + k * sep
            moved = abs(xl - float(xs[i])) > 0.2 * sep
            ax.annotate(texts[i], (float(xs[i]), float(ys[i])), xytext=(xl, base),
                        textcoords="data", ha="center", va="bottom", fontsize=fontsize,
                        color=color, rotation=rotation, annotation_clip=True,
                        arrowprops=dict(arrowstyle="-", lw=0.5, color=color, alpha=0.6,
                                        shrinkA=0, shrinkB=2) if moved else None)
        last = first + (n - 1) * sep


def mesh_band(f_mesh: float, f_carrier: float, nyquist: float, *, harmonics: int = 3,
              sidebands: int = 12) -> tuple[float, float]:
    """The default band of a gearbox: from ``fm − sidebands·fc`` to ``harmonics·fm +
    sidebands·fc``, capped at `nyquist` (Hz); the mesh harmonics the record holds with their
    carrier sidebands."""
    lo = max(0.0, f_mesh - sidebands * f_carrier)
    k = max(1, min(int(harmonics), int(np.floor((nyquist - sidebands * f_carrier) / f_mesh)) or 1))
    hi = min(nyquist, k * f_mesh + sidebands * f_carrier)
    return lo, hi
