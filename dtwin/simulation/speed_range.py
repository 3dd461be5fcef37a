"""The accepted range of an input (sun) speed: one constant and one check, used by every command
and library entry that takes a speed (``--f-sun``, ``--runup``, ``simulate(f_sun=)``,
:func:`dtwin.identify.operating_point.resolve_speed`).

A speed is given in Hz; ``0 < f_sun <= F_SUN_MAX`` (500 Hz = 30 000 rpm). A value above the
range that reads as rpm gets the conversion as a hint (``1800`` → "did you mean 1800 rpm = 30 Hz?").
"""

from __future__ import annotations

import math

from ..errors import SpecError

__all__ = ["F_SUN_MAX", "check_input_speed"]

#: Highest accepted input speed (Hz): 30 000 rpm.
F_SUN_MAX = 500.0


def check_input_speed(value: float, option: str = "--f-sun") -> float:
    """`value` (Hz) as a float when ``0 < value <= F_SUN_MAX``; otherwise a
    :class:`~dtwin.errors.SpecError` naming `option`, with the rpm reading as a hint."""
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise SpecError([(option, f"must be the input speed in Hz, got {value!r}")]) from None
    if not math.isfinite(f) or not 0.0 < f <= F_SUN_MAX:
        hint = f" (did you mean {f:g} rpm = {f / 60:g} Hz?)" if f > F_SUN_MAX else ""
        raise SpecError([(option, f"must be the input speed in Hz in (0, {F_SUN_MAX:g}], got "
                                  f"{f:g}{hint}")])
    return f
