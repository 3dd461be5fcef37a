"""Refit: each candidate of the refit set fitted about the current model and tested on
held-out data.

Per candidate (:func:`refit_candidate`): set aside when its lines are the calibration's
shortfall (:mod:`dtwin.identify.shortfall`); otherwise the linearised fit
(:mod:`dtwin.identify.discover.statistics`) gives the held-out statistic ``T``, the held-out
gap with the linearised model, the bootstrap p-value against the step's level
(:func:`_heldout_test`), the joint fit's parameter intervals and the profile interval of the
main amplitude (:func:`_joint_fit`). A candidate whose refit fails is set aside; one fitted
outside its physical range is marked for a refit inside it (:mod:`.in_range`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from dtwin import _maps
from dtwin.errors import DtwinError

from ..shortfall import SHORTFALL_SHARE, shortfall_share
from .propose import candidate_result
from .results import CandidateResult
from .statistics import (
    amplitude_profile,
    candidate_inputs,
    fit_joint,
    heldout_statistic,
    is_identified,
    null_statistics,
    p_value,
    residual_variance,
    theta_of,
)

if TYPE_CHECKING:
    from .locate import Current
    from .propose import Proposal
    from .search import Search, State


def refit_all(search: Search, state: State, cur: Current, prop: Proposal,
              step_no: int) -> list[CandidateResult]:
    """The results of the candidates of the refit set, in its order."""
    settings = search.settings
    # the smallest attainable p-value 1/(B+1) must lie below the level alpha/K
    n_boot = max(settings.n_boot, int(np.ceil(prop.K_tried / settings.alpha)))
    state.model.ensure_responses([i for _, i, _ in prop.ranked])
    # one padded bin count for every candidate refit in the step, never below the previous
    # step's: one compilation of the fits and the bootstrap serves them all
    sp = prop.spectra
    state.n_bins = max([state.n_bins] + [int((sp.signature_bins(state.candidates[i])
                                              | sp.model_line).any(axis=0).sum())
                                         for _, i, _ in prop.ranked])
    results: list[CandidateResult] = []
    for cov, i, matched in prop.ranked:
        _maps.relieve()  # a safe point between candidates' programs (dtwin._maps)
        results.append(refit_candidate(search, state, cur, prop, (cov, i, matched), step_no,
                                       n_boot))
    return results


def refit_candidate(search: Search, state: State, cur: Current, prop: Proposal, entry,
                    step_no: int, n_boot: int) -> CandidateResult:
    """Candidate `entry` ``(coverage, index, matched lines)`` refit and tested; one candidate
    never ends the run: a failure sets it aside."""
    say = search.say
    cov, i, matched = entry
    e = state.candidates[i]
    cr = candidate_result(e, cov, matched, prop, i)
    share, on = shortfall_share(matched, search.shortfall_orders, search.f_sun, search.df)
    if share >= SHORTFALL_SHARE:  # the healthy machine shows the same lines
        cr.rejected = (f"calibration shortfall: {100 * share:.0f} % of its lines' excess "
                       f"lies on lines the calibrated twin left unexplained on the "
                       f"healthy calibration record(s) ({', '.join(f'{f:.2f}' for f in on[:6])}"
                       f" Hz{', …' if len(on) > 6 else ''}): not a finding")
        cr.significant = cr.identified = False
        say(f"  {e.name} set aside: {cr.rejected}")
        return cr
    try:  # one candidate never ends the run: a failure sets it aside
        say(f"  refit {e.name} (coverage {cov:.2f})")
        inp, fold_params, p = _heldout_test(search, state, cur, prop, cr, i, step_no, n_boot)
        _joint_fit(search, state, cr, i, inp, fold_params, p)
        say(f"    T {cr.statistic:.1f} p {cr.p_value:.4f} (level {prop.level:.4f}) "
            f"gap {cr.gap_after:.2f} dB "
            f"main {cr.main:.3g} [{cr.main_interval[0]:.3g}, {cr.main_interval[1]:.3g}] "
            f"identified {cr.identified}")
        out = [f"{q.name} = {v:.4g} {q.unit} lies outside its physical range "
               f"[{q.bounds[0]:g}, {q.bounds[1]:g}]"
               for q, v in zip(state.model.parameters[i], cr.theta, strict=True)
               if not q.bounds[0] <= v <= q.bounds[1]]
        if out:  # the linearised model extrapolated: refit inside the range in full
            cr.out_of_range = "; ".join(out)
            say(f"    {cr.out_of_range}: refit inside its range if it is kept")
    except (DtwinError, FloatingPointError, np.linalg.LinAlgError, ValueError) as err:
        cr.rejected = f"refit failed: {type(err).__name__}: {err}"
    if cr.rejected:
        cr.significant = cr.identified = False
        say(f"    set aside: {cr.rejected}")
    return cr


def _heldout_test(search: Search, state: State, cur: Current, prop: Proposal,
                  cr: CandidateResult, i: int, step_no: int, n_boot: int):
    """The held-out statistic ``T``, the held-out gap with the linearised model (parameters
    from the other fold), the bootstrap p-value and significance, set on `cr`. Returns the fit
    inputs, the fold parameters and the candidate's parameter count."""
    settings, sp = search.settings, prop.spectra
    Jc = sp.response_spectra(i)  # (F, K, p)
    sig = sp.signature_bins(state.candidates[i])
    ps = state.model.parameters[i]
    p = Jc.shape[-1]
    inp, sel, _ = candidate_inputs(cur.Z0, Jc, search.Y, search.floor, sig, sp.model_line,
                                   [q.nonnegative for q in ps], cur.lg0, state.n_bins)
    nonneg = np.asarray(inp.nonneg)
    active = np.asarray(inp.active)
    T, fold_params = heldout_statistic(inp)
    T = float(T)
    fold_params = np.asarray(fold_params)
    # held-out gap with the linearised model, parameters from the other fold
    a_lin = np.zeros_like(search.Y)
    for f in range(settings.n_folds):
        pf = fold_params[1 - f]
        th = theta_of(pf, nonneg, active)[:p]
        a_f = np.exp(pf[-1]) * np.abs(cur.Z0[f] + Jc[f] @ th)
        a_lin[f] = a_f
    cr.gap_after = search.search_gap(a_lin).total
    cr.statistic = T
    # bootstrap null
    # the draws stop once the decision p > level is certain; each candidate has
    # its own stream of draws (the same whichever candidates are refit before it)
    rng_c = np.random.default_rng([settings.seed, step_no, i])
    t_null = null_statistics(inp, rng_c, n_boot, cur.Z0, search.floor, sel, search.seg_len,
                             stop=(T, prop.level))
    cr.p_value = p_value(T, t_null, rng_c)
    cr.significant = cr.p_value <= prop.level and cr.gap_after < cur.gap_now.total
    return inp, fold_params, p


def _joint_fit(search: Search, state: State, cr: CandidateResult, i: int, inp,
               fold_params, p: int) -> None:
    """The joint fit over both folds, set on `cr`: parameters and their intervals, the main
    amplitude with its delta-method sigma and profile interval, identification, fold gains."""
    settings, model = search.settings, state.model
    e = state.candidates[i]
    nonneg = np.asarray(inp.nonneg)
    active = np.asarray(inp.active)
    val, loss, jac, r = fit_joint(inp, fold_params)
    n_par = p + settings.n_folds
    P = inp.J.shape[-1]  # the padded parameter count
    keep = np.r_[np.arange(p), P + np.arange(settings.n_folds)]
    Jk = jac[:, keep]
    s2 = residual_variance(inp, r, n_par)
    try:
        cov_u = s2 * np.linalg.inv(Jk.T @ Jk)
    except np.linalg.LinAlgError:
        cov_u = np.full((n_par, n_par), np.inf)
    u = val[:p]
    dth = np.where(nonneg[:p] > 0, np.exp(np.clip(u, -700, 700)), 1.0)  # dθ/du
    th_units = theta_of(val, nonneg, active)[:p]
    scales = model.scales[model.slice(i)]
    cr.theta = th_units * scales
    cr.sigma = np.sqrt(np.abs(np.diag(cov_u)[:p])) * dth * scales
    gmain = np.asarray(jax.grad(e.main)(jnp.asarray(cr.theta)))
    cov_th = cov_u[:p, :p] * np.outer(dth * scales, dth * scales)
    cr.main = float(e.main(jnp.asarray(cr.theta)))
    cr.main_sigma = float(np.sqrt(max(gmain @ cov_th @ gmain, 0.0)))
    # identified: the profile interval of the overall amplitude excludes zero (more
    # reliable than the delta method for a norm near zero, and scale-free)
    c_lo, c_hi, evidence = amplitude_profile(inp, val, s2, search.chi2)
    cr.main_interval = (c_lo * cr.main, c_hi * cr.main)
    cr.evidence = evidence
    cr.identified = is_identified(c_lo, evidence, cr.main, settings.confidence)
    cr.log_gains = val[P:]
