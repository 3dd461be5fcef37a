"""Calibration of the discovery significance statistic (issue 8): on ≥ 500 cheap null draws
the false-alarm rate of the bootstrap p-value is within a factor 1.5 of the nominal level.

Cheap: synthetic spectra (a base gearbox-like line set plus white noise, a two-parameter effect
adding sidebands), no ODE. The null records are made in the *time domain* (sinusoids + white
noise, then the same segment spectra and running-median floor as `discover`), independently of
the bootstrap's spectral noise generator, so the test checks the noise model, the floor
estimate and the whole fit-and-score procedure."""

import numpy as np
import pytest

from dtwin.identify.discover import (
    candidate_inputs,
    heldout_statistic,
    null_statistics,
    p_value,
)
from dtwin.identify.gap import FLOOR_BINS, segment_spectra
from dtwin.signal.spectrum import noise_floor

FS, N = 5000.0, 10000
T = np.arange(N) / FS
BASE = [(500.0, 1.0), (482.0, 0.3), (518.0, 0.3), (1000.0, 0.2)]
SIDEBANDS = [494.0, 506.0, 488.0, 512.0, 994.0, 1006.0]
SIGMA = 0.02


def _tones(lines, phase=0.0):
    return sum(a * np.sin(2 * np.pi * f * T + phase) for f, a in lines)


def _effect_columns():
    rng = np.random.default_rng(5)
    cols = []
    for _ in range(2):
        cols.append(sum(0.01 * rng.uniform(0.3, 1.0) * np.sin(2 * np.pi * f * T
                                                              + rng.uniform(0, 2 * np.pi))
                        for f in SIDEBANDS))
    return np.stack(cols)  # (p, n)


def _inputs(x, Z0, Jc):
    freqs, Yc = segment_spectra(x, FS)
    Y = np.abs(Yc)
    floor = noise_floor(Y, FLOOR_BINS)
    df = freqs[1] - freqs[0]
    sig = np.zeros(Y.shape, bool)
    for f in SIDEBANDS:
        k = int(round(f / df))
        sig[:, k - 1: k + 2] = True
    model_line = np.abs(Z0) > floor * 10 ** (12 / 20)
    model_line[:, 1:] |= model_line[:, :-1].copy()
    model_line[:, :-1] |= model_line[:, 1:].copy()
    sig &= ~model_line
    inp, sel, K = candidate_inputs(Z0, Jc, Y, floor, sig, model_line, [False, False],
                                   np.zeros(2))
    return inp, sel, K


@pytest.fixture(scope="module")
def setup():
    base = _tones(BASE)
    _, Z0 = segment_spectra(base, FS)
    _, Jc = segment_spectra(_effect_columns(), FS)
    Jc = np.moveaxis(Jc, 0, -1)
    rng = np.random.default_rng(11)
    x_ref = base + SIGMA * rng.standard_normal(N)
    inp, sel, K = _inputs(x_ref, Z0, Jc)
    floor = noise_floor(np.abs(segment_spectra(x_ref, FS)[1]), FLOOR_BINS)
    t_null = null_statistics(inp, rng, 2000, Z0, floor, sel, N // 2)
    return base, Z0, Jc, t_null


def test_false_alarm_rate_calibrated(setup):
    base, Z0, Jc, t_null = setup
    rng = np.random.default_rng(123)
    n_draws = 600
    pvals = []
    for _ in range(n_draws):
        x = base + SIGMA * rng.standard_normal(N)
        inp, _, _ = _inputs(x, Z0, Jc)
        t, _ = heldout_statistic(inp)
        pvals.append(p_value(float(t), t_null, rng))
    pvals = np.array(pvals)
    for alpha in (0.05, 0.1):
        rate = float(np.mean(pvals <= alpha))
        assert alpha / 1.5 <= rate <= 1.5 * alpha, (alpha, rate)


def test_effect_is_detected(setup):
    # power against a real effect of a few noise-floor heights (independent of the null)
    base, Z0, Jc, t_null = setup
    rng = np.random.default_rng(7)
    eff = _effect_columns()
    x = base + 2.0 * eff[0] - 1.5 * eff[1] + SIGMA * rng.standard_normal(N)
    inp, _, _ = _inputs(x, Z0, Jc)
    t, params = heldout_statistic(inp)
    assert p_value(float(t), t_null) < 0.01 / 6
    # each fold recovers the effect's amplitude (norm of the parameters, 2.5) within 20 %
    for p in np.asarray(params):
        assert np.linalg.norm(p[:2]) == pytest.approx(2.5, rel=0.2)


def test_confidence_sets_the_identification_threshold():
    """`DiscoverySettings.confidence` acts: the χ² threshold of the amplitude's profile interval
    is the published quantile (χ²₁: 3.841 at 95 %, 6.635 at 99 %; Abramowitz & Stegun 1964,
    table 26.8), and an effect whose evidence lies between the two is identified at 95 % and
    not at 99 % (the 95 % interval excludes zero, the 99 % one does not)."""
    from dtwin.identify.discover import (
        amplitude_profile,
        chi2_quantile,
        fit_joint,
        is_identified,
        normal_quantile,
        residual_variance,
    )

    assert chi2_quantile(0.95) == pytest.approx(3.841459, abs=1e-5)
    assert chi2_quantile(0.99) == pytest.approx(6.634897, abs=1e-5)
    assert normal_quantile(0.99) == pytest.approx(2.575829, abs=1e-6)
    base = _tones(BASE)
    _, Z0 = segment_spectra(base, FS)
    _, Jc = segment_spectra(_effect_columns(), FS)
    Jc = np.moveaxis(Jc, 0, -1)
    eff = _effect_columns()
    rng = np.random.default_rng(7)
    x = base + 0.15 * (eff[0] - 0.75 * eff[1]) + SIGMA * rng.standard_normal(N)
    inp, _, _ = _inputs(x, Z0, Jc)
    _, fold_params = heldout_statistic(inp)
    val, _, _, r = fit_joint(inp, np.asarray(fold_params))
    s2 = residual_variance(inp, r, 2 + 2)
    decided = {}
    for c in (0.95, 0.99):
        c_lo, c_hi, evidence = amplitude_profile(inp, val, s2, chi2_quantile(c))
        decided[c] = (c_lo, c_hi, is_identified(c_lo, evidence, 1.0, c))
    assert chi2_quantile(0.95) < evidence < chi2_quantile(0.99), evidence
    assert decided[0.95][2] and not decided[0.99][2]
    # nested intervals: the 99 % profile interval contains the 95 % one
    assert decided[0.99][0] <= decided[0.95][0] and decided[0.99][1] >= decided[0.95][1]
