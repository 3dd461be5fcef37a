"""Decide: what a step records once a candidate is kept, and what the search reports.

:func:`accept` names the kept candidate, or its look-alike group when a member fits as well
or was not refit (:func:`_ties`), states its parameters and main amplitude with their
intervals, records the :class:`~dtwin.identify.discover.results.Step` and makes the twin with it
the current one. :func:`outcome` assembles the :class:`~dtwin.identify.discover.results.DiscoveryResult`.
"""

from __future__ import annotations

import dataclasses
import time
from typing import TYPE_CHECKING

import numpy as np

from ..gap import segment_spectra
from .coverage import signature_labels
from .results import CandidateResult, DiscoveryResult, Step

if TYPE_CHECKING:
    from .confirm import Kept
    from .locate import Current
    from .propose import Proposal
    from .search import Search, State


def _ties(best: CandidateResult, candidates, tried: dict[str, CandidateResult],
          cov_all: dict[str, float], settings) -> list[str]:
    """The members of the kept candidate's group the data do not tell apart from it: a member
    not refit is told apart only when its signature covers (almost) none of the residual
    lines (one that covers them but was not refit may fit as well); one refit, when its
    linearised gap is worse by `tie_db` or more."""
    members = [e.name for e in candidates if e.group == best.group and e.name != best.name]
    return [nm for nm in members
            if (nm not in tried and cov_all.get(nm, 0.0) >= settings.min_coverage)
            or (nm in tried and (not np.isfinite(tried[nm].gap_after)
                                 or tried[nm].gap_after - best.gap_after < settings.tie_db))]


def accept(search: Search, state: State, cur: Current, prop: Proposal,
           refits: list[CandidateResult], results: list[CandidateResult], kept: Kept,
           step_no: int) -> None:
    """Record step `step_no` with the kept candidate (`refits`: the step's refit candidates,
    `results`: all its candidates) and make the twin with it the current model."""
    settings, kin, z = search.settings, search.kin, search.z
    best, i_best = kept.best, kept.index
    state.theta_units, state.m_sig = kept.theta_units, kept.m_sig
    tried = {c.name: c for c in refits}
    ties = _ties(best, state.candidates, tried, prop.cov_all, settings)
    named = best.name if not ties else best.group
    gap_lin = best.gap_after
    e_best = state.candidates[i_best]
    params = [dict(name=q.name, unit=q.unit, value=float(v), sigma=float(s),
                   interval=[float(v - z * s), float(v + z * s)])
              for q, v, s in zip(state.model.parameters[i_best], best.theta, best.sigma,
                                 strict=True)]
    main = dict(name=e_best.main_name, unit=e_best.main_unit, value=best.main,
                sigma=best.main_sigma,
                interval=list(best.main_interval),
                interval_kind=(f"profile of the overall amplitude, {100 * settings.confidence:g} %"
                               if best.out_of_range is None else
                               f"none: {best.out_of_range}"),
                delta_method_sigma=best.main_sigma,
                typical_range=list(e_best.typical_range), typical_note=e_best.typical_note)
    gap_now = cur.gap_now
    gap_after = dataclasses.replace(gap_now, total=gap_lin,
                                    bands=dict(gap_now.bands, all=gap_lin))
    state.steps.append(Step(step_no, best.name, best.group, named, ties, best.matched, params,
                            main, best.p_value, prop.level, gap_now, gap_after, kept.gap_conf,
                            results,
                            signature_labels(e_best, kin, best.matched, search.tol_full,
                                             search.f_max),
                            getattr(e_best, "summary", e_best.description), cur.held_now,
                            kept.held_after))
    state.added.add(best.name)
    if getattr(e_best, "f_x", None) is not None:
        state.added_fx.append((float(e_best.f_x), step_no))
    search.say(f"  added {best.name} (named {named}); held-out gap {cur.held_now.total:.2f} → "
               f"{kept.held_after.total:.2f} dB; the search's {gap_now.total:.2f} → "
               f"{gap_lin:.2f} dB (confirmed {kept.gap_conf.total:.2f})")


def outcome(search: Search, state: State, cur: Current, initial_gap, stop: str,
            last_cands: list[CandidateResult], t_start: float) -> DiscoveryResult:
    """The search's result: its steps, the held-out gap of the base and the final twin, the
    lines left unexplained (measured) and extra (in the model), the last step's candidates;
    `t_start`: the search's start (``time.perf_counter``)."""
    final_lines = state.residual_sets[-1]
    unexplained = [r for r in final_lines if r.side == "measured"]
    extra = [r for r in final_lines if r.side == "model"]
    _, Zf = segment_spectra(state.m_sig, search.fs, search.settings.n_folds)
    final_gap = search.reported_gap(search.heldout_spectra(Zf))
    return DiscoveryResult(search.kin, search.f_sun, search.fs, search.settings, state.steps,
                           initial_gap, final_gap, unexplained, extra, search.chance, stop,
                           last_cands, search.freqs_full, search.a_full, state.models,
                           state.residual_sets, time.perf_counter() - t_start, cur.combs, cur.modulation,
                           state.respecialised, search.f_lo)
