"""Tests of dtwin.signal.indicators on small signals whose values are computed by hand."""

import jax.numpy as jnp
import numpy as np
import pytest

from dtwin.errors import RecordError
from dtwin.signal.indicators import (
    crest_factor,
    difference_signal,
    fm0,
    fm4,
    kurtosis,
    na4,
    residual_signal,
    rms,
    time_stats,
)


def test_rms_kurtosis_crest_on_four_samples():
    x = np.array([0.0, 0.0, 0.0, 4.0])
    # rms = sqrt(16/4) = 2; deviations from mean 1: -1,-1,-1,3 -> m2 = 3, m4 = 21 -> 21/9
    assert rms(x) == pytest.approx(2.0)
    assert kurtosis(x) == pytest.approx(21 / 9)
    assert crest_factor(x) == pytest.approx(2.0)
    s = time_stats(jnp.asarray(x))
    assert float(s.kurtosis) == pytest.approx(21 / 9)
    assert float(s.rms) == pytest.approx(2.0)


def _theta(n=256):
    return 2 * np.pi * np.arange(n) / n


def test_fm0_of_a_pure_mesh_tone_is_two():
    th = _theta()
    assert fm0(3.0 * np.cos(20 * th), 20) == pytest.approx(2.0)
    # u + 0.5 (2u^2 - 1) with u = cos(20 th): max 1.5 (u = 1), min -0.75 (u = -1/2);
    # p-p 2.25 over the harmonic sum 1.5 -> 1.5
    th = _theta(240)  # 12 samples per mesh period: u = -1/2 is sampled
    assert fm0(np.cos(20 * th) + 0.5 * np.cos(40 * th), 20) == pytest.approx(1.5)
    # a shaft-order component adds peak-to-peak but no mesh amplitude: p-p(cos20 + cos 3) = 4
    x = np.cos(20 * th) + np.cos(3 * th)
    assert fm0(x, 20) == pytest.approx((x.max() - x.min()) / 1.0)


def test_fm4_is_the_kurtosis_of_what_is_left():
    th = _theta()
    x = np.cos(20 * th) + 0.3 * np.cos(19 * th) + 0.2 * np.cos(th) + 0.5 * np.cos(3 * th)
    d = difference_signal(x, 20)
    np.testing.assert_allclose(d, 0.5 * np.cos(3 * th), atol=1e-12)
    assert fm4(x, 20) == pytest.approx(1.5)  # kurtosis of a sine
    # residual keeps the sidebands
    np.testing.assert_allclose(residual_signal(x, 20), 0.3 * np.cos(19 * th) + 0.5 * np.cos(3 * th),
                               atol=1e-12)


def test_na4_against_hand_computation():
    th = _theta()
    mesh = np.cos(20 * th)
    old = mesh + 0.5 * np.cos(3 * th)  # residual variance 0.125
    new = mesh + 1.0 * np.cos(3 * th)  # residual variance 0.5, m4 = 3/8
    assert na4(new, 20) == pytest.approx(1.5)  # no history: kurtosis of the residual
    assert na4(new, 20, [old]) == pytest.approx(0.375 / ((0.125 + 0.5) / 2) ** 2)


def test_non_integer_mesh_order_refused():
    with pytest.raises(RecordError, match="mesh order"):
        fm0(np.ones(16), 12)
