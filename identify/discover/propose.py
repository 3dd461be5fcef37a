"""Propose: which candidates a step refits.

The candidates whose signature covers at least `min_coverage` of the residual line power
(:func:`dtwin.identify.discover.coverage.coverage`), scored at zero amplitude by a score test
(:func:`~dtwin.identify.discover.statistics.screen_score`, one response column per parameter,
no refit) on one bin set shared by all, and the refit set (:func:`_refit_set`): the best
`max_refit` by score, and another group's best when those are all look-alikes of one group.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from ..gap import segment_spectra
from .coverage import _bins_of, _dilate, coverage
from .results import CandidateResult
from .statistics import screen_score

if TYPE_CHECKING:
    from .locate import Current
    from .model import ExtendedModel
    from .search import Search, State


class StepSpectra:
    """A step's spectra of the candidates, about the step's model: each candidate's response
    per fold (computed once, :meth:`response_spectra`) and its signature bins
    (:meth:`signature_bins`); `model_line`: the bins where the current model has a line."""

    def __init__(self, search: Search, model: ExtendedModel, cur: Current):
        self.search = search
        self.model = model
        self.model_line = _dilate(np.abs(cur.Z0) * np.exp(cur.lg0)[:, None]
                                  > search.floor * 10 ** (search.settings.threshold_db / 20.0))
        self._spectra: dict[int, np.ndarray] = {}

    def response_spectra(self, i) -> np.ndarray:
        """Candidate `i`'s response spectra per fold, (F, K, p)."""
        if i not in self._spectra:
            _, Jc = segment_spectra(self.model.response(i).T, self.search.fs,
                                    self.search.settings.n_folds)  # (p, F, K)
            self._spectra[i] = np.moveaxis(Jc, 0, -1)  # (F, K, p)
        return self._spectra[i]

    def signature_bins(self, e) -> np.ndarray:
        """The bins of effect `e`'s signature lines, (F, K); off the model's lines unless the
        effect modifies them."""
        s = self.search
        sig_lines = [x.frequency for x in e.signature(s.kin, s.f_max)]
        sig = np.broadcast_to(_bins_of(sig_lines, s.df, s.nb), s.Y.shape)
        if not getattr(e, "modifies_model_lines", False):
            sig = sig & ~self.model_line
        return sig


@dataclasses.dataclass(eq=False)
class Proposal:
    """The candidates of a step (:func:`propose`)."""

    #: ``(coverage, index, matched lines)`` of the covering candidates, ranked (by score, or by
    #: coverage without screening); every candidate's coverage by name
    covering: list
    cov_all: dict[str, float]
    #: screening scores by candidate index: ``(score, df, log10 p)``
    scores: dict[int, tuple[float, int, float]]
    #: the candidates refit (:func:`_refit_set`) and those screened out
    ranked: list
    screened_out: list
    #: the number of candidates tried (Bonferroni) and the step's level ``alpha / K``
    K_tried: int
    level: float
    spectra: StepSpectra


def _covering(search: Search, state: State, lines) -> tuple[list, dict[str, float]]:
    """Candidates not yet added that cover at least `min_coverage` of the residual lines,
    ranked by coverage, and every such candidate's coverage by name."""
    covering = []
    cov_all: dict[str, float] = {}
    for i, e in enumerate(state.candidates):
        if e.name in state.added:
            continue
        cov, matched = coverage(e, search.kin, lines, search.tol_full, search.f_max,
                                search.f_lo)
        cov_all[e.name] = cov
        if cov >= search.settings.min_coverage:
            covering.append((cov, i, matched))
    covering.sort(key=lambda t: -t[0])
    return covering, cov_all


def _refit_set(covering, candidates, max_refit: int):
    """The candidates a step refits: the first `max_refit` of `covering` (ranked), and, when
    there are two or more and all of them are look-alikes of one group (members that make the
    same lines in different ways, :mod:`dtwin.identify.discover.effects`), also the first candidate of
    another group: a step compares explanations of two kinds, not only two members of one."""
    ranked = list(covering[:max_refit])
    groups = {candidates[i].group for _, i, _ in ranked}
    if len(ranked) >= 2 and len(groups) == 1:
        other = next((t for t in covering[max_refit:] if candidates[t[1]].group not in groups),
                     None)
        if other is not None:
            ranked.append(other)
    return ranked


def propose(search: Search, state: State, cur: Current) -> Proposal | None:
    """The step's candidates: covering, screened and ranked, and the refit set (None when no
    candidate covers the residual lines)."""
    settings, say, candidates, model = search.settings, search.say, state.candidates, state.model
    covering, cov_all = _covering(search, state, cur.lines)
    if not covering:
        return None
    spectra = StepSpectra(search, model, cur)
    scores: dict[int, tuple[float, int, float]] = {}
    if settings.screen == "score":
        # score every covering candidate at zero amplitude (one response column per
        # parameter, no refit), on one bin set shared by all: their signature bins and the
        # model's lines; refit the best max_refit (and another group's best: _refit_set)
        model.ensure_responses([i for _, i, _ in covering])
        common = spectra.model_line.copy()
        for _, i, _ in covering:
            common = common | spectra.signature_bins(candidates[i])
        for _, i, _ in covering:
            scores[i] = screen_score(cur.Z0, spectra.response_spectra(i), search.Y,
                                     search.floor, cur.lg0, common)
        covering.sort(key=lambda t: (scores[t[1]][2], -t[0]))
        K_tried = len(covering)
    ranked = _refit_set(covering, candidates, settings.max_refit)
    refit_idx = {i for _, i, _ in ranked}
    screened_out = [t for t in covering if t[1] not in refit_idx]
    if len(ranked) > settings.max_refit:
        say(f"  the best {settings.max_refit} are look-alikes of group "
            f"{candidates[ranked[0][1]].group}: {candidates[ranked[-1][1]].name} "
            f"(group {candidates[ranked[-1][1]].group}) refit as well")
    if settings.screen == "coverage":
        K_tried = len(ranked)
    for k, (cov, i, _) in enumerate(covering):
        if i in scores:
            say(f"  score {candidates[i].name}: {scores[i][0]:.1f} ({scores[i][1]} df, "
                f"log10 p {scores[i][2]:.1f}), rank {k + 1}, coverage {cov:.2f}")
    return Proposal(covering, cov_all, scores, ranked, screened_out, K_tried,
                    settings.alpha / K_tried, spectra)


def candidate_result(e, cov, matched, prop: Proposal, i) -> CandidateResult:
    """A fresh result for candidate `i` (effect `e`), with its screening score and rank
    (nothing without screening)."""
    cr = CandidateResult(e.name, e.group, cov, matched,
                         main_name=getattr(e, "main_name", ""),
                         main_unit=getattr(e, "main_unit", ""))
    if i in prop.scores:
        cr.score, cr.score_df, cr.score_log10p = prop.scores[i]
        cr.score_rank = 1 + [j for _, j, _ in prop.covering].index(i)
    return cr


def screened_results(candidates, prop: Proposal) -> list[CandidateResult]:
    """Results of the candidates scored but not refit."""
    out = []
    for cov, i, matched in prop.screened_out:
        cr = candidate_result(candidates[i], cov, matched, prop, i)
        cr.screened = (f"screened out, score {cr.score:.3g} ({cr.score_df} df), "
                       f"rank {cr.score_rank}")
        out.append(cr)
    return out
