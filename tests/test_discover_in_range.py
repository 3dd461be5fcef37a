"""A candidate whose linearised fit leaves its physical range is refitted inside it
(:mod:`dtwin.identify.discover.in_range`), not set aside."""

from __future__ import annotations

import numpy as np

from dtwin.identify.discover.in_range import SCALES, in_range_trials, refit_in_range
from dtwin.identify.discover.results import CandidateResult


def test_trials_stay_inside_the_bounds_along_the_fitted_direction():
    """A severity of 1.186 on [0, 1] and a second parameter inside its range: every trial lies
    in the box, the first is the clipped fit, the others shrink it by SCALES (closed form)."""
    theta = np.array([1.186, 0.2])
    trials = in_range_trials(theta, [(0.0, 1.0), (0.0, 0.5)])
    assert len(trials) == len(SCALES)
    np.testing.assert_allclose(trials[0], [1.0, 0.2])
    for s, t in zip(SCALES, trials, strict=True):
        np.testing.assert_allclose(t, [s * 1.0, s * 0.2])
        assert np.all(t >= 0.0) and t[0] <= 1.0 and t[1] <= 0.5


def test_a_lower_bound_above_zero_holds():
    trials = in_range_trials(np.array([5.0]), [(0.5, 2.0)])
    assert min(t[0] for t in trials) >= 0.5 and trials[0][0] == 2.0


def test_refit_records_the_value_and_says_why_there_is_no_interval():
    class Effect:
        @staticmethod
        def main(theta):
            return theta[0]

    cand = CandidateResult("sun_local_fault", "sun_rotation", 0.9, [])
    cand.out_of_range = "pitting severity = 1.186 1 lies outside its physical range [0, 1]"
    refit_in_range(cand, np.array([0.55]), Effect(), [4.0, 3.1, 5.2])
    assert cand.main == 0.55 and np.isnan(cand.main_interval[0])
    assert "refitted inside the range" in cand.out_of_range and "3.10" in cand.out_of_range
    assert cand.to_dict()["out_of_range"] == cand.out_of_range
