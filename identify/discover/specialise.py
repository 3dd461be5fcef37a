"""Specialise: the candidates fitted to the machine and the record, and the extended model
about them.

:func:`first_model` specialises the candidates to the machine (spec, base twin), then to the
record (the base twin's residual lines), and builds the extended model
(:func:`dtwin.identify.discover.model.extended_model`); :func:`respecialise` specialises them
again from the current model's residual after a step and rebuilds the model about the current
twin when that offers a new candidate covering the residual lines.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from dtwin.errors import DtwinError
from dtwin.signal.spectrum import amplitude_spectrum, noise_floor
from dtwin.spec.build import build_twin, twin_kind

from ..gap import FLOOR_BINS, segment_spectra
from ..lines import residual_lines
from .coverage import _adapted, coverage
from .effects.base import EffectContext
from .locate import Current, _labelled, locate
from .model import extended_model
from .search import State, _log_gain

if TYPE_CHECKING:
    from .search import Search


def first_model(search: Search, base_twin, kind, candidates) -> State:
    """The search's first state: the base twin (``build_twin(spec, kind=kind)`` unless given),
    the candidates specialised to the machine first, then to the record (the base twin's
    residual lines), and the extended model about them; a second model only when the record
    changed the set."""
    spec, settings, kin, fs = search.spec, search.settings, search.kin, search.fs
    if base_twin is None:
        base_twin = build_twin(spec, kind=twin_kind(spec, kind, default=spec["model"]["kind"]),
                               f_sun=search.f_sun)
    ctx = EffectContext(spec, base_twin, kin, threshold_db=settings.threshold_db,
                        tolerance_bins=settings.tolerance_bins)
    originals = candidates
    candidates = _adapted(originals, ctx)
    model = extended_model(base_twin, candidates, kin, search.daq, search.n, search.f_sun,
                           settings.solver(), settings.response)
    m_sig = model.base_signal()
    _, Zb = segment_spectra(m_sig, fs, settings.n_folds)
    _, Yb = segment_spectra(search.x, fs, settings.n_folds)
    lgb = [_log_gain(np.abs(Yb[f]), Zb[f], noise_floor(np.abs(Yb[f]), FLOOR_BINS),
                     settings.threshold_db) for f in range(settings.n_folds)]
    _, m_b = amplitude_spectrum(m_sig * float(np.exp(np.mean(lgb))), fs, "hann")
    floor_b = noise_floor(search.a_full, FLOOR_BINS)
    lines_b = residual_lines(search.freqs_full, search.a_full, np.asarray(m_b), kin,
                             threshold_db=settings.threshold_db, excess_db=settings.excess_db,
                             tolerance_bins=settings.tolerance_bins, f_max=search.f_max)
    lines_b, _, mod_b = _labelled(lines_b, kin, search.tol_full, search.f_max)
    ctx = dataclasses.replace(ctx, freqs=search.freqs_full, measured=search.a_full,
                              model=np.asarray(m_b), floor=floor_b, lines=tuple(lines_b),
                              modulation=mod_b)
    with_data = _adapted(originals, ctx)
    if with_data != candidates:
        search.say("candidates specialised to the record: "
                   + ", ".join(repr(e) for e in with_data if e not in candidates))
        candidates = with_data
        model = extended_model(base_twin, candidates, kin, search.daq, search.n, search.f_sun,
                               settings.solver(), settings.response)
        m_sig = model.base_signal()
    return State(originals, ctx, candidates, model, m_sig, np.zeros(model.size))


def respecialise(search: Search, state: State, cur: Current, step_no: int) -> Current:
    """The candidates specialised again from the current model's residual: where that offers
    one the earlier residual withdrew and it covers the residual lines (a housing resonance
    that lifts the comb of the fault just added), the model is rebuilt about the current twin
    (the added effects at their fitted values), so every response is linearised there. A model
    that cannot be built or simulated leaves the current one. Returns the current model
    against the record (located again after a rebuild)."""
    settings, kin = search.settings, search.kin
    # the effects added since `model` was built (those before are in its base twin)
    twin_now = state.model.twin(state.theta_units, [i for i, e in enumerate(state.candidates)
                                                    if e.name in state.added])
    ctx_now = dataclasses.replace(state.ctx, base_twin=twin_now, model=cur.m_full,
                                  lines=tuple(cur.lines), modulation=cur.modulation)
    again = [e for e in _adapted(state.originals, ctx_now) if e.name not in state.added]
    # only a new candidate that covers the current residual is worth a rebuild: one
    # that does not would be neither scored nor refit in this step
    new = [e for e in again if e.name not in {c.name for c in state.candidates}
           and coverage(e, kin, cur.lines, search.tol_full, search.f_max,
                        search.f_lo)[0]
           >= settings.min_coverage]
    if not new:
        return cur
    offered = ", ".join(getattr(e, "summary", e.name) for e in new)
    try:  # a model that cannot be built or simulated leaves the current one
        rebuilt = extended_model(twin_now, again, kin, search.daq, search.n, search.f_sun,
                                 settings.solver(), settings.response)
        sig_new = rebuilt.base_signal()
    except (DtwinError, FloatingPointError, ValueError) as err:
        search.say(f"step {step_no}: the current residual offers {offered}, but the model "
                   f"about the current twin failed ({type(err).__name__}: {err}); the "
                   "candidates stay as they were")
        return cur
    search.say(f"step {step_no}: the current residual offers {offered}; candidates "
               "specialised again and linearised about the current model")
    state.candidates, state.model, state.m_sig = again, rebuilt, sig_new
    state.theta_units = np.zeros(state.model.size)
    state.respecialised.append(step_no)
    return locate(search, state.m_sig, state.added_fx)
