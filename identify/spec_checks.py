"""The fitted values checked against the spec: parameters the calibrated mesh excitation and
load-share clearances confound (:mod:`dtwin.identify.confounding`), and a mesh stiffness the
spec's gear pair cannot have (:mod:`dtwin.identify.plausibility`). Used by
:func:`dtwin.identify.fit.fit` and :func:`dtwin.identify.fit_batch.fit_batch` after the
uncertainty analysis."""

from __future__ import annotations

from .confounding import calibrated_excitation, calibration_confounding, needs_check
from .plausibility import MESHES, flag_implausible
from .problem import Problem, calibrated_spec, spec_of
from .solve import jacobian_at
from .uncertainty import Uncertainty

__all__ = ["checked_against_spec", "checked_stiffness"]


def checked_against_spec(unc: Uncertainty, problem: Problem, theta, spec_or_twin, *,
                         confounding: bool, groups, expected_rss, say=lambda m: None
                         ) -> Uncertainty:
    """`unc` with the calibration's confounding flagged (with `confounding`, a calibrated spec
    and a free parameter it can confound: one more Jacobian) and an implausible mesh stiffness
    flagged (:func:`checked_stiffness`)."""
    spec = calibrated_spec(spec_or_twin)
    if confounding and spec is not None and needs_check(problem.pset.free, spec):
        say("checking the fitted values against the calibration (one more Jacobian, with "
            f"its {len(calibrated_excitation(spec))} excitation coefficients and load-share "
            "clearances free) …")
        unc, _ = calibration_confounding(problem, theta, unc, spec, groups=groups,
                                         expected_rss=expected_rss, jacobian=jacobian_at)
    return checked_stiffness(unc, problem.pset, theta, spec_or_twin)


def checked_stiffness(unc, pset, theta, spec_or_twin):
    """`unc` with a free mesh stiffness that the spec's gear pair cannot have flagged, and
    the parameters fitted beside it (:mod:`dtwin.identify.plausibility`); the spec is read only
    when a mesh stiffness is free."""
    if unc is None or not any(n in MESHES for n in pset.free):
        return unc
    return flag_implausible(unc, pset.as_dict(theta), spec_of(spec_or_twin))
