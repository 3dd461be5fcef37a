"""What one linearisation of the calibration is trusted with (docs/calibration.md, "How far
one linearisation goes").

- The mesh damping: a resonant line is ``1/ζ`` times its stiffness term, which the linearised
  response predicts to first order in ``log ζ``. :func:`zeta_step` is the step of ``log ζ`` at
  which that prediction of a single-degree-of-freedom oscillator's response at resonance —
  differentiated here by JAX, not from the closed form — is `relinearize_db` low, and the row
  that bounds the step is zero inside it and linear outside.
- The response's solve: a line the twin makes at the linearisation point keeps its weight in
  the closed-form solve of the sensor's response when a fit cancels it in the twin, so the fit
  cannot hand the knot that line held to the smoothness prior.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dtwin.identify.calibration_model import (
    CONTACT_TOL,
    _Data,
    _frf_solve,
    _zeta_rows,
    zeta_step,
)


def _sdof(log_zeta, w=1.0, wn=1.0):
    """Receptance of a unit-mass oscillator (rad/s) at `w`, damping ratio e^log_zeta."""
    zeta = jnp.exp(log_zeta)
    return 1.0 / (wn**2 - w**2 + 2j * zeta * w * wn)


@pytest.mark.parametrize("db", [0.5, 1.0, 2.0])
def test_the_damping_step_is_where_a_first_order_resonance_misses_by_the_departure(db):
    step = zeta_step(db)
    s0 = math.log(0.07)
    h0 = complex(_sdof(s0))
    dh = complex(jax.jacfwd(lambda s: _sdof(s).real)(s0)) + 1j * complex(
        jax.jacfwd(lambda s: _sdof(s).imag)(s0))
    first_order = abs(h0 + dh * step)
    exact = abs(complex(_sdof(s0 + step)))
    assert 20 * math.log10(first_order / exact) == pytest.approx(-db, abs=1e-6)
    # a smaller step misses by less
    assert abs(h0 + dh * step / 2) / abs(complex(_sdof(s0 + step / 2))) > first_order / exact


def _data(theta_lin, step, Z0=None, A=None, W=None, B=None, smooth=1.0):
    Z0 = jnp.zeros((1, 2), complex) if Z0 is None else jnp.asarray(Z0, complex)
    z = jnp.zeros(Z0.shape)
    P = len(theta_lin)
    return _Data(Z0=Z0, JZ=jnp.zeros((*Z0.shape, P), complex),
                 theta_lin=jnp.asarray(theta_lin, float),
                 A=z if A is None else jnp.asarray(A), F=z, S=z,
                 W=z if W is None else jnp.asarray(W),
                 B=jnp.zeros((Z0.shape[-1], 1)) if B is None else jnp.asarray(B),
                 prior_sd=jnp.ones(P), smooth=smooth, frf_prior=60.0, zeta_step=step)


def test_the_damping_row_is_zero_within_the_step_and_linear_beyond():
    step = zeta_step(1.0)
    data = _data([0.3, 0.2], step)  # θ's last entry is log ζ
    for inside in (0.2, 0.2 + 0.9 * step, 0.2 - 0.9 * step):
        assert float(_zeta_rows(jnp.array([5.0, inside]), data)[0]) == 0.0
    beyond = 0.2 - 1.5 * step
    np.testing.assert_allclose(np.asarray(_zeta_rows(jnp.array([0.0, beyond]), data)),
                               [0.5 * step / (CONTACT_TOL * step)])
    assert np.asarray(_zeta_rows(jnp.zeros(2), _data([0.0, 0.0], math.inf))).size == 0


def test_a_line_the_fit_cancels_keeps_its_weight_in_the_response_solve():
    # three lines, one knot each; the twin makes all three at the linearisation point and the
    # records hold them 40 dB below it
    Z0 = np.ones((1, 3))
    A = np.full((1, 3), 1e-2)
    data = _data([0.0], math.inf, Z0=Z0, A=A, W=np.ones((1, 3)), B=np.eye(3))
    G = np.asarray(_frf_solve(jnp.abs(jnp.asarray(Z0)), data))
    np.testing.assert_allclose(G, -40.0, atol=0.5)
    # a fit that cancels the middle line in the twin (80 dB down) raises that knot towards the
    # record (+40 dB), held back only by the smoothness prior (1 dB per second difference)
    cancelled = np.array([[1.0, 1e-4, 1.0]])
    G = np.asarray(_frf_solve(jnp.asarray(cancelled), data))
    assert G[1] > G[0] + 10.0, G
    # weighted by the twin's line at θ instead, the cancelled line would leave the solve and
    # the smoothness prior would set its knot on the others' straight line
    at_theta = _data([0.0], math.inf, Z0=cancelled, A=A, W=np.ones((1, 3)), B=np.eye(3))
    G = np.asarray(_frf_solve(jnp.asarray(cancelled), at_theta))
    np.testing.assert_allclose(G, -40.0, atol=0.5)
