"""The discrepancy search loop (:func:`discover`): the stages walked step by step (the method
in the package docstring).

Per step: locate the residual lines (:mod:`.locate`), specialise the candidates again from them
(:mod:`.specialise`), propose the candidates to refit (:mod:`.propose`), refit and test them on
held-out folds (:mod:`.refit`), confirm the best in full simulation (:mod:`.confirm`) and record
the step (:mod:`.decide`); the search's fixed inputs and changing state: :mod:`.search`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from .confirm import confirm
from .decide import accept, outcome
from .effects import registered_effects
from .locate import locate
from .propose import propose, screened_results
from .refit import refit_all
from .results import DiscoveryResult
from .search import open_search
from .settings import DiscoverySettings
from .specialise import first_model, respecialise


def discover(
    record,
    spec,
    *,
    sample_rate: float | None = None,
    f_sun: float | None = None,
    base_twin=None,
    kind: str | None = None,
    candidates: Sequence | None = None,
    settings: DiscoverySettings = DiscoverySettings(),
    log=None,
) -> DiscoveryResult:
    """Find what the twin is missing, name it, add it, refit, and repeat (docs/discovery.md).

    **Arguments:**

    - `record`: a :class:`dtwin.io.Record` (first channel) or a 1-D signal with `sample_rate`.
    - `f_sun`: the input speed (Hz), if known; otherwise the record's tachometer, metadata or
      lines give it (:func:`dtwin.identify.operating_point.resolve_speed`).
    - `spec`: the gearbox spec (`dtwin.spec.Spec`, path or mapping): kinematics, DAQ and the
      base twin (``build_twin(spec, kind=kind)``) unless `base_twin` is given (e.g. the twin
      fitted by :func:`dtwin.identify.fit.fit`).
    - `candidates`: effects to try (default: :func:`dtwin.identify.discover.effects.registered_effects`).
    - `settings`: :class:`DiscoverySettings`.
    - `log`: a callable receiving progress lines (default: silent).

    **Returns:** :class:`DiscoveryResult`.
    """
    t_start = time.perf_counter()
    say = log or (lambda s: None)
    search = open_search(record, spec, sample_rate, f_sun, settings, say)
    candidates = list(candidates) if candidates is not None else registered_effects()
    state = first_model(search, base_twin, kind, candidates)
    stop, last_cands, initial_gap = "budget", [], None
    for step_no in range(1, settings.max_steps + 2):
        cur = locate(search, state.m_sig, state.added_fx)
        if state.steps and settings.respecialise and step_no <= settings.max_steps:
            cur = respecialise(search, state, cur, step_no)
        if initial_gap is None:
            initial_gap = cur.held_now
        state.models.append(cur.m_full)
        state.residual_sets.append(cur.lines)
        if step_no > settings.max_steps:
            break
        say(f"step {step_no}: held-out gap {cur.held_now.total:.2f} dB (the search's, over "
            f"{settings.threshold_db:g} dB: {cur.gap_now.total:.2f} dB), "
            f"{sum(r.side == 'measured' for r in cur.lines)} residual lines")
        prop = propose(search, state, cur)
        if prop is None:
            stop, last_cands = "no candidate covers the residual lines", []
            break
        refits = refit_all(search, state, cur, prop, step_no)
        last_cands = results = refits + screened_results(state.candidates, prop)
        ok = [c for c in results if c.significant and c.identified]
        if not ok:
            stop = "no candidate significant and identified"
            break
        kept = confirm(search, state, cur, ok)
        if kept is None:
            stop = "no candidate reduced the held-out gap once simulated in full"
            break
        accept(search, state, cur, prop, refits, results, kept, step_no)
    return outcome(search, state, cur, initial_gap, stop, last_cands, t_start)
