"""`fit` and `fit_batch` take a `FitSettings` and keyword overrides of its fields (issue #52):
the same settings either way, make_problem's keywords passed on, any other name refused with
the names that exist, before anything is built or simulated."""

import pytest

from dtwin.errors import SettingsError
from dtwin.identify.fit import fit, fit_batch
from dtwin.identify.fit_settings import FIELDS, FitSettings, settings_and_problem_kwargs
from dtwin.identify.problem import PROBLEM_KEYS


def test_overrides_replace_fields_and_problem_keywords_pass_on():
    base = FitSettings(max_steps=5, starts=3)
    s, kw = settings_and_problem_kwargs(base, {"tol": 1e-3, "f_sun": 30.0, "jac": "rev"},
                                        PROBLEM_KEYS)
    assert s == FitSettings(max_steps=5, starts=3, tol=1e-3, jac="rev")
    assert kw == {"f_sun": 30.0}
    assert settings_and_problem_kwargs(None, {}, PROBLEM_KEYS) == (FitSettings(), {})
    assert settings_and_problem_kwargs(base, {}, PROBLEM_KEYS)[0] is base
    assert "jac" in FIELDS and "jac" not in PROBLEM_KEYS and "f_sun" in PROBLEM_KEYS


def test_an_unknown_name_is_refused_with_the_names_that_exist():
    with pytest.raises(SettingsError) as e:
        fit(None, "no-such-spec.toml", ["sun_fault"], max_step=3)
    msg = str(e.value)
    assert "'max_step'" in msg and "max_steps" in msg and "f_sun" in msg


def test_a_bad_solver_is_refused_as_before():
    with pytest.raises(SettingsError, match="solver must be one of"):
        fit(None, "no-such-spec.toml", ["sun_fault"], solver="newton")
    with pytest.raises(SettingsError, match="solver must be one of"):
        FitSettings(solver="newton")
    with pytest.raises(SettingsError, match="FitSettings"):
        fit(None, "no-such-spec.toml", ["sun_fault"], {"max_steps": 3})


def test_fit_batch_refuses_the_settings_it_has_no_use_for():
    with pytest.raises(SettingsError, match="'starts'"):
        fit_batch([], "no-such-spec.toml", ["sun_fault"], starts=3)
