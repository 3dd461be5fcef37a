"""Confirm: the kept candidate simulated in full.

Among the candidates significant and identified, in order of their linearised held-out gap,
the first whose full (nonlinear) twin at the joint fit lowers the search's held-out gap and
does not raise the reported one is kept (:func:`confirm`); one fitted outside its physical
range is simulated at trial values inside it and the best is taken
(:mod:`dtwin.identify.discover.in_range`). The others are marked not kept.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from ..gap import GapResult, segment_spectra
from .in_range import in_range_trials, refit_in_range
from .results import CandidateResult

if TYPE_CHECKING:
    from .locate import Current
    from .search import Search, State


@dataclasses.dataclass(frozen=True)
class Kept:
    """The candidate kept (:func:`confirm`) and the twin with it."""

    best: CandidateResult
    #: its index in the state's candidates
    index: int
    #: the model's parameters (fitting units) and signal with it
    theta_units: np.ndarray
    m_sig: np.ndarray
    #: the held-out gap of the simulated twin: the search's and as reported
    gap_conf: GapResult
    held_after: GapResult


def _simulated(search: Search, state: State, i_c: int, th):
    """The held-out gap (search's, a :class:`GapResult`) of the twin with candidate `i_c` at
    `th` (physical units), the values, the model's parameters, signal and held-out fold
    spectra."""
    model = state.model
    theta_c = state.theta_units.copy()
    theta_c[model.slice(i_c)] = th / model.scales[model.slice(i_c)]
    sig_c = model.signal(theta_c)
    _, Z1 = segment_spectra(sig_c, search.fs, search.settings.n_folds)
    a1 = search.heldout_spectra(Z1)
    return search.search_gap(a1), th, theta_c, sig_c, a1


def confirm(search: Search, state: State, cur: Current, ok: list[CandidateResult]) -> Kept | None:
    """The first of `ok` (by linearised gap) whose simulated twin lowers the search's held-out
    gap (bins over ``threshold_db``) and does not raise the reported one (the family-wise
    threshold's bins: what the step prints as "held-out gap A → B", and its verdict calls
    "held-out gap lower simulated in full"); None when none does."""
    for cand in sorted(ok, key=lambda c: c.gap_after):
        i_c = next(i for i, e in enumerate(state.candidates) if e.name == cand.name)
        trials = [cand.theta] if cand.out_of_range is None else \
            in_range_trials(cand.theta, [q.bounds for q in state.model.parameters[i_c]])
        tried_c = [_simulated(search, state, i_c, th) for th in trials]
        gap_c, th, theta_c, sig_c, a1 = min(tried_c, key=lambda t: t[0].total)
        if cand.out_of_range is not None:
            refit_in_range(cand, th, state.candidates[i_c], [t[0].total for t in tried_c],
                           search.say)
        held_c = search.reported_gap(a1)
        if gap_c.total < cur.gap_now.total and held_c.total <= cur.held_now.total:
            return Kept(cand, i_c, theta_c, sig_c, gap_c, held_c)
        cand.significant = False
        if gap_c.total < cur.gap_now.total:
            cand.rejected = (f"not kept: simulated in full, the search's gap went "
                             f"{cur.gap_now.total:.2f} → {gap_c.total:.2f} dB but the reported "
                             f"held-out gap rose {cur.held_now.total:.2f} → "
                             f"{held_c.total:.2f} dB")
        else:
            cand.rejected = (f"not kept: simulated in full, the held-out gap went "
                             f"{cur.gap_now.total:.2f} → {gap_c.total:.2f} dB (linearised "
                             f"{cand.gap_after:.2f} dB)")
        search.say(f"  {cand.name} {cand.rejected}")
    return None
