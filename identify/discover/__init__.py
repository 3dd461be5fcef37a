"""Discrepancy discovery: where the twin and the measurement disagree, which effect explains it,
add it, refit, and show the held-out gap shrink (docs/discovery.md).

**Loop** (:func:`discover`): speed given or from the data (:func:`dtwin.identify.operating_point.resolve_speed`); the
base twin simulated over the record; then per step

1. residual lines over 0 … Nyquist (:func:`dtwin.identify.lines.residual_lines`), each with its
   kinematic description, fault combs and a modulation at a located frequency found as
   families (:func:`dtwin.identify.lines.find_combs`, :func:`~dtwin.identify.lines.find_modulation`);
2. the candidates whose signature covers at least `min_coverage` of the residual line power
   (measured over model; :func:`coverage`) are each scored at zero amplitude by a score test
   (:func:`~dtwin.identify.discover.statistics.screen_score`: one response column per
   parameter, no refit) and the best `max_refit` by score are refit (when those are all
   look-alikes of one group, the best candidate of another group too, so that two kinds of
   explanation are compared);
3. each is refit about the current model (below) and scored on held-out data: statistic ``T``,
   bootstrap p-value, held-out gap (:mod:`dtwin.identify.gap`) and parameter intervals;
4. kept: among candidates with ``p <= alpha / K`` (Bonferroni over the K scored; family-wise level
   `alpha` = 1 % per step) whose main parameter's interval excludes zero, the one with the
   smallest held-out gap. Members of its look-alike group that fit as well (within `tie_db`) or
   were not refit make the step name the *group*; otherwise the member is named;
5. the full (nonlinear) twin is simulated with the fitted effect (confirmation) and becomes the
   current model. Stop when nothing is significant and identified, or at `max_steps`.

Lines still missing at the end are reported as unexplained, with their kinematic description
(or "no kinematic match"), never assigned to an effect that failed the test.

**Model.** The current model's complex Hann spectrum ``Z0`` per record segment (fold) and the
first-order response ``J`` of that spectrum to the candidate's parameters (``jax.jvp`` through
the diffrax solve, exact in parameters that enter the parts linearly) give::

    A_model(theta, g) = g |Z0 + J theta|

The fit compares levels ``L = 20 log10(A + F)`` (``F`` the measured noise floor, added before
the log as in :mod:`dtwin.identify.gap`) with ``optimistix.least_squares`` (Levenberg–Marquardt,
``jac="fwd"``) with a free gain per fold, over the *fit bins*: the candidate's signature bins plus the bins where the
current model has a line. Non-negative parameters are fitted as ``exp(u)``. Starts: the
dominant eigenvector of the signature-weighted response ``sum_k w_k Re(J_k^H J_k)`` scaled to
the excess power, its negative and a third of it (one batched ``vmap``).

The model level includes the expected noise, ``A -> sqrt(A^2 + F^2 / ln 2)``.

**Held-out statistic.** With the parameters fitted on segment A, on segment B the reduction
of the squared level error over the signature bins (levels with the expected noise)::

    T = sum_{k in signature bins of B} [ (L_meas − L_before)^2 − (L_meas − L_after)^2 ]

pooled over both directions (A→B, B→A). (A likelihood ratio of the amplitudes would be more
powerful on a perfect model but punishes every small misfit of a line 40 dB over the floor;
the level error is bounded and robust to the base model's own imperfections.) When the fit
stays at "no effect" T is exactly 0; such ties get a randomised p-value
(:func:`p_value`), so the test is exactly calibrated at every level. Under the null (no effect) the signature bins of the
measurement hold only noise; its distribution is drawn by a parametric bootstrap that repeats
the whole fit on noise spectra with the measured floor's level and the Hann window's bin
correlation, the floor re-estimated in every draw (:func:`null_statistics`), so the p-value is calibrated without asymptotics.

**Modules.** The stages, in the order a step walks them (``loop``: :func:`discover`):
``search`` (the run's fixed inputs and the state its steps change), ``locate`` (the residual
lines and the current model's held-out gaps), ``specialise`` (the candidates specialised to the
machine, the record and again after a step; the extended model about them), ``propose``
(covering candidates, the score screen, the refit set), ``refit`` (a candidate's linearised
fit, held-out statistic, bootstrap p-value and intervals), ``confirm`` (the best simulated in
full), ``decide`` (naming, the step's record, the search's result). Their tools: ``settings``
(:class:`DiscoverySettings`), ``statistics`` (the linearised fit, the held-out statistic, its
bootstrap null, intervals), ``model`` (:class:`ExtendedModel` and its cache), ``coverage``
(coverage, signature bins and labels, specialisation), ``in_range`` (a refit inside the
physical range), ``depth`` (fault depths), ``results`` (result types), ``effects`` (the
candidate effects).

Arrays are padded to fixed sizes (parameters to the smallest of ``P_SIZES`` that holds the
effect's, bins to a multiple of ``BIN_BLOCK``) so that one compilation serves every candidate of
a size.
"""

from .coverage import coverage as coverage
from .coverage import signature_labels as signature_labels
from .depth import fault_depths as fault_depths
from .loop import discover as discover
from .model import ExtendedModel as ExtendedModel
from .model import extended_model as extended_model
from .results import CandidateResult as CandidateResult
from .results import DiscoveryResult as DiscoveryResult
from .results import Step as Step
from .settings import DiscoverySettings as DiscoverySettings
from .statistics import BIN_BLOCK as BIN_BLOCK
from .statistics import CHI2_1_99 as CHI2_1_99
from .statistics import MAX_LM_STEPS as MAX_LM_STEPS
from .statistics import P_MAX as P_MAX
from .statistics import T_RESOLUTION as T_RESOLUTION
from .statistics import FitInputs as FitInputs
from .statistics import amplitude_profile as amplitude_profile
from .statistics import candidate_inputs as candidate_inputs
from .statistics import chi2_quantile as chi2_quantile
from .statistics import expected_level as expected_level
from .statistics import fit_fold as fit_fold
from .statistics import fit_joint as fit_joint
from .statistics import heldout_statistic as heldout_statistic
from .statistics import is_identified as is_identified
from .statistics import model_amplitudes as model_amplitudes
from .statistics import normal_quantile as normal_quantile
from .statistics import null_statistics as null_statistics
from .statistics import p_value as p_value
from .statistics import residual_variance as residual_variance
from .statistics import theta_of as theta_of
from .statistics import white_noise_spectra as white_noise_spectra

__all__ = [
    "BIN_BLOCK",
    "CHI2_1_99",
    "CandidateResult",
    "DiscoveryResult",
    "DiscoverySettings",
    "ExtendedModel",
    "FitInputs",
    "MAX_LM_STEPS",
    "P_MAX",
    "Step",
    "T_RESOLUTION",
    "amplitude_profile",
    "candidate_inputs",
    "fault_depths",
    "chi2_quantile",
    "coverage",
    "discover",
    "expected_level",
    "extended_model",
    "fit_fold",
    "fit_joint",
    "heldout_statistic",
    "is_identified",
    "model_amplitudes",
    "normal_quantile",
    "null_statistics",
    "p_value",
    "residual_variance",
    "signature_labels",
    "theta_of",
    "white_noise_spectra",
]
