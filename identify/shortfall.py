"""Calibration shortfall: what the calibrated twin leaves unexplained on its healthy records.

A calibrated twin never explains a healthy record completely: a mesh harmonic misfitted by
some dB, a line above the modelled band. Discovery on a later record of the same machine finds
those misfits again and, unless told, may "explain" them with an effect that the healthy machine
has too (a housing resonance on 2 f_m). A candidate whose evidence lies on the lines the
calibration itself left unexplained is a calibration shortfall, not a finding.

:func:`shortfall_lines` lists those lines at the end of :func:`dtwin.identify.calibrate.calibrate`
(lines ``threshold_db`` over the noise floor that the calibrated twin misses, or makes, by
``excess_db`` or more: :func:`dtwin.identify.lines.residual_lines`), as orders of the input
speed so that they carry over to a record at another speed; the calibrated spec stores them
(``[calibration] shortfall_orders``, ``shortfall_db``). :func:`shortfall_share` is the share of
a candidate's evidence (the excess power of its matched residual lines) that lies on them;
discovery refuses a candidate whose share reaches :data:`SHORTFALL_SHARE`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .lines import Kinematics, residual_lines

__all__ = ["SHORTFALL_SHARE", "shortfall_lines", "shortfall_share"]

#: A candidate whose matched lines carry at least this share of their excess power on lines
#: the calibration left unexplained is refused as a calibration shortfall: most of what it
#: would explain, the healthy machine shows too.
SHORTFALL_SHARE = 0.5


def shortfall_lines(freqs: np.ndarray, measured: np.ndarray, model: np.ndarray,
                    kin: Kinematics, f_max: float, *, threshold_db: float = 12.0,
                    excess_db: float = 6.0) -> tuple[list[float], list[float]]:
    """Lines of the healthy records that the calibrated twin misses or makes.

    **Arguments:** `freqs` (Hz); `measured`, `model`: amplitude spectra, rows of record halves
    or one row (the model scaled to the record); `kin` at the records' speed; `f_max` (Hz):
    the top of the scored band; thresholds (dB) as
    :func:`dtwin.identify.lines.residual_lines`.

    **Returns:** ``(orders, excess_db)``: each line's frequency over the input speed, and its
    excess over the other spectrum (dB), largest first.
    """
    rms = lambda a: np.sqrt(np.mean(np.atleast_2d(np.asarray(a, float)) ** 2, axis=0))  # noqa: E731
    lines = residual_lines(np.asarray(freqs), rms(measured), rms(model), kin,
                           threshold_db=threshold_db, excess_db=excess_db, f_max=f_max)
    return ([float(r.frequency / kin.f_sun) for r in lines],
            [float(r.excess_db) for r in lines])


def shortfall_share(matched: Sequence, orders: Sequence[float], f_sun: float,
                    tol_hz: float) -> tuple[float, list[float]]:
    """Share of the excess power of `matched` (residual lines, each with ``frequency`` Hz and
    ``excess_db``) that lies within `tol_hz` of a calibration shortfall line (`orders` × `f_sun`),
    and those lines' frequencies (Hz). 0 when there is no shortfall line or no matched line."""
    if not orders or not matched:
        return 0.0, []
    at = np.asarray(orders, float) * float(f_sun)
    power = np.array([10 ** (r.excess_db / 10) for r in matched])
    on = np.array([bool(np.any(np.abs(at - r.frequency) <= tol_hz)) for r in matched])
    share = float(power[on].sum() / power.sum()) if power.sum() > 0 else 0.0
    return share, [float(r.frequency) for r, o in zip(matched, on, strict=True) if o]
