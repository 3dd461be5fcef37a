"""Settings of a discrepancy search (:func:`dtwin.identify.discover.discover`)."""

from __future__ import annotations

import dataclasses

from dtwin.errors import SettingsError
from dtwin.simulation.simulate import SolverOptions


@dataclasses.dataclass(frozen=True)
class DiscoverySettings:
    """Settings of :func:`discover` (defaults documented in ``docs/discovery.md``).

    - `alpha`: family-wise level of each step's decision (Bonferroni over the candidates refit
      in the step): a candidate is kept only with p ≤ alpha / (number refit).
    - `n_boot`: bootstrap draws of the null statistic per candidate (raised to K / alpha so that
      the smallest attainable p-value lies below the level).
    - `threshold_db`, `excess_db`, `tolerance_bins`: residual-line detection (dtwin.identify.lines).
      `threshold_db` also sets the bins of the search's own gaps, which its decisions compare
      (:attr:`Step.gap_before`, `gap_after`, `gap_confirmed`): every bin where the record or
      the model stands that high over the floor, so that lines as weak as those the search
      looks for can show a candidate's worth.
    - `gap_threshold_db`: height over the floor (dB) of the bins of the **reported** held-out
      gap (:attr:`DiscoveryResult.initial_gap`, `final_gap`, :attr:`Step.heldout_before`,
      `heldout_after`). None (default): the family-wise threshold of
      :func:`dtwin.identify.gap.gap`, the one calibration reports, which noise alone reaches
      anywhere in the band with probability 1 % (17.1 dB on a 4 s, 5 kHz record), where at
      12 dB a noise bin enters the gap of a healthy record about once in six.
    - `max_steps`: budget of effects added; `max_refit`: candidates refit per step.
    - `screen`: how the candidates to refit are chosen among those covering `min_coverage`:
      ``"score"`` (default) ranks every one of them by its score statistic at zero amplitude
      (:func:`dtwin.identify.discover.statistics.screen_score`: one response column per
      parameter, no refit) and refits the best `max_refit`; the Bonferroni correction is then
      over every candidate scored, so the family-wise level `alpha` holds whatever the
      screening picks. ``"coverage"`` refits the `max_refit` of largest coverage, Bonferroni
      over those refit. Either way, when the `max_refit` chosen are all look-alikes of one
      group, the best candidate of another group is refit with them.
    - `min_coverage`: a candidate must cover this fraction of the residual line power.
    - `tie_db`: members of one look-alike group whose held-out gaps differ by less are not told
      apart (the group is named).
    - `confidence`: level of the parameter intervals (``value ± z sigma``) and of the
      identification decision: a candidate is identified when its profile interval at this
      level excludes zero (:func:`dtwin.identify.discover.statistics.is_identified`).
    - `rtol`, `atol`: solver tolerances of the model simulations; `response`: ``"fd"`` or
      ``"jvp"`` (:meth:`ExtendedModel.ensure_responses`).
    - `periodic`: ``"auto"`` (default) simulates a constant-speed, periodic model over a
      settling time and one period of the gear set and tiles it, checking the periodicity and
      settling longer, then integrating the whole record, where it fails
      (`dtwin.simulation.simulate.settling_sequence`); ``"off"`` always integrates the whole record.
    - `respecialise`: after each added effect, specialise the candidates again from the current
      model's residual; where that offers a candidate the earlier residual withdrew and it
      covers `min_coverage` of the residual lines, rebuild the model about the current twin
      (one more compilation and one response per candidate parameter). ``False``: candidates
      specialised once, from the base twin's residual.
    """

    n_folds: int = 2
    alpha: float = 0.01
    n_boot: int = 400
    threshold_db: float = 12.0
    gap_threshold_db: float | None = None
    excess_db: float = 6.0
    tolerance_bins: float = 0.25
    max_steps: int = 3
    max_refit: int = 2
    screen: str = "score"
    min_coverage: float = 0.05
    tie_db: float = 0.2
    confidence: float = 0.99
    seed: int = 0
    rtol: float = 1e-4
    atol: float = 1e-4
    response: str = "fd"
    periodic: str = "auto"
    respecialise: bool = True

    def __post_init__(self):
        if self.screen not in ("score", "coverage"):
            raise SettingsError(f"screen must be 'score' or 'coverage', got {self.screen!r}")
        if self.gap_threshold_db is not None and not self.gap_threshold_db > 0.0:
            raise SettingsError("gap_threshold_db must be a height over the noise floor above "
                                f"0 dB, or None (family-wise), got {self.gap_threshold_db!r}")
        if self.max_refit < 1:
            raise SettingsError(f"max_refit must be at least 1, got {self.max_refit!r}")

    def solver(self):
        """Solver options of the model simulations (forward-mode responses)."""
        return SolverOptions(rtol=self.rtol, atol=self.atol, adjoint="forward",
                             periodic=self.periodic)

