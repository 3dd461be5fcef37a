"""Condition indicators of gear vibration: RMS, kurtosis, crest factor, FM0, FM4, NA4.

All indicators take a signal as the last axis of an array (numpy or JAX; JAX input gives JAX
output and is differentiable). FM0, FM4 and NA4 are defined on a time-synchronous average
(TSA, :mod:`dtwin.signal.tsa`) covering exactly one revolution of the reference shaft, sampled
uniformly in angle, so that FFT bin ``k`` of the TSA is shaft order ``k``.

Definitions (Stewart 1977; Zakrajsek, Townsend & Decker 1993; the review of Lebold, McClintic,
Campbell, Byington & Maynard 2000, "Review of vibration analysis methods for gearbox
diagnostics and prognostics", Proc. 54th MFPT):

- RMS ``= sqrt(mean(x^2))`` (about zero, in the signal's unit).
- kurtosis ``= mean((x - xbar)^4) / mean((x - xbar)^2)^2`` (normalised fourth moment, not the
  excess: a Gaussian gives 3, a sine 1.5).
- crest factor ``= max|x| / RMS``.
- FM0 ``= (max x - min x) / sum_h A(h * mesh_order)``: peak-to-peak of the TSA over the sum of
  the amplitudes of the mesh harmonics (Stewart 1977).
- FM4: kurtosis of the *difference signal* ``d`` = TSA minus the regular meshing components
  (the shaft orders listed, the mesh harmonics and their first-order sidebands) (Stewart 1977).
- NA4: the *residual signal* ``r`` = TSA minus the shaft orders and the mesh harmonics
  (sidebands kept); ``NA4 = mean((r - rbar)^4) / (mean_j var(r_j))^2`` with the variance averaged
  over the run history ``j = 1..M`` up to the current record (Zakrajsek et al. 1993). Without a
  history NA4 is the kurtosis of the residual.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..errors import RecordError

__all__ = [
    "TimeStats",
    "crest_factor",
    "difference_signal",
    "fm0",
    "fm4",
    "kurtosis",
    "na4",
    "residual_signal",
    "rms",
    "time_stats",
]


def _xp(x):
    return jnp if isinstance(x, jax.Array) else np


def _as_array(x):
    if isinstance(x, jax.Array):
        return x
    return np.asarray(x, dtype=np.float64)


def rms(x: Float[Array, "... time"]) -> Float[Array, "..."]:
    """Root mean square ``sqrt(mean(x^2))`` over the last axis (unit of `x`)."""
    x = _as_array(x)
    xp = _xp(x)
    return xp.sqrt(xp.mean(x * x, axis=-1))


def kurtosis(x: Float[Array, "... time"]) -> Float[Array, "..."]:
    """Normalised fourth central moment ``m4 / m2^2`` over the last axis (dimensionless).

    Gaussian noise gives 3, a sine 1.5, a sparse train of impulses much more. Not the excess
    kurtosis (no ``- 3``).
    """
    x = _as_array(x)
    xp = _xp(x)
    d = x - xp.mean(x, axis=-1, keepdims=True)
    m2 = xp.mean(d * d, axis=-1)
    m4 = xp.mean(d**4, axis=-1)
    return m4 / (m2 * m2)


def crest_factor(x: Float[Array, "... time"]) -> Float[Array, "..."]:
    """Crest factor ``max|x| / RMS`` over the last axis (dimensionless; a sine gives sqrt 2)."""
    x = _as_array(x)
    xp = _xp(x)
    return xp.max(xp.abs(x), axis=-1) / rms(x)


class TimeStats(NamedTuple):
    """RMS (signal unit), kurtosis and crest factor (dimensionless) of a time signal."""

    rms: Float[Array, "..."]
    kurtosis: Float[Array, "..."]
    crest_factor: Float[Array, "..."]


def time_stats(x: Float[Array, "... time"]) -> TimeStats:
    """RMS, kurtosis and crest factor of `x` over its last axis (see the module docstring)."""
    return TimeStats(rms(x), kurtosis(x), crest_factor(x))


def _order_mask(n: int, orders: Sequence[float]) -> np.ndarray:
    """Boolean mask over the rfft bins of an n-sample one-revolution signal, True at `orders`."""
    n_bins = n // 2 + 1
    mask = np.zeros(n_bins, dtype=bool)
    for o in orders:
        k = int(round(float(o)))
        if abs(k - float(o)) > 1e-9:
            raise RecordError(
                f"order {o} is not an integer: FM0/FM4/NA4 need a TSA over one revolution of the "
                "shaft whose mesh order (tooth count) is an integer; average over the right shaft"
            )
        if 0 <= k < n_bins:
            mask[k] = True
    return mask


def _regular_orders(
    n: int, mesh_order: int, shaft_orders: Sequence[int], sidebands: int
) -> list[int]:
    orders = [int(o) for o in shaft_orders]
    h = 1
    while h * mesh_order <= n // 2:
        for s in range(-sidebands, sidebands + 1):
            orders.append(h * mesh_order + s)
        h += 1
    return orders


def _remove_orders(tsa, orders: Sequence[int]):
    tsa = _as_array(tsa)
    xp = _xp(tsa)
    n = tsa.shape[-1]
    mask = _order_mask(n, orders)
    spec = xp.fft.rfft(tsa, axis=-1)
    keep = xp.asarray(~mask)
    return xp.fft.irfft(spec * keep, n=n, axis=-1)


def _check_tsa(tsa, mesh_order: int):
    n = tsa.shape[-1]
    if mesh_order < 1 or mesh_order > n // 2:
        raise RecordError(
            f"mesh order {mesh_order} must lie between 1 and half the TSA length ({n // 2}); "
            "resample the TSA with more samples per revolution"
        )


def difference_signal(
    tsa: Float[Array, "... angle"],
    mesh_order: int,
    *,
    shaft_orders: Sequence[int] = (1,),
    sidebands: int = 1,
) -> Float[Array, "... angle"]:
    """TSA minus the regular meshing components (Stewart 1977): DC is kept only as the mean.

    Removes, by zeroing their FFT bins, the `shaft_orders`, every mesh harmonic ``h * mesh_order``
    and its sidebands ``h * mesh_order +- 1 .. sidebands``.

    **Arguments:**

    - `tsa`: one revolution of a time-synchronous average, uniformly sampled in angle.
    - `mesh_order`: teeth of the gear the TSA belongs to (mesh cycles per revolution).
    - `shaft_orders`: shaft orders removed besides the mesh components (default the first).
    - `sidebands`: how many sideband orders each side of every mesh harmonic are removed.

    **Returns:** the difference signal (unit of `tsa`).
    """
    tsa = _as_array(tsa)
    _check_tsa(tsa, mesh_order)
    return _remove_orders(tsa, _regular_orders(tsa.shape[-1], mesh_order, shaft_orders, sidebands))


def residual_signal(
    tsa: Float[Array, "... angle"], mesh_order: int, *, shaft_orders: Sequence[int] = (1,)
) -> Float[Array, "... angle"]:
    """TSA minus the shaft orders and the mesh harmonics, sidebands kept (Zakrajsek 1993)."""
    tsa = _as_array(tsa)
    _check_tsa(tsa, mesh_order)
    return _remove_orders(tsa, _regular_orders(tsa.shape[-1], mesh_order, shaft_orders, 0))


def fm0(tsa: Float[Array, "... angle"], mesh_order: int) -> Float[Array, "..."]:
    """FM0 = peak-to-peak of the TSA / sum of the mesh-harmonic amplitudes (Stewart 1977).

    The amplitude of order ``k`` is ``2 |X_k| / n`` (one-sided, a sine of amplitude A gives A).
    A TSA that is a pure mesh tone ``A cos(Z theta)`` gives FM0 = 2.
    """
    tsa = _as_array(tsa)
    _check_tsa(tsa, mesh_order)
    xp = _xp(tsa)
    n = tsa.shape[-1]
    spec = xp.fft.rfft(tsa, axis=-1)
    harm = np.arange(mesh_order, n // 2 + 1, mesh_order)
    amp = 2.0 * xp.abs(spec[..., harm]) / n
    if n % 2 == 0 and harm[-1] == n // 2:  # the Nyquist bin is not doubled
        amp = amp * xp.asarray(np.where(harm == n // 2, 0.5, 1.0))
    pp = xp.max(tsa, axis=-1) - xp.min(tsa, axis=-1)
    return pp / xp.sum(amp, axis=-1)


def fm4(
    tsa: Float[Array, "... angle"],
    mesh_order: int,
    *,
    shaft_orders: Sequence[int] = (1,),
    sidebands: int = 1,
) -> Float[Array, "..."]:
    """FM4 = kurtosis of the difference signal (Stewart 1977); about 3 for a healthy gear."""
    return kurtosis(
        difference_signal(tsa, mesh_order, shaft_orders=shaft_orders, sidebands=sidebands)
    )


def na4(
    tsa: Float[Array, " angle"],
    mesh_order: int,
    history: Sequence[Float[Array, " angle"]] = (),
    *,
    shaft_orders: Sequence[int] = (1,),
) -> Float[Array, ""]:
    """NA4 (Zakrajsek, Townsend & Decker 1993): residual kurtosis normalised by the run history.

    ``NA4 = mean((r - rbar)^4) / ((1/M) sum_j var(r_j))^2`` where ``r`` is the residual signal of
    the current TSA and ``r_j`` those of the M TSAs of the run so far (the `history` plus the
    current one). With an empty history NA4 equals the kurtosis of the residual.

    **Arguments:**

    - `tsa`: the current one-revolution TSA.
    - `mesh_order`: teeth of the gear (mesh cycles per revolution).
    - `history`: earlier TSAs of the same gear and run (same length), oldest first.
    - `shaft_orders`: shaft orders removed with the mesh harmonics.

    **Returns:** NA4 (dimensionless; about 3 for a healthy gear with Gaussian residual).
    """
    tsa = _as_array(tsa)
    xp = _xp(tsa)
    r = residual_signal(tsa, mesh_order, shaft_orders=shaft_orders)
    d = r - xp.mean(r)
    m4 = xp.mean(d**4)
    variances = [xp.var(residual_signal(_as_array(h), mesh_order, shaft_orders=shaft_orders))
                 for h in history]
    variances.append(xp.mean(d * d))
    mean_var = sum(variances) / len(variances)
    return m4 / (mean_var * mean_var)
