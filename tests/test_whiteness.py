"""The whiteness test of a fit's residuals (issue 53, "an interval is ok only when the fit passes
its own checks"): :func:`dtwin.identify.uncertainty.residual_whiteness` against residuals whose
correlation is known in closed form, :func:`dtwin.identify.residuals.window_reach` against the
DFT grid, and the status a fit reports when its residuals are not white."""

import dataclasses

import numpy as np
import pytest

from dtwin.identify.uncertainty import WHITENESS_P, residual_whiteness

#: the Hann window's transform on the bin grid: each bin is −¼, ½, −¼ of its neighbours' noise
HANN_TAPS = np.array([-0.25, 0.5, -0.25])


def _hann_log_residuals(rng, n_groups=40, size=60):
    """Log-amplitude residuals of noise-only bins seen through a Hann window: complex white
    noise convolved with the window's three taps (neighbours correlated, -2/3 in the complex
    bins, nothing beyond two bins), its log amplitude less the mean; and the group of each."""
    z = rng.normal(size=(n_groups, size + 2)) + 1j * rng.normal(size=(n_groups, size + 2))
    x = np.stack([np.convolve(row, HANN_TAPS, mode="valid") for row in z])
    r = np.log(np.abs(x))
    r = r - r.mean()
    return r.ravel(), np.repeat(np.arange(n_groups), size)


def test_noise_through_a_hann_window_is_white_past_its_reach():
    """Under the null (Hann-correlated noise, nothing past two bins) the p-values are uniform:
    about 5 % fall below 0.05 (binomial 99.9 % bound over 300 draws), none below
    WHITENESS_P; reading the correlation within the reach as whiteness (reach 0) rejects."""
    rng = np.random.default_rng(11)
    ps = np.array([residual_whiteness(*_hann_log_residuals(rng), reach=2)[1] for _ in range(300)])
    assert 0.015 <= np.mean(ps < 0.05) <= 0.095, np.mean(ps < 0.05)
    assert np.mean(ps < WHITENESS_P) <= 2 / 300
    r, g = _hann_log_residuals(rng)
    assert residual_whiteness(r, g, reach=0)[1] < 1e-6


def test_a_misfit_coherent_over_several_bins_is_not_white():
    """A model line narrower than the measured one (a speed that drifts over the record smears
    each line over ~9 bins) leaves a residual of one sign over those bins, below the noise's
    size: the loss grows by a quarter (the lack-of-fit rule widens from twice the noise's), the
    test rejects."""
    rng = np.random.default_rng(5)
    r, g = _hann_log_residuals(rng)
    sd = r.std()
    bump = np.zeros(60)
    for c in (10, 30, 50):
        bump[c - 4:c + 5] = 0.7 * sd
    smeared = r + np.tile(bump, 40)
    assert np.sum(smeared ** 2) < 1.3 * np.sum(r ** 2)
    assert residual_whiteness(smeared, g, reach=2)[1] < WHITENESS_P


def test_a_lone_missing_line_stays_within_the_reach():
    """A line the model lacks is a residual confined to the window's reach: the whiteness test
    does not see it (the lack-of-fit rule and the band jackknife do; module docstring)."""
    rng = np.random.default_rng(5)
    r, g = _hann_log_residuals(rng)
    line = np.zeros(60)
    line[[29, 30, 31]] = [1.0, 3.0, 1.0]
    assert residual_whiteness(r + np.tile(line, 40), g, reach=2)[1] > WHITENESS_P


def test_too_few_points_give_no_verdict():
    assert all(np.isnan(residual_whiteness(np.ones(3), np.zeros(3), reach=2)))
    assert all(np.isnan(residual_whiteness(np.zeros(50), np.zeros(50))))


@pytest.mark.parametrize(("step_bins", "interpolated", "reach"),
                         [(1.0, False, 2), (0.5, True, 5), (2.0, False, 2), (0.25, True, 9)])
def test_window_reach_counts_points_of_the_grid(step_bins, interpolated, reach):
    """Two DFT bins in points of the fit's grid, one more where points lie between bins."""
    from types import SimpleNamespace

    from dtwin.identify.residuals import window_reach

    fs, n = 5000.0, 10000
    freqs = 500.0 + np.arange(40) * step_bins * fs / n
    obs = SimpleNamespace(sample_rate=fs, n_samples=n, kind="spectrum", segment_len=n,
                          freqs=freqs, group=np.zeros(40, int),
                          w=np.full(40, 0.5 if interpolated else 0.0))
    assert window_reach([obs]) == reach


def test_a_fit_whose_residuals_are_not_white_is_not_ok():
    """The fit's status: "ok" only when the whiteness test passes too; otherwise it names it."""

    from dtwin.identify.fit import FitResult
    from dtwin.identify.uncertainty import Uncertainty

    unc = Uncertainty(names=("sun_fault",), values=np.array([0.3]), std=np.array([0.01]),
                      interval=np.array([[0.28, 0.32]]), cov_theta=np.eye(1), cov=np.eye(1),
                      correlation=np.eye(1), singular_values=np.ones(1),
                      null_directions=np.zeros((0, 1)), not_determined={}, s2=1.0, kappa=1.9,
                      m=400, m_eff=210.0, dof=399, whiteness=3.0, whiteness_p=0.8)
    res = FitResult(names=("sun_fault",), values={"sun_fault": 0.3}, theta=np.zeros(1),
                    initial={"sun_fault": 0.2}, uncertainty=unc, loss=200.0, loss_history=[],
                    start_losses=np.zeros(1), starts=np.zeros((1, 1)), refined=[],
                    converged=True, at_bound=[], message="converged", iterations=5,
                    wall_time=1.0, operating_points=[])
    assert res.status("sun_fault") == "ok"
    bad = dataclasses.replace(res, uncertainty=dataclasses.replace(unc, whiteness=40.0,
                                                                   whiteness_p=2e-6))
    assert bad.status("sun_fault") == "residuals not white (p = 2e-06)"
    assert bad.uncertainty.to_dict()["whiteness_p"] == 2e-6
