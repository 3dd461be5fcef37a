"""Result types of a discrepancy search: one candidate refit, one accepted step, the outcome."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..gap import GapResult
from ..lines import Kinematics, ResidualLine
from .settings import DiscoverySettings


@dataclasses.dataclass
class CandidateResult:
    """One candidate refit in a step."""

    name: str
    group: str
    coverage: float
    matched: list[ResidualLine]
    statistic: float = float("nan")
    p_value: float = float("nan")
    gap_after: float = float("nan")
    identified: bool = False
    significant: bool = False
    theta: np.ndarray | None = None
    sigma: np.ndarray | None = None
    main: float = float("nan")
    main_sigma: float = float("nan")
    main_interval: tuple[float, float] = (float("nan"), float("nan"))
    evidence: float = float("nan")
    log_gains: np.ndarray | None = None
    #: why the candidate was set aside (a fitted value outside its physical range, a refit that
    #: failed); None when it was judged on its statistics
    rejected: str | None = None
    #: a linearised fit outside the parameters' physical range, and how it was refitted inside
    #: it in full simulation (:mod:`dtwin.identify.discover.in_range`); None when it was inside
    out_of_range: str | None = None
    #: score statistic at zero amplitude (screening), its degrees of freedom, log10 of its χ²
    #: tail and its rank among the candidates scored in the step (1 = most significant)
    score: float = float("nan")
    score_df: int = 0
    score_log10p: float = float("nan")
    score_rank: int = 0
    #: "screened out, score …, rank k" for a candidate scored but not refit; None when refit
    screened: str | None = None
    #: name and physical unit of the main value `main` (the effect's ``main_name`` and
    #: ``main_unit``, "1" for dimensionless); "" where unknown
    main_name: str = ""
    main_unit: str = ""

    def to_dict(self) -> dict:
        return dict(name=self.name, group=self.group, coverage=self.coverage,
                    statistic=self.statistic, p_value=self.p_value, gap_after=self.gap_after,
                    identified=self.identified, significant=self.significant,
                    main=self.main, main_name=self.main_name, main_unit=self.main_unit,
                    main_sigma=self.main_sigma,
                    main_interval=list(self.main_interval), evidence=self.evidence,
                    rejected=self.rejected, out_of_range=self.out_of_range, score=self.score,
                    score_df=self.score_df,
                    score_log10p=self.score_log10p, score_rank=self.score_rank,
                    screened=self.screened)


def candidate_verdict(c: CandidateResult, step: Step | None, level: float | None
                      ) -> tuple[str, str]:
    """Whether candidate `c` was accepted or set aside, and why, in words: the one verdict
    that the terminal, ``discover.json``, ``discover.md`` and ``report.html`` all print.

    **Arguments:** `c`; `step`, the step that judged it (None for the last step, which accepted
    nothing); `level`, that step's family-wise level (None where unknown).

    **Returns:** ``(outcome, why)``, outcome ``"accepted"`` or ``"set aside"``. The reasons,
    in the order they are checked: screened out (scored, not refit), rejected (a calibration
    shortfall, a failed refit, not kept once simulated in full), not significant (p above the
    level, or the search's gap not lowered), amplitude not identified (its profile interval
    includes zero), significant and identified but another candidate closed the gap more.
    """
    if step is not None and c.name == step.effect:
        how = ("amplitude identified (its profile interval excludes zero)"
               if c.out_of_range is None else
               "amplitude identified by the linearised fit's profile interval, then refitted "
               "inside its physical range in full simulation (no interval)")
        return "accepted", (f"p = {c.p_value:.2g} ≤ {step.level:.2g}, {how}, held-out gap "
                            "lower simulated in full")
    if c.screened:
        return "set aside", c.screened
    if c.rejected:
        return "set aside", c.rejected
    if not c.significant:
        if level is not None and not c.p_value <= level:
            return "set aside", f"not significant: p = {c.p_value:.2g} > {level:.2g}"
        if level is None and c.p_value == c.p_value:
            return "set aside", f"not significant (p = {c.p_value:.2g})"
        return "set aside", "did not lower the search's gap"
    if not c.identified:
        return "set aside", "amplitude not identified: its interval includes zero"
    return "set aside", (f"significant and identified, but {step.effect} closed the gap more"
                         if step is not None else "significant and identified, not confirmed")



@dataclasses.dataclass
class Step:
    """One accepted effect: what was added, why, with which values, and the gaps.

    `gap_before`, `gap_after` (the linearised model at the joint fit) and `gap_confirmed` (the
    twin with the effect simulated in full) are the search's gaps, over the bins
    `DiscoverySettings.threshold_db` over the floor, which its decisions compare.
    `heldout_before` and `heldout_after` are the held-out gaps as reported
    (`DiscoverySettings.gap_threshold_db`; by default the family-wise definition of
    :func:`dtwin.identify.gap.gap`, as calibration's) of the twin before the step and of the
    twin with the effect, simulated in full."""

    number: int
    effect: str
    group: str
    named: str
    indistinguishable_from: list[str]
    matched_lines: list[ResidualLine]
    parameters: list[dict]
    main: dict
    p_value: float
    level: float
    gap_before: GapResult
    gap_after: GapResult
    gap_confirmed: GapResult
    candidates: list[CandidateResult]
    #: the effect's own label (its signature) of each matched line
    matched_labels: list[str] = dataclasses.field(default_factory=list)
    #: what was added, in words ("load/speed fluctuation at 2.10 Hz")
    summary: str = ""
    #: held-out gaps as reported, before the step and with the effect (class docstring)
    heldout_before: GapResult | None = None
    heldout_after: GapResult | None = None
    #: for a local tooth fault, its depth as ``dtwin severity`` fits it (severity, peak
    #: stiffness loss, 95 % intervals, status: :func:`dtwin.identify.discover.depth.fault_depths`);
    #: None when not fitted
    depth: dict | None = None

    def to_dict(self) -> dict:
        return dict(
            number=self.number, effect=self.effect, group=self.group, named=self.named,
            depth=self.depth,
            summary=self.summary,
            indistinguishable_from=self.indistinguishable_from,
            matched_lines=[dict(r.to_dict(), signature=lab) for r, lab in
                           zip(self.matched_lines, self.matched_labels or
                               [""] * len(self.matched_lines), strict=True)],
            parameters=self.parameters, main=self.main, p_value=self.p_value, level=self.level,
            gap_before=self.gap_before.to_dict(), gap_after=self.gap_after.to_dict(),
            gap_confirmed=self.gap_confirmed.to_dict(),
            heldout_before=None if self.heldout_before is None else self.heldout_before.to_dict(),
            heldout_after=None if self.heldout_after is None else self.heldout_after.to_dict(),
            candidates=[c.to_dict() for c in self.candidates])


@dataclasses.dataclass
class DiscoveryResult:
    """Outcome of :func:`discover` (``to_dict`` for JSON; spectra kept for the figures).

    `initial_gap` and `final_gap` are the held-out gaps of the base twin and of the final one as
    reported (`DiscoverySettings.gap_threshold_db`: by default the family-wise definition of
    :func:`dtwin.identify.gap.gap`, as calibration's)."""

    kinematics: Kinematics
    f_sun: float
    sample_rate: float
    settings: DiscoverySettings
    steps: list[Step]
    initial_gap: GapResult
    final_gap: GapResult
    unexplained: list[ResidualLine]
    extra_in_model: list[ResidualLine]
    chance_match_probability: float
    stop_reason: str
    last_candidates: list[CandidateResult]
    freqs: np.ndarray
    measured: np.ndarray
    models: list[np.ndarray]
    residuals: list[list[ResidualLine]]
    timing_s: float = 0.0
    #: combs and the located modulation in the last residual lines (scored as families)
    combs: list = dataclasses.field(default_factory=list)
    modulation: object = None
    #: the steps before which the candidates were specialised again from the current model's
    #: residual and the model rebuilt about it (`DiscoverySettings.respecialise`)
    respecialised: list[int] = dataclasses.field(default_factory=list)
    #: the bottom of the scored band (Hz): the lowest knot of a calibrated sensor response,
    #: ``0.8 N f_c``; the lines below are listed, not scored (:mod:`dtwin.identify.gap`)
    scored_from: float = 0.0

    @property
    def named(self) -> list[str]:
        return [s.named for s in self.steps]

    @property
    def groups(self) -> list[str]:
        return [s.group for s in self.steps]

    def to_dict(self) -> dict:
        return dict(
            f_sun=self.f_sun, sample_rate=self.sample_rate,
            kinematics=dataclasses.asdict(self.kinematics),
            settings=dataclasses.asdict(self.settings),
            steps=[s.to_dict() for s in self.steps],
            initial_gap=self.initial_gap.to_dict(), final_gap=self.final_gap.to_dict(),
            unexplained=[r.to_dict() for r in self.unexplained],
            extra_in_model=[r.to_dict() for r in self.extra_in_model],
            chance_match_probability=self.chance_match_probability,
            stop_reason=self.stop_reason,
            last_candidates=[c.to_dict() for c in self.last_candidates],
            combs=[c.to_dict() for c in self.combs],
            modulation=None if self.modulation is None else self.modulation.to_dict(),
            respecialised=list(self.respecialised), timing_s=self.timing_s,
            scored_from_hz=self.scored_from,
            candidate_table=self.candidate_table())

    def candidate_table(self) -> list[dict]:
        """One row per candidate judged in each step, the last (unaccepted) step included: the
        single source of what the terminal, ``discover.json``, ``discover.md`` and
        ``report.html`` say of each candidate.

        Keys: ``step``; ``candidate`` and its ``group``; ``coverage`` (share of the residual
        lines' excess power on its signature, 0–1); the screening ``score`` at zero amplitude,
        its degrees of freedom ``score df`` and ``rank`` (NaN, 0, 0 where not scored); the
        search's gap before the step and with the candidate (``gap before (dB)``, ``gap with
        it (dB)``, linearised); ``p-value`` against the step's family-wise ``level``;
        ``identified`` (the candidate's :attr:`CandidateResult.identified`, as decided in the
        refit); the fitted ``main`` value with its ``main unit`` and its ``interval``
        (``[low, high]`` in the same unit, None where there is none); ``out of range`` (a
        linearised fit outside the physical range and how it was refitted, None otherwise);
        ``outcome`` and ``why`` (:func:`candidate_verdict`)."""
        rows: list[dict] = []

        def add(number: int, step: Step | None, cands, before: float | None,
                level: float | None) -> None:
            for c in cands:
                outcome, why = candidate_verdict(c, step, level)
                lo, hi = (float(v) for v in c.main_interval)
                rows.append({"step": number, "candidate": c.name, "group": c.group,
                             "coverage": float(c.coverage), "score": float(c.score),
                             "score df": int(c.score_df), "rank": int(c.score_rank),
                             "gap before (dB)": before,
                             "gap with it (dB)": float(c.gap_after),
                             "p-value": float(c.p_value), "level": level,
                             "identified": bool(c.identified), "main": float(c.main),
                             "main unit": c.main_unit,
                             "interval": [lo, hi] if lo == lo and hi == hi else None,
                             "out of range": c.out_of_range, "outcome": outcome, "why": why})

        for s in self.steps:
            add(s.number, s, s.candidates, float(s.gap_before.total), float(s.level))
        kept = {id(c) for s in self.steps for c in s.candidates}
        last = [c for c in self.last_candidates if id(c) not in kept]
        if last:  # the step that accepted nothing: its level as the search set it (alpha / K)
            before = float(self.steps[-1].gap_confirmed.total) if self.steps else None
            k = (sum(1 for c in last if not c.screened) if self.settings.screen == "coverage"
                 else len(last))
            add(len(self.steps) + 1, None, last, before, self.settings.alpha / max(k, 1))
        return rows

