"""A candidate whose linearised fit leaves its physical range, refitted inside it.

Discovery fits each candidate with the linearised model ``|Z0 + J θ|``
(:mod:`dtwin.identify.discover.statistics`). A tooth fault's spectrum is not linear in its
severity: where the record's fault is deep, the linear model can place the severity beyond its
range (a pitting severity of 1.19 on a record whose truth is 0.6). Such a candidate is not set
aside: its parameters are brought inside their bounds and scaled down along their direction
(:func:`in_range_trials`), each trial is simulated in full, and the one with the smallest
held-out gap is kept (:func:`refit_in_range`). The candidate is then confirmed, or not, as any
other. Its interval is not the linearised one (the linear model did not hold there): the step
reports none and says why; ``dtwin severity`` gives the depth with its interval.
"""

from __future__ import annotations

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np

from .results import CandidateResult

#: Fractions of the in-range parameters tried (along the fitted direction, from the bound
#: inwards): the full model's gap over a fault's depth is smooth and one-sided, so a coarse
#: geometric grid brackets its minimum.
SCALES = (1.0, 0.75, 0.55, 0.4, 0.3, 0.2)


def in_range_trials(theta: np.ndarray, bounds: Sequence[tuple[float, float]]) -> list[np.ndarray]:
    """Parameter vectors inside `bounds` along `theta`'s direction: `theta` clipped to its
    bounds, times each of :data:`SCALES` (each clipped again, so a lower bound above 0 holds).

    **Arguments:** `theta` (the linearised fit, physical units); `bounds` (``(low, high)`` per
    parameter). **Returns:** the trial vectors, first the clipped one.
    """
    lo = np.array([b[0] for b in bounds], dtype=float)
    hi = np.array([b[1] for b in bounds], dtype=float)
    clipped = np.clip(np.asarray(theta, dtype=float), lo, hi)
    return [np.clip(s * clipped, lo, hi) for s in SCALES]


def refit_in_range(cand: CandidateResult, theta: np.ndarray, effect, gaps: Sequence[float],
                   say=lambda s: None) -> None:
    """Record on `cand` the in-range parameters `theta` chosen by the full model (the trial of
    least held-out gap among `gaps`, dB): its values, main value, and a note; the linearised
    sigma and interval no longer apply and are set to NaN."""
    cand.theta = np.asarray(theta, dtype=float)
    cand.sigma = np.full(cand.theta.shape, np.nan)
    cand.main = float(effect.main(jnp.asarray(cand.theta)))
    cand.main_sigma = float("nan")
    cand.main_interval = (float("nan"), float("nan"))
    cand.out_of_range = (f"{cand.out_of_range}; refitted inside the range in full simulation "
                         f"({len(gaps)} trials, held-out gap {min(gaps):.2f} to "
                         f"{max(gaps):.2f} dB): {cand.main:.3g}, no interval from the "
                         f"linearised model")
    say(f"    {cand.name}: {cand.out_of_range}")
