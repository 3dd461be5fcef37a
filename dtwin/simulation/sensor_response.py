"""A smooth sensor frequency response: the transfer path's magnitude over the band.

The path from a gear mesh to an accelerometer on a housing (housing structure, bolted joints,
the sensor's mount and its own response) multiplies each spectral line by a gain that varies
smoothly with frequency between the housing's resonances. A calibrated twin describes it by a
few knots ``(f_j, G_j)`` (Hz, dB), log-spaced over the band, and interpolates the gain in dB
linearly in ``log f``; below the first and above the last knot the gain is held constant.
Only the magnitude is modelled (zero phase): the residuals of identification compare
amplitudes, which a phase response does not change.

The gain in dB is linear in the knot values ``G_j``, so a fit can solve for them in closed
form inside its residual function (variable projection: Golub & Pereyra 1973, "The
differentiation of pseudo-inverses and nonlinear least squares problems whose variables
separate").
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float


def knot_basis(freqs: ArrayLike, knots_hz: ArrayLike) -> np.ndarray:
    """Interpolation matrix ``B`` (n_freqs, n_knots): ``gain_db(f) = B @ G``.

    Linear interpolation in ``log f`` between knots, constant outside them; a frequency at or
    below 0 takes the first knot's gain.
    """
    f = np.asarray(freqs, dtype=np.float64)
    k = np.log(np.asarray(knots_hz, dtype=np.float64))
    if k.ndim != 1 or k.size < 1 or np.any(np.diff(k) <= 0):
        raise ValueError("FRF knots must be a non-empty, increasing list of positive Hz")
    lf = np.log(np.clip(f, np.exp(k[0]), np.exp(k[-1])))
    B = np.zeros((f.size, k.size))
    if k.size == 1:
        B[:, 0] = 1.0
        return B
    j = np.clip(np.searchsorted(k, lf, side="right") - 1, 0, k.size - 2)
    u = (lf - k[j]) / (k[j + 1] - k[j])
    B[np.arange(f.size), j] = 1.0 - u
    B[np.arange(f.size), j + 1] = u
    return B


def frf_gain(freqs: ArrayLike, knots_hz, gains_db) -> Float[Array, " n"]:
    """Linear gain (1) of the smooth response at `freqs` (Hz): ``10^(gain_db/20)``.

    **Arguments:** `freqs` (Hz); `knots_hz` (Hz, increasing); `gains_db` (dB re 1, one per
    knot; may be a JAX array, the result is differentiable in it).
    """
    B = jnp.asarray(knot_basis(freqs, knots_hz))
    return 10.0 ** ((B @ jnp.asarray(gains_db, dtype=jnp.float64)) / 20.0)


def apply_frf(x: Float[Array, " n"], sample_rate: float, knots_hz, gains_db) -> Array:
    """`x` filtered by the zero-phase smooth response (frequency domain, circular).

    **Arguments:** `x` a record (any unit); `sample_rate` (Hz); `knots_hz`, `gains_db` as in
    :func:`frf_gain`. **Returns:** the filtered record, same length and unit.
    """
    n = x.shape[0]
    g = frf_gain(np.fft.rfftfreq(n, 1.0 / sample_rate), knots_hz, gains_db)
    return jnp.fft.irfft(jnp.fft.rfft(x) * jax.lax.complex(g, jnp.zeros_like(g)), n)
