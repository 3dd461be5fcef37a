"""Which residual lines a candidate covers (:func:`coverage`), its signature bins, the
labels of the lines it matches (:func:`signature_labels`) and the candidates specialised to the
machine and record (:func:`_adapted`)."""

from __future__ import annotations

import numpy as np

from ..lines import Kinematics, ResidualLine


def _bins_of(freqs_hz: list[float], df: float, n_bins: int, half: int = 1) -> np.ndarray:
    mask = np.zeros(n_bins, bool)
    for f in freqs_hz:
        k = int(round(f / df))
        mask[max(k - half, 0): min(k + half + 1, n_bins)] = True
    return mask



def _dilate(mask, half=1):
    out = mask.copy()
    for s in range(1, half + 1):
        out[..., s:] |= mask[..., :-s]
        out[..., :-s] |= mask[..., s:]
    return out


def coverage(effect, kin: Kinematics, lines: list[ResidualLine], tol: float, f_max: float,
             f_min: float = 0.0):
    """Fraction of the residual (measured-side) line power from `f_min` (Hz) up that an
    effect's signature covers, and the lines matched."""
    sig = np.array([s.frequency for s in effect.signature(kin, f_max)])
    meas = [r for r in lines if r.side == "measured" and r.frequency >= f_min]
    total = sum(r.power_excess for r in meas)
    if sig.size == 0 or total <= 0:
        return 0.0, []
    matched = [r for r in meas if np.min(np.abs(sig - r.frequency)) <= tol]
    return float(sum(r.power_excess for r in matched) / total), matched



def _adapted(effects, context) -> list:
    """The effects specialised by their :meth:`~dtwin.identify.discover.effects.AbstractEffect.adapt` (those
    returning ``None`` withdrawn)."""
    out = []
    for e in effects:
        a = e.adapt(context)
        if a is not None:
            out.append(a)
    return out


def signature_labels(effect, kin: Kinematics, lines: list[ResidualLine], tol: float,
                     f_max: float) -> list[str]:
    """For each line, the label of the nearest signature line of `effect` within `tol` (Hz),
    or "" (the effect's own kinematic description, e.g. bearing frequencies)."""
    sig = effect.signature(kin, f_max)
    if not sig:
        return ["" for _ in lines]
    fs = np.array([s.frequency for s in sig])
    out = []
    for r in lines:
        i = int(np.argmin(np.abs(fs - r.frequency)))
        out.append(sig[i].label if abs(fs[i] - r.frequency) <= tol else "")
    return out


